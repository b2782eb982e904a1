//! One line to a controller (`line::Line`) on its own: its command, its
//! reply, and the ledger of replies that may still arrive (owed replies,
//! settled by 200H fences; copies, kept for `duplicate_window_ms`), driven
//! by arbitrary call sequences on a virtual clock.
//!
//! Input layout: station; timeout byte (1 + 20 x b ms); flags (bits 0-2:
//! `max_sends` 0-4, `% 5`; 0x08 `resend_unsafe`; 0x10 fences off; 0x20
//! `@@` instead of checksums); turnaround byte (`% 64` ms); late window
//! (u16 ms); duplicate window (u16 ms); fence seed (u32); start tick (u32);
//! then operations, one byte each (`% 13`) with their arguments: start a
//! catalogue command (pick byte), `start_raw` (ID u16 `& 0xFFF`, sends
//! byte), poll, `sent`, offer the command's reply (body length and digits,
//! content check bit), offer an `&` (code, station bit), offer a 200H reply
//! (the fence's echo, an earlier fence's, another seed's, any text; this or
//! another station), offer a foreign frame (another station, a command
//! header, another ID), `broken` (the command's envelope, an `&`'s, another
//! station's, a command's, none), `unread`, `abandon`, advance the clock
//! (u8, u16 or up to 2^31 - 1 ms; the start tick makes it wrap; the
//! total stays below 2^32 - 2^30 ms so that no hold can seem to come back),
//! and poll-and-send (poll, then `sent` at once). When the operations run
//! out, the harness polls, sends and follows the deadlines (no reply ever
//! comes) until the command is over.
//!
//! Beside the line the harness keeps a simple model (a 64-bit clock, the
//! phase it saw the line take, sends, the end of each send, when each
//! reply of the station was heard, the owed replies as "sends not answered,
//! until `timeout + late_window` after the last one, cleared by an echo")
//! and checks after every call:
//! - sends: `Send { fresh: true }` once per send (then `fresh: false`
//!   until `sent`), counted by `sends()` and `stats()`; at most
//!   `max_sends` (0 read as 1), one for a command the catalogue marks
//!   unsafe (an ID outside it too) unless `resend_unsafe`, one for a
//!   command without normal response (25BH);
//! - timeouts run from the end of transmission: while a reply is awaited
//!   `WaitUntil` is exactly `sent + timeout` (or, after a broken frame with
//!   the command's envelope, the turnaround after it, unless that was the
//!   last send of several); a resend, `Timeout` / `OutcomeUnknown` (by
//!   resend safety, with the sends made) and a 25BH's `Ok` not before it;
//!   a fence's `WaitUntil` is exactly its `sent + timeout`;
//! - every transmission (a fence, a first send) waits for the turnaround
//!   after the last reply or echo taken (`turnaround + 1` ticks) and for a
//!   controller's restart (`ready_after_ms` after a 25BH was sent);
//! - owed replies: a command's first send never goes out while a reply
//!   owed to an earlier send (or the unknown past of a line just opened,
//!   `timeout + late_window` from its first start) may still arrive,
//!   unless a fence's echo came after those sends; a fence goes out only
//!   while something is owed, only with fences on, and not while the line
//!   waits instead after a fence that got no echo;
//! - copies: no send (first or resend) while a reply heard from the
//!   station with the command's ID (or an `&`, a broken frame without a
//!   readable envelope, bytes dropped unread) lies less than
//!   `duplicate_window + 1` ticks back;
//! - `WaitUntil` never in the past nor further ahead than the longest hold
//!   (`timeout + late + duplicate + turnaround + 2`, or the 10 s restart),
//!   and, before a send, no later than the latest hold the model knows of
//!   (turnaround, restart, a copy, owed replies when it must wait for them);
//! - the fence: a 200H command for the station whose ten characters are
//!   the six hex digits of the seed and a sequence number counting from 1,
//!   with the line's checksum mode;
//! - `offer` is classified by the documented rules: `Foreign` for another
//!   station or a command, `Fence` exactly for the echo of the fence in
//!   flight while it is awaited, `Foreign` for a reply to another ID,
//!   `Stale` unless the reply is awaited (before `sent`, after the end),
//!   `Rejected(code)` for an `&`, `Mismatch` when the content check failed
//!   (still awaiting), `Answer` otherwise; the next poll says `Done(Ok)` /
//!   `Done(Err(Controller { code }))`, a broken `&` to 25BH ends it
//!   `OutcomeUnknown`;
//! - `busy()`, `awaiting()`, `answered()`, `faulted()`, `id()` and every
//!   counter of `stats()` as the model has them.
#![no_main]

