//! The transfer engine (`transfer::Transfer`) against a simulated
//! controller that holds a position table and misbehaves as the input says.
//!
//! Input layout: a config (write kind 26DH / 245H / 244H / 290H / 291H,
//! verification policy, station, table size 0-47, seed and shape, range
//! start, first position number, what the controller holds beforehand,
//! frame and reply size limits, timeout, sends, rewrites, turnaround, late
//! and duplicate windows, start tick, resumes 0-3), then a script. The
//! engine runs on a virtual millisecond clock (the harness keeps a 64-bit
//! time; the engine sees it wrapped from the start tick).
//!
//! The controller applies every write it receives to its table and answers
//! every read-back query (21FH, 22DH, 209H) from that table; replies are
//! scheduled and delivered in time order. Script bytes choose, per frame
//! sent: how long the transmission takes (replies due meanwhile arrive
//! *before* `sent`), whether the frame is lost, corrupted (the SC fails:
//! the controller stays silent and executes nothing) or, for a write,
//! altered by an SC-preserving swap of two digits of a coordinate (the
//! controller stores the wrong value); and for its reply: a delay (up to
//! far beyond the timeout), a duplicate later on, loss, a corrupted byte,
//! an `&` reply (controller or bridge code), a partial write (the first k
//! records stored, count k reported), and for a read-back reply a wrong
//! record (never the one the source holds), a missing record, a swapped
//! digit, or a stale reply (an earlier real reply of the controller sent
//! again). While the engine waits, script bytes advance the clock, deliver
//! what is due, inject noise (never a LF, so noise cannot complete a
//! frame; with the raw-noise bit of the config any bytes, as the old target
//! did), or replay an earlier write or read-back reply. When the script
//! ends the controller is well-behaved (replies after 1 ms), so every run
//! ends.
//!
//! Checked:
//! - no panic; it stops (`Complete`, or `Failed` with no resume left)
//!   within a bounded number of steps; `NeedRecords` never (an iterator is
//!   never pending);
//! - every write sent is a valid frame of the kind, within `max_frame`,
//!   carrying the next unconfirmed records of the source in order (with
//!   the right start number for a range write); every read-back query is a
//!   valid query of the matching kind (21FH for 26DH, 22DH for 290H/291H,
//!   209H for 244H/245H) for a window of at most `window(max_response)`
//!   positions, starting at a position of the frame being verified; the
//!   controller's reply to it fits `max_response`;
//! - `records_confirmed` never exceeds the source, never shrinks, and
//!   grows only by the record count of the last write frame sent, and only
//!   after its `sent`; `Confirmed { records }` only for a write reply with
//!   exactly that count (and start), never before `sent`; `CountMismatch`
//!   only for a write reply with another count or start, and it never
//!   confirms; `Rejected { code }` only for an `&` reply with that code;
//!   `Compared { head, .. }` only for the window last asked, from a
//!   read-back reply whose records all lie in it (the reply fed, or, since
//!   bytes of a failed text frame are decoded again, one fed earlier since
//!   the last transmission);
//! - no wait before the first send, none longer than the longest hold
//!   (timeout + late window + duplicate window + turnaround);
//! - `Complete` only with every record confirmed, the guarantee of the
//!   policy (`Full` -> `Verified`, `AfterFault` -> `FaultsVerified`, `Off` ->
//!   `Unverified`), and: with `Verified`, the controller's table holds
//!   exactly the source at every source position (exact compare: never a
//!   false success, also when a late or duplicated copy of a read-back
//!   reply from before a rewrite came within the engine's contract:
//!   finding F5, fixed; no claim once such a reply came outside it, later
//!   than `timeout + late_window` after its query and not within
//!   `duplicate_window` of an original that came in time); with
//!   `FaultsVerified` or `Unverified`, the same unless an SC-preserving swap
//!   was applied to a write, a write reply arrived outside the engine's
//!   guard windows (later than `timeout + late_window` after its send, and
//!   later than `duplicate_window` after the engine confirmed that frame),
//!   or a partial write's count reached a later frame: the faults those
//!   policies do not claim to catch (and no table claim at all once raw
//!   noise held a frame that passed for a reply: a forged reply can confirm
//!   or verify anything);
//! - `Failed` only with `Timeout`, `Controller { code }` (a code the
//!   controller sent, outside the bridge range), `Bridge { code }` (inside
//!   it) or `Mismatch { first_position, records }` (a position of the frame
//!   being verified, `records >= 1`), never with every record confirmed.
//!
//! What changed with the verifying engine: an `&` is not resent (the run
//! fails with `Controller` / `Bridge`, then resumes), frames may carry fewer
//! records than fit (late-reply count guard) and shrink after timeouts (the
//! "next records in order" check covers both), and the old "`Complete`
//! only with every record confirmed" became the exact table compare.
#![no_main]

#[path = "common/controller.rs"]
mod controller;
#[path = "common/records.rs"]
mod records;

