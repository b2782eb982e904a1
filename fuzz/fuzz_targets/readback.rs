//! The read-back engine (`readback::ReadBack`), fed arbitrary replies or
//! answered by a simulated controller that holds a table.
//!
//! Input layout: a config (query kind 21FH / 22DH / 209H and the mode,
//! station, first position, span 0-255, reply size limit, timeout, sends,
//! turnaround, late and duplicate windows, start tick, resumes 0-3), then a
//! script of what happens whenever the engine waits.
//! - mode 0 (arbitrary): the script advances the clock, sends arbitrary
//!   bytes, generated replies (records numbered in, around and outside the
//!   window; right or wrong counts and stations), `&` replies, or lets the
//!   deadline pass; bytes the engine does not take (it holds a reply until
//!   the next poll delivers it) are fed again after that poll. When the
//!   script ends the line is silent.
//! - mode 1 (table): a controller with a table (some positions defined)
//!   answers each query with the defined records of its window; per query
//!   the script picks the transmission time, loss of the query, a reply
//!   delay (up to far past the timeout), loss, a duplicate later on, a
//!   corrupted byte, an `&` reply; while the engine waits it may also
//!   inject noise (never a LF) or replay an earlier real reply (a stale
//!   one). When the script ends the controller answers after 1 ms.
//!
//! Checked (both modes): no panic; it stops within a bounded number of
//! steps; every query is a valid query of the kind for the station and
//! asks a window of 1 to `window()` positions inside `first..=last`; a
//! query is either the window in flight again (after a timeout: the same
//! head, the same or a smaller span), the next window (starting right
//! after the last window delivered: no gap, no overlap), or a re-read of a
//! window delivered empty before; `Records` come for the window last asked
//! (`head()`, `asked()`, `reread()` agree), hold at most `asked` records,
//! each inside the window and inside `first..=last`; `stats().records`
//! adds them up (with confirmed reads, `confirm`, the records of every
//! reply taken until open finding F7 is fixed); `Answered`/`Rejected` events only for a reply / an `&`
//! carrying that count / code (the one fed, or, since bytes of a failed
//! text frame are decoded again, one fed earlier since the last query);
//! `Complete` only after the last window; `Failed` only with `Timeout`,
//! `Controller { code }` or `Bridge { code }` (by the code's range); no
//! wait before the first query, none longer than the longest hold.
//! Confirmed reads (`confirm`, a config bit) ask each window until two
//! replies in a row agree: the same window asked again.
//!
//! Mode 1 also checks the records themselves: every record delivered is
//! one the controller holds, unaltered; if every reply arrived within the
//! engine's contract (at most `timeout + late_window` after its query was
//! sent, a copy at most `duplicate_window` after an original that was in
//! time), every window delivered with records holds exactly the
//! controller's records of that window (open finding F8, F6 left in
//! `ReadBack`: a duplicate of a late reply to a window that then shrank
//! is taken for the next window; tolerated only with that signature until
//! fixed); if moreover no reply came twice, every window (empty ones too: an empty reply is the same for every window,
//! the engine's documented limit) is exact and at `Complete` the records
//! delivered are exactly the table's in `first..=last`.
//!
//! What changed with the new engine: windows shrink after a timeout and
//! windows answered empty by what turns out to be a duplicate are read
//! again, so "windows follow each other without gaps" became the three
//! kinds of query above.
#![no_main]

#[path = "common/controller.rs"]
mod controller;
#[path = "common/records.rs"]
mod records;

use controller::Table;
use iai_protocol_b::checksum::ChecksumMode;
use iai_protocol_b::error::BRIDGE_CODES;
use iai_protocol_b::exchange::ExchangeConfig;
use iai_protocol_b::field::FieldSpec;
use iai_protocol_b::frame::{emit_frame, Header, Station};
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::readback::{ReadBack, ReadBackConfig, ReadEvent, ReadStep};
use iai_protocol_b::transfer::TransferError;
use libfuzzer_sys::fuzz_target;
use records::Input;

