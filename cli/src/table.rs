//! `iai table write` / `iai table read`: the core's transfer and read-back
//! engines driven over a [`Link`] in real time.
//!
//! Writing: the transfer engine packs the records into controller-sized
//! commands and confirms each (timeouts and retries are the engine's).
//! Verification then reads the written positions back with the read-back
//! engine and compares them record by record; a record that differs is
//! written again and read again (at most [`REPAIR_ROUNDS`] times). Only a
//! table read back equal counts as held by the controller.

use std::collections::BTreeMap;
use std::time::Duration;

use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::profile::Profile;
use iai_protocol_b::readback::{ReadBack, ReadBackConfig, ReadStep};
use iai_protocol_b::stream::PositionStream;
use iai_protocol_b::transfer::{Step, Transfer, TransferConfig, TransferError, TransferStats};

use crate::link::Link;

/// Times a verification may rewrite the records that read back wrong.
pub const REPAIR_ROUNDS: u32 = 3;

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
        }
    }

    fn transfer_config(&self) -> TransferConfig {
        TransferConfig {
            stream: self.write,
            max_frame: self.profile.max_command_frame(),
            ..TransferConfig::tta(self.station)
        }
    }

    fn read_config(&self, first: u16, last: u16) -> ReadBackConfig {
        ReadBackConfig {
            stream: self.read,
            max_response: self.profile.max_response_frame(),
            ..ReadBackConfig::tta(self.station, first, last)
        }
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
            TableError::Engine(TransferError::ErrorResponse { code }) => {
                write!(f, "the controller kept refusing with error code {code:03X}")
            }
            TableError::Engine(TransferError::InvalidRecord { index, error }) => {
                write!(f, "record {} cannot be encoded: {error}", index + 1)
            }
            TableError::Engine(e) => write!(f, "{e:?}"),
            TableError::Io(e) => write!(f, "the line failed: {e}"),
            TableError::Interrupted => write!(f, "interrupted"),
        }
    }
}

/// The frame buffer for the engines: the largest frame any profile allows.
const FRAME: usize = 2051;

/// Writes `records` (in order) over `link`. `progress` is called with the
/// number of records confirmed so far; `stop` is polled for an
/// interruption. On failure the records confirmed so far are in the error
/// path's stats (second tuple member).
pub fn write(
    link: &mut Link,
    plan: &Plan,
    records: impl Iterator<Item = PositionRecord>,
    total: u32,
    mut progress: impl FnMut(u32),
    stop: &dyn Fn() -> bool,
) -> (Result<TransferStats, TableError>, u32) {
    let mut t: Transfer<_, FRAME> =
        Transfer::new(plan.transfer_config(), records).with_total(total);
    let mut buf = [0u8; 4096];
    let mut last = u32::MAX;
    loop {
        let now = link.now();
        let done = t.stats().records_confirmed;
        if done != last {
            progress(done);
            last = done;
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
                    Ok(n) => t.received(buf.get(..n).unwrap_or(&[]), link.now()),
                    Err(e) => return (Err(TableError::Io(e)), done),
                }
            }
            // The source is a finished iterator: it never waits.
            Step::NeedRecords => std::thread::sleep(Duration::from_millis(1)),
            Step::Complete(stats) => return (Ok(stats), stats.records_confirmed),
            Step::Failed(e) => return (Err(TableError::Engine(e)), done),
        }
    }
}

/// Reads positions `first..=last` over `link`, calling `each` for every
/// defined record in order.
pub fn read(
    link: &mut Link,
    plan: &Plan,
    first: u16,
    last: u16,
    mut each: impl FnMut(PositionRecord),
    stop: &dyn Fn() -> bool,
) -> Result<(), TableError> {
    let mut rb: ReadBack<FRAME> = ReadBack::new(plan.read_config(first, last));
    let mut pending: Vec<u8> = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        if stop() {
            return Err(TableError::Interrupted);
        }
        let now = link.now();
        if !pending.is_empty() {
            let used = rb.received(&pending, now);
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
                    let used = rb.received(&pending, link.now());
                    if used == 0 {
                        pending.clear();
                    } else {
                        pending.drain(..used.min(pending.len()));
                    }
                }
            }
            ReadStep::Records(recs) => recs.for_each(&mut each),
            ReadStep::Complete(_) => return Ok(()),
            ReadStep::Failed(e) => return Err(TableError::Engine(e)),
        }
    }
}

/// One difference between the file and the controller.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mismatch {
    /// Position number.
    pub number: u16,
    /// What the controller holds (`None`: not defined).
    pub found: Option<PositionRecord>,
}

/// Reads back the positions of `expected` and lists those that differ.
pub fn verify(
    link: &mut Link,
    plan: &Plan,
    expected: &BTreeMap<u16, PositionRecord>,
    stop: &dyn Fn() -> bool,
) -> Result<Vec<Mismatch>, TableError> {
    let mut mismatches = Vec::new();
    // Read contiguous runs of numbers, so that a sparse table does not
    // read 65,536 positions.
    let numbers: Vec<u16> = expected.keys().copied().collect();
    let mut runs: Vec<(u16, u16)> = Vec::new();
    for n in numbers {
        match runs.last_mut() {
            Some((_, hi)) if u32::from(n) <= u32::from(*hi) + 64 => *hi = n,
            _ => runs.push((n, n)),
        }
    }
    for (lo, hi) in runs {
        let mut seen: BTreeMap<u16, PositionRecord> = BTreeMap::new();
        read(
            link,
            plan,
            lo,
            hi,
            |r| {
                seen.insert(r.number, r);
            },
            stop,
        )?;
        for (n, want) in expected.range(lo..=hi) {
            let got = seen.remove(n);
            if got.as_ref() != Some(want) {
                mismatches.push(Mismatch {
                    number: *n,
                    found: got,
                });
            }
        }
    }
    Ok(mismatches)
}
