//! The read-back engine (`readback::ReadBack`) over a `line::Line`, on a
//! virtual clock, against a simulated controller that holds a position
//! table and answers in order.
//!
//! Input layout: the line (`common/link.rs`: station, timeout, flags with
//! sends 1-4, fences off, raw noise, turnaround, late and duplicate
//! windows, fence seed, start tick); a byte: query kind (bits 0-3 `% 3`: 21FH,
//! 22DH, 209H), 0x10 confirmed reads (`ReadBackConfig::confirm`); first
//! position (u16, cut to the layout's number width); span (u8: last =
//! first + span, at most 32 windows); reply room (`% 8`: 1-8 records of
//! 8 axes); the table's
//! seed and mask of defined positions (u8, u32); resumes (`% 4`); then a
//! script.
//!
//! The controller receives each transmission at its end and answers in
//! order: fences with their echo, each query with the defined records of
//! its window (in position order). Per transmission the script picks its
//! length (replies due meanwhile arrive before `sent`), whether the
//! controller gets it, and the reply's fate: at once, lost, a corrupted
//! byte, a copy later, a lie (a record altered, missing, or two digits
//! swapped: the SC still checks), an `&`, a stale answer (an earlier reply
//! sent again: a lie outside the contract), a delay with a copy.
//!
//! While the engine waits, a script byte (`% 5`): 0 advances the clock
//! (u16 ms) delivering what is due, 1 injects noise (a byte `k`, `k % 64`
//! bytes, no LF unless raw noise is on; with `k & 0x40` the next delivery
//! follows with no poll between), 2 sends a copy of any reply made before
//! (a byte: which, `& 0x80` broken), 3 delivers the next delivery, 4 waits
//! until the deadline; when the script ends, the deadline or the next
//! delivery, whichever comes first. A transmission's op byte: bits 0-2
//! its length (ms), bits 3-4 = 2 the query lost, bits 5-7 the reply's
//! fault (then a byte and a u16 delay): 0 at once, 1 lost, 2 a corrupted
//! byte, 3 a copy later, 4 a lie, 5 an `&`, 6 a stale answer, 7 a delay
//! with a copy; fences are echoed (4 and 5: an `&` instead).
//!
//! Deliveries keep the contract as in `Link::arrives` (originals within
//! `timeout + late_window` of their send, copies within
//! `duplicate_window` of a first arrival that kept it, no lies, no raw
//! noise); a plain `FrameDecoder` beside the engine's (reset with it at
//! each send) tells which delivery made each frame.
//!
//! Checked:
//! - no panic; it ends (`Done(Ok(None))`, or a failure with no resume
//!   left) within a bounded number of steps; no wait before the first
//!   transmission of a line with fences, none in the past or beyond the
//!   longest hold;
//! - fences are 200H with the seed's text; every query is one of the
//!   kind, asks 1..=`window()` positions, all inside `first..=last` and
//!   not before the next window to deliver; the controller's reply fits
//!   `max_response`;
//! - a reply is taken (`Answer`) only while awaited, holds at most the
//!   positions asked, all in the window of the query last sent;
//!   `Rejected(code)` only for an `&` with that code; `Mismatch` only for a
//!   reply with records outside the window or more than asked; `Fence`
//!   only for the echo of the last fence sent;
//! - windows are delivered in order: the first at `first`, each next one
//!   where the last ended, the last ending at `last` before `Done(Ok(None))`;
//!   **every record delivered is the controller's, unaltered** (the reply
//!   taken last, a reply the controller made, never bytes it did not send
//!   unless raw noise is on), at most `asked`, inside the window, in order;
//! - **with confirmed reads no window is delivered that differs from the
//!   table** unless those very bytes came outside the contract (raw noise,
//!   a stale answer, a late reply, a late copy) or from two separate lies
//!   of the controller (two replies altered alike: nothing can tell them
//!   from the truth);
//! - `stats().records` adds up the records delivered; a failure is only
//!   `Timeout` (with the sends made, after the timeout or a broken frame)
//!   or `Controller { code }` after an `&` with that code; `resume` goes
//!   on from the window it stopped at.
//!
//! Removed with the redesign: the checks of re-reads of windows answered
//! empty and of the holds before a read (the engine has neither now: a
//! window is delivered once, in order, and the line decides when a query
//! may go out).
#![no_main]

#[path = "common/controller.rs"]
mod controller;
#[path = "common/link.rs"]
mod link;
#[path = "common/records.rs"]
mod records;

use std::collections::{BTreeMap, BTreeSet};