use controller::Table;
use iai_protocol_b::checksum::ChecksumMode;
use iai_protocol_b::error::BRIDGE_CODES;
use iai_protocol_b::exchange::ExchangeConfig;
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::transfer::{
    Guarantee, Step, Transfer, TransferConfig, TransferError, TransferEvent, Verify,
};
use libfuzzer_sys::fuzz_target;
use records::Input;

/// Finding F11 (fixed in the core; the check is strict) (fuzz/README.md): after a rewrite, the read-back hold
/// (the F5 fix: `duplicate_window_ms` after the rewrite) is checked against
/// the horizon of the transfer's exchange, which runs with
/// `duplicate_window_ms = 0`; a hold further ahead than that horizon reads
/// as expired, so with a duplicate window longer than the horizon an old
/// read-back reply verifies a rewritten frame again (a false `Verified`).
/// Before the fix, the table check
/// tolerates exactly that: an old reply compared within the contract, with
/// such a duplicate window.
const F11_FIXED: bool = true;

/// Finding F8 (fixed in the core; the check is strict) (fuzz/README.md), as far as `Transfer` goes: its
/// exchange runs with `duplicate_window_ms = 0`, so the F6 fix (a stale
/// reply extends the quarantine by the duplicate window) does not apply: a
/// late read-back reply from before a rewrite that arrives while the next
/// read-back is held is dropped, and a copy of it after the hold verifies
/// the rewritten frame. Before the fix, the
/// table check tolerates exactly that: a compared old reply within the
/// duplicate window of a copy of it heard after the last write to its
/// window.
const F8_FIXED: bool = true;

/// Finding F12 (fixed in the core; the check is strict) (fuzz/README.md): after `Failed` and `resume`, the
/// transfer's guard and its `AfterFault` policy see only the sends since
/// the resume: the frame counts as answered at its first send (no late
/// window kept for the send before the resume, whose late reply then
/// confirms the next frame of that count) and as not faulted (no
/// read-back). Before the fix, the guard
/// model counts sends since the last resume, as the engine does.
const F12_FIXED: bool = true;

/// The engine's frame buffer: the TTA's receive limit.
const N: usize = iai_protocol_b::limits::TTA.command;

const WRITES: [PositionStream; 5] = [
    PositionStream::CHANGE_2,
    PositionStream::CHANGE,
    PositionStream::RANGE,
    PositionStream::RANGE_3,
    PositionStream::CHANGE_3,
];

/// What a scheduled delivery is.
#[derive(Debug, Clone, PartialEq)]
enum What {
    /// A write reply: (start, count), the write frame it answers, and
    /// whether it still lies inside the engine's guard windows is judged
    /// at delivery from `sent_at`.
    WriteReply {
        start: u16,
        count: u16,
        frame: usize,
        sent_at: u64,
        partial: bool,
    },
    /// A read-back reply for the window (head, asked).
    ReadReply { head: u16, asked: u16, made_at: u64 },
    /// An `&` reply.
    Error(u16),
    /// Bytes that cannot complete a frame (noise, a corrupted frame).
    Noise,
    /// Arbitrary bytes: they may hold a valid frame that passes for a reply.
    Forged,
}

#[derive(Debug, Clone)]
struct Delivery {
    at: u64,
    bytes: Vec<u8>,
    what: What,
}

/// The simulated line and controller.
struct Sim {
    kind: PositionStream,
    rb: PositionStream,
    station: Station,
    table: Table,
    /// Deliveries to the engine, in time order.
    outbox: Vec<Delivery>,
    /// Every write reply and read-back reply made, for stale replays.
    history: Vec<Delivery>,
    /// Faults the weaker policies do not claim to catch.
    unguarded: bool,
    /// Deliveries fed since the last transmission (the frame behind an
    /// event may come from one of them, see `made_by`).
    recent: Vec<What>,
    /// Noise may hold LF (config), and a frame in it passed for a reply.
    raw_noise: bool,
    forged: bool,
    /// When each write frame (first index, count) was sent.
    sent_at: Vec<((usize, u16), u64)>,
    /// The frame answered last, and whether the engine has seen a late or
    /// duplicated reply (a stale one, or a count mismatch).
    last_answered: Option<(usize, u16)>,
    line_showed_dups: bool,
    /// When each position was last written.
    written_at: std::collections::BTreeMap<u16, u64>,
    /// A read-back reply made before the last write to its window was
    /// compared although it came outside the engine's contract (later than
    /// `timeout + late_window` after its query, and no copy of an original
    /// that came in time, within `duplicate_window` of it): nothing can
    /// tell it from the answer, so no table claim.
    old_out_of_contract: bool,
    /// ... and one that came within it (open finding F11), or a copy of
    /// a late reply that first arrived after the last write to its window
    /// (open finding F8, as far as `Transfer` goes).
    old_in_contract: bool,
    old_copy_of_late: bool,
    /// When each read-back reply (made at, head, asked) first arrived
    /// intact, and when a copy of it arrived last before the one being fed.
    read_first: std::collections::BTreeMap<(u64, u16, u16), u64>,
    read_last: std::collections::BTreeMap<(u64, u16, u16), u64>,
    read_prev: Option<u64>,
    /// When the run was last resumed (open finding F12).
    resumed_at: Option<u64>,
    /// Write frames sent (index = frame id): the first source index and
    /// record count of each, and when the engine confirmed those records.
    frames: Vec<(usize, u16, Option<u64>)>,
}