/// Finding F7 (fixed in the core; the check is strict) (fuzz/README.md): `ReadBackStats::records` ("records
/// received (and delivered)") adds up the records of every reply the
/// engine takes, so with confirmed reads (`ReadBackConfig::confirm`, the
/// default) it counts each window's records once per reply (twice or more)
/// instead of once per delivery. Before the fix, with `confirm`, the count
/// had to be exactly that sum.
const F7_FIXED: bool = true;

/// What `stats().records` must be after `delivered` records were delivered
/// from replies that held `answered` records in all.
fn counted(delivered: u32, answered: u32, confirm: bool) -> u32 {
    if confirm && !F7_FIXED {
        answered
    } else {
        delivered
    }
}

/// Finding F8 (fixed in the core; the check is strict) (fuzz/README.md), what is left of F6 in `ReadBack`:
/// the core now holds back a duplicate of a late reply in `Exchange`, but
/// a read-back runs its exchange without a duplicate window (it guards
/// only after empty replies), so a copy of a late reply to a window that
/// then shrank is still taken for the next window, which overlaps it, and
/// records are lost. Before the fix, the
/// window check tolerated exactly that signature (the reply taken was made
/// for a window that does not cover the one delivered).
const F8_FIXED: bool = true;

/// Finding F10 (fixed in the core; the check is strict) (fuzz/README.md): with confirmed reads, the first
/// (unconfirmed) empty reply of a window already counts as "answered
/// empty" (`ReadBack::received` registers it in `empties`), so a stale
/// reply holding a record of that window queues a re-read of a window
/// that was never delivered: the window in flight comes out marked
/// `reread`, and since a re-read does not advance the head, it is read and
/// delivered again afterwards (or, once delivered with records, read again
/// as a re-read). Before the fix, with
/// `confirm`, a window in flight delivered as a re-read (it then counts as
/// one) and a re-read of a window answered empty but not delivered empty
/// were tolerated.
const F10_FIXED: bool = true;

const QUERIES: [PositionStream; 3] = [
    PositionStream::QUERY_2_RESPONSE,
    PositionStream::QUERY_3_RESPONSE,
    PositionStream::QUERY_RESPONSE,
];

/// A reply carrying `n` generated records (count field `count`), mode 0.
fn arbitrary_reply(
    kind: PositionStream,
    station: Station,
    count: u16,
    recs_input: &mut Input<'_>,
    n: usize,
    base: u32,
    spread: u8,
) -> Vec<u8> {
    let mut buf = [0u8; 4096];
    let res = emit_frame(
        &mut buf,
        Header::Response,
        station,
        kind.id,
        ChecksumMode::Compute,
        |w| {
            if kind.reserved {
                w.put(b"00")?;
            }
            w.unsigned(FieldSpec::hex(kind.count_width), u64::from(count))?;
            for i in 0..n {
                let mut rec = records::arbitrary_record(kind.layout, recs_input);
                // Mostly inside the window, sometimes around or outside it.
                let num = base
                    .wrapping_add(i as u32 * u32::from(spread % 3))
                    .wrapping_add(u32::from(rec.number % 4))
                    .wrapping_sub(u32::from(spread >> 6));
                rec.number = records::fit_number(kind.layout, num as u16);
                kind.layout.write_record(&rec, w)?;
            }
            Ok(())
        },
    );
    match res {
        Ok(len) => buf[..len].to_vec(),
        Err(_) => Vec::new(),
    }
}

/// What a byte string fed to the engine is.
#[derive(Debug, Clone, PartialEq)]
enum What {
    /// A real reply of the controller: its record count, when its query was
    /// sent, when the original copy was due, and whether this is a second
    /// copy (a duplicate, or an old reply sent again).
    Reply {
        records: u16,
        sent_at: u64,
        first_at: u64,
        copy: bool,
        /// The window of the query it answers.
        window: (u16, u16),
    },
    Error(u16),
    /// Anything else (noise, generated or corrupted frames).
    Other,
}

#[derive(Debug, Clone)]
struct Delivery {
    at: u64,
    bytes: Vec<u8>,
    what: What,
}

