//! The read-back engine (`readback::ReadBack`) over a `line::Line`, on a
//! virtual clock, against a simulated controller that holds a position
//! table and answers in order.
//!
//! Input: the line (`common/link.rs`); a byte: query kind (bits 0-3 `% 3`:
//! 21FH, 22DH, 209H), 0x10 confirmed reads; first position (u16); span
//! (u8, at most 32 windows); reply room (`% 8`: 1-8 records of 8 axes);
//! the table's seed and mask of defined positions (u8, u32); resumes
//! (`% 4`); then a script. The controller echoes fences and answers each
//! query with the defined records of its window; per transmission an op
//! byte (bits 0-2 length ms, bits 3-4 = 2 lost, bits 5-7 the reply: 0 at
//! once, 1 lost, 2 corrupted, 3 copied later, 4 a lie (a record altered,
//! missing, two digits swapped), 5 an `&`, 6 a stale answer (an earlier
//! reply again), 7 late with a copy; then a byte and a delay); fences get
//! an `&` for 4 and 5. While it waits (`% 5`): time, noise (raw with the
//! link's bit), a copy of any reply made (whole or broken), the next
//! delivery, the deadline. Every byte is fed: the engine takes all.
//!
//! A `Shadow` mirrors the engine's decoders (its own, and the line's while
//! it keeps a reply to deliver: the harness follows which queries deliver,
//! the confirmations or, unconfirmed, every query) and tells which delivery
//! made each frame. Checked (beside no panic, a bounded end, waits):
//! - fences numbered from 1 with the seed's text; queries of the kind, of
//!   1..=`window()` positions inside `first..=last`, none before the next
//!   window to deliver; replies within `max_response`;
//! - `Answer` only while awaited, never while a reply is kept, its records
//!   in the window asked; **a confirmation (or unconfirmed query) takes
//!   only a reply the controller made for it**, a first read also an
//!   in-contract copy, unless the delivery broke the contract, was forged,
//!   or an echo outside the contract settled it; `Mismatch` only for a
//!   reply that does not fit; `Rejected` for an `&`; `Fence` exactly for
//!   the echo of the fence in flight; `Foreign` exactly for another
//!   station or a command; **`Unplaced` never for a reply within the
//!   contract** (but those of a query another reply stood in for);
//! - windows in order, from `first` to `last`; **every record delivered is
//!   the reply kept, a reply the controller made**; each window only after
//!   a proof: a fence echoed since its reply (or, without one, the replies
//!   waited out) and nothing unplaced since the last proof; **confirmed,
//!   no window differs from the table** unless its bytes came outside the
//!   contract or from two lies alike; `stats().records` adds up;
//! - failures: `Timeout` after the timeout or a broken frame, `Controller`
//!   after that `&`, `Unconfirmed` after `MAX_RECONFIRMS` rounds read again.
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
use iai_protocol_b::decoder::Status;
use iai_protocol_b::engine::Step;
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::line::{Heard, Line};
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::readback::{ReadBack, ReadBackConfig, MAX_RECONFIRMS};
use libfuzzer_sys::fuzz_target;
use link::{Delivery, Kind, Link, Seen, Setup, Shadow, Source};
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
struct Fed {
    out_of_contract: bool,
    lies: BTreeSet<usize>,
}