use controller::Table;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::engine::Step;
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::line::{Heard, Line};
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::readback::{ReadBack, ReadBackConfig};
use libfuzzer_sys::fuzz_target;
use link::{Delivery, Kind, Link, Setup, Shadow, Source};
use records::Input;

const N: usize = iai_protocol_b::limits::TTA.response;

const QUERIES: [PositionStream; 3] = [
    PositionStream::QUERY_2_RESPONSE,
    PositionStream::QUERY_3_RESPONSE,
    PositionStream::QUERY_RESPONSE,
];

/// Reply bytes fed whole, and what may excuse them: fed outside the
/// contract, and the lies of the controller (made indices) that carried
/// them.
#[derive(Default)]
struct Seen {
    out_of_contract: bool,
    lies: BTreeSet<usize>,
}

struct H<'a> {
    input: Input<'a>,
    setup: Setup,
    kind: PositionStream,
    cfg: ReadBackConfig,
    table: Table,
    link: Link,
    line: Line,
    rb: ReadBack<N>,
    shadow: Shadow,
    clock: u64,
    /// The query last sent (head, asked); whether `sent` came after it.
    query: Option<(u16, u16)>,
    awaiting: bool,
    last_sent: u64,
    broken_since_sent: bool,
    /// The frame taken last (bytes, where from).
    last_answer: Option<(Vec<u8>, Source)>,
    rejected: Option<u16>,
    /// The last fence sent (controller command index), if it got there.
    last_fence: Option<usize>,
    seen: BTreeMap<Vec<u8>, Seen>,
    /// Made indices of the controller's content lies.
    lies: BTreeSet<usize>,
    transmitted: bool,
}