#[path = "common/records.rs"]
mod records;

use iai_protocol_b::catalogue::{self, MessageInfo, Reply, Resend, LONGEST_RESTART_MS};
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::line::{Due, Heard, Line, LineConfig, LineStats};
use libfuzzer_sys::fuzz_target;
use records::Input;

/// Finding F14 (fixed, fuzz/README.md): `Line::broken` compares the
/// reply's deadline with `clock::reached`, so a deadline that passed more
/// than 2^31 ms before the broken frame (no poll meanwhile) reads as a
/// future one and is replaced by the turnaround after the frame: the
/// timeout came `turnaround + 1` ms late. `true`: the model is strict.
const F14_FIXED: bool = true;

/// Finding F15 (fixed, fuzz/README.md): a reply taken for a command without
/// normal response (an `&` to 25BH) sets no turnaround: only the
/// controller's restart (`ready_after_ms` after the send) holds the next
/// command, so a reply later than `ready_after_ms - turnaround` after the
/// send (a timeout over 10 s, or a late poll) let it out at once. `true`:
/// the model is strict.
const F15_FIXED: bool = true;

/// The model's stand-in for "any ID" (an `&`, an unreadable envelope).
const ANY: u16 = 0xFFFF;
/// The clock never runs further than this from the start tick (holds are
/// at most 2^30 ms ahead: beyond 2^32 - 2^30 one could seem to come back).
const CLOCK_CAP: u64 = 0xB000_0000;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Idle,
    Ready,
    FenceSending,
    FenceAwait { sent: u64 },
    Sending,
    Await { deadline: u64 },
    Done(Result<(), Failure>),
}

struct Model {
    cfg: LineConfig,
    seed: u32,
    phase: Phase,
    id: u16,
    resend: Resend,
    reply: Reply,
    limit: u8,
    sends: u8,
    last_sent: u64,
    opened: bool,
    /// Owed replies since the last echo: the first tick at which each can
    /// no longer arrive.
    owed: Vec<u64>,
    /// After a fence without echo: the line waits for owed replies
    /// instead until this tick.
    no_fence_until: Option<u64>,
    /// Replies (and broken frames, dropped bytes) heard from the station:
    /// (ID or `ANY`, tick).
    heard: Vec<(u16, u64)>,
    /// Earliest next transmission: turnaround after a reply or echo, and a
    /// controller's restart.
    turnaround_until: u64,
    restart_until: u64,
    fence_seq: u16,
    faulted: bool,
    stats: LineStats,
}

impl Model {
    fn horizon(&self) -> u64 {
        let c = &self.cfg;
        let sum = u64::from(c.timeout_ms)
            + u64::from(c.late_window_ms)
            + u64::from(c.duplicate_window_ms)
            + u64::from(c.turnaround_ms)
            + 2;
        sum.max(u64::from(LONGEST_RESTART_MS))
    }

    fn late(&self, sent: u64) -> u64 {
        sent + u64::from(self.cfg.timeout_ms) + u64::from(self.cfg.late_window_ms) + 1
    }

    fn owed_at(&self, clock: u64) -> Option<u64> {
        self.owed.iter().copied().filter(|&u| clock < u).max()
    }

    fn fence_text(&self, seq: u16) -> String {
        format!("{:06X}{:04X}", self.seed & 0x00FF_FFFF, seq)
    }

    fn busy(&self) -> bool {
        !matches!(self.phase, Phase::Idle | Phase::Done(_))
    }

    fn copy_possible(&mut self, id: u16, clock: u64) {
        if self.cfg.duplicate_window_ms > 0 {
            self.heard.push((id, clock));
        }
    }

    /// The first tick at which no copy of a reply heard could pass for the
    /// reply to `id` (`all`: whatever its ID).
    fn copies_until(&self, id: u16, all: bool) -> u64 {
        let dup = u64::from(self.cfg.duplicate_window_ms);
        self.heard
            .iter()
            .filter(|(h, _)| all || *h == id || *h == ANY)
            .map(|(_, t)| t + dup + 1)
            .max()
            .unwrap_or(0)
    }