/// The query on the line: its window, whether its reply is kept to be
/// delivered, and whether it was begun as one (a confirmation, or any
/// query of an unconfirmed read: the line then waits out every copy that
/// could pass for its reply).
#[derive(Debug, Clone, Copy)]
struct Query {
    head: u16,
    asked: u16,
    delivers: bool,
    proof: bool,
    /// The line's count of commands when it was begun: who it is.
    serial: u32,
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
    shadow: Shadow<N>,
    clock: u64,
    query: Option<Query>,
    /// Windows (head, asked) whose first read is recorded by the engine.
    firsts: BTreeSet<(u16, u16)>,
    next_head: u32,
    awaiting: bool,
    last_sent: u64,
    broken_since_sent: bool,
    /// The frame taken last (bytes, where from), and whether a fence's echo
    /// came since.
    last_answer: Option<(Vec<u8>, Source)>,
    echo_since_answer: bool,
    rejected: Option<u16>,
    /// The last fence sent (controller command index), its number, and
    /// whether its echo is still awaited.
    last_fence: Option<usize>,
    fences: u32,
    fence_awaited: bool,
    /// Who each command frame the controller received was for (the
    /// query's serial; `None`: a fence).
    owners: Vec<Option<u32>>,
    adrift: BTreeSet<u32>,
    excused_before: usize,
    seen: BTreeMap<Vec<u8>, Fed>,
    /// Made indices of the controller's content lies.
    lies: BTreeSet<usize>,
    /// Positions the lies showed wrong (altered or missing), and how many
    /// lies did: a confirmation compares each half of a window with the
    /// first read's, so a wrong record is confirmed only by two lies alike.
    lied: BTreeMap<u16, u32>,
    transmitted: bool,
}