/// The query sequence as the engine must keep it.
struct Windows {
    first: u32,
    last: u32,
    /// Start of the next new window.
    next_head: u32,
    /// The window in flight: (head, asked, re-read?, delivered?).
    current: Option<(u32, u16, bool, bool)>,
    /// Windows delivered empty (may be read again).
    empty: Vec<(u32, u16)>,
    /// Confirmed reads, and the windows a reply answered empty before
    /// their confirmation (open finding F10).
    confirm: bool,
    answered_empty: Vec<(u32, u16)>,
}

impl Windows {
    fn query(&mut self, head: u32, asked: u16, limit: u16) {
        assert!(
            asked >= 1 && asked <= limit,
            "window of {asked} (limit {limit})"
        );
        assert!(
            head >= self.first && head + u32::from(asked) - 1 <= self.last,
            "window {head}+{asked} outside {}..={}",
            self.first,
            self.last
        );
        let kind = match self.current {
            Some((h, a, reread, false)) if h == head && asked <= a => {
                // The window in flight again (resume, or a timeout: maybe
                // halved).
                (h, asked, reread, false)
            }
            _ if head == self.next_head => (head, asked, false, false),
            _ => {
                // Finding F10 (fixed in the core; the check is strict): with confirmed reads, a window answered
                // empty before its confirmation can be read again although
                // it was not delivered empty.
                let f10 =
                    self.confirm && !F10_FIXED && self.answered_empty.contains(&(head, asked));
                assert!(
                    self.empty.contains(&(head, asked)) || f10,
                    "query {head}+{asked}: neither the window in flight, nor the next \
                     ({}), nor a window answered empty",
                    self.next_head
                );
                (head, asked, true, false)
            }
        };
        self.current = Some(kind);
    }
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let c = input.u8();
    let kind = QUERIES[usize::from(c % 3)];
    let table_mode = c & 0x40 != 0;
    let station = Station(if c & 0x80 != 0 { 0x99 } else { input.u8() });
    let first = records::fit_number(kind.layout, input.u16());
    let span = input.u8();
    let last = records::fit_number(kind.layout, first.saturating_add(u16::from(span)));
    let last = last.max(first);
    let max_response =
        kind.overhead() + kind.layout.record_len(8) * (1 + usize::from(input.u8() % 8));
    let mut exchange = ExchangeConfig::new(station);
    exchange.timeout_ms = 1 + u32::from(input.u8()) * 20;
    exchange.max_sends = 1 + input.u8() % 4;
    exchange.turnaround_ms = 1 + u32::from(input.u8() % 4);
    exchange.late_window_ms = u32::from(input.u16());
    exchange.duplicate_window_ms = u32::from(input.u16());
    let cfg = ReadBackConfig {
        exchange,
        stream: kind,
        first,
        last,
        max_response,
        // Confirmed reads: every window until two replies in a row agree.
        confirm: c & 0x10 != 0,
    };
    let base = input.u32();
    let mut resumes = input.u8() % 4;

    // Mode 1: the controller's table, positions defined by a bit mask.
    let mut table = Table::new();
    if table_mode {
        let seed = input.u8();
        let mask = input.u32();
        let recs = records::table(kind.layout, seed, first, usize::from(span) + 1);
        for (i, r) in recs.into_iter().enumerate() {
            let n = u32::from(first) + i as u32;
            if mask >> (i % 32) & 1 == 1 && n <= u32::from(last) {
                let mut r = r;
                r.number = n as u16;
                if !kind.layout.extended {
                    r.extended = 0;
                }
                table.insert(r.number, r);
            }
        }
    }

    let mut rb: ReadBack<{ iai_protocol_b::limits::TTA.response }> = ReadBack::new(cfg);
    let windows = (u32::from(last) - u32::from(first)) / u32::from(cfg.window()) + 1;
    // Confirmed reads ask each window at least twice.
    let reads = if cfg.confirm { 2 } else { 1 };
    let max_steps = 256
        + 16 * data.len()
        + 16 * reads
            * windows as usize
            * usize::from(exchange.max_sends)
            * (1 + usize::from(resumes));