impl Sim {
    fn apply(&mut self, recs: &[PositionRecord], clock: u64) {
        controller::apply(&mut self.table, recs);
        for r in recs {
            self.written_at.insert(r.number, clock);
        }
    }

    fn schedule(&mut self, d: Delivery) {
        let i = self.outbox.partition_point(|e| e.at <= d.at);
        self.outbox.insert(i, d);
    }
}

struct Cfg {
    exchange: ExchangeConfig,
    max_frame: usize,
    max_response: usize,
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let c = input.u8();
    let kind = WRITES[usize::from(c % 5)];
    let verify = [Verify::Full, Verify::AfterFault, Verify::Off][usize::from(c / 5 % 3)];
    let rb = kind.read_back();
    let station = Station(input.u8());
    let size = usize::from(input.u8() % 48);
    let seed = input.u8();
    let shape = input.u8();
    // Range writes (244H, 290H): the table ends inside the start field's
    // range, up to exactly its top (which once failed; fixed in the core).
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
    let mut exchange = ExchangeConfig::new(station);
    exchange.timeout_ms = 1 + u32::from(input.u8()) * 20;
    let b = input.u8();
    exchange.max_sends = 1 + b % 4;
    let rewrites = (b >> 2) % 4;
    exchange.turnaround_ms = 1 + u32::from(input.u8() % 4);
    exchange.late_window_ms = u32::from(input.u16());
    exchange.duplicate_window_ms = u32::from(input.u16());
    let base = input.u32();
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

    let mut cfg = TransferConfig::tta(station).with_verify(verify);
    cfg.exchange = exchange;
    cfg.stream = kind;
    cfg.start = start;
    cfg.max_frame = max_frame;
    cfg.max_response = max_response;
    cfg.checksum = ChecksumMode::Compute;
    cfg.rewrites = rewrites;
    let lim = Cfg {
        exchange,
        max_frame,
        max_response,
    };

    // What the controller holds beforehand: nothing, the source itself (a
    // table uploaded again), or other records at the same positions.
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
    let mut sim = Sim {
        kind,
        rb,
        station,
        table,
        outbox: Vec::new(),
        history: Vec::new(),
        unguarded: false,
        sent_at: Vec::new(),
        last_answered: None,
        line_showed_dups: false,
        recent: Vec::new(),
        raw_noise: shape & 0x10 != 0,
        forged: false,
        written_at: Default::default(),
        old_out_of_contract: false,
        old_in_contract: false,
        old_copy_of_late: false,
        read_first: Default::default(),
        read_last: Default::default(),
        read_prev: None,
        resumed_at: None,
        frames: Vec::new(),
    };

    trace!(
        "{:03X} {verify:?} {} records, exchange {exchange:?}, rewrites {rewrites}",
        kind.id,
        source.len()
    );
    let mut t: Transfer<_, N> = Transfer::new(cfg, source.clone().into_iter());
    let max_steps = 2_000
        + 16 * data.len()
        + 64 * (size + 1)
            * usize::from(exchange.max_sends)
            * (1 + usize::from(rewrites))
            * (1 + usize::from(resumes));

