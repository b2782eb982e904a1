//! A scripted controller for the engines' unit tests: it stores position
//! writes, answers 21FH from its table, echoes 200H, and answers in order
//! (a reply never overtakes one sent before it). Tests make it slow,
//! silent, or repeat a reply, and alter what it stores.

extern crate std;

use std::collections::BTreeMap;
use std::vec::Vec;

use crate::checksum::BypassPolicy;
use crate::decoder::{Event, FrameDecoder, Status};
use crate::engine::{feed, Engine, Step};
use crate::frame::Station;
use crate::line::Line;
use crate::message::{
    ChangePositionData2Response, EffectivePositionQuery2, EffectivePositionResponse2, Message,
    Repeated, TestCall, TestCallResponse,
};
use crate::position::PositionRecord;
use crate::table::{PositionStreamDecoder, StreamEvent};

pub(crate) const ST: Station = Station(0x99);

/// What the controller does to the reply of one command.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Fault {
    /// Not answered at all.
    pub(crate) silent: bool,
    /// Lost on the way: neither executed nor answered.
    pub(crate) lost: bool,
    /// Answered this much later than usual.
    pub(crate) late_ms: u32,
    /// Answered, and the same reply again this long after (an echoing
    /// converter: the copy may come after later replies).
    pub(crate) copy_after_ms: Option<u32>,
    /// A 21FH reply that shows this position with coordinate 1 at this
    /// value (two digits swapped: the SC does not see it).
    pub(crate) shows: Option<(u16, i32)>,
}

pub(crate) struct Controller {
    pub(crate) table: BTreeMap<u16, PositionRecord>,
    commands: FrameDecoder,
    /// Replies waiting, with their tick; in order except copies.
    outbox: Vec<(u32, Vec<u8>)>,
    /// Replies go out this long after their command.
    pub(crate) delay_ms: u32,
    /// Faults for the n-th command (0-based, fences included).
    pub(crate) faults: BTreeMap<usize, Fault>,
    /// Position writes whose n-th (0-based) stores position `.0` with
    /// coordinate 1 set to `.1` instead (a swap the SC does not see).
    pub(crate) alter: BTreeMap<usize, (u16, i32)>,
    /// Position writes whose n-th (0-based) stores the record of position
    /// `.0` at position `.1` instead (two flips in its number that the SC
    /// does not see).
    pub(crate) misplace: BTreeMap<usize, (u16, u16)>,
    /// Every command received, with its tick.
    pub(crate) received: Vec<(u32, Vec<u8>)>,
    writes: usize,
    /// When the last reply (not a copy) is due: none goes before it.
    last_due: u32,
}

impl Controller {
    pub(crate) fn new() -> Self {
        Controller {
            table: BTreeMap::new(),
            commands: FrameDecoder::new(),
            outbox: Vec::new(),
            delay_ms: 5,
            faults: BTreeMap::new(),
            alter: BTreeMap::new(),
            misplace: BTreeMap::new(),
            received: Vec::new(),
            writes: 0,
            last_due: 0,
        }
    }

    /// Commands received whose bytes start with `prefix`.
    pub(crate) fn count(&self, prefix: &[u8]) -> usize {
        self.received
            .iter()
            .filter(|(_, c)| c.starts_with(prefix))
            .count()
    }

    pub(crate) fn next_at(&self) -> Option<u32> {
        self.outbox.iter().map(|(t, _)| *t).min()
    }

    pub(crate) fn take(&mut self, now: u32) -> Vec<u8> {
        self.outbox.sort_by_key(|(t, _)| *t);
        let due = self.outbox.iter().take_while(|(t, _)| *t <= now).count();
        self.outbox.drain(..due).flat_map(|(_, b)| b).collect()
    }

    pub(crate) fn receive(&mut self, bytes: &[u8], now: u32) {
        for &b in bytes {
            let cmd = match self.commands.push(b) {
                Status::Complete(Event::Frame(f)) => f.as_bytes().to_vec(),
                _ => continue,
            };
            let n = self.received.len();
            self.received.push((now, cmd.clone()));
            let fault = self.faults.get(&n).copied().unwrap_or_default();
            if fault.lost {
                continue;
            }
            let reply = self.answer(&cmd, fault.shows);
            if fault.silent {
                continue;
            }
            // In order: not before a reply due earlier (copies aside).
            let at = (now + self.delay_ms + fault.late_ms).max(self.last_due);
            self.last_due = at;
            if let Some(after) = fault.copy_after_ms {
                self.outbox.push((at + after, reply.clone()));
            }
            self.outbox.push((at, reply));
        }
    }