    let mut w = Windows {
        first: u32::from(first),
        last: u32::from(last),
        next_head: u32::from(first),
        current: None,
        empty: Vec::new(),
        confirm: cfg.confirm,
        answered_empty: Vec::new(),
    };
    let mut clock: u64 = 0;
    let now = |clock: u64| base.wrapping_add(clock as u32);
    let mut delivered = 0u32;
    // Records in every reply the engine took (`Answered`): with confirmed
    // reads each window's records come at least twice.
    let mut answered = 0u32;
    let exchange = cfg.exchange;
    let mut got = Table::new();
    // Bytes fed but not taken yet (the engine holds a reply for delivery).
    let mut pending: Vec<(Vec<u8>, What)> = Vec::new();
    let mut outbox: Vec<Delivery> = Vec::new();
    let mut history: Vec<Delivery> = Vec::new();
    let mut line = Line::default();
    let mut held;
    let mut any_sent = false;
    // The window of the reply the engine took last (mode 1), and what was
    // fed since the last query.
    let mut taken: Option<(u16, u16)> = None;
    let mut recent: Vec<What> = Vec::new();
    let mut steps = 0usize;

    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        held = false;
        match rb.poll(now(clock)) {
            ReadStep::Transmit(q) => {
                trace!(
                    "t={clock} now={} TX {}",
                    now(clock),
                    String::from_utf8_lossy(q).trim_end()
                );
                let (head, asked) = controller::parse_query(kind, station, q)
                    .expect("the engine sent an invalid query");
                w.query(u32::from(head), asked, cfg.window());
                any_sent = true;
                // The engine resets its reply decoder for every send.
                recent.clear();
                let op = if table_mode { input.next() } else { None };
                let dur = u64::from(op.map_or(1, |o| o & 7));
                if table_mode {
                    // Replies due while the query goes out arrive before `sent`.
                    let to = clock + dur;
                    while outbox.first().is_some_and(|d| d.at <= to) {
                        let d = outbox.remove(0);
                        clock = clock.max(d.at);
                        queue(&mut pending, &d, clock, &exchange, &mut line);
                        feed(
                            &mut rb,
                            &mut pending,
                            now(clock),
                            &mut held,
                            &mut taken,
                            &mut answered,
                            &mut w,
                            &mut recent,
                        );
                    }
                    clock = to;
                }
                rb.sent(now(clock));
                if table_mode {
                    answer(
                        &mut input,
                        op,
                        kind,
                        station,
                        &table,
                        head,
                        asked,
                        clock,
                        &cfg,
                        &mut outbox,
                        &mut history,
                    );
                }
            }
            ReadStep::WaitUntil(deadline) => {
                trace!("t={clock} now={} WAIT until {deadline}", now(clock));
                // The longest hold: the quarantine after a resend (timeout
                // + late window), the duplicate guard and the turnaround.
                let bound = u64::from(exchange.timeout_ms)
                    + u64::from(exchange.late_window_ms)
                    + u64::from(exchange.duplicate_window_ms)
                    + u64::from(exchange.turnaround_ms)
                    + 2;
                let ahead = records::check_wait(now(clock), deadline, bound, !any_sent);
                let until = clock + u64::from(ahead);
                if table_mode {
                    match input.next() {
                        None => {
                            let next = outbox.first().map_or(until, |d| d.at.min(until));
                            while outbox.first().is_some_and(|d| d.at <= next) {
                                let d = outbox.remove(0);
                                clock = clock.max(d.at);
                                queue(&mut pending, &d, clock, &exchange, &mut line);
                                feed(
                                    &mut rb,
                                    &mut pending,
                                    now(clock),
                                    &mut held,
                                    &mut taken,
                                    &mut answered,
                                    &mut w,
                                    &mut recent,
                                );
                            }
                            clock = clock.max(next);
                        }
                        Some(op) => {
                            let to = match op % 4 {
                                0 => clock + u64::from(input.u16()),
                                1 => {
                                    let n = usize::from(input.u8() % 64);
                                    let bytes: Vec<u8> = input
                                        .take(n)
                                        .iter()
                                        .map(|&b| if b == b'\n' { b'?' } else { b })
                                        .collect();
                                    pending.push((bytes, What::Other));
                                    clock
                                }
                                2 => {
                                    if !history.is_empty() {
                                        let mut d = history
                                            [usize::from(input.u8()) % history.len()]
                                        .clone();
                                        if let What::Reply { copy, .. } = &mut d.what {
                                            *copy = true;
                                        }
                                        queue(&mut pending, &d, clock, &exchange, &mut line);
                                    }
                                    clock
                                }
                                _ => until,
                            };
                            while outbox.first().is_some_and(|d| d.at <= to) {
                                let d = outbox.remove(0);
                                clock = clock.max(d.at);
                                queue(&mut pending, &d, clock, &exchange, &mut line);
                                feed(
                                    &mut rb,
                                    &mut pending,
                                    now(clock),
                                    &mut held,
                                    &mut taken,
                                    &mut answered,
                                    &mut w,
                                    &mut recent,
                                );
                            }
                            clock = clock.max(to);
                        }
                    }
                } else {
                    match input.next() {
                        None => {
                            pending.clear();
                            clock = until;
                        }
                        Some(op) => match op % 6 {
                            0 => clock += u64::from(input.u16()),
                            1 => {
                                let n = usize::from(input.u8());
                                pending.push((input.take(n).to_vec(), What::Other));
                            }
                            2 | 3 => {
                                let (head, asked) = w.current.map_or((0, 1), |c| (c.0, c.1));
                                let n = usize::from(input.u8()) % (usize::from(asked) + 2);
                                let count = if op & 0x80 == 0 {
                                    n as u16
                                } else {
                                    u16::from(input.u8())
                                };
                                let st = if op & 0x40 == 0 {
                                    station
                                } else {
                                    Station(input.u8())
                                };
                                let spread = input.u8();
                                let r =
                                    arbitrary_reply(kind, st, count, &mut input, n, head, spread);
                                pending.push((r, What::Other));
                            }
                            4 => {
                                let code = input.u16() & 0xFFF;
                                pending.push((
                                    controller::error_reply(station, code),
                                    What::Error(code),
                                ));
                            }
                            _ => clock = until,
                        },
                    }
                }
                feed(
                    &mut rb,
                    &mut pending,
                    now(clock),
                    &mut held,
                    &mut taken,
                    &mut answered,
                    &mut w,
                    &mut recent,
                );
            }
            ReadStep::Records(recs) => {
                trace!(
                    "t={clock} RECORDS {}+{} reread {}",
                    recs.head(),
                    recs.asked(),
                    recs.reread()
                );
                let (head, asked, mut reread, done) = w.current.expect("records before any query");
                assert!(!done, "a window delivered twice");
                // Finding F10 (fixed in the core; the check is strict): with confirmed reads, a window still
                // being confirmed can be delivered marked `reread`.
                if cfg.confirm && !F10_FIXED && recs.reread() && !reread {
                    reread = true;
                }
                assert_eq!(
                    (u32::from(recs.head()), recs.asked(), recs.reread()),
                    (head, asked, reread),
                    "records for another window than the one asked"
                );
                let mut n = 0u16;
                let mut these: Vec<PositionRecord> = Vec::new();
                for rec in recs {
                    let p = u32::from(rec.number);
                    assert!(
                        p >= head && p < head + u32::from(asked),
                        "record {p} outside the window {head}+{asked}"
                    );
                    assert!(p >= u32::from(first) && p <= u32::from(last));
                    assert_eq!(rec.positions.len(), rec.axes.count());
                    n += 1;
                    these.push(rec);
                }
                assert!(n <= asked, "{n} records for {asked} positions");
                delivered += u32::from(n);
                assert_eq!(
                    rb.stats().records,
                    counted(delivered, answered, cfg.confirm)
                );
                if table_mode {
                    // Every record delivered is the controller's, unaltered.
                    for r in &these {
                        assert_eq!(
                            table.get(&r.number),
                            Some(r),
                            "a record the controller does not hold"
                        );
                    }
                    let truth = controller::window(&table, head as u16, asked);
                    // Finding F8 (fixed in the core; the check is strict) (fuzz/README.md), F6 left in `ReadBack`: a
                    // duplicate of a late reply to a window that then shrank
                    // is taken for the next window, which overlaps it.
                    let f8 = !F8_FIXED
                        && taken.is_some_and(|(h, a)| {
                            u32::from(h) > head
                                || u32::from(h) + u32::from(a) < head + u32::from(asked)
                        });
                    if !line.out_of_contract && (n > 0 || !line.copies) && !f8 {
                        assert_eq!(these, truth, "window {head}+{asked} read wrong");
                    }
                    taken = None;
                    for r in these {
                        got.insert(r.number, r);
                    }
                }
                if n == 0 {
                    w.empty.push((head, asked));
                }
                w.current = Some((head, asked, reread, true));
                if !reread {
                    w.next_head = head + u32::from(asked);
                }
                feed(
                    &mut rb,
                    &mut pending,
                    now(clock),
                    &mut held,
                    &mut taken,
                    &mut answered,
                    &mut w,
                    &mut recent,
                );
            }
            ReadStep::Complete(stats) => {
                assert_eq!(stats.records, counted(delivered, answered, cfg.confirm));
                assert_eq!(
                    w.next_head,
                    u32::from(last) + 1,
                    "Complete before the last window"
                );
                if table_mode && !line.out_of_contract && !line.copies {
                    let truth: Table = table
                        .range(first..=last)
                        .map(|(&n, r)| (n, r.clone()))
                        .collect();
                    assert_eq!(got, truth, "the read-back missed or invented records");
                }
                break;
            }
            ReadStep::Failed(e) => {
                trace!("t={clock} FAILED {e:?}");
                match e {
                    TransferError::Timeout => {}
                    TransferError::Controller { code } => assert!(!BRIDGE_CODES.contains(&code)),
                    TransferError::Bridge { code } => assert!(BRIDGE_CODES.contains(&code)),
                    other => panic!("unexpected failure {other:?}"),
                }
                if resumes == 0 || (!table_mode && input.is_empty()) {
                    break;
                }
                resumes -= 1;
                rb.resume(now(clock));
            }
        }
    }
});

