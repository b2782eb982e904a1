//! The transfer engine (`transfer::Transfer`) over a `line::Line`, on a
//! virtual clock, against a simulated controller that holds a position
//! table, applies every write it gets and answers in order.
//!
//! Input layout: the line (`common/link.rs`: station, timeout, flags with
//! sends 1-4, `resend_unsafe`, fences off, raw noise, turnaround, late and
//! duplicate windows, fence seed, start tick); a byte: write kind (`% 5`:
//! 26DH, 245H, 244H, 290H, 291H) and verification policy (`/ 5 % 3`:
//! `Full`, `AfterFault`, `Off`); table size (`% 48`); table seed; shape
//! (bits 0-1: sequential, reversed, a record repeated, a number reused
//! with other content; bits 2-3: what the controller holds beforehand:
//! nothing, the source, other records at its positions); range start
//! (u16, for 244H / 290H, so that the table ends inside the start field);
//! first position number (u16); frame room (u8: `max_frame` = one 8-axis
//! record + 4 x b bytes); reply room (`% 8`); a byte: rewrites (`% 4`) and
//! `max_records` (1 + b / 4); resumes (`% 4`); then a script.
//!
//! The controller receives each transmission at its end and answers in
//! order: fences with their echo; a write is applied to its table and
//! answered with its count; a read-back query (21FH, 22DH, 209H) with the
//! defined records of its window. Per transmission the script picks its
//! length (replies due meanwhile arrive before `sent`), whether the
//! controller gets it (lost: nothing applied), for a write an SC-preserving
//! swap of two digits (the controller stores the wrong value; only reading
//! back sees it), and the reply's fate: at once, lost, a corrupted byte, a
//! copy later, a partial write (k records stored, k reported) or for a
//! read-back a lie (a record altered, missing or swapped, never showing
//! the source's value), an `&` (for a write after storing part of it), a
//! stale answer (an earlier reply sent again: a lie outside the contract),
//! a delay with a copy.
//!
//! While the engine waits, a script byte (`% 5`): 0 advances the clock
//! (u16 ms) delivering what is due, 1 injects noise (a byte `k`, `k % 64`
//! bytes, no LF unless raw noise is on; with `k & 0x40` the next delivery
//! follows with no poll between), 2 sends a copy of any reply made before
//! (a byte: which, `& 0x80` broken), 3 delivers the next delivery, 4 waits
//! until the deadline; when the script ends, the deadline or the next
//! delivery, whichever comes first. A transmission's op byte: bits 0-2
//! its length (ms), bits 3-4 = 2 the command lost, = 3 a swap in a write,
//! bits 5-7 the reply's fault (then a byte and a u16 delay): 0 at once, 1
//! lost, 2 a corrupted byte, 3 a copy later, 4 a partial write / a
//! read-back lie, 5 an `&`, 6 a stale answer, 7 a delay with a copy;
//! fences are echoed (4 and 5: an `&` instead).
//!
//! Deliveries keep the contract as in `Link::arrives` (originals within
//! `timeout + late_window` of their send and in order, copies within
//! `duplicate_window` of a first arrival that kept it, no lies, no raw
//! noise).
//!
//! Checked:
//! - no panic; it ends (`Done(Ok)`, or a failure with no resume left)
//!   within a bounded number of steps; `Idle` never (an iterator source is
//!   never pending); no wait before the first transmission of a line with
//!   fences, none in the past or beyond the longest hold;
//! - fences are 200H with the seed's text; every write is a valid frame of
//!   the kind within `max_frame` carrying the next unconfirmed records of
//!   the source in order (the right start number for a range write), at
//!   most `max_records`; every read-back query is of the matching kind
//!   (21FH for 26DH, 22DH for 290H / 291H, 209H for 244H / 245H), starts at
//!   a position of the frame last written and asks at most
//!   `window(max_response)` positions; the controller's reply fits
//!   `max_response`; a resend comes no earlier than `sent + timeout` unless
//!   a broken frame came after `sent`;
//! - `records_confirmed` never shrinks, never passes the source, and grows
//!   only by the record count of the last write frame, after its `sent`;
//! - an `Answer` while a write is awaited comes from a write reply with
//!   its count (and start) among the bytes fed since the send, an
//!   `Answer` to a query from a read-back reply holding only positions of
//!   its window, `Rejected(code)` from an `&` with that code, `Fence` from
//!   the echo of the last fence sent;
//! - `Done(Ok(g))` with the policy's guarantee and every record confirmed;
//!   **with `Verified` the controller's table holds exactly the source at
//!   every source position (never a false success)**, unless a delivery
//!   outside the contract (or raw noise) was among the bytes that made a
//!   reply or an echo taken; with `FaultsVerified` / `Unverified` the same
//!   unless a write was swapped (what those policies do not claim to
//!   catch);
//! - a failure is `Timeout` / `OutcomeUnknown` (by the resend safety of the
//!   command, with its sends), `Controller { code }` after an `&` with that
//!   code, or `Mismatch { first_position, records }` naming a position of
//!   the frame last written, `records >= 1`; never with every record
//!   confirmed; `resume` goes on. `Misplaced { position }` only at the end
//!   (every record confirmed), and only when two read-back lies left that
//!   record out (this controller stores every record at its number) or
//!   bytes outside the contract were taken.
//!
//! Removed with the redesign: the checks of the engine's guard windows and
//! holds (the line decides now when a command may go out: the `line`
//! target checks that), and of the events `Confirmed` / `CountMismatch` /
//! `Compared`, which no longer exist (the line's `Heard` replaces them).
#![no_main]