    fn answer(&mut self, cmd: &[u8], shows: Option<(u16, i32)>) -> Vec<u8> {
        let mut out = std::vec![0u8; 2048];
        let mut dec: FrameDecoder = FrameDecoder::with_policy(BypassPolicy::Accept);
        let Status::Complete(Event::Frame(f)) = dec.decode(cmd).status else {
            return Vec::new();
        };
        let n = if let Ok(q) = TestCall::parse(&f) {
            TestCallResponse {
                test_string: q.test_string,
            }
            .emit(ST, &mut out)
        } else if let Ok(q) = EffectivePositionQuery2::parse(&f) {
            let head = q.query_head_position_number;
            let end = head.saturating_add(q.number_of_query_records);
            let mut found: Vec<_> = self
                .table
                .range(head..end)
                .map(|(_, r)| r.clone())
                .collect();
            for r in found.iter_mut() {
                if let Some((_, v)) = shows.filter(|(n, _)| *n == r.number) {
                    r.positions[0] = v;
                }
            }
            EffectivePositionResponse2 {
                records: Repeated::from_slice(&found),
            }
            .emit(ST, &mut out)
        } else if !cmd.starts_with(b"!9926D") {
            // Anything else: its normal response with default fields.
            match crate::message::Response::default_for(f.code()) {
                Some(r) => r.emit(ST, &mut out),
                None => return Vec::new(),
            }
        } else {
            let mut dec = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
            let mut input = cmd;
            let mut written = 0;
            let alter = self.alter.get(&self.writes).copied();
            let misplace = self.misplace.get(&self.writes).copied();
            self.writes += 1;
            loop {
                let r = dec.decode(input);
                input = &input[r.consumed..];
                match r.status {
                    Status::Complete(StreamEvent::Record(mut rec)) => {
                        if let Some((n, v)) = alter.filter(|(n, _)| *n == rec.number) {
                            let _ = n;
                            rec.positions[0] = v;
                        }
                        if let Some((_, to)) = misplace.filter(|(n, _)| *n == rec.number) {
                            rec.number = to;
                        }
                        self.table.insert(rec.number, rec);
                        written += 1;
                    }
                    Status::Partial | Status::Complete(StreamEvent::Start { .. }) => {}
                    _ => break,
                }
            }
            ChangePositionData2Response {
                number_of_changed_positions: written,
            }
            .emit(ST, &mut out)
        };
        let n = n.unwrap_or(0);
        out.truncate(n);
        out
    }
}

/// How a run against the controller ended.
pub(crate) struct Run<T> {
    pub(crate) result: Result<T, crate::error::Failure>,
    pub(crate) now: u32,
}

/// Drives `engine` on `line` against `ctl` from `now` to its result; each
/// transmission takes 1 ms.
pub(crate) fn run<G: Engine>(
    engine: &mut G,
    line: &mut Line,
    ctl: &mut Controller,
    mut now: u32,
) -> Run<G::Output> {
    let mut pending = Vec::new();
    for _ in 0..1_000_000 {
        pending.extend(ctl.take(now));
        feed(engine, line, &pending, now);
        pending.clear();
        match engine.poll(line, now) {
            Step::Transmit(b) => {
                let b = b.to_vec();
                now += 1;
                ctl.receive(&b, now);
                engine.sent(line, now);
            }
            Step::WaitUntil(t) => now = ctl.next_at().map_or(t, |r| r.min(t)).max(now + 1),
            Step::Idle => now += 1,
            Step::Done(result) => return Run { result, now },
        }
    }
    panic!("the engine never ended");
}

/// Position record `n` with coordinate 1 at `x` (0.001 mm).
pub(crate) fn record(n: u16, x: i32) -> PositionRecord {
    PositionRecord::new(n, 30, 30, 100, &[(1, x)]).unwrap_or_default()
}