    let mut clock: u64 = 0;
    let now = |clock: u64| base.wrapping_add(clock as u32);
    // The write frame last transmitted: (frame id, first index, records,
    // start) and whether `sent` was called for it.
    let mut write: Option<(usize, usize, u16, u16)> = None;
    let mut write_sent = false;
    // The read-back query last transmitted (head, asked) and its frame.
    let mut query: Option<(u16, u16)> = None;
    let mut confirmed = 0u32;
    let mut steps = 0usize;

    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        let step = t.poll(now(clock));
        match step {
            Step::Transmit(bytes) => {
                let bytes = bytes.to_vec();
                // The engine resets its reply decoder for every send.
                sim.recent.clear();
                trace!(
                    "t={clock} now={} TX {}",
                    now(clock),
                    String::from_utf8_lossy(&bytes).trim_end()
                );
                let op = input.next();
                let is_write = bytes.get(3..6) == Some(hex3(kind.id).as_slice());
                // The write as the controller reads it (checked below).
                let mut parsed = None;
                if is_write {
                    let (s, recs) = controller::parse_write(kind, &bytes)
                        .expect("the engine sent an invalid write");
                    assert!(bytes.len() <= max_frame, "a frame over max_frame");
                    assert!(!recs.is_empty(), "a write without records");
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
                    let id = sim.frames.len();
                    sim.frames.push((from, recs.len() as u16, None));
                    write = Some((id, from, recs.len() as u16, s));
                    parsed = Some((s, recs));
                    write_sent = false;
                    query = None;
                } else {
                    let (head, asked) = controller::parse_query(rb, station, &bytes)
                        .expect("the engine sent neither a write nor a read-back query");
                    assert!(
                        asked >= 1 && asked <= rb.window(max_response),
                        "window {asked}"
                    );
                    assert!(
                        u64::from(head) + u64::from(asked) - 1 <= rb.count_field().max_unsigned(),
                        "window past the position field"
                    );
                    let (_, from, n, _) = write.expect("a read-back before any write");
                    let positions: Vec<u16> = (0..usize::from(n))
                        .map(|i| controller::position_of(kind, start, from + i, &source[from + i]))
                        .collect();
                    assert!(
                        positions.contains(&head),
                        "a window that starts outside the frame: {head}+{asked} for {positions:?}"
                    );
                    query = Some((head, asked));
                }
                // The transmission takes `dur` ms; what is due meanwhile
                // arrives before `sent`.
                let dur = u64::from(op.map_or(1, |o| o & 7));
                deliver_until(
                    &mut t,
                    &mut sim,
                    &lim,
                    clock + dur,
                    true,
                    &mut clock,
                    base,
                    write,
                    write_sent,
                    query,
                );
                clock += dur;
                t.sent(now(clock));
                if is_write {
                    write_sent = true;
                    if let Some((_, from, n, _)) = write {
                        sim.sent_at.push(((from, n), clock));
                    }
                }
                check_progress(&t, &mut confirmed, write, write_sent, source.len());
                controller_answers(
                    &mut sim, &mut input, op, &bytes, parsed, clock, &lim, &expected, write,
                );
            }
            Step::WaitUntil(deadline) => {
                trace!("t={clock} now={} WAIT until {deadline}", now(clock));
                // The longest hold: the late-reply guard (timeout + late
                // window, or a duplicate window) and the turnaround.
                let bound = u64::from(exchange.timeout_ms)
                    + u64::from(exchange.late_window_ms)
                    + u64::from(exchange.duplicate_window_ms)
                    + u64::from(exchange.turnaround_ms)
                    + 2;
                let ahead = records::check_wait(now(clock), deadline, bound, sim.frames.is_empty());
                let until = clock + u64::from(ahead);
                match input.next() {
                    None => {
                        let next = sim.outbox.first().map_or(until, |d| d.at.min(until));
                        deliver_until(
                            &mut t, &mut sim, &lim, next, false, &mut clock, base, write,
                            write_sent, query,
                        );
                        clock = clock.max(next);
                    }
                    Some(op) => match op % 6 {
                        0 => {
                            let to = clock + u64::from(input.u16());
                            deliver_until(
                                &mut t, &mut sim, &lim, to, false, &mut clock, base, write,
                                write_sent, query,
                            );
                            clock = to;
                        }
                        1 => {
                            // Noise: anything but LF (so it cannot complete a
                            // frame), or with the raw-noise bit anything at all.
                            let n = usize::from(input.u8() % 64);
                            let raw = sim.raw_noise;
                            let bytes: Vec<u8> = input
                                .take(n)
                                .iter()
                                .map(|&b| if b == b'\n' && !raw { b'?' } else { b })
                                .collect();
                            let d = Delivery {
                                at: clock,
                                bytes,
                                what: if raw { What::Forged } else { What::Noise },
                            };
                            feed(
                                &mut t, &mut sim, &lim, &d, false, clock, base, write, write_sent,
                                query,
                            );
                        }
                        2 => {
                            // An earlier real reply, again (late or stale).
                            if !sim.history.is_empty() {
                                let i = usize::from(input.u8()) % sim.history.len();
                                let mut d = sim.history[i].clone();
                                d.at = clock;
                                feed(
                                    &mut t, &mut sim, &lim, &d, false, clock, base, write,
                                    write_sent, query,
                                );
                            }
                        }
                        3 => {
                            // The next delivery, now or when due.
                            if let Some(at) = sim.outbox.first().map(|d| d.at) {
                                deliver_until(
                                    &mut t, &mut sim, &lim, at, false, &mut clock, base, write,
                                    write_sent, query,
                                );
                                clock = clock.max(at);
                            }
                        }
                        _ => {
                            deliver_until(
                                &mut t, &mut sim, &lim, until, false, &mut clock, base, write,
                                write_sent, query,
                            );
                            clock = clock.max(until);
                        }
                    },
                }
                check_progress(&t, &mut confirmed, write, write_sent, source.len());
            }
            Step::NeedRecords => panic!("an iterator source is never pending"),
            Step::Complete(report) => {
                trace!("t={clock} COMPLETE {report:?}");
                assert_eq!(report.stats, t.stats());
                assert_eq!(
                    report.stats.records_confirmed as usize,
                    source.len(),
                    "Complete before every record was confirmed"
                );
                let want = match verify {
                    Verify::Full => Guarantee::Verified,
                    Verify::AfterFault => Guarantee::FaultsVerified,
                    Verify::Off => Guarantee::Unverified,
                };
                assert_eq!(report.guarantee, want);
                // A frame forged by arbitrary bytes can confirm or verify
                // anything: no claim then.
                // (Nor after an old read-back reply that came outside the
                // engine's contract was compared: see `old_out_of_contract`.)
                if !sim.forged
                    && !sim.old_out_of_contract
                    && (report.guarantee == Guarantee::Verified || !sim.unguarded)
                {
                    // Finding F11 (fixed in the core; the check is strict) (fuzz/README.md): the hold after a
                    // rewrite lies `duplicate_window` ahead, further than the
                    // horizon of the engine's exchange (which runs without a
                    // duplicate window), so it reads as expired.
                    let short = ExchangeConfig {
                        duplicate_window_ms: 0,
                        ..lim.exchange
                    }
                    .horizon();
                    let f11 = !F11_FIXED
                        && sim.old_in_contract
                        && lim.exchange.duplicate_window_ms > short;
                    // Finding F8 (fixed in the core; the check is strict): the transfer's exchange runs without
                    // a duplicate window, so a late reply that arrives
                    // while the read-back is held starts none: its copy
                    // can verify the rewritten frame.
                    let f8 = !F8_FIXED && sim.old_copy_of_late;
                    for (n, r) in &expected {
                        assert!(
                            sim.table.get(n) == Some(r) || f11 || f8,
                            "false success ({:?}): position {n} holds {:?}, the source {r:?}",
                            report.guarantee,
                            sim.table.get(n)
                        );
                    }
                }
                let s = report.stats;
                assert!(s.frames_confirmed <= s.frames_sent);
                if verify == Verify::Full {
                    assert!(s.records_verified as usize >= source.len());
                }
                if verify == Verify::Off {
                    assert_eq!((s.verify_queries, s.frames_verified), (0, 0));
                }
                break;
            }
            Step::Failed(e) => {
                trace!("t={clock} FAILED {e:?}");
                match e {
                    TransferError::Timeout => {}
                    TransferError::Controller { code } => {
                        assert!(!BRIDGE_CODES.contains(&code), "a bridge code as Controller")
                    }
                    TransferError::Bridge { code } => {
                        assert!(BRIDGE_CODES.contains(&code), "a controller code as Bridge")
                    }
                    TransferError::Mismatch {
                        first_position,
                        records,
                    } => {
                        assert!(records >= 1);
                        let (_, from, n, _) = write.expect("a mismatch before any write");
                        let positions: Vec<u16> = (0..usize::from(n))
                            .map(|i| {
                                controller::position_of(kind, start, from + i, &source[from + i])
                            })
                            .collect();
                        assert!(
                            positions.contains(&first_position),
                            "mismatch names {first_position}"
                        );
                        assert!(usize::from(records) <= usize::from(n));
                    }
                    other => panic!("unexpected failure {other:?}"),
                }
                assert!((t.stats().records_confirmed as usize) < source.len());
                if resumes == 0 {
                    break;
                }
                resumes -= 1;
                t.resume(now(clock));
                sim.resumed_at = Some(clock);
            }
        }
        check_progress(&t, &mut confirmed, write, write_sent, source.len());
    }
    let s = t.stats();
    assert!(s.frames_confirmed <= s.frames_sent);
});

