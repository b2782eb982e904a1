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

use std::cell::Cell;
use std::ops::RangeInclusive;

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::engine::Engine;
use iai_protocol_b::frame::Frame;
use iai_protocol_b::message::{
    ClearPositionData, EffectivePositionCountQuery, EffectivePositionCountResponse, Fields,
    Message, Request,
};
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::profile::Profile;
use iai_protocol_b::readback::{ReadBackStats, ReplyRecords};
use iai_protocol_b::transfer::{Guarantee, TransferStats};
use iai_protocol_b::upload::{Upload, UploadConfig};
use iai_protocol_b::{
    client::Client, error::Failure, frame::Station, line::LineConfig, readback::ReadBack,
    readback::ReadBackConfig, transfer::Transfer, transfer::TransferConfig, transfer::Verify,
};

use crate::fields::{tree, Node};
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

    /// The highest position number the profile's read-back query carries
    /// (FFFFH for 21FH's 4 digits, FFFH for 209H's 3).
    pub fn last_position(&self) -> u16 {
        let digits = u32::from(self.write_stream().read_back().layout.number_width);
        u16::try_from((1u32 << (4 * digits)) - 1).unwrap_or(u16::MAX)
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
    /// Nothing was sent: the request cannot be expressed (why).
    Refused(String),
}

impl std::fmt::Display for TableError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TableError::Engine(Failure::Timeout { sends }) => {
                write!(f, "the controller did not answer ({sends} send(s))")
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
            TableError::Refused(why) => write!(f, "{why}"),
        }
    }
}

/// The frame buffer for the engines: the largest frame any profile allows.
const FRAME: usize = iai_protocol_b::limits::LARGEST_FRAME;

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

/// One window of a read: the positions it spans and the defined records
/// in it, in order.
pub struct Window {
    /// The positions the window covered (defined or not).
    pub span: RangeInclusive<u16>,
    /// Its defined records.
    pub records: Vec<PositionRecord>,
}

impl Window {
    fn of(recs: ReplyRecords<'_>, last: u16) -> Window {
        let head = recs.head();
        let end = u32::from(head) + u32::from(recs.asked().max(1)) - 1;
        let end = u16::try_from(end).unwrap_or(u16::MAX).min(last);
        Window {
            span: head..=end,
            records: recs.collect(),
        }
    }
}

/// Reads positions `first..=last` over `link`, handing each window to
/// `window` in order; `window` returns `false` to end the read there
/// (the rest is not needed). Error responses are answered as in
/// [`write()`].
pub fn read(
    link: &mut Link,
    plan: &Plan,
    first: u16,
    last: u16,
    window: impl FnMut(Window) -> bool,
    hooks: &Hooks<'_>,
) -> Result<ReadBackStats, TableError> {
    read_with(link, plan.read_config(first, last), window, hooks)
}

/// Reads positions `first..=last` once per window (each reply proved,
/// not confirmed by a second): the records they hold. What a resumed
/// read checks its kept records against: together with the confirmed
/// read that kept them, two replies agree.
pub fn read_once(
    link: &mut Link,
    plan: &Plan,
    first: u16,
    last: u16,
    hooks: &Hooks<'_>,
) -> Result<BTreeMap<u16, PositionRecord>, TableError> {
    let cfg = ReadBackConfig {
        confirm: false,
        ..plan.read_config(first, last)
    };
    let mut got = BTreeMap::new();
    read_with(
        link,
        cfg,
        |w| {
            got.extend(w.records.into_iter().map(|r| (r.number, r)));
            true
        },
        hooks,
    )?;
    Ok(got)
}