    fn turnaround(&self, clock: u64) -> u64 {
        clock + u64::from(self.cfg.turnaround_ms) + 1
    }

    /// Ends the command with `r`; `pending` replies to its sends are owed.
    fn finish(&mut self, r: Result<(), Failure>, pending: u8) {
        self.phase = Phase::Done(r);
        let no_reply = matches!(self.reply, Reply::None { .. });
        if pending > 0 {
            let until = self.late(self.last_sent);
            self.owed.push(until);
            self.faulted |= !no_reply;
        }
    }

    /// What `abandon` (also inside `start`) does at `clock`.
    fn abandon(&mut self, clock: u64) {
        match self.phase {
            Phase::FenceSending | Phase::FenceAwait { .. } => {
                let until = self.late(clock);
                self.owed.push(until);
            }
            Phase::Sending => {
                self.last_sent = clock;
                let s = self.sends;
                self.finish(Err(Failure::Timeout { sends: s }), s);
            }
            Phase::Ready | Phase::Await { .. } => {
                let s = self.sends;
                self.finish(Err(Failure::Timeout { sends: s }), s);
            }
            Phase::Idle | Phase::Done(_) => {}
        }
        self.phase = Phase::Idle;
    }

    fn begin(&mut self, id: u16, resend: Resend, reply: Reply, max_sends: u8, clock: u64) {
        self.abandon(clock);
        if std::mem::take(&mut self.opened) {
            let until = self.late(clock);
            self.owed.push(until);
            self.copy_possible(ANY, clock);
        }
        self.id = id;
        self.resend = resend;
        self.reply = reply;
        self.limit = match (resend, reply) {
            (_, Reply::None { .. }) => 1,
            (Resend::Unsafe, _) if !self.cfg.resend_unsafe => 1,
            _ => max_sends.max(1),
        };
        self.sends = 0;
        self.faulted = false;
        self.stats.commands += 1;
        self.phase = Phase::Ready;
    }

    /// A transmission starts at `clock`: the holds every one respects.
    fn check_transmission(&self, clock: u64, what: &str) {
        assert!(
            clock >= self.turnaround_until,
            "{what} at {clock} inside the turnaround (until {})",
            self.turnaround_until
        );
        assert!(
            clock >= self.restart_until,
            "{what} at {clock} while the controller restarts (until {})",
            self.restart_until
        );
    }

    /// The latest hold the model knows of (what a wait before a send may
    /// be for).
    fn latest_hold(&self, clock: u64) -> u64 {
        let mut h = self.turnaround_until.max(self.restart_until);
        h = h.max(self.copies_until(self.id, true));
        let must_wait = !self.cfg.fences || self.no_fence_until.is_some_and(|t| clock < t);
        if must_wait {
            h = h.max(self.owed_at(clock).unwrap_or(0));
        }
        h
    }
}

struct Harness<'a> {
    input: Input<'a>,
    line: Line,
    m: Model,
    clock: u64,
    base: u32,
    steps: usize,
}