#[path = "common/controller.rs"]
mod controller;
#[path = "common/link.rs"]
mod link;
#[path = "common/records.rs"]
mod records;

use std::collections::BTreeMap;

use controller::Table;
use iai_protocol_b::catalogue::{self, Resend};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::Status;
use iai_protocol_b::engine::Step;
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::Frame;
use iai_protocol_b::line::{Heard, Line};
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::transfer::{Guarantee, Transfer, TransferConfig, Verify};
use libfuzzer_sys::fuzz_target;
use link::{Delivery, Kind, Link, Setup};
use records::Input;

/// The engine's frame buffer: the TTA's receive limit.
const N: usize = iai_protocol_b::limits::TTA.command;

const WRITES: [PositionStream; 5] = [
    PositionStream::CHANGE_2,
    PositionStream::CHANGE,
    PositionStream::RANGE,
    PositionStream::RANGE_3,
    PositionStream::CHANGE_3,
];

/// What a reply the controller made says (by made index).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Said {
    Count {
        start: u16,
        count: u16,
    },
    Records {
        head: u16,
        asked: u16,
    },
    Error(u16),
    /// The echo of fence command `cmd`.
    Echo(usize),
}

/// The write frame last sent: first source index, records, start.
#[derive(Debug, Clone, Copy)]
struct Write {
    from: usize,
    n: u16,
    start: u16,
}