/// What the replies on the line allow the table check to expect.
#[derive(Default)]
struct Line {
    /// A reply arrived outside the engine's contract: later than
    /// `timeout + late_window` after its query was sent, and (for a copy)
    /// later than `duplicate_window` after the original.
    out_of_contract: bool,
    /// A second copy of a reply arrived (an empty reply is the same for
    /// every window: the engine's documented limit).
    copies: bool,
}

/// Queues a delivery's bytes arriving at `clock`; notes replies outside
/// the contract and copies.
fn queue(
    pending: &mut Vec<(Vec<u8>, What)>,
    d: &Delivery,
    clock: u64,
    ex: &ExchangeConfig,
    line: &mut Line,
) {
    if let What::Reply {
        sent_at,
        first_at,
        copy,
        ..
    } = d.what
    {
        let in_time = sent_at + u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms);
        let late = clock >= in_time;
        // A copy is in time up to `duplicate_window` after an original that
        // was in time itself.
        let dup_late =
            !copy || first_at >= in_time || clock >= first_at + u64::from(ex.duplicate_window_ms);
        if late && dup_late {
            line.out_of_contract = true;
        }
        line.copies |= copy;
    }
    pending.push((d.bytes.clone(), d.what.clone()));
}

/// Feeds what is pending until the engine holds a reply or all is taken;
/// checks each event against what was fed. After `Answered` nothing more
/// is fed until the next poll has delivered the records (`held`).
fn feed<const N: usize>(
    rb: &mut ReadBack<N>,
    pending: &mut Vec<(Vec<u8>, What)>,
    now: u32,
    held: &mut bool,
    taken: &mut Option<(u16, u16)>,
    answered: &mut u32,
    w: &mut Windows,
    recent: &mut Vec<What>,
) {
    if *held {
        return;
    }
    while let Some((bytes, what)) = pending.first_mut() {
        let r = rb.received(bytes, now);
        trace!(
            "now={now} RX {:?} -> {:?}",
            String::from_utf8_lossy(&bytes[..r.consumed]),
            r.event
        );
        assert!(r.consumed <= bytes.len());
        bytes.drain(..r.consumed);
        // The frame behind an event is the one being fed, or (bytes of a
        // failed text frame are decoded again) one fed before since the
        // last query.
        let made_by = |fits: &dyn Fn(&What) -> bool| -> Option<What> {
            std::iter::once(&*what)
                .chain(recent.iter().rev())
                .find(|w| fits(w))
                .cloned()
        };
        match r.event {
            ReadEvent::NeedMore => {
                if !bytes.is_empty() {
                    // Held for delivery: the rest waits for the next poll.
                    return;
                }
                recent.push(pending.remove(0).1);
            }
            ReadEvent::Answered { records } => {
                *answered += u32::from(records);
                if let (0, Some((h, a, ..))) = (records, w.current) {
                    w.answered_empty.push((h, a));
                }
                let by = made_by(&|w| match w {
                    What::Reply { records: k, .. } => *k == records,
                    What::Other => true,
                    What::Error(_) => false,
                });
                match by {
                    Some(What::Reply { window, .. }) => *taken = Some(window),
                    Some(_) => {}
                    None => panic!("answered ({records} records) by {what:?}"),
                }
                if bytes.is_empty() {
                    recent.push(pending.remove(0).1);
                }
                *held = true;
                return;
            }
            ReadEvent::Rejected { code } => {
                let by =
                    made_by(&|w| matches!(w, What::Error(c) if *c == code) || *w == What::Other);
                assert!(by.is_some(), "rejected ({code:03X}) by {what:?}");
            }
            ReadEvent::Stale | ReadEvent::Foreign | ReadEvent::Broken(_) => {}
        }
    }
}