/// [`read`] with the read-back's settings given.
fn read_with(
    link: &mut Link,
    cfg: ReadBackConfig,
    mut window: impl FnMut(Window) -> bool,
    hooks: &Hooks<'_>,
) -> Result<ReadBackStats, TableError> {
    let last = cfg.last;
    let mut rb: ReadBack<FRAME> = ReadBack::new(cfg);
    let mut refusals = 0;
    let enough = Cell::new(false);
    let stop = || enough.get() || (hooks.stop)();
    let inner = Hooks {
        note: hooks.note,
        stop: &stop,
    };
    loop {
        let mut delivered = false;
        let result = {
            let mut engine = rb.delivering(|recs| {
                delivered = true;
                if !enough.get() && !window(Window::of(recs, last)) {
                    enough.set(true);
                }
            });
            run(link, &mut engine, &inner, |_| false, None)
        };
        if delivered {
            refusals = 0;
        }
        match result {
            Err(TableError::Interrupted) if enough.get() => return Ok(rb.stats()),
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

/// Sends one command `req` and returns its reply frame (empty for a
/// command without normal response); an `&` reply is
/// `Engine(Failure::Controller)`.
pub fn command<'a, R: Request<'a>>(
    link: &mut Link,
    req: &R,
    hooks: &Hooks<'_>,
) -> Result<Vec<u8>, TableError> {
    let mut client: Box<Client> = Box::new(Client::new().with_proof());
    let now = link.now();
    client
        .start(link.line_mut(), req, now)
        .map_err(|e| TableError::Engine(Failure::Protocol(e)))?;
    run(link, client.as_mut(), hooks, |_| false, None)?;
    Ok(client
        .reply_frame()
        .map(|f| f.as_bytes().to_vec())
        .unwrap_or_default())
}

/// Sends the raw command `frame` to another responder on the line (a
/// bridge's own station), on a line of its own with settings `cfg`: its
/// reply frame; an `&` is `Engine(Failure::Controller)`.
pub fn command_to(
    link: &mut Link,
    cfg: LineConfig,
    frame: &[u8],
    hooks: &Hooks<'_>,
) -> Result<Vec<u8>, TableError> {
    link.with_line(cfg, |link| {
        let mut client: Box<Client> = Box::new(Client::new().with_proof());
        let now = link.now();
        client
            .start_frame(link.line_mut(), frame, now)
            .map_err(|e| TableError::Engine(Failure::Protocol(e)))?;
        run(link, client.as_mut(), hooks, |_| false, None)?;
        Ok(client
            .reply_frame()
            .map(|f| f.as_bytes().to_vec())
            .unwrap_or_default())
    })
}

/// Sends `records` as one command of `stream` (a bridge splits it into
/// the controller's commands and answers once; see
/// [`iai_protocol_b::upload`]), the reply awaited `intake_ms` longer than
/// the sending took; `progress` is told the bytes sent so far. The count
/// the reply confirmed.
pub fn upload(
    link: &mut Link,
    stream: PositionStream,
    records: &[PositionRecord],
    intake_ms: u32,
    mut progress: impl FnMut(u64),
    hooks: &Hooks<'_>,
) -> Result<u16, TableError> {
    let count = u16::try_from(records.len()).map_err(|_| {
        TableError::Refused(format!("{} records do not fit one message", records.len()))
    })?;
    let cfg = UploadConfig {
        stream,
        start: 0,
        intake_ms,
    };
    let now = link.now();
    let mut up = Upload::start(cfg, records.iter(), count, link.line_mut(), now)
        .map_err(|e| TableError::Engine(Failure::Protocol(e)))?;
    run(
        link,
        &mut up,
        hooks,
        |u| {
            progress(u.bytes_sent());
            false
        },
        None,
    )
}

/// The largest value field `field` of `msg` carries, from its width in
/// the core's layout of the message (0 if `msg` has no such field).
fn field_max(msg: &dyn Fields, field: &str) -> u16 {
    tree(msg)
        .iter()
        .find_map(|n| match n {
            Node::Leaf { name, spec, .. } if *name == field => Some(spec.max_unsigned()),
            _ => None,
        })
        .map_or(0, |m| u16::try_from(m).unwrap_or(u16::MAX))
}

/// The largest value of 208H's count field (FFFH): a table of this many
/// records or more cannot be counted exactly.
pub fn count_max() -> u16 {
    field_max(
        &EffectivePositionCountResponse::default(),
        "number_of_effective_positions",
    )
}

/// 208H: how many positions the controller's table defines.
pub fn count(link: &mut Link, hooks: &Hooks<'_>) -> Result<u16, TableError> {
    let reply = command(link, &EffectivePositionCountQuery {}, hooks)?;
    let bad = |e| TableError::Engine(Failure::Protocol(e));
    let frame = Frame::new_checked(&reply, BypassPolicy::Reject).map_err(bad)?;
    let r = EffectivePositionCountResponse::parse(&frame).map_err(bad)?;
    Ok(r.number_of_effective_positions)
}

/// The reach of 246H's fields (the first position, how many): a clear
/// starts at position FFFH at the latest and spans at most FFFH positions
/// (2003 p. 42; the TTA page is lost and the layout assumed identical).
fn clear_fields_max() -> (u16, u16) {
    let clear = ClearPositionData::default();
    (
        field_max(&clear, "clear_start_position_number"),
        field_max(&clear, "number_of_clear_positions"),
    )
}

/// The last position a 246H reaches: FFFH + FFFH - 1 = 8189.
pub fn clear_last() -> u16 {
    let (start, count) = clear_fields_max();
    (start + count).saturating_sub(1)
}

/// The 246H commands (start, count) that clear exactly `first..=last`, in
/// ascending order; an error says why the range cannot be cleared.
pub fn clear_commands(first: u16, last: u16) -> Result<Vec<(u16, u16)>, String> {
    if first > last {
        return Err(format!("the range {first}..={last} is empty"));
    }
    let (start_max, count_max) = clear_fields_max();
    let clear_last = clear_last();
    let reach = format!(
        "246H gives the first position in 3 hex digits (at most {start_max}) and clears at most {count_max} positions at a time, so it reaches positions 0..={clear_last}"
    );
    if last > clear_last {
        return Err(format!("position {last} is out of reach: {reach}"));
    }
    // From the top down, each command as long as it may be.
    let mut out = Vec::new();
    let mut end = u32::from(last);
    let lo = u32::from(first);
    loop {
        let start = lo.max(end.saturating_sub(u32::from(count_max) - 1));
        if start > u32::from(start_max) {
            return Err(format!(
                "positions {first}..={last} cannot be cleared without clearing others: {reach}"
            ));
        }
        out.push((start as u16, (end - start + 1) as u16));
        if start == lo {
            break;
        }
        end = start - 1;
    }
    out.reverse();
    Ok(out)
}

/// 246H: clears positions `first..=last` ([`clear_commands`]); `done` is
/// told the last position cleared after each command.
pub fn clear(
    link: &mut Link,
    first: u16,
    last: u16,
    mut done: impl FnMut(u16),
    hooks: &Hooks<'_>,
) -> Result<u32, TableError> {
    let cmds = clear_commands(first, last).map_err(TableError::Refused)?;
    let n = cmds.len() as u32;
    for (start, count) in cmds {
        command(
            link,
            &ClearPositionData {
                clear_start_position_number: start,
                number_of_clear_positions: count,
            },
            hooks,
        )?;
        done(start + (count - 1));
    }
    Ok(n)
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
        |w| {
            held.extend(w.records.into_iter().map(|r| (r.number, r)));
            true
        },
        hooks,
    )?;
    Ok(want
        .into_values()
        .filter(|r| held.get(&r.number) != Some(*r))
        .cloned()
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_count_and_clear_fields_hold_3_hex_digits() {
        // 208H's count and 246H's fields: 3 hex digits (TTA p. 18, 2003 pp. 17, 42).
        assert_eq!(count_max(), 0xFFF);
        assert_eq!(clear_fields_max(), (0xFFF, 0xFFF));
        assert_eq!(clear_last(), 8189);
    }

    #[test]
    fn clears_tile_the_range_within_246h_reach() {
        assert_eq!(clear_commands(0, 8189), Ok(vec![(0, 4095), (4095, 4095)]));
        assert_eq!(clear_commands(5, 5), Ok(vec![(5, 1)]));
        assert_eq!(
            clear_commands(100, 8189),
            Ok(vec![(100, 3995), (4095, 4095)])
        );
        assert_eq!(
            clear_commands(0, 10_000),
            Err("position 10000 is out of reach: 246H gives the first position in 3 hex digits (at most 4095) and clears at most 4095 positions at a time, so it reaches positions 0..=8189".into())
        );
        assert!(clear_commands(5000, 5001)
            .unwrap_err()
            .starts_with("positions 5000..=5001 cannot be cleared without clearing others"));
        for (a, b) in [
            (0, 0),
            (0, 4094),
            (0, 4095),
            (1, 8189),
            (4095, 8189),
            (300, 7000),
        ] {
            let cmds = clear_commands(a, b).unwrap();
            let mut next = u32::from(a);
            for (s, n) in cmds {
                assert_eq!(u32::from(s), next);
                assert!(s <= 0xFFF && (1..=0xFFF).contains(&n));
                next += u32::from(n);
            }
            assert_eq!(next, u32::from(b) + 1);
        }
    }
}