struct H<'a> {
    input: Input<'a>,
    setup: Setup,
    kind: PositionStream,
    rb: PositionStream,
    table: Table,
    expected: Table,
    link: Link,
    line: Line,
    t: Transfer<std::vec::IntoIter<PositionRecord>, N>,
    clock: u64,
    said: Vec<Said>,
    /// Deliveries fed since the engine last reset its decoders (at each
    /// send): the frame behind an event is one of them.
    recent: Vec<Delivery>,
    write: Option<Write>,
    write_sent: bool,
    /// The query last sent (head, asked).
    query: Option<(u16, u16)>,
    awaiting: bool,
    last_sent: u64,
    broken_since_sent: bool,
    /// No table claim: a reply or echo was taken with bytes outside the
    /// contract among its candidates.
    no_claim: bool,
    /// Read-back lies that left a record out, by its position: two in a
    /// row make a record read back twice missing (`Misplaced`).
    left_out: BTreeMap<u16, u32>,
    swapped: bool,
    rejected: Vec<u16>,
    /// The last fence sent (controller command index), if it got there.
    last_fence: Option<usize>,
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

    fn feed(&mut self, mut d: Delivery) {
        d.at = self.clock;
        self.link.arrives(&mut d, self.clock);
        self.recent.push(d.clone());
        let mut rest = &d.bytes[..];
        let now = self.now();
        loop {
            let errors = self.line.stats().line_errors;
            let r = self.t.received(&mut self.line, rest, now);
            if self.line.stats().line_errors > errors {
                // A broken frame (the read-back path reports none).
                self.broken_since_sent = true;
            }
            trace!(
                "t={} RX {:?} -> {:?} ({:?})",
                self.clock,
                String::from_utf8_lossy(&rest[..r.consumed]),
                r.status,
                d.kind
            );
            assert!(r.consumed <= rest.len());
            rest = &rest[r.consumed..];
            match r.status {
                Status::Partial => {
                    assert!(rest.is_empty(), "Partial with bytes left");
                    return;
                }
                Status::Complete(heard) => self.heard(heard),
            }
        }
    }

    /// The deliveries fed since the send that `fits`.
    fn candidates(&self, fits: impl Fn(&Said) -> bool) -> Vec<&Delivery> {
        self.recent
            .iter()
            .filter(|d| match d.kind {
                Kind::Reply { made, .. } => fits(&self.said[made]),
                Kind::Forged => true,
                _ => false,
            })
            .collect()
    }

    fn heard(&mut self, heard: Heard) {
        match heard {
            Heard::Answer => {
                assert!(self.awaiting, "a reply taken while none was awaited");
                let kind = self.kind;
                let cands: Vec<&Delivery> = match (self.query, self.write) {
                    (Some((qh, qa)), _) => {
                        let rb = self.rb;
                        self.recent
                            .iter()
                            .filter(|d| match d.kind {
                                Kind::Reply { .. } => fits_window(rb, &d.bytes, qh, qa),
                                Kind::Forged => true,
                                _ => false,
                            })
                            .collect()
                    }
                    (None, Some(w)) => self.candidates(|s| match *s {
                        Said::Count { start, count } => {
                            count == w.n && (kind.start_width == 0 || start == w.start)
                        }
                        _ => false,
                    }),
                    (None, None) => panic!("a reply taken before anything was sent"),
                };
                assert!(!cands.is_empty(), "a reply taken that no delivery made");
                if cands.iter().any(|d| !d.ok()) {
                    self.no_claim = true;
                }
                self.awaiting = false;
            }
            Heard::Fence => {
                let last = self.last_fence;
                let cands = self.candidates(|s| Some(*s) == last.map(Said::Echo));
                assert!(!cands.is_empty(), "no echo of the last fence was fed");
                if cands.iter().any(|d| !d.ok()) {
                    self.no_claim = true;
                }
            }
            Heard::Rejected(code) => {
                assert!(self.awaiting, "an & taken while no reply was awaited");
                let cands = self.candidates(|s| *s == Said::Error(code));
                assert!(!cands.is_empty(), "rejected ({code:03X}) by no delivery");
                self.rejected.push(code);
                self.awaiting = false;
            }
            Heard::Broken(_) => self.broken_since_sent = true,
            _ => {}
        }
    }

    /// Applies `recs` (already numbered by position).
    fn apply(&mut self, recs: &[PositionRecord]) {
        controller::apply(&mut self.table, recs);
    }

    fn reply(
        &mut self,
        bytes: Vec<u8>,
        said: Said,
        cmd: usize,
        at: u64,
        f: &link::Fate,
        lie: bool,
    ) {
        let first = self.link.made.len();
        self.link.answer(bytes, cmd, at, f, lie);
        while self.said.len() < self.link.made.len() {
            self.said.push(said);
        }
        debug_assert!(self.said.len() > first);
    }

    /// The controller got command `cmd` at the clock.
    fn answer(&mut self, cmd: usize, bytes: &[u8], fence: bool, f: &link::Fate) {
        let at = if f.fault == 0 {
            self.clock + 1
        } else {
            self.clock + f.delay
        };
        let station = self.setup.line.station;
        let error_code = 0x0A0 + u16::from(f.extra);
        if fence {
            let echo = self.link.echo(bytes);
            match f.fault {
                4 | 5 => {
                    let e = controller::error_reply(station, error_code);
                    self.reply(
                        e,
                        Said::Error(error_code),
                        cmd,
                        at,
                        &link::Fate::default(),
                        false,
                    );
                }
                _ => self.reply(echo, Said::Echo(cmd), cmd, at, f, false),
            }
            return;
        }
        // A stale answer: an earlier reply of the same kind again.
        let stale = |h: &H<'_>, want: fn(&Said) -> bool| -> Option<(Vec<u8>, Said)> {
            let olds: Vec<usize> = (0..h.said.len()).filter(|&i| want(&h.said[i])).collect();
            let i = *olds.get(usize::from(f.extra) % olds.len().max(1))?;
            Some((h.link.made[i].bytes.clone(), h.said[i]))
        };
        let plain = link::Fate { fault: 0, ..*f };
        if let Some((start, mut recs)) = controller::parse_write(self.kind, bytes) {
            if f.special
                && controller::swap_digits(&mut recs, u32::from(f.extra) | (f.delay as u32) << 8)
                    .is_some()
            {
                self.swapped = true;
            }
            let n = recs.len() as u16;
            match f.fault {
                4 if n > 1 => {
                    let k = 1 + usize::from(f.extra) % (recs.len() - 1);
                    self.apply(&recs[..k]);
                    let b = controller::write_reply(self.kind, station, start, k as u16);
                    let said = Said::Count {
                        start,
                        count: k as u16,
                    };
                    self.reply(b, said, cmd, at, &plain, false);
                }
                5 => {
                    let k = usize::from(f.extra) % (recs.len() + 1);
                    self.apply(&recs[..k]);
                    let e = controller::error_reply(station, error_code);
                    self.reply(e, Said::Error(error_code), cmd, at, &plain, false);
                }
                6 => {
                    self.apply(&recs);
                    let old = stale(self, |s| matches!(s, Said::Count { .. }));
                    if let Some((b, said)) = old {
                        self.reply(b, said, cmd, at, &plain, true);
                    }
                }
                _ => {
                    self.apply(&recs);
                    let b = controller::write_reply(self.kind, station, start, n);
                    self.reply(b, Said::Count { start, count: n }, cmd, at, f, false);
                }
            }
            return;
        }
        let (head, asked) =
            controller::parse_query(self.rb, station, bytes).expect("a write or a query");
        let mut recs = controller::window(&self.table, head, asked);
        match f.fault {
            4 => {
                // A lie the SC does not show, never showing the source's
                // value where the table differs.
                match f.extra % 3 {
                    0 if !recs.is_empty() => {
                        let i = usize::from(f.extra / 3) % recs.len();
                        let mut r = recs[i].clone();
                        r.speed = r.speed.wrapping_add(1);
                        if self.expected.get(&r.number) == Some(&r) {
                            r.speed = r.speed.wrapping_add(1);
                        }
                        recs[i] = r;
                    }
                    1 if !recs.is_empty() => {
                        let gone = recs.remove(usize::from(f.extra / 3) % recs.len());
                        *self.left_out.entry(gone.number).or_default() += 1;
                    }
                    _ => {
                        let mut swapped = recs.clone();
                        if let Some(i) =
                            controller::swap_digits(&mut swapped, u32::from(f.extra) * 131 + 7)
                        {
                            if self.expected.get(&swapped[i].number) != Some(&swapped[i]) {
                                recs = swapped;
                            }
                        }
                    }
                }
            }
            5 => {
                let e = controller::error_reply(station, error_code);
                self.reply(e, Said::Error(error_code), cmd, at, &plain, false);
                return;
            }
            6 => {
                if let Some((b, said)) = stale(self, |s| matches!(s, Said::Records { .. })) {
                    self.reply(b, said, cmd, at, &plain, true);
                    return;
                }
            }
            _ => {}
        }
        let reply = controller::query_reply(self.rb, station, &recs);
        let max_response = self.t.config().max_response;
        assert!(
            reply.len() <= max_response,
            "a read-back reply of {} bytes for a window the engine asked (max {max_response})",
            reply.len()
        );
        self.reply(reply, Said::Records { head, asked }, cmd, at, f, false);
    }
}

