//! `iai table write` / `iai table read`: the core's transfer and read-back
//! engines driven over a [`Link`] in real time.
//!
//! Writing: the transfer engine packs the records into controller-sized
//! commands, confirms each, and reads them back as its verification policy
//! asks, rewriting a frame that reads back different; what may still
//! arrive on the line (late replies, copies) is the link's line's to
//! settle. Its guarantee says what the controller is known to hold.

use std::collections::BTreeMap;
use std::time::Duration;

use iai_protocol_b::engine::Engine;
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::profile::Profile;
use iai_protocol_b::readback::ReadBackStats;
use iai_protocol_b::transfer::{Guarantee, TransferStats};
use iai_protocol_b::{
    Failure, LineConfig, ReadBack, ReadBackConfig, Station, Transfer, TransferConfig, Verify,
};

use crate::link::Link;

/// Longest wait for one read, so that an interruption is seen promptly.
const POLL_CAP: Duration = Duration::from_millis(200);

/// The controller's kind and the line's settings.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// The profile: buffer sizes, the table write (26DH on a TTA, 245H on a
    /// 2003 X-SEL) and its read-back query (21FH, 209H).
    pub profile: Profile,
    /// Station, timeouts, duplicate window.
    pub line: LineConfig,
}

impl Plan {
    /// The spec's line settings for `station` on a controller of `profile`.
    pub fn new(profile: Profile, station: Station) -> Self {
        Plan {
            profile,
            line: LineConfig::new(station),
        }
    }

    /// The write message.
    pub fn write_stream(&self) -> PositionStream {
        self.profile.table_write()
    }

    fn read_config(&self, first: u16, last: u16) -> ReadBackConfig {
        ReadBackConfig::new(self.profile, first, last)
    }
}

/// Why a table operation stopped.
#[derive(Debug)]
pub enum TableError {
    /// The engine gave up (after its retries).
    Engine(Failure),
    /// The line failed.
    Io(std::io::Error),
    /// The user interrupted.
    Interrupted,
}

impl std::fmt::Display for TableError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TableError::Engine(Failure::Timeout { sends }) => {
                write!(f, "the controller did not answer ({sends} sends, 3 s each)")
            }
            TableError::Engine(Failure::Controller { code, .. }) => {
                write!(f, "{}", crate::codes::answered_with(*code))
            }
            TableError::Engine(Failure::Mismatch {
                first_position,
                records,
            }) => write!(
                f,
                "the controller does NOT hold the table: {records} record(s) of a frame still read back different after rewriting it (first: position {first_position})"
            ),
            TableError::Engine(Failure::InvalidRecord { index, error }) => {
                write!(f, "record {} cannot be encoded: {error}", index + 1)
            }
            TableError::Engine(e) => write!(f, "{e}"),
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

/// What `run` does to an engine after an error response: resume it.
type Resume<'r, G> = &'r mut dyn FnMut(&mut G, &mut Link);

/// Runs `engine` on `link` to its result; `between` runs before each turn
/// (progress) and says whether the engine moved on. An error response is
/// answered by `resume` up to [`ERROR_RESENDS`] times in a row (moving on
/// resets the count).
fn run<G: Engine>(
    link: &mut Link,
    engine: &mut G,
    hooks: &Hooks<'_>,
    mut between: impl FnMut(&mut G) -> bool,
    mut resume: Option<Resume<'_, G>>,
) -> Result<G::Output, TableError> {
    let mut refusals = 0;
    loop {
        if between(engine) {
            refusals = 0;
        }
        if (hooks.stop)() {
            return Err(TableError::Interrupted);
        }
        match link.turn(engine, POLL_CAP).map_err(TableError::Io)? {
            None => {}
            Some(Ok(out)) => return Ok(out),
            Some(Err(Failure::Controller { code, .. })) if refusals < ERROR_RESENDS => {
                let Some(resume) = resume.as_mut() else {
                    return Err(TableError::Engine(Failure::Controller {
                        code,
                        detail: None,
                    }));
                };
                refusals += 1;
                (hooks.note)(&format!(
                    "{}; sending again ({refusals} of {ERROR_RESENDS})",
                    crate::codes::answered_with(code)
                ));
                resume(engine, link);
            }
            Some(Err(e)) => return Err(TableError::Engine(e)),
        }
    }
}

/// Writes `records` (in order) over `link`, verified as `verify` asks.
/// `progress` is called with the number of records confirmed (and
/// verified as the policy asks) so far. Returns the guarantee and the
/// counters (also after a failure: `records_confirmed` says how far it
/// went).
pub fn write(
    link: &mut Link,
    plan: &Plan,
    verify: Verify,
    records: impl Iterator<Item = PositionRecord>,
    total: u32,
    mut progress: impl FnMut(u32),
    hooks: &Hooks<'_>,
) -> (Result<Guarantee, TableError>, TransferStats) {
    let cfg = TransferConfig::new(plan.profile).with_verify(verify);
    let mut t: Transfer<_, FRAME> = Transfer::new(cfg, records).with_total(total);
    let mut last = u32::MAX;
    let result = run(
        link,
        &mut t,
        hooks,
        |t| {
            let done = t.stats().records_confirmed;
            let moved = done != last;
            if moved {
                progress(done);
                last = done;
            }
            moved
        },
        Some(&mut |t: &mut Transfer<_, FRAME>, link: &mut Link| {
            let now = link.now();
            t.resume(link.line_mut(), now);
        }),
    );
    (result, t.stats())
}

/// Reads positions `first..=last` over `link`, calling `each` for every
/// defined record, in order. Error responses are answered as in
/// [`write()`].
pub fn read(
    link: &mut Link,
    plan: &Plan,
    first: u16,
    last: u16,
    mut each: impl FnMut(PositionRecord),
    hooks: &Hooks<'_>,
) -> Result<ReadBackStats, TableError> {
    let mut rb: ReadBack<FRAME> = ReadBack::new(plan.read_config(first, last));
    let mut refusals = 0;
    loop {
        let mut delivered = false;
        let result = {
            let mut engine = rb.delivering(|recs| {
                delivered = true;
                recs.for_each(&mut each);
            });
            run(link, &mut engine, hooks, |_| false, None)
        };
        if delivered {
            refusals = 0;
        }
        match result {
            Err(TableError::Engine(Failure::Controller { code, .. }))
                if refusals < ERROR_RESENDS =>
            {
                refusals += 1;
                (hooks.note)(&format!(
                    "{}; asking again ({refusals} of {ERROR_RESENDS})",
                    crate::codes::answered_with(code)
                ));
                rb.resume();
            }
            r => return r,
        }
    }
}

/// Reads back the positions of `records` (records a state file says were
/// confirmed earlier) and returns those the controller does not hold as
/// they are: missing, or different.
pub fn not_held(
    link: &mut Link,
    plan: &Plan,
    records: &[PositionRecord],
    hooks: &Hooks<'_>,
) -> Result<Vec<PositionRecord>, TableError> {
    let (Some(first), Some(last)) = (
        records.iter().map(|r| r.number).min(),
        records.iter().map(|r| r.number).max(),
    ) else {
        return Ok(Vec::new());
    };
    // The last copy of a position in the file is what it holds.
    let want: BTreeMap<u16, &PositionRecord> = records.iter().map(|r| (r.number, r)).collect();
    let mut held = BTreeMap::new();
    read(
        link,
        plan,
        first,
        last,
        |r| {
            held.insert(r.number, r);
        },
        hooks,
    )?;
    Ok(want
        .into_values()
        .filter(|r| held.get(&r.number) != Some(*r))
        .cloned()
        .collect())
}
