//! `iai table write` / `iai table read`: the core's transfer and read-back
//! engines driven over a [`Link`] in real time.
//!
//! Writing: the transfer engine packs the records into controller-sized
//! commands, confirms each (timeouts, resends and the guards against late
//! and duplicated replies are the engine's), and reads them back as its
//! verification policy asks, rewriting a frame that reads back different.
//! Its report says what the controller is known to hold.

use std::time::Duration;

use iai_protocol_b::frame::Station;
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::profile::Profile;
use iai_protocol_b::readback::{ReadBack, ReadBackConfig, ReadStep};
use iai_protocol_b::transfer::{
    Step, Transfer, TransferConfig, TransferError, TransferReport, Verify,
};

use crate::link::Link;

/// Longest wait for one read, so that an interruption is seen promptly.
const POLL_CAP: Duration = Duration::from_millis(200);

/// The messages and limits used for a controller profile.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// The profile.
    pub profile: Profile,
    /// Station addressed.
    pub station: Station,
    /// The write message (26DH on a TTA, 245H on a 2003 X-SEL).
    pub write: PositionStream,
    /// The query response layout (21FH on a TTA, 209H on a 2003 X-SEL).
    pub read: PositionStream,
    /// How long a reply may still come twice (the engines' guard against
    /// duplicated replies); `None` keeps the engines' default (3 s).
    pub duplicate_window_ms: Option<u32>,
}

impl Plan {
    /// The messages a profile supports: the 4-digit ones where it has them.
    pub fn new(profile: Profile, station: Station) -> Self {
        let (write, read) = if profile.supports(PositionStream::CHANGE_2.id) {
            (PositionStream::CHANGE_2, PositionStream::QUERY_2_RESPONSE)
        } else {
            (PositionStream::CHANGE, PositionStream::QUERY_RESPONSE)
        };
        Plan {
            profile,
            station,
            write,
            read,
            duplicate_window_ms: None,
        }
    }

    fn transfer_config(&self, verify: Verify) -> TransferConfig {
        let mut cfg = TransferConfig {
            stream: self.write,
            max_frame: self.profile.max_command_frame(),
            max_response: self.profile.max_response_frame(),
            ..TransferConfig::tta(self.station)
        }
        .with_verify(verify);
        if let Some(ms) = self.duplicate_window_ms {
            cfg.exchange.duplicate_window_ms = ms;
        }
        cfg
    }

    fn read_config(&self, first: u16, last: u16) -> ReadBackConfig {
        let mut cfg = ReadBackConfig {
            stream: self.read,
            max_response: self.profile.max_response_frame(),
            ..ReadBackConfig::tta(self.station, first, last)
        };
        if let Some(ms) = self.duplicate_window_ms {
            cfg.exchange.duplicate_window_ms = ms;
        }
        cfg
    }
}

/// Why a table operation stopped.
#[derive(Debug)]
pub enum TableError {
    /// The engine gave up (after its retries).
    Engine(TransferError),
    /// The line failed.
    Io(std::io::Error),
    /// The user interrupted.
    Interrupted,
}

impl std::fmt::Display for TableError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TableError::Engine(TransferError::Timeout) => {
                write!(f, "the controller did not answer (3 sends, 3 s each)")
            }
            TableError::Engine(TransferError::Controller { code }) => {
                write!(f, "the controller answered with error code {code:03X}")
            }
            TableError::Engine(TransferError::Bridge { code }) => {
                write!(f, "a bridge on the line answered with its error code {code:03X}")
            }
            TableError::Engine(TransferError::Mismatch {
                first_position,
                records,
            }) => write!(
                f,
                "the controller does NOT hold the table: {records} record(s) of a frame still read back different after rewriting it (first: position {first_position})"
            ),
            TableError::Engine(TransferError::InvalidRecord { index, error }) => {
                write!(f, "record {} cannot be encoded: {error}", index + 1)
            }
            TableError::Engine(TransferError::Config(e)) => write!(f, "{e}"),
            TableError::Engine(TransferError::Io(never)) => match *never {},
            TableError::Io(e) => write!(f, "the line failed: {e}"),
            TableError::Interrupted => write!(f, "interrupted"),
        }
    }
}

/// The frame buffer for the engines: the largest frame any profile allows.
const FRAME: usize = 2051;

/// What a table operation tells its caller, and asks it.
#[derive(Clone, Copy)]
pub struct Hooks<'a> {
    /// A line for the user (an error response answered by a resend).
    pub note: &'a dyn Fn(&str),
    /// Whether the user asked to stop.
    pub stop: &'a dyn Fn() -> bool,
}

/// Error responses to one frame that `write` answers by sending it again
/// (position writes are idempotent; the engine itself stops at the first,
/// leaving the decision to its caller).
pub const ERROR_RESENDS: u32 = 3;