enum S {
    Transmit(Vec<u8>),
    Wait(u32),
    Idle,
    Done(Result<Guarantee, Failure>),
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let setup = link::setup(&mut input);
    let c = input.u8();
    let kind = WRITES[usize::from(c % 5)];
    let verify = [Verify::Full, Verify::AfterFault, Verify::Off][usize::from(c / 5 % 3)];
    let rb = kind.read_back();
    let size = usize::from(input.u8() % 48);
    let seed = input.u8();
    let shape = input.u8();
    // Range writes (244H, 290H): the table ends inside the start field's
    // range, up to exactly its top.
    let start_max = match kind.start_width {
        0 => 0u32,
        w => (1u32 << (4 * u32::from(w))) - 1,
    };
    let start = (u32::from(input.u16()) & start_max)
        .min((start_max + 1).saturating_sub(size as u32)) as u16;
    let first_number = input.u16();
    let min_frame = kind.overhead() + kind.layout.record_len(8);
    let max_frame = min_frame + usize::from(input.u8()) * 4;
    let min_response = rb.overhead() + rb.layout.record_len(8);
    let max_response = min_response + usize::from(input.u8() % 8) * rb.layout.record_len(8);
    let b = input.u8();
    let rewrites = b % 4;
    let max_records = 1 + u16::from(b >> 2);
    let mut resumes = input.u8() % 4;