/// The 3 hex digits of a message ID as on the wire.
fn hex3(id: u16) -> [u8; 3] {
    let d = |n: u16| b"0123456789ABCDEF"[usize::from(n & 0xF)];
    [d(id >> 8), d(id >> 4), d(id)]
}

/// `records_confirmed` grows only by the last write frame's count, after
/// its `sent`, and never past the source.
fn check_progress<I: iai_protocol_b::transfer::RecordSource>(
    t: &Transfer<I, N>,
    confirmed: &mut u32,
    write: Option<(usize, usize, u16, u16)>,
    write_sent: bool,
    total: usize,
) {
    let now = t.stats().records_confirmed;
    assert!(now as usize <= total, "more confirmed than the source");
    if now != *confirmed {
        let grew = now.checked_sub(*confirmed).expect("confirmed shrank");
        match write {
            Some((_, from, n, _)) if write_sent && from == *confirmed as usize => {
                assert_eq!(grew, u32::from(n), "confirmed grew by a count never sent")
            }
            other => panic!("confirmed grew by {grew} with frame {other:?} (sent: {write_sent})"),
        }
        *confirmed = now;
    }
}

/// What made the frame behind an event: the delivery being fed, or (when
/// bytes of a failed text frame are decoded again) an earlier one since the
/// last transmission; the most recent that `fits`.
fn made_by(sim: &Sim, fits: impl Fn(&What) -> bool) -> Option<What> {
    sim.recent.iter().rev().find(|w| fits(w)).cloned()
}