/// The controller answers the query for (head, asked) sent at `clock`,
/// with the faults the script picks.
#[allow(clippy::too_many_arguments)]
fn answer(
    input: &mut Input<'_>,
    op: Option<u8>,
    kind: PositionStream,
    station: Station,
    table: &Table,
    head: u16,
    asked: u16,
    clock: u64,
    cfg: &ReadBackConfig,
    outbox: &mut Vec<Delivery>,
    history: &mut Vec<Delivery>,
) {
    let op = op.unwrap_or(0);
    // The query lost or corrupted: no answer.
    if (op >> 3) & 3 == 2 {
        return;
    }
    let fault = op >> 5;
    let extra = if fault != 0 { input.u8() } else { 0 };
    let delay = if fault == 0 {
        1
    } else {
        u64::from(input.u16())
            % (3 * u64::from(cfg.exchange.timeout_ms) + u64::from(cfg.exchange.late_window_ms) + 2)
    };
    let recs = controller::window(table, head, asked);
    let bytes = controller::query_reply(kind, station, &recs);
    assert!(
        bytes.len() <= cfg.max_response,
        "a reply over max_response for an engine window"
    );
    let mut d = Delivery {
        at: clock + delay,
        bytes,
        what: What::Reply {
            records: recs.len() as u16,
            sent_at: clock,
            first_at: clock + delay,
            copy: false,
            window: (head, asked),
        },
    };
    history.push(d.clone());
    let schedule = |outbox: &mut Vec<Delivery>, d: Delivery| {
        let i = outbox.partition_point(|e| e.at <= d.at);
        outbox.insert(i, d);
    };
    match fault {
        1 => {}
        2 => {
            controller::corrupt_byte(&mut d.bytes, u32::from(extra) * 977 + u32::from(op));
            d.what = What::Other;
            schedule(outbox, d);
        }
        3 => {
            let mut dup = d.clone();
            dup.at += u64::from(extra) * 50;
            if let What::Reply { copy, .. } = &mut dup.what {
                *copy = true;
            }
            schedule(outbox, d);
            schedule(outbox, dup);
        }
        5 => {
            let code = if extra & 1 == 0 {
                *BRIDGE_CODES.start() + u16::from(extra >> 1) % 0x20
            } else {
                0x0A0 + u16::from(extra)
            };
            d.bytes = controller::error_reply(station, code);
            d.what = What::Error(code);
            schedule(outbox, d);
        }
        _ => schedule(outbox, d),
    }
}