impl H<'_> {
    fn now(&self) -> u32 {
        self.setup.base.wrapping_add(self.clock as u32)
    }

    fn deliver_until(&mut self, to: u64) {
        while let Some(d) = self.link.due(to) {
            self.clock = self.clock.max(d.at);
            self.feed(d);
        }
    }

    /// Feeds one delivery, checking what each frame did.
    fn feed(&mut self, mut d: Delivery) {
        d.at = self.clock;
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
                self.broken_since_sent = true;
            }
            trace!(
                "t={} RX {:?} -> {:?} ({:?}{})",
                self.clock,
                String::from_utf8_lossy(&rest[..r.consumed]),
                r.status,
                d.kind,
                if self.shadow.holding() { ", held" } else { "" }
            );
            assert!(r.consumed <= rest.len());
            let seen = self.shadow.decoded(rest, &r);
            rest = &rest[r.consumed..];
            let heard = match r.status {
                Status::Partial => {
                    assert!(rest.is_empty(), "Partial with bytes left");
                    return;
                }
                Status::Complete(h) => h,
            };
            if let Some(seen) = seen {
                self.heard(heard, seen);
            }
            if heard == Heard::Answer && self.query.is_some_and(|q| q.delivers) {
                // A reply to deliver: kept until the next send.
                self.shadow.hold();
            }
        }
    }

    fn heard(&mut self, heard: Heard, seen: Seen) {
        let station = self.setup.line.station;
        let (header, from, code) = seen.envelope;
        let ours = from == station && header != Header::Command;
        assert_eq!(
            heard == Heard::Foreign,
            !ours,
            "{heard:?} for a frame from {from:?} ({header:?})"
        );
        if let Source::Delivery(d) = &seen.source {
            self.link.heard_whole(d);
        }
        link::check_fence_echo(
            &self.setup,
            &seen,
            ours,
            heard,
            self.fences,
            self.fence_awaited,
        );
        if seen.held {
            assert!(
                !matches!(heard, Heard::Answer | Heard::Rejected(_) | Heard::Mismatch),
                "{heard:?} while the engine keeps a reply"
            );
        }
        let d = match &seen.source {
            Source::Forged => None,
            Source::Delivery(d) => Some(d.clone()),
        };
        match heard {
            Heard::Answer | Heard::Rejected(_) => {
                assert!(self.awaiting, "{heard:?} while no reply was awaited");
                let q = self.query.expect("a query");
                let f = seen.frame();
                if let Heard::Answer = heard {
                    assert_eq!(
                        (f.header(), f.station(), f.code()),
                        (Header::Response, station, self.kind.id)
                    );
                    let recs = parse_reply(self.kind, &f).expect("a reply taken parses");
                    assert!(fits(&recs, q.head, q.asked), "a reply taken for {q:?}");
                    self.last_answer = Some((seen.bytes.clone(), seen.source.clone()));
                    self.echo_since_answer = false;
                    self.firsts.insert((q.head, q.asked));
                } else {
                    assert_eq!((f.header(), f.code()), (Header::Error, code));
                    self.rejected = Some(code);
                }
                self.origin(q, d.as_ref());
                self.awaiting = false;
            }
            Heard::Mismatch => {
                assert!(self.awaiting, "a mismatch while no reply was awaited");
                let q = self.query.expect("a query");
                let f = seen.frame();
                assert_eq!(
                    (f.header(), f.station(), f.code()),
                    (Header::Response, station, self.kind.id)
                );
                if let Some(recs) = parse_reply(self.kind, &f) {
                    assert!(
                        !fits(&recs, q.head, q.asked),
                        "a reply that fits {q:?} called a mismatch"
                    );
                }
            }
            Heard::Fence => {
                let in_order = match &d {
                    Some(d) => {
                        let cmd = self
                            .link
                            .origin(d)
                            .expect("an echo the controller never made");
                        assert_eq!(Some(cmd), self.last_fence, "the echo of another fence");
                        d.ok()
                    }
                    None => false,
                };
                if !in_order {
                    // An echo outside the contract settles what is owed:
                    // replies to earlier commands are no longer in order.
                    self.excused_before = self.link.cmds.len();
                }
                self.fence_awaited = false;
                self.echo_since_answer = true;
            }
            Heard::Unplaced => {
                if let Some(cmd) = d.as_ref().and_then(|d| self.link.placeable(d)) {
                    let owner = self.owners[cmd];
                    let excused = cmd < self.excused_before
                        || owner.is_some_and(|o| self.adrift.contains(&o));
                    assert!(
                        excused,
                        "a reply within the contract heard Unplaced: command {cmd} of {owner:?} \
                         sent at {}, now {} ({:?})",
                        self.link.cmds[cmd].at,
                        self.clock,
                        d.map(|d| d.kind)
                    );
                }
            }
            Heard::Stale | Heard::Foreign | Heard::Broken(_) => {}
        }
    }

    /// Query `q` took a reply from delivery `d` (`None`: forged): it must
    /// be one the controller made for it, unless the delivery broke the
    /// contract (or an echo outside it settled it), or the query was a
    /// first read and the delivery an in-contract copy (a first read does
    /// not wait for copies: its confirmation checks it).
    fn origin(&mut self, q: Query, d: Option<&Delivery>) {
        let Some(d) = d else {
            self.adrift.insert(q.serial);
            return;
        };
        let cmd = self
            .link
            .origin(d)
            .expect("a frame the controller never made");
        let owner = self.owners[cmd];
        let copy = matches!(d.kind, Kind::Reply { copy: true, .. });
        let excused = cmd < self.excused_before || (copy && !q.proof);
        if owner != Some(q.serial) && d.ok() && !excused {
            assert!(
                owner.is_some_and(|o| self.adrift.contains(&o)),
                "query {q:?} took a reply made for query {owner:?} (command {cmd} sent at {}, now {}, {:?})",
                self.link.cmds[cmd].at,
                self.clock,
                d.kind
            );
        }
        if owner != Some(q.serial) || !d.ok() {
            // Something else stood in for its reply.
            self.adrift.insert(q.serial);
        }
    }

    /// The controller got command `cmd` at the clock.
    fn answer(&mut self, cmd: usize, bytes: &[u8], fence: bool, f: &link::Fate) {
        let at = if f.fault == 0 {
            self.clock + 1
        } else {
            self.clock + f.delay
        };
        let station = self.setup.line.station;
        if fence {
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
            let wrong: BTreeSet<u16> = truth
                .iter()
                .chain(recs.iter())
                .map(|r| r.number)
                .filter(|&n| {
                    truth.iter().find(|r| r.number == n) != recs.iter().find(|r| r.number == n)
                })
                .collect();
            for n in wrong {
                *self.lied.entry(n).or_default() += 1;
            }
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

/// Whether `recs` answer the window `head..head + asked`.
fn fits(recs: &[PositionRecord], head: u16, asked: u16) -> bool {
    recs.len() <= usize::from(asked)
        && recs.iter().all(|r| {
            let n = u32::from(r.number);
            n >= u32::from(head) && n < u32::from(head) + u32::from(asked)
        })
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
        shadow: Shadow::streaming(kind),
        clock: 0,
        query: None,
        firsts: BTreeSet::new(),
        next_head: u32::from(first),
        awaiting: false,
        last_sent: 0,
        broken_since_sent: false,
        last_answer: None,
        echo_since_answer: false,
        rejected: None,
        last_fence: None,
        fences: 0,
        fence_awaited: false,
        owners: Vec::new(),
        adrift: BTreeSet::new(),
        excused_before: 0,
        seen: BTreeMap::new(),
        lies: BTreeSet::new(),
        lied: BTreeMap::new(),
        transmitted: false,
    };
    let ex = setup.line;
    let windows = (u32::from(last) - u32::from(first)) / u32::from(cfg.window()) + 1;
    let reads = if cfg.confirm { 3 } else { 1 };
    let round = 32 * reads * usize::from(ex.max_sends);
    let mut max_steps =
        400 + 16 * data.len() + round * windows as usize * (1 + usize::from(resumes));
    let mut steps = 0usize;
    let mut delivered = 0u32;
    // The line's count of unplaced frames at the last proof (or start).
    let mut proven = 0u32;
    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        let now = h.now();
        let before = h.line.stats();
        let reconfirmed = h.rb.stats().reconfirmed;
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
        if after.fences_failed > before.fences_failed {
            h.fence_awaited = false;
        }
        if h.rb.stats().reconfirmed > reconfirmed {
            // A proof found frames unplaced: every window is read again.
            assert_ne!(after.unplaced, proven, "read again with nothing unplaced");
            let waited = u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms);
            assert!(
                h.echo_since_answer || h.clock > h.last_sent + waited,
                "read again before a proof"
            );
            proven = after.unplaced;
            h.firsts.clear();
            max_steps += round * 16;
        }
        if after.sends > before.sends {
            // The engine cleared its receiver for the send.
            h.shadow.release();
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
                let fence = after.fences > before.fences;
                assert_eq!(
                    fence,
                    setup.is_fence(&bytes),
                    "a fence not counted, or counted and not sent"
                );
                if fence {
                    link::check_fence(&setup, &bytes, after.fences);
                    h.fences = after.fences;
                } else {
                    assert_eq!(after.sends, before.sends + 1, "a send not counted");
                    let (head, asked) = controller::parse_query(kind, ex.station, &bytes)
                        .expect("neither a fence nor a query of the kind");
                    assert!(asked >= 1 && asked <= cfg.window(), "window of {asked}");
                    assert!(
                        u32::from(head) >= h.next_head
                            && u32::from(head) + u32::from(asked) - 1 <= u32::from(last),
                        "query {head}+{asked} outside {}..={last}",
                        h.next_head
                    );
                    let q = if h.line.sends() > 1 {
                        assert!(
                            h.clock >= h.last_sent + u64::from(ex.timeout_ms)
                                || h.broken_since_sent,
                            "resent at {} after a send that ended at {}",
                            h.clock,
                            h.last_sent
                        );
                        let mut q = h.query.expect("a resend of a query");
                        assert_eq!(q.head, head, "a resend of another window");
                        if asked != q.asked {
                            // Split after a timeout: a first read of fewer
                            // positions (unconfirmed: still delivered).
                            assert!(asked < q.asked, "a resend of a larger window");
                            h.firsts.remove(&(q.head, q.asked));
                            q.delivers &= !cfg.confirm;
                            q.asked = asked;
                        }
                        assert_eq!(q.delivers, h.rb.delivers(), "a resend delivers otherwise");
                        q
                    } else {
                        // The engine says whether it delivers this reply;
                        // what it may deliver is checked: the next positions
                        // in order, and (confirmed) only positions read once
                        // before since the last round read again.
                        let delivers = h.rb.delivers();
                        if delivers {
                            assert_eq!(u32::from(head), h.next_head, "a delivery out of order");
                            let read = |n: u32| {
                                h.firsts.iter().any(|&(fh, fa)| {
                                    n >= u32::from(fh) && n < u32::from(fh) + u32::from(fa)
                                })
                            };
                            assert!(
                                !cfg.confirm
                                    || (u32::from(head)..u32::from(head) + u32::from(asked))
                                        .all(read),
                                "a confirmation of positions not read before"
                            );
                        }
                        Query {
                            head,
                            asked,
                            delivers,
                            proof: delivers,
                            serial: after.commands,
                        }
                    };
                    h.query = Some(q);
                }
                h.awaiting = false;
                let op = h.input.next();
                let fate = h.link.fate(&mut h.input, op);
                let to = h.clock + fate.dur;
                h.deliver_until(to);
                h.clock = to;
                let now = h.now();
                h.rb.sent(&mut h.line, now);
                if fence {
                    h.fence_awaited = true;
                    h.last_fence = None;
                } else {
                    h.awaiting = true;
                    h.last_sent = h.clock;
                    h.broken_since_sent = false;
                }
                if !fate.lost {
                    let cmd = h.link.received(&bytes, h.clock);
                    let owner = (!fence).then(|| h.query.expect("a query").serial);
                    h.owners.push(owner);
                    if fence {
                        h.last_fence = Some(cmd);
                    }
                    h.answer(cmd, &bytes, fence, &fate);
                }
            }
            S::Wait(t) => {
                let nothing_sent = !h.transmitted && ex.fences;
                let bound = setup.horizon(h.line.copy_window());
                let ahead = records::check_wait(now, t, bound, nothing_sent);
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
                assert_eq!(u32::from(head), h.next_head, "windows out of order");
                assert!(asked >= 1 && asked <= cfg.window());
                let end = u32::from(head) + u32::from(asked);
                assert!(
                    end - 1 <= u32::from(last),
                    "a window past the last position"
                );
                h.next_head = end;
                h.firsts.remove(&(head, asked));
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
                // Proven: a fence echoed since the reply, or its replies
                // waited out; nothing unplaced since the last proof.
                let waited = u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms);
                assert!(
                    h.echo_since_answer || h.clock > h.last_sent + waited,
                    "window {head}+{asked} delivered without a proof"
                );
                assert_eq!(
                    after.unplaced, proven,
                    "window {head}+{asked} delivered with frames unplaced since the last proof"
                );
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
                    let wrong = truth
                        .iter()
                        .chain(recs.iter())
                        .map(|r| r.number)
                        .filter(|&n| {
                            truth.iter().find(|r| r.number == n)
                                != recs.iter().find(|r| r.number == n)
                        });
                    let alike = wrong
                        .clone()
                        .all(|n| h.lied.get(&n).is_some_and(|&c| c >= 2));
                    let excused =
                        s.is_some_and(|s| s.out_of_contract || (!s.lies.is_empty() && alike));
                    assert!(
                        excused,
                        "confirmed window {head}+{asked} differs from the table \
                         (delivered {recs:?}, table {truth:?})"
                    );
                }
            }
            S::End => {
                assert_eq!(
                    h.next_head,
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
                    Failure::Unconfirmed { unplaced } => {
                        assert_eq!(unplaced, after.unplaced, "Unconfirmed names another count");
                        assert!(
                            h.rb.stats().reconfirmed > u32::from(MAX_RECONFIRMS),
                            "Unconfirmed after {} rounds",
                            h.rb.stats().reconfirmed
                        );
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