/// Delivers everything due up to `to` (moving the clock to each delivery).
#[allow(clippy::too_many_arguments)]
fn deliver_until<I: iai_protocol_b::transfer::RecordSource>(
    t: &mut Transfer<I, N>,
    sim: &mut Sim,
    lim: &Cfg,
    to: u64,
    before_sent: bool,
    clock: &mut u64,
    base: u32,
    write: Option<(usize, usize, u16, u16)>,
    write_sent: bool,
    query: Option<(u16, u16)>,
) {
    while sim.outbox.first().is_some_and(|d| d.at <= to) {
        let d = sim.outbox.remove(0);
        *clock = (*clock).max(d.at);
        feed(
            t,
            sim,
            lim,
            &d,
            before_sent,
            *clock,
            base,
            write,
            write_sent,
            query,
        );
    }
}

/// Feeds one delivery, checking each event it causes.
#[allow(clippy::too_many_arguments)]
fn feed<I: iai_protocol_b::transfer::RecordSource>(
    t: &mut Transfer<I, N>,
    sim: &mut Sim,
    lim: &Cfg,
    d: &Delivery,
    before_sent: bool,
    clock: u64,
    base: u32,
    write: Option<(usize, usize, u16, u16)>,
    write_sent: bool,
    query: Option<(u16, u16)>,
) {
    let now = base.wrapping_add(clock as u32);
    sim.recent.push(d.what.clone());
    if let What::ReadReply {
        head,
        asked,
        made_at,
    } = d.what
    {
        sim.read_first
            .entry((made_at, head, asked))
            .or_insert(clock);
        sim.read_prev = sim.read_last.insert((made_at, head, asked), clock);
    }
    // A write reply outside the engine's guard windows (module docs of
    // `transfer`): a frame's replies are guarded until `timeout +
    // late_window` after its last send while it is unanswered or was sent
    // more than once; once answered at its first send, only duplicates of
    // the reply can come, guarded for `duplicate_window` after the answer
    // if it was the last frame answered or the line has shown a late or
    // duplicated reply before (the first duplicate on a line is outside).
    if let What::WriteReply {
        frame,
        sent_at,
        partial,
        ..
    } = d.what
    {
        let ex = &lim.exchange;
        let (from, n, answered) = sim.frames[frame];
        // Finding F12 (fixed in the core; the check is strict) (fuzz/README.md): the engine's guard counts only
        // the sends since the last resume, so a frame sent before and after
        // a resume counts as answered at its first send. Until fixed, the
        // model counts the same way (a reply to a send before the resume is
        // then outside the guard windows: no claim).
        let since = if F12_FIXED {
            0
        } else {
            sim.resumed_at.unwrap_or(0)
        };
        let sends = sim
            .sent_at
            .iter()
            .filter(|&&(k, t)| k == (from, n) && t >= since)
            .count();
        let last_send = sim
            .sent_at
            .iter()
            .filter(|&&(k, _)| k == (from, n))
            .map(|&(_, t)| t)
            .max()
            .unwrap_or(sent_at);
        let late_ok = clock < last_send + u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms);
        let guarded = match answered {
            None => late_ok,
            Some(_) if sends > 1 && late_ok => true,
            Some(a) => {
                clock < a + u64::from(ex.duplicate_window_ms)
                    && (sim.last_answered == Some((from, n)) || sim.line_showed_dups)
            }
        };
        if !guarded {
            sim.unguarded = true;
        }
        // A partial write's count was never sent by the engine: no guard
        // can keep it from a later frame with that count.
        if partial && write.is_some_and(|(_, f, k, _)| (f, k) != (from, n)) {
            sim.unguarded = true;
        }
    }
    let mut rest = &d.bytes[..];
    loop {
        let r = t.received(rest, now);
        trace!(
            "t={clock} RX {:?} -> {:?}",
            String::from_utf8_lossy(&rest[..r.consumed]),
            r.event
        );
        assert!(r.consumed <= rest.len());
        rest = &rest[r.consumed..];
        match r.event {
            TransferEvent::NeedMore => {
                assert!(rest.is_empty(), "NeedMore with bytes left");
                break;
            }
            TransferEvent::Confirmed { records } => {
                assert!(!before_sent, "a reply confirmed a frame before it was sent");
                let (_, from, n, s) = write.expect("confirmed without a write");
                assert!(write_sent);
                assert_eq!(records, n, "confirmed another count");
                // The frame may come from an earlier delivery: bytes of a
                // failed text frame are decoded again.
                let by = made_by(sim, |w| match w {
                    What::WriteReply { start, count, .. } => {
                        *count == n && (sim.kind.start_width == 0 || *start == s)
                    }
                    What::Forged => true,
                    _ => false,
                });
                match by {
                    Some(What::Forged) => sim.forged = true,
                    Some(_) => {}
                    None => panic!("confirmed by {:?}: no reply with count {n} was fed", d.what),
                }
                for f in sim.frames.iter_mut() {
                    if (f.0, f.1) == (from, n) && f.2.is_none() {
                        f.2 = Some(clock);
                    }
                }
                sim.last_answered = Some((from, n));
            }
            TransferEvent::CountMismatch { sent, reported } => {
                sim.line_showed_dups = true;
                let (_, _, n, s) = write.expect("a mismatch without a write");
                assert_eq!(sent, n);
                let by = made_by(sim, |w| match w {
                    What::WriteReply { start, count, .. } => {
                        *count == reported
                            && (*count != n || (sim.kind.start_width > 0 && *start != s))
                    }
                    What::Forged => true,
                    _ => false,
                });
                assert!(by.is_some(), "count mismatch {reported} from {:?}", d.what);
            }
            TransferEvent::Rejected { code } => {
                let by = made_by(sim, |w| {
                    matches!(w, What::Error(c) if *c == code) || *w == What::Forged
                });
                assert!(by.is_some(), "rejected ({code:03X}) by {:?}", d.what);
            }
            TransferEvent::Compared {
                head,
                equal,
                differ,
            } => {
                assert!(
                    !before_sent,
                    "a read-back reply counted before the query was sent"
                );
                let (qh, qa) = query.expect("compared without a query");
                assert_eq!(head, qh);
                // The reply taken holds at most the window's positions, all
                // inside it (it may be a stale reply to another window).
                match d.what {
                    What::ReadReply {
                        head: h,
                        asked: a,
                        made_at,
                    } => {
                        // A reply made before the last write to a position of
                        // the window (an old copy) is compared. Since F5 was
                        // fixed the engine holds its query until no such
                        // reply can come within the contract; one that came
                        // outside it cannot be told from the answer.
                        let end = u32::from(qh) + u32::from(qa);
                        let old = sim
                            .written_at
                            .range(qh..)
                            .take_while(|(&p, _)| u32::from(p) < end)
                            .any(|(_, &w)| w > made_at);
                        let late = made_at
                            + u64::from(lim.exchange.timeout_ms)
                            + u64::from(lim.exchange.late_window_ms);
                        // The first arrival: within `timeout + late_window` of
                        // its query; a copy: within `duplicate_window` of the
                        // last copy before it, of an original in time.
                        let in_contract = match sim.read_prev {
                            None => clock <= late,
                            Some(l) => {
                                sim.read_first
                                    .get(&(made_at, h, a))
                                    .is_some_and(|&f| f <= late)
                                    && clock <= l + u64::from(lim.exchange.duplicate_window_ms)
                            }
                        };
                        if old && !in_contract {
                            sim.old_out_of_contract = true;
                        }
                        let last_write = sim
                            .written_at
                            .range(qh..)
                            .take_while(|(&p, _)| u32::from(p) < end)
                            .map(|(_, &w)| w)
                            .max()
                            .unwrap_or(0);
                        // A copy heard after the last write, within the
                        // duplicate window of this one.
                        let dup = u64::from(lim.exchange.duplicate_window_ms);
                        let prev = sim.read_prev;
                        if old && in_contract {
                            if prev.is_some_and(|l| l > last_write && clock <= l + dup) {
                                sim.old_copy_of_late = true;
                            } else {
                                sim.old_in_contract = true;
                            }
                        }
                        let f = iai_protocol_b::frame::Frame::new_checked(
                            &d.bytes,
                            iai_protocol_b::checksum::BypassPolicy::Reject,
                        )
                        .expect("a read-back reply the controller made");
                        let mut r = f.reader();
                        let (_, count) = sim.rb.read_prefix(&mut r).expect("prefix");
                        assert!(count <= qa, "a reply of {count} records for {qa} positions");
                        for _ in 0..count {
                            let rec = sim.rb.layout.read_record(&mut r).expect("record");
                            let n = u32::from(rec.number);
                            assert!(
                                n >= u32::from(qh) && n < u32::from(qh) + u32::from(qa),
                                "record {n} of a reply to {h}+{a} taken for {qh}+{qa}"
                            );
                        }
                    }
                    What::Forged => sim.forged = true,
                    ref other => panic!("compared with {other:?}"),
                }
                assert!(u32::from(equal) + u32::from(differ) <= u32::from(qa));
            }
            TransferEvent::Stale => sim.line_showed_dups = true,
            TransferEvent::Foreign | TransferEvent::Broken(_) => {}
        }
    }
    let _ = lim.max_frame;
}