    // The source: sequential numbers, or reversed, or with a record
    // repeated (same content), or a number reused with other content.
    let mut source = records::table(kind.layout, seed, first_number, size);
    if kind.layout.number_width > 0 && size > 2 {
        match shape & 3 {
            1 => source.reverse(),
            2 => {
                let r = source[size / 3].clone();
                source[size - 1] = r;
            }
            3 => {
                let n = source[0].number;
                source[size / 2].number = n;
            }
            _ => {}
        }
    }
    let expected = controller::expected(kind, start, &source);
    let mut table = Table::new();
    match (shape >> 2) & 3 {
        1 => table = expected.clone(),
        2 => {
            for (i, (&n, r)) in expected.iter().enumerate() {
                let mut o = r.clone();
                o.speed = o.speed.wrapping_add(1 + i as u16);
                table.insert(n, o);
            }
        }
        _ => {}
    }
    let cfg = TransferConfig {
        stream: kind,
        start,
        max_frame,
        max_response,
        verify,
        rewrites,
        max_records,
    };
    trace!("{:?} {cfg:?} {} records", setup.line, source.len());
    let mut h = H {
        input,
        setup,
        kind,
        rb,
        table,
        expected,
        link: Link::new(setup),
        line: Line::new(setup.line, setup.seed),
        t: Transfer::new(cfg, source.clone().into_iter()),
        clock: 0,
        said: Vec::new(),
        recent: Vec::new(),
        write: None,
        write_sent: false,
        query: None,
        awaiting: false,
        last_sent: 0,
        broken_since_sent: false,
        no_claim: setup.raw_noise,
        left_out: BTreeMap::new(),
        swapped: false,
        rejected: Vec::new(),
        last_fence: None,
        transmitted: false,
    };
    let ex = setup.line;
    let max_steps = 2_000
        + 16 * data.len()
        + 64 * (size + 1)
            * usize::from(ex.max_sends)
            * (1 + usize::from(rewrites))
            * (1 + usize::from(resumes));
    let mut steps = 0usize;
    let mut confirmed = 0u32;
    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        let now = h.now();
        let before = h.line.stats();
        let step = match h.t.poll(&mut h.line, now) {
            Step::Transmit(b) => S::Transmit(b.to_vec()),
            Step::WaitUntil(t) => S::Wait(t),
            Step::Idle => S::Idle,
            Step::Done(r) => S::Done(r),
        };
        let after = h.line.stats();
        let fresh = after.sends > before.sends;
        if fresh {
            // The engine resets its reply decoders for every send.
            h.recent.clear();
        }
        check_progress(&h, &mut confirmed, source.len());
        match step {
            S::Idle => panic!("an iterator source is never pending"),
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
                } else if let Some((s, recs)) = controller::parse_write(kind, &bytes) {
                    assert!(bytes.len() <= max_frame, "a frame over max_frame");
                    assert!(!recs.is_empty(), "a write without records");
                    assert!(
                        recs.len() <= usize::from(max_records),
                        "more than max_records"
                    );
                    let from = confirmed as usize;
                    assert!(
                        from + recs.len() <= source.len(),
                        "more records than the source"
                    );
                    for (i, r) in recs.iter().enumerate() {
                        let mut want = source[from + i].clone();
                        want.number = controller::position_of(kind, start, from + i, &want);
                        assert_eq!(*r, want, "records out of order (record {})", from + i);
                    }
                    if kind.start_width > 0 {
                        assert_eq!(
                            u32::from(s),
                            u32::from(start) + confirmed,
                            "wrong start number"
                        );
                    }
                    h.write = Some(Write {
                        from,
                        n: recs.len() as u16,
                        start: s,
                    });
                    h.write_sent = false;
                    h.query = None;
                } else {
                    let (head, asked) = controller::parse_query(rb, ex.station, &bytes)
                        .expect("neither a fence, a write nor a read-back query");
                    assert!(
                        asked >= 1 && asked <= rb.window(max_response),
                        "window {asked}"
                    );
                    assert!(
                        u64::from(head) + u64::from(asked) - 1 <= rb.count_field().max_unsigned(),
                        "window past the position field"
                    );
                    let w = h.write.expect("a read-back before any write");
                    let positions: Vec<u16> = (0..usize::from(w.n))
                        .map(|i| {
                            controller::position_of(kind, start, w.from + i, &source[w.from + i])
                        })
                        .collect();
                    assert!(
                        positions.contains(&head),
                        "a window that starts outside the frame: {head}+{asked} for {positions:?}"
                    );
                    h.query = Some((head, asked));
                }
                if !fence && fresh && h.line.sends() > 1 {
                    assert!(
                        h.clock >= h.last_sent + u64::from(ex.timeout_ms) || h.broken_since_sent,
                        "resent at {} after a send that ended at {}",
                        h.clock,
                        h.last_sent
                    );
                }
                h.awaiting = false;
                let op = h.input.next();
                let fate = h.link.fate(&mut h.input, op);
                let to = h.clock + fate.dur;
                h.deliver_until(to);
                h.clock = to;
                let now = h.now();
                h.t.sent(&mut h.line, now);
                if !fence {
                    h.awaiting = true;
                    h.last_sent = h.clock;
                    h.broken_since_sent = false;
                    if h.query.is_none() {
                        h.write_sent = true;
                    }
                }
                if fence {
                    h.last_fence = None;
                }
                if !fate.lost {
                    let cmd = h.link.received(&bytes, h.clock);
                    if fence {
                        h.last_fence = Some(cmd);
                    }
                    h.answer(cmd, &bytes, fence, &fate);
                }
            }
            S::Wait(t) => {
                let nothing_sent = !h.transmitted && ex.fences;
                let ahead =
                    records::check_wait(now, t, setup.horizon(h.line.copy_window()), nothing_sent);
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
            S::Done(Ok(g)) => {
                trace!("t={} COMPLETE {g:?}", h.clock);
                assert_eq!(g, cfg.guarantee(), "another guarantee than the policy's");
                assert_eq!(
                    h.t.stats().records_confirmed as usize,
                    source.len(),
                    "complete with records unconfirmed"
                );
                let claim = !h.no_claim && (verify == Verify::Full || !h.swapped);
                if claim {
                    for (n, r) in &h.expected {
                        assert!(
                            h.table.get(n) == Some(r),
                            "false success ({g:?}): position {n} holds {:?}, the source {r:?}",
                            h.table.get(n)
                        );
                    }
                }
                let s = h.t.stats();
                assert!(s.frames_confirmed <= s.frames_sent);
                if verify == Verify::Full {
                    assert!(s.records_verified as usize >= source.len());
                }
                if verify == Verify::Off {
                    assert_eq!((s.verify_queries, s.frames_verified), (0, 0));
                }
                break;
            }
            S::Done(Err(e)) => {
                trace!("t={} FAILED {e:?}", h.clock);
                match e {
                    Failure::Timeout { sends } | Failure::OutcomeUnknown { sends } => {
                        let id = match h.query {
                            Some(_) => rb.id,
                            None => kind.id,
                        };
                        let unsafe_ =
                            catalogue::request_rules(id).is_none_or(|(r, _)| r == Resend::Unsafe);
                        assert_eq!(
                            matches!(e, Failure::OutcomeUnknown { .. }),
                            unsafe_,
                            "{e:?}"
                        );
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
                        assert!(h.rejected.contains(&code), "Controller without that &")
                    }
                    Failure::Mismatch {
                        first_position,
                        records,
                    } => {
                        assert!(records >= 1);
                        let w = h.write.expect("a mismatch before any write");
                        let positions: Vec<u16> = (0..usize::from(w.n))
                            .map(|i| {
                                controller::position_of(
                                    kind,
                                    start,
                                    w.from + i,
                                    &source[w.from + i],
                                )
                            })
                            .collect();
                        assert!(
                            positions.contains(&first_position),
                            "mismatch names {first_position}"
                        );
                        assert!(records <= w.n);
                    }
                    Failure::Misplaced { position } => {
                        // At the end, every frame verified: a record its
                        // read-back lacked twice after a reply that counted
                        // it. This controller stores every record at its
                        // number: only two lies leaving it out (or bytes
                        // outside the contract) can make it look so.
                        assert_eq!(
                            h.t.stats().records_confirmed as usize,
                            source.len(),
                            "Misplaced before the end"
                        );
                        assert!(
                            h.no_claim || h.left_out.get(&position).is_some_and(|&n| n >= 2),
                            "Misplaced {position} without a record stored elsewhere"
                        );
                        break;
                    }
                    other => panic!("unexpected failure {other:?}"),
                }
                assert!((h.t.stats().records_confirmed as usize) < source.len());
                if resumes == 0 {
                    break;
                }
                resumes -= 1;
                let now = h.now();
                h.t.resume(&mut h.line, now);
            }
        }
    }
    let s = h.t.stats();
    assert!(s.frames_confirmed <= s.frames_sent);
});