impl H<'_> {
    fn now(&self) -> u32 {
        self.setup.base.wrapping_add(self.clock as u32)
    }

    fn deliver_until(&mut self, to: u64) {
        while let Some(d) = self.link.due(to) {
            self.clock = self.clock.max(d.at);
            if !self.feed(d) {
                break;
            }
        }
    }

    /// Feeds one delivery; `false` if the engine holds a reply (the rest
    /// was put back).
    fn feed(&mut self, mut d: Delivery) -> bool {
        if d.ok.is_none() {
            d.at = self.clock;
        }
        let ok = self.link.arrives(&mut d, self.clock);
        if let Kind::Reply { made, .. } = d.kind {
            let s = self.seen.entry(d.bytes.clone()).or_default();
            s.out_of_contract |= !ok;
            if self.lies.contains(&made) {
                s.lies.insert(made);
            }
        }
        self.shadow.begin(&d);
        let mut rest = &d.bytes[..];
        let now = self.now();
        loop {
            let errors = self.line.stats().line_errors;
            let r = self.rb.received(&mut self.line, rest, now);
            if self.line.stats().line_errors > errors {
                // A broken frame (the read-back path reports none).
                self.broken_since_sent = true;
            }
            trace!(
                "t={} RX {:?} -> {:?} ({:?})",
                self.clock,
                String::from_utf8_lossy(&rest[..r.consumed]),
                r.event,
                d.kind
            );
            assert!(r.consumed <= rest.len());
            if r.consumed == 0 && r.event == Heard::NeedMore && !rest.is_empty() {
                // The engine holds a reply to deliver: the rest waits.
                assert!(self.line.answered(), "bytes refused with no reply held");
                let mut tail = d.clone();
                tail.bytes = rest.to_vec();
                self.link.put_back(tail);
                return false;
            }
            let heard = self.shadow.decoded(rest, r.consumed, &r.event);
            rest = &rest[r.consumed..];
            if let Heard::Broken(_) = r.event {
                self.broken_since_sent = true;
            }
            if let Some((frame, src)) = heard {
                self.heard(r.event, frame, src);
            }
            if r.event == Heard::NeedMore {
                assert!(rest.is_empty(), "NeedMore with bytes left");
                return true;
            }
        }
    }

    fn heard(&mut self, heard: Heard, frame: Vec<u8>, src: Source) {
        let f = Frame::new_checked(&frame, BypassPolicy::Reject).expect("a frame");
        let station = self.setup.line.station;
        match heard {
            Heard::Answer => {
                assert!(self.awaiting, "a reply taken while none was awaited");
                let (head, asked) = self.query.expect("a query");
                assert_eq!(
                    (f.header(), f.station(), f.code()),
                    (Header::Response, station, self.kind.id)
                );
                let recs = parse_reply(self.kind, &f).expect("a reply taken parses");
                assert!(recs.len() <= usize::from(asked), "more records than asked");
                for r in &recs {
                    let n = u32::from(r.number);
                    assert!(
                        n >= u32::from(head) && n < u32::from(head) + u32::from(asked),
                        "record {n} taken for {head}+{asked}"
                    );
                }
                self.last_answer = Some((frame, src));
                self.awaiting = false;
            }
            Heard::Rejected(code) => {
                assert!(self.awaiting, "an & taken while no reply was awaited");
                assert_eq!((f.header(), f.code()), (Header::Error, code));
                self.rejected = Some(code);
                self.awaiting = false;
            }
            Heard::Mismatch => {
                let (head, asked) = self.query.expect("a query");
                assert_eq!(
                    (f.header(), f.station(), f.code()),
                    (Header::Response, station, self.kind.id)
                );
                if let Some(recs) = parse_reply(self.kind, &f) {
                    let fits = recs.len() <= usize::from(asked)
                        && recs.iter().all(|r| {
                            let n = u32::from(r.number);
                            n >= u32::from(head) && n < u32::from(head) + u32::from(asked)
                        });
                    assert!(!fits, "a reply that fits {head}+{asked} called a mismatch");
                }
            }
            Heard::Fence => {
                assert_eq!((f.header(), f.code()), (Header::Response, 0x200));
                if let Source::Delivery(d) = &src {
                    let cmd = self
                        .link
                        .origin(d)
                        .expect("an echo the controller never made");
                    assert_eq!(Some(cmd), self.last_fence, "the echo of another fence");
                }
            }
            _ => {}
        }
    }

    /// The controller got command `cmd` at the clock.
    fn answer(&mut self, cmd: usize, bytes: &[u8], f: &link::Fate) {
        let at = if f.fault == 0 {
            self.clock + 1
        } else {
            self.clock + f.delay
        };
        let station = self.setup.line.station;
        if self.setup.is_fence(bytes) {
            let echo = self.link.echo(bytes);
            match f.fault {
                4 | 5 => {
                    let e = controller::error_reply(station, 0x0A0 + u16::from(f.extra));
                    self.link.reply(e, cmd, at, false);
                }
                _ => self.link.answer(echo, cmd, at, f, false),
            }
            return;
        }
        let (head, asked) = controller::parse_query(self.kind, station, bytes).expect("a query");
        let mut recs = controller::window(&self.table, head, asked);
        let truth = recs.clone();
        match f.fault {
            4 => {
                // A lie the SC does not show.
                match f.extra % 3 {
                    0 if !recs.is_empty() => {
                        let i = usize::from(f.extra / 3) % recs.len();
                        recs[i].speed = recs[i].speed.wrapping_add(1);
                    }
                    1 if !recs.is_empty() => {
                        recs.remove(usize::from(f.extra / 3) % recs.len());
                    }
                    _ => {
                        controller::swap_digits(&mut recs, u32::from(f.extra) * 131 + 7);
                    }
                }
            }
            5 => {
                let e = controller::error_reply(station, 0x0A0 + u16::from(f.extra));
                self.link.reply(e, cmd, at, false);
                return;
            }
            6 => {
                // A stale answer: an earlier read-back reply again.
                let olds: Vec<Vec<u8>> = self
                    .link
                    .made
                    .iter()
                    .filter(|m| m.bytes.get(3..6) == Some(&hex3(self.kind.id)[..]))
                    .map(|m| m.bytes.clone())
                    .collect();
                if let Some(b) = olds.get(usize::from(f.extra) % olds.len().max(1)) {
                    self.link.reply(b.clone(), cmd, at, true);
                    return;
                }
            }
            _ => {}
        }
        let reply = controller::query_reply(self.kind, station, &recs);
        assert!(
            reply.len() <= self.cfg.max_response,
            "a reply of {} bytes for a window the engine asked (max {})",
            reply.len(),
            self.cfg.max_response
        );
        let lie = recs != truth;
        let made = self.link.made.len();
        self.link.answer(reply, cmd, at, f, false);
        if lie {
            self.lies.insert(made);
        }
    }
}

fn hex3(id: u16) -> [u8; 3] {
    let s = format!("{id:03X}");
    [s.as_bytes()[0], s.as_bytes()[1], s.as_bytes()[2]]
}

/// The records of a read-back reply of `kind`, if it is one.
fn parse_reply(kind: PositionStream, f: &Frame<'_>) -> Option<Vec<PositionRecord>> {
    let mut r = f.reader();
    let (_, count) = kind.read_prefix(&mut r).ok()?;
    let mut out = Vec::new();
    for _ in 0..count {
        out.push(kind.layout.read_record(&mut r).ok()?);
    }
    r.finish().ok()?;
    Some(out)
}