/// The controller receives the frame just sent at `clock` and schedules
/// its answer.
#[allow(clippy::too_many_arguments)]
fn controller_answers(
    sim: &mut Sim,
    input: &mut Input<'_>,
    op: Option<u8>,
    bytes: &[u8],
    parsed: Option<(u16, Vec<PositionRecord>)>,
    clock: u64,
    lim: &Cfg,
    expected: &Table,
    write: Option<(usize, usize, u16, u16)>,
) {
    let is_write = parsed.is_some();
    // Fate of the command: bits 3-4 of op (0, 1: arrives; 2: lost or
    // corrupted, the controller is silent and executes nothing; 3: a write
    // swapped, SC-preserving).
    let op = op.unwrap_or(0);
    let fate = (op >> 3) & 3;
    if fate == 2 {
        return;
    }
    // Reply faults: bits 5-7 of op and one more byte when there are any.
    let fault = op >> 5;
    let extra = if fault != 0 { input.u8() } else { 0 };
    let delay = if fault == 0 {
        1
    } else {
        u64::from(input.u16())
            % (3 * u64::from(lim.exchange.timeout_ms) + u64::from(lim.exchange.late_window_ms) + 2)
    };
    let at = clock + delay;
    let station = sim.station;
    let mut out: Option<Delivery> = None;
    if is_write {
        let (start, mut recs) = parsed.expect("a write");
        let (frame, ..) = write.expect("a write is in flight");
        if fate == 3
            && controller::swap_digits(&mut recs, u32::from(extra) | u32::from(op) << 8).is_some()
        {
            sim.unguarded = true;
        }
        let n = recs.len() as u16;
        match fault {
            // An `&` reply; how far the write went is not said.
            5 => {
                let k = usize::from(extra) % (recs.len() + 1);
                sim.apply(&recs[..k], clock);
                let code = if extra & 1 == 0 {
                    *BRIDGE_CODES.start() + u16::from(extra >> 1) % 0x20
                } else {
                    0x0A0 + u16::from(extra)
                };
                out = Some(Delivery {
                    at,
                    bytes: controller::error_reply(station, code),
                    what: What::Error(code),
                });
            }
            // A partial write: the first k records stored, k reported.
            6 if n > 1 => {
                let k = 1 + usize::from(extra) % (recs.len() - 1);
                sim.apply(&recs[..k], clock);
                out = Some(Delivery {
                    at,
                    bytes: controller::write_reply(sim.kind, station, start, k as u16),
                    what: What::WriteReply {
                        start,
                        count: k as u16,
                        frame,
                        sent_at: clock,
                        partial: true,
                    },
                });
            }
            _ => {
                sim.apply(&recs, clock);
                out = Some(Delivery {
                    at,
                    bytes: controller::write_reply(sim.kind, station, start, n),
                    what: What::WriteReply {
                        start,
                        count: n,
                        frame,
                        sent_at: clock,
                        partial: false,
                    },
                });
            }
        }
    } else if let Some((head, asked)) = controller::parse_query(sim.rb, station, bytes) {
        let mut recs = controller::window(&sim.table, head, asked);
        let reply_fault = (extra >> 4) & 7;
        if fault == 4 {
            match reply_fault {
                // A wrong record: never what the source holds there.
                0 | 1 if !recs.is_empty() => {
                    let i = usize::from(extra) % recs.len();
                    let mut r = recs[i].clone();
                    r.speed = r.speed.wrapping_add(1);
                    if expected.get(&r.number) == Some(&r) {
                        r.speed = r.speed.wrapping_add(1);
                    }
                    recs[i] = r;
                }
                // A record missing.
                2 if !recs.is_empty() => {
                    recs.remove(usize::from(extra) % recs.len());
                }
                // A digit swapped, unless that shows what the source holds.
                3 => {
                    let mut swapped = recs.clone();
                    if let Some(i) =
                        controller::swap_digits(&mut swapped, u32::from(extra) << 3 | u32::from(op))
                    {
                        if expected.get(&swapped[i].number) != Some(&swapped[i]) {
                            recs = swapped;
                        }
                    }
                }
                // A stale reply: an earlier real reply of the controller.
                4 | 5 => {
                    let olds: Vec<&Delivery> = sim
                        .history
                        .iter()
                        .filter(|d| matches!(d.what, What::ReadReply { .. }))
                        .collect();
                    if !olds.is_empty() {
                        let mut d = olds[usize::from(extra) % olds.len()].clone();
                        d.at = at;
                        sim.schedule(d);
                        return;
                    }
                }
                _ => {}
            }
        }
        let reply = controller::query_reply(sim.rb, station, &recs);
        assert!(
            reply.len() <= lim.max_response,
            "a read-back reply of {} bytes for a window the engine asked (max {})",
            reply.len(),
            lim.max_response
        );
        out = Some(Delivery {
            at,
            bytes: reply,
            what: What::ReadReply {
                head,
                asked,
                made_at: clock,
            },
        });
        if fault == 5 {
            let code = 0x0A0 + u16::from(extra);
            out = Some(Delivery {
                at,
                bytes: controller::error_reply(station, code),
                what: What::Error(code),
            });
        }
    }
    let Some(mut d) = out else { return };
    if !matches!(d.what, What::Error(_)) {
        sim.history.push(d.clone());
    }
    match fault {
        // Lost.
        1 => {}
        // A corrupted byte: the SC fails.
        2 => {
            controller::corrupt_byte(&mut d.bytes, u32::from(extra) * 977 + u32::from(op));
            d.what = What::Noise;
            sim.schedule(d);
        }
        // Twice: the duplicate later.
        3 => {
            let mut dup = d.clone();
            dup.at += u64::from(extra) * 50;
            sim.schedule(d);
            sim.schedule(dup);
        }
        _ => sim.schedule(d),
    }
}