impl Harness<'_> {
    fn now(&self) -> u32 {
        self.base.wrapping_add(self.clock as u32)
    }

    fn advance(&mut self, ms: u64) {
        let to = (self.clock + ms).min(CLOCK_CAP);
        self.clock = self.clock.max(to);
    }

    fn frame(&self, header: Header, station: Station, code: u16, body: &[u8]) -> Option<Vec<u8>> {
        let mut buf = [0u8; 64];
        let n = emit_frame(
            &mut buf,
            header,
            station,
            code,
            ChecksumMode::Compute,
            |w| w.put(body),
        )
        .ok()?;
        Frame::new_checked(&buf[..n], BypassPolicy::Reject).ok()?;
        Some(buf[..n].to_vec())
    }

    /// Offers `bytes` (a valid frame) and checks the classification.
    fn offer(&mut self, bytes: &[u8], content_ok: bool) {
        let f = Frame::new_checked(bytes, BypassPolicy::Reject).expect("a valid frame");
        let (h, s, code) = (f.header(), f.station(), f.code());
        let clock = self.clock;
        let m = &mut self.m;
        let ours = s == m.cfg.station && h != Header::Command;
        let expected = if !ours {
            Heard::Foreign
        } else {
            let id = if h == Header::Error { ANY } else { code };
            m.copy_possible(id, clock);
            let seq = m.fence_seq;
            let echo = h == Header::Response
                && code == catalogue::TEST_CALL.id
                && f.body() == m.fence_text(seq).as_bytes();
            let for_command = h == Header::Error || (h == Header::Response && code == m.id);
            if echo && matches!(m.phase, Phase::FenceAwait { .. }) {
                Heard::Fence
            } else if !for_command {
                Heard::Foreign
            } else if !matches!(m.phase, Phase::Await { .. }) {
                Heard::Stale
            } else if h == Header::Error {
                Heard::Rejected(code)
            } else if !content_ok {
                Heard::Mismatch
            } else {
                Heard::Answer
            }
        };
        let heard = self.line.offer(&f, content_ok, self.now());
        trace!(
            "t={clock} offer {} ok={content_ok} -> {heard:?}",
            String::from_utf8_lossy(bytes).trim_end()
        );
        assert_eq!(heard, expected, "offer classified against the rules");
        let m = &mut self.m;
        match heard {
            Heard::Foreign => m.stats.foreign += 1,
            Heard::Fence => {
                m.owed.clear();
                m.no_fence_until = None;
                m.turnaround_until = m.turnaround(clock);
                m.phase = Phase::Ready;
            }
            Heard::Stale => {
                if m.busy() {
                    m.faulted = true;
                }
                m.stats.stale += 1;
            }
            Heard::Rejected(code) => {
                m.stats.error_replies += 1;
                let pending = m.sends.saturating_sub(1);
                m.finish(Err(Failure::Controller { code, detail: None }), pending);
                if F15_FIXED || !matches!(m.reply, Reply::None { .. }) {
                    m.turnaround_until = m.turnaround(clock);
                }
            }
            Heard::Mismatch => {
                m.faulted = true;
                m.stats.mismatches += 1;
            }
            Heard::Answer => {
                let pending = m.sends.saturating_sub(1);
                m.finish(Ok(()), pending);
                if F15_FIXED || !matches!(m.reply, Reply::None { .. }) {
                    m.turnaround_until = m.turnaround(clock);
                }
            }
            Heard::NeedMore | Heard::Broken(_) => panic!("offer gave {heard:?}"),
        }
    }

    fn broken(&mut self, env: Option<(Header, Station, u16)>) {
        let clock = self.clock;
        self.line.broken(env, self.now());
        trace!("t={clock} broken {env:?}");
        let m = &mut self.m;
        m.stats.line_errors += 1;
        let ours = match env {
            Some((h, s, code)) if s == m.cfg.station && h != Header::Command => {
                let id = if h == Header::Error { ANY } else { code };
                m.copy_possible(id, clock);
                h == Header::Error || code == m.id
            }
            Some(_) => false,
            None => {
                m.copy_possible(ANY, clock);
                false
            }
        };
        let Phase::Await { deadline } = m.phase else {
            return;
        };
        if !ours {
            return;
        }
        m.faulted = true;
        if let Reply::None { .. } = m.reply {
            let s = m.sends;
            m.finish(Err(Failure::OutcomeUnknown { sends: s }), 0);
            return;
        }
        // Nothing is owed while a reply is awaited (checked at the send):
        // only the command's own earlier sends make it ambiguous.
        if m.sends > 1 && m.sends >= m.limit {
            return;
        }
        let soon = m.turnaround(clock);
        // Finding F14 (open): a deadline passed more than 2^31 ms ago (no
        // poll meanwhile) reads as a future one, and is moved to `soon`.
        let f14 = !F14_FIXED && soon > deadline + (1u64 << 31);
        m.phase = Phase::Await {
            deadline: if f14 { soon } else { deadline.min(soon) },
        };
    }

    /// Polls and checks what is due.
    fn poll(&mut self) -> Due {
        let clock = self.clock;
        let now = self.now();
        let due = self.line.poll(now);
        trace!("t={clock} poll -> {due:?} (model {:?})", self.m.phase);
        let m = &mut self.m;
        // What the deadlines passed by now did.
        if let Phase::FenceAwait { sent } = m.phase {
            if clock >= sent + u64::from(m.cfg.timeout_ms) {
                m.stats.timeouts += 1;
                m.stats.fences_failed += 1;
                m.faulted = true;
                let until = m.late(sent);
                m.owed.push(until);
                m.no_fence_until = m.owed_at(clock);
                m.phase = Phase::Ready;
            }
        }
        if let Phase::Await { deadline } = m.phase {
            if clock >= deadline {
                if let Reply::None { .. } = m.reply {
                    m.finish(Ok(()), 1);
                } else {
                    m.faulted = true;
                    m.stats.timeouts += 1;
                    if m.sends < m.limit {
                        m.phase = Phase::Ready;
                    } else {
                        let sends = m.sends;
                        let f = match m.resend {
                            Resend::Safe => Failure::Timeout { sends },
                            Resend::Unsafe => Failure::OutcomeUnknown { sends },
                        };
                        m.finish(Err(f), sends);
                    }
                }
            }
        }
        match due {
            Due::Idle => assert_eq!(m.phase, Phase::Idle, "Idle with a command"),
            Due::Done(r) => match m.phase {
                Phase::Done(want) => assert_eq!(r, want, "the command ended otherwise"),
                other => panic!("Done({r:?}) in {other:?}"),
            },
            Due::Fence => match m.phase {
                Phase::FenceSending => {}
                Phase::Ready => {
                    assert!(m.cfg.fences, "a fence with fences off");
                    assert!(
                        m.no_fence_until.is_none_or(|t| clock >= t),
                        "a fence while the line must wait after a failed one"
                    );
                    assert!(
                        m.owed_at(clock).is_some(),
                        "a fence at {clock} with nothing owed ({:?})",
                        m.owed
                    );
                    m.check_transmission(clock, "a fence");
                    m.fence_seq = m.fence_seq.wrapping_add(1);
                    m.stats.fences += 1;
                    m.phase = Phase::FenceSending;
                }
                other => panic!("Fence in {other:?}"),
            },
            Due::Send { fresh } => match m.phase {
                Phase::Sending => assert!(!fresh, "the same send fresh twice"),
                Phase::Ready => {
                    assert!(fresh, "a new send not fresh");
                    m.sends += 1;
                    assert!(
                        m.sends <= m.limit,
                        "{} sends of {:03X} (limit {})",
                        m.sends,
                        m.id,
                        m.limit
                    );
                    m.stats.sends += 1;
                    if m.sends > 1 {
                        m.stats.resends += 1;
                    }
                    if m.sends == 1 {
                        m.check_transmission(clock, "a first send");
                        assert!(
                            m.owed_at(clock).is_none(),
                            "a first send at {clock} while replies are owed until {:?}",
                            m.owed_at(clock)
                        );
                    }
                    let copies = m.copies_until(m.id, false);
                    assert!(
                        clock >= copies,
                        "a send of {:03X} at {clock} while a copy may come until {copies}",
                        m.id
                    );
                    m.phase = Phase::Sending;
                }
                other => panic!("Send in {other:?}"),
            },
            Due::WaitUntil(t) => {
                let ahead = records::check_wait(now, t, m.horizon(), false);
                let at = clock + u64::from(ahead);
                match m.phase {
                    Phase::Await { deadline } => {
                        assert_eq!(at, deadline, "the reply is not awaited until its deadline")
                    }
                    Phase::FenceAwait { sent } => assert_eq!(
                        at,
                        sent + u64::from(m.cfg.timeout_ms),
                        "the echo is not awaited until the fence's timeout"
                    ),
                    Phase::Ready => {
                        let latest = m.latest_hold(clock);
                        assert!(at <= latest, "waits until {at} with no hold after {latest}");
                    }
                    other => panic!("WaitUntil in {other:?}"),
                }
            }
        }
        if due == Due::Fence {
            let want = format!("!{:02X}200{}", m.cfg.station.0, m.fence_text(m.fence_seq));
            let bytes = self.line.fence_bytes();
            assert!(
                bytes.starts_with(want.as_bytes()),
                "fence {:?}, expected {want}",
                String::from_utf8_lossy(bytes)
            );
            let policy = BypassPolicy::Accept;
            let f = Frame::new_checked(bytes, policy).expect("a valid fence");
            assert_eq!(f.len(), 20);
            let bypass = m.cfg.checksum == ChecksumMode::Bypass;
            assert_eq!(&bytes[16..18] == b"@@", bypass, "checksum mode");
        }
        due
    }

    fn sent(&mut self) {
        let clock = self.clock;
        self.line.sent(self.now());
        trace!("t={clock} sent");
        let m = &mut self.m;
        match m.phase {
            Phase::FenceSending => m.phase = Phase::FenceAwait { sent: clock },
            Phase::Sending => {
                m.last_sent = clock;
                m.phase = Phase::Await {
                    deadline: clock + u64::from(m.cfg.timeout_ms),
                };
                if let Reply::None { ready_after_ms } = m.reply {
                    m.restart_until = m.restart_until.max(clock + u64::from(ready_after_ms));
                }
            }
            _ => {}
        }
    }

    fn start(&mut self, id: u16, resend: Resend, reply: Reply, max_sends: u8) {
        trace!("t={} start {id:03X}", self.clock);
        let clock = self.clock;
        self.m.begin(id, resend, reply, max_sends, clock);
    }

    /// The model and the line agree on what can be seen.
    fn check_state(&self) {
        let m = &self.m;
        let l = &self.line;
        assert_eq!(l.busy(), m.busy(), "busy() in {:?}", m.phase);
        assert_eq!(
            l.awaiting(),
            matches!(m.phase, Phase::Await { .. }),
            "awaiting() in {:?}",
            m.phase
        );
        assert_eq!(l.answered(), m.phase == Phase::Done(Ok(())), "answered()");
        assert_eq!(l.faulted(), m.faulted, "faulted() in {:?}", m.phase);
        assert_eq!(l.id(), m.id);
        assert_eq!(l.sends(), m.sends);
        assert_eq!(l.stats(), m.stats, "stats");
    }
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let mut cfg = LineConfig::new(Station(input.u8()));
    cfg.timeout_ms = 1 + u32::from(input.u8()) * 20;
    let flags = input.u8();
    cfg.max_sends = flags % 5;
    cfg.resend_unsafe = flags & 0x08 != 0;
    cfg.fences = flags & 0x10 == 0;
    cfg.checksum = if flags & 0x20 != 0 {
        ChecksumMode::Bypass
    } else {
        ChecksumMode::Compute
    };
    cfg.turnaround_ms = u32::from(input.u8() % 64);
    cfg.late_window_ms = u32::from(input.u16());
    cfg.duplicate_window_ms = u32::from(input.u16());
    let seed = input.u32();
    let base = input.u32();
    trace!("config {cfg:?} seed {seed:08X} base {base}");
    let mut h = Harness {
        input,
        line: Line::new(cfg, seed),
        m: Model {
            cfg,
            seed,
            phase: Phase::Idle,
            id: 0,
            resend: Resend::Safe,
            reply: Reply::Normal,
            limit: 1,
            sends: 0,
            last_sent: 0,
            opened: true,
            owed: Vec::new(),
            no_fence_until: None,
            heard: Vec::new(),
            turnaround_until: 0,
            restart_until: 0,
            fence_seq: 0,
            faulted: false,
            stats: LineStats::default(),
        },
        clock: 0,
        base,
        steps: 0,
    };
    let max_steps = 200 + 4 * data.len();
    loop {
        h.steps += 1;
        assert!(h.steps <= max_steps, "no end after {} steps", h.steps);
        let Some(op) = h.input.next() else { break };
        match op % 13 {
            0 => {
                let all = catalogue::ALL;
                let info: &MessageInfo = all[usize::from(h.input.u8()) % all.len()];
                h.line.start(info, h.now());
                h.start(info.id, info.resend, info.reply, cfg.max_sends);
            }
            1 => {
                let id = h.input.u16() & 0xFFF;
                let max_sends = h.input.u8() % 5;
                h.line.start_raw(id, max_sends, h.now());
                let (resend, reply) =
                    catalogue::request_rules(id).unwrap_or((Resend::Unsafe, Reply::Normal));
                h.start(id, resend, reply, max_sends);
            }
            2 => {
                h.poll();
            }
            3 => h.sent(),
            4 => {
                // The command's reply: a body of hex digits.
                let k = h.input.u8();
                let body: Vec<u8> = (0..usize::from(k % 9))
                    .map(|_| b"0123456789ABCDEF"[usize::from(h.input.u8() % 16)])
                    .collect();
                let station = cfg.station;
                let id = h.m.id;
                if let Some(f) = h.frame(Header::Response, station, id, &body) {
                    h.offer(&f, k & 0x80 == 0);
                }
            }
            5 => {
                let k = h.input.u8();
                let code = h.input.u16() & 0xFFF;
                let station = if k & 1 == 0 {
                    cfg.station
                } else {
                    Station(cfg.station.0 ^ (k | 1))
                };
                if let Some(f) = h.frame(Header::Error, station, code, &[]) {
                    h.offer(&f, true);
                }
            }
            6 => {
                // A 200H reply: the echo of the fence in flight, of an
                // earlier or later one, of another seed, or any text.
                let k = h.input.u8();
                let seq = h.m.fence_seq;
                let text = match k & 3 {
                    0 => h.m.fence_text(seq),
                    1 => h.m.fence_text(seq.wrapping_sub(1 + u16::from(k >> 4))),
                    2 => format!("{:06X}{:04X}", (seed ^ 0x0001_0000) & 0xFF_FFFF, seq),
                    _ => String::from_utf8_lossy(h.input.take(10))
                        .chars()
                        .map(|c| if c.is_ascii_graphic() { c } else { '0' })
                        .chain(std::iter::repeat('0'))
                        .take(10)
                        .collect(),
                };
                let station = if k & 4 == 0 {
                    cfg.station
                } else {
                    Station(cfg.station.0.wrapping_add(1))
                };
                if let Some(f) = h.frame(Header::Response, station, 0x200, text.as_bytes()) {
                    h.offer(&f, k & 8 == 0);
                }
            }
            7 => {
                let k = h.input.u8();
                let id = h.m.id;
                let (header, station, code) = match k % 3 {
                    0 => (Header::Response, Station(cfg.station.0 ^ (k | 1)), id),
                    1 => (Header::Command, cfg.station, id),
                    _ => (Header::Response, cfg.station, h.input.u16() & 0xFFF),
                };
                if let Some(f) = h.frame(header, station, code, &[]) {
                    h.offer(&f, true);
                }
            }
            8 => {
                let k = h.input.u8();
                let id = h.m.id;
                let env = match k % 5 {
                    0 => Some((Header::Response, cfg.station, id)),
                    1 => Some((Header::Error, cfg.station, h.input.u16() & 0xFFF)),
                    2 => Some((Header::Response, Station(cfg.station.0 ^ 0x40), id)),
                    3 => Some((Header::Command, cfg.station, id)),
                    _ => None,
                };
                h.broken(env);
            }
            9 => {
                h.line.unread(h.now());
                let clock = h.clock;
                h.m.stats.line_errors += 1;
                h.m.copy_possible(ANY, clock);
            }
            10 => {
                h.line.abandon(h.now());
                let clock = h.clock;
                h.m.abandon(clock);
                assert_eq!(h.line.poll(h.now()), Due::Idle);
            }
            11 => {
                let ms = match h.input.u8() % 4 {
                    0 | 1 => u64::from(h.input.u8()),
                    2 => u64::from(h.input.u16()),
                    _ => u64::from(h.input.u32() & 0x7FFF_FFFF),
                };
                h.advance(ms);
            }
            _ => {
                if matches!(h.poll(), Due::Fence | Due::Send { .. }) {
                    let ms = u64::from(h.input.u8() % 8);
                    h.advance(ms);
                    h.sent();
                }
            }
        }
        h.check_state();
    }
    // No more operations: the controller is silent; follow the deadlines.
    loop {
        h.steps += 1;
        assert!(h.steps <= max_steps + 400, "the command never ended");
        match h.poll() {
            Due::Idle | Due::Done(_) => break,
            Due::Fence | Due::Send { .. } => {
                h.advance(1);
                h.sent();
            }
            Due::WaitUntil(t) => {
                let ahead = t.wrapping_sub(h.now());
                if h.clock + u64::from(ahead) > CLOCK_CAP {
                    break;
                }
                h.advance(u64::from(ahead));
            }
        }
        h.check_state();
    }
    h.check_state();
});