/// Writes `records` (in order) over `link`, verified as `verify` asks.
/// An error response stops the engine; up to [`ERROR_RESENDS`] of them in
/// a row are answered by resuming (the frame, or its read-back, is sent
/// again), and `note` is told.
/// `progress` is called with the number of records confirmed (and
/// verified as the policy asks) so far; `stop` is polled for an
/// interruption. The second member is that number when it ended.
pub fn write(
    link: &mut Link,
    plan: &Plan,
    verify: Verify,
    records: impl Iterator<Item = PositionRecord>,
    total: u32,
    mut progress: impl FnMut(u32),
    hooks: &Hooks<'_>,
) -> (Result<TransferReport, TableError>, u32) {
    let Hooks { note, stop } = *hooks;
    let mut refusals = 0;
    let mut t: Transfer<_, FRAME> =
        Transfer::new(plan.transfer_config(verify), records).with_total(total);
    let mut buf = [0u8; 4096];
    let mut last = u32::MAX;
    loop {
        let now = link.now();
        let done = t.stats().records_confirmed;
        if done != last {
            progress(done);
            last = done;
            refusals = 0;
        }
        if stop() {
            return (Err(TableError::Interrupted), done);
        }
        match t.poll(now) {
            Step::Transmit(bytes) => {
                if let Err(e) = link.write_all(bytes) {
                    return (Err(TableError::Io(e)), done);
                }
                t.sent(link.now());
            }
            Step::WaitUntil(until) => {
                let left = Duration::from_millis(u64::from(until.saturating_sub(now)));
                match link.read_for(&mut buf, left.min(POLL_CAP)) {
                    Ok(0) => {}
                    Ok(n) => t.received_all(buf.get(..n).unwrap_or(&[]), link.now()),
                    Err(e) => return (Err(TableError::Io(e)), done),
                }
            }
            // The source is a finished iterator: it never waits.
            Step::NeedRecords => std::thread::sleep(Duration::from_millis(1)),
            Step::Complete(report) => return (Ok(report), report.stats.records_confirmed),
            Step::Failed(TransferError::Controller { code }) if refusals < ERROR_RESENDS => {
                refusals += 1;
                note(&format!(
                    "the controller answered with error code {code:03X}; sending again ({refusals} of {ERROR_RESENDS})"
                ));
                t.resume(link.now());
            }
            Step::Failed(e) => return (Err(TableError::Engine(e)), done),
        }
    }
}

/// Reads positions `first..=last` over `link`, calling `each` for every
/// defined record (a window the engine reads again delivers its records
/// late: key them by number). Error responses are answered as in
/// [`write()`].
pub fn read(
    link: &mut Link,
    plan: &Plan,
    first: u16,
    last: u16,
    mut each: impl FnMut(PositionRecord),
    hooks: &Hooks<'_>,
) -> Result<(), TableError> {
    let Hooks { note, stop } = *hooks;
    let mut rb: ReadBack<FRAME> = ReadBack::new(plan.read_config(first, last));
    let mut refusals = 0;
    let mut pending: Vec<u8> = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        if stop() {
            return Err(TableError::Interrupted);
        }
        let now = link.now();
        if !pending.is_empty() {
            let used = rb.received_all(&pending, now);
            pending.drain(..used.min(pending.len()));
        }
        match rb.poll(now) {
            ReadStep::Transmit(q) => {
                link.write_all(q).map_err(TableError::Io)?;
                rb.sent(link.now());
            }
            ReadStep::WaitUntil(until) => {
                if pending.is_empty() {
                    let left = Duration::from_millis(u64::from(until.saturating_sub(now)));
                    let n = link
                        .read_for(&mut buf, left.min(POLL_CAP))
                        .map_err(TableError::Io)?;
                    pending.extend_from_slice(buf.get(..n).unwrap_or(&[]));
                } else {
                    // Bytes the engine did not take yet: offer them again
                    // after the next poll.
                    let used = rb.received_all(&pending, link.now());
                    if used == 0 {
                        pending.clear();
                    } else {
                        pending.drain(..used.min(pending.len()));
                    }
                }
            }
            ReadStep::Records(recs) => {
                refusals = 0;
                recs.for_each(&mut each);
            }
            ReadStep::Complete(_) => return Ok(()),
            ReadStep::Failed(TransferError::Controller { code }) if refusals < ERROR_RESENDS => {
                refusals += 1;
                note(&format!(
                    "the controller answered with error code {code:03X}; asking again ({refusals} of {ERROR_RESENDS})"
                ));
                rb.resume(link.now());
            }
            ReadStep::Failed(e) => return Err(TableError::Engine(e)),
        }
    }
}