enum S {
    Transmit(Vec<u8>),
    Wait(u32),
    Idle,
    Window(u16, u16, Vec<PositionRecord>),
    End,
    Failed(Failure),
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let setup = link::setup(&mut input);
    let c = input.u8();
    let kind = QUERIES[usize::from((c & 0x0F) % 3)];
    let first = records::fit_number(kind.layout, input.u16());
    let span = input.u8();
    let max_response =
        kind.overhead() + kind.layout.record_len(8) * (1 + usize::from(input.u8() % 8));
    // At most 32 windows (a run costs about one decode per window read).
    let window = kind.window(max_response);
    let span = u16::from(span).min(32 * window - 1);
    let last = records::fit_number(kind.layout, first.saturating_add(span)).max(first);
    let cfg = ReadBackConfig {
        stream: kind,
        first,
        last,
        max_response,
        confirm: c & 0x10 != 0,
    };
    let seed = input.u8();
    let mask = input.u32();
    let mut resumes = input.u8() % 4;
    let mut table = Table::new();
    let recs = records::table(kind.layout, seed, first, usize::from(last - first) + 1);
    for (i, mut r) in recs.into_iter().enumerate() {
        if mask >> (i % 32) & 1 == 1 {
            r.number = first + i as u16;
            table.insert(r.number, r);
        }
    }
    trace!("{:?} {cfg:?} {} defined", setup.line, table.len());
    let mut h = H {
        input,
        setup,
        kind,
        cfg,
        table,
        link: Link::new(setup),
        line: Line::new(setup.line, setup.seed),
        rb: ReadBack::new(cfg),
        shadow: Shadow::default(),
        clock: 0,
        query: None,
        awaiting: false,
        last_sent: 0,
        broken_since_sent: false,
        last_answer: None,
        rejected: None,
        last_fence: None,
        seen: BTreeMap::new(),
        lies: BTreeSet::new(),
        transmitted: false,
    };
    let ex = setup.line;
    let windows = (u32::from(last) - u32::from(first)) / u32::from(cfg.window()) + 1;
    let reads = if cfg.confirm { 3 } else { 1 };
    let max_steps = 400
        + 16 * data.len()
        + 32 * reads * windows as usize * usize::from(ex.max_sends) * (1 + usize::from(resumes));
    let mut steps = 0usize;
    let mut next_head = u32::from(first);
    let mut delivered = 0u32;
    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        let now = h.now();
        let before = h.line.stats();
        let step = match h.rb.poll(&mut h.line, now) {
            Step::Transmit(b) => S::Transmit(b.to_vec()),
            Step::WaitUntil(t) => S::Wait(t),
            Step::Idle => S::Idle,
            Step::Done(Ok(Some(recs))) => {
                let (head, asked) = (recs.head(), recs.asked());
                S::Window(head, asked, recs.collect())
            }
            Step::Done(Ok(None)) => S::End,
            Step::Done(Err(e)) => S::Failed(e),
        };
        let after = h.line.stats();
        if after.sends > before.sends {
            // The engine reset its reply decoder for the send.
            h.shadow.reset();
        }
        match step {
            S::Idle => panic!("a read-back idle"),
            S::Transmit(bytes) => {
                trace!(
                    "t={} TX {}",
                    h.clock,
                    String::from_utf8_lossy(&bytes).trim_end()
                );
                h.transmitted = true;
                let fence = setup.is_fence(&bytes);
                if fence {
                    link::check_fence(&setup, &bytes);
                } else {
                    let (head, asked) = controller::parse_query(kind, ex.station, &bytes)
                        .expect("neither a fence nor a query of the kind");
                    assert!(asked >= 1 && asked <= cfg.window(), "window of {asked}");
                    assert!(
                        u32::from(head) >= next_head
                            && u32::from(head) + u32::from(asked) - 1 <= u32::from(last),
                        "query {head}+{asked} outside {next_head}..={last}"
                    );
                    if after.sends == before.sends + 1 && h.line.sends() > 1 {
                        assert!(
                            h.clock >= h.last_sent + u64::from(ex.timeout_ms)
                                || h.broken_since_sent,
                            "resent at {} after a send that ended at {}",
                            h.clock,
                            h.last_sent
                        );
                    }
                    h.query = Some((head, asked));
                }
                h.awaiting = false;
                let op = h.input.next();
                let fate = h.link.fate(&mut h.input, op);
                let to = h.clock + fate.dur;
                h.deliver_until(to);
                h.clock = to;
                let now = h.now();
                h.rb.sent(&mut h.line, now);
                if !fence {
                    h.awaiting = true;
                    h.last_sent = h.clock;
                    h.broken_since_sent = false;
                }
                if fence {
                    h.last_fence = None;
                }
                if !fate.lost {
                    let cmd = h.link.received(&bytes, h.clock);
                    if fence {
                        h.last_fence = Some(cmd);
                    }
                    h.answer(cmd, &bytes, &fate);
                }
            }
            S::Wait(t) => {
                let nothing_sent = !h.transmitted && ex.fences;
                let ahead = records::check_wait(now, t, setup.horizon(), nothing_sent);
                trace!("t={} WAIT {ahead}", h.clock);
                let until = h.clock + u64::from(ahead);
                match h.input.next() {
                    None => {
                        let next = h.link.outbox.first().map_or(until, |d| d.at.min(until));
                        h.deliver_until(next);
                        h.clock = h.clock.max(next);
                    }
                    Some(op) => match op % 5 {
                        0 => {
                            let to = h.clock + u64::from(h.input.u16());
                            h.deliver_until(to);
                            h.clock = h.clock.max(to);
                        }
                        1 => {
                            let (d, then_next) = h.link.noise(&mut h.input, h.clock);
                            h.feed(d);
                            if then_next {
                                if let Some(at) = h.link.outbox.first().map(|d| d.at) {
                                    h.deliver_until(at);
                                }
                            }
                        }
                        2 => {
                            // A copy of any reply made before.
                            if let Some(d) = h.link.copy(&mut h.input, h.clock) {
                                h.feed(d);
                            }
                        }
                        3 => {
                            if let Some(at) = h.link.outbox.first().map(|d| d.at) {
                                h.deliver_until(at);
                            }
                        }
                        _ => {
                            h.deliver_until(until);
                            h.clock = h.clock.max(until);
                        }
                    },
                }
            }
            S::Window(head, asked, recs) => {
                trace!(
                    "t={} WINDOW {head}+{asked}: {} records",
                    h.clock,
                    recs.len()
                );
                assert_eq!(u32::from(head), next_head, "windows out of order");
                assert!(asked >= 1 && asked <= cfg.window());
                let end = u32::from(head) + u32::from(asked);
                assert!(
                    end - 1 <= u32::from(last),
                    "a window past the last position"
                );
                next_head = end;
                assert!(recs.len() <= usize::from(asked), "more records than asked");
                let mut prev = None;
                for r in &recs {
                    let n = u32::from(r.number);
                    assert!(
                        n >= u32::from(head) && n < end,
                        "record {n} outside {head}+{asked}"
                    );
                    assert!(prev.is_none_or(|p| p < n), "records out of order");
                    prev = Some(n);
                }
                delivered += recs.len() as u32;
                assert_eq!(h.rb.stats().records, delivered, "stats().records");
                let (frame, src) = h
                    .last_answer
                    .clone()
                    .expect("a window without a reply taken");
                let f = Frame::new_checked(&frame, BypassPolicy::Reject).expect("frame");
                let taken = parse_reply(kind, &f).expect("parses");
                assert_eq!(recs, taken, "the records delivered are not the reply taken");
                match &src {
                    Source::Forged => assert!(setup.raw_noise, "a reply the controller never sent"),
                    Source::Delivery(d) => assert!(
                        matches!(d.kind, Kind::Reply { .. }),
                        "a window from {:?}",
                        d.kind
                    ),
                }
                let truth = controller::window(&h.table, head, asked);
                if cfg.confirm && recs != truth && !setup.raw_noise {
                    let s = h.seen.get(&frame);
                    let excused = s.is_some_and(|s| s.out_of_contract || s.lies.len() >= 2);
                    assert!(
                        excused,
                        "confirmed window {head}+{asked} differs from the table \
                         (delivered {recs:?}, table {truth:?})"
                    );
                }
            }
            S::End => {
                assert_eq!(
                    next_head,
                    u32::from(last) + 1,
                    "ended before the last window"
                );
                assert_eq!(h.rb.stats().records, delivered);
                break;
            }
            S::Failed(e) => {
                trace!("t={} FAILED {e:?}", h.clock);
                match e {
                    Failure::Timeout { sends } => {
                        assert_eq!(sends, h.line.sends());
                        assert!(
                            h.clock >= h.last_sent + u64::from(ex.timeout_ms)
                                || h.broken_since_sent,
                            "gave up at {} after a send that ended at {}",
                            h.clock,
                            h.last_sent
                        );
                    }
                    Failure::Controller { code, detail: None } => {
                        assert_eq!(h.rejected.take(), Some(code), "Controller without that &")
                    }
                    other => panic!("unexpected {other:?}"),
                }
                if resumes == 0 {
                    break;
                }
                resumes -= 1;
                h.rb.resume();
            }
        }
    }
});