/// Whether `bytes` is a read-back reply of `rb` with at most `asked`
/// records, all in `head..head + asked`.
fn fits_window(rb: PositionStream, bytes: &[u8], head: u16, asked: u16) -> bool {
    let Ok(f) = Frame::new_checked(bytes, BypassPolicy::Reject) else {
        return false;
    };
    if f.code() != rb.id {
        return false;
    }
    let mut r = f.reader();
    let Ok((_, count)) = rb.read_prefix(&mut r) else {
        return false;
    };
    if count > asked {
        return false;
    }
    (0..count).all(|_| {
        rb.layout.read_record(&mut r).is_ok_and(|rec| {
            let n = u32::from(rec.number);
            n >= u32::from(head) && n < u32::from(head) + u32::from(asked)
        })
    })
}

/// `records_confirmed` grows only by the last write frame's count, after
/// its `sent`, and never past the source.
fn check_progress(h: &H<'_>, confirmed: &mut u32, total: usize) {
    let now = h.t.stats().records_confirmed;
    assert!(now as usize <= total, "more confirmed than the source");
    if now != *confirmed {
        let grew = now.checked_sub(*confirmed).expect("confirmed shrank");
        match h.write {
            Some(w) if h.write_sent && w.from == *confirmed as usize => {
                assert_eq!(grew, u32::from(w.n), "confirmed grew by a count never sent")
            }
            other => panic!(
                "confirmed grew by {grew} with frame {other:?} (sent: {})",
                h.write_sent
            ),
        }
        *confirmed = now;
    }
}
