//! The reply matcher and retry rules (`exchange::Exchange`) on their own,
//! driven by arbitrary call sequences in both quarantine modes.
//!
//! Input layout: a config (station, timeout, sends 0-4, turnaround, late
//! and duplicate windows, resend of unsafe commands, quarantine mode, start
//! tick), then operations: start a catalogue command (or a raw ID with a
//! chosen resend safety and reply kind), poll, advance the clock, report
//! `sent`, offer a frame envelope (header, station, code, content check:
//! mostly the command's own, sometimes another station, ID or header),
//! report a broken frame or a lost reply, abandon, change the settings
//! between commands. When the operations run out the clock follows the
//! deadlines until every command is done.
//!
//! The harness keeps, beside the exchange, what the rules say must hold
//! (sends so far, when the last send ended, the end of the turnaround and
//! of every stale window) and checks after every call:
//! - `poll`: `Transmit { fresh: true }` exactly once per send, counted by
//!   `sends()`; at most `max_sends` sends (one for an unsafe command unless
//!   `resend_unsafe`, one for a command without normal response); a first
//!   send not before the turnaround after the previous reply (two ticks at
//!   least), the restart after 25BH, and, with `Quarantine::Wait`, the end
//!   of every window in which a stale reply may arrive; a resend, a
//!   `TimedOut` / `OutcomeUnknown` (by resend safety, with the sends made)
//!   not before `sent + timeout` unless a reply was reported lost; a
//!   `WaitUntil` never in the past nor further than the longest hold;
//! - `offer_head`: `Foreign` exactly when `judge` says so; otherwise `Stale`
//!   unless a reply is awaited (before `sent`, after the end); while
//!   awaited: a matching reply is `Accepted` (`Mismatch` if its content
//!   check failed, and the exchange keeps waiting), an `&` is
//!   `Rejected(code)`; the next poll says `Done(Replied)` /
//!   `Done(ErrorReply(code))` and nothing is ever sent again for it;
//! - `faulted()` exactly after a resend, a final timeout, a mismatch, a lost
//!   reply or a stale frame during the command, or an abandon after a send
//!   (never for a 25BH that simply got no reply); `busy()` / `awaiting()`
//!   agree with the phases; `stale_possible()` is true exactly inside the
//!   windows the model keeps: `timeout + late_window` after the last send
//!   of a command that ended with replies still owed (a timeout, an
//!   abandon: from the abandon if a send was in progress, a reply after
//!   resends, 25BH's possible `&`), and `duplicate_window` after a reply.
#![no_main]

#[path = "common/records.rs"]
mod records;

use iai_protocol_b::catalogue::{self, MessageInfo, Reply, Resend};
use iai_protocol_b::exchange::{
    judge, Due, Exchange, ExchangeConfig, Finish, Offer, Quarantine, Verdict,
};
use iai_protocol_b::frame::{Header, Station};
use libfuzzer_sys::fuzz_target;
use records::Input;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Idle,
    /// Started, `sends` made; `sending`: polled `Transmit` but no `sent`.
    Running {
        sending: bool,
    },
    Awaiting,
    Done,
}

struct Cmd {
    id: u16,
    resend: Resend,
    reply: Reply,
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let station = Station(input.u8());
    let mut cfg = ExchangeConfig::new(station);
    cfg.timeout_ms = 1 + u32::from(input.u8()) * 20;
    let b = input.u8();
    cfg.max_sends = b % 5;
    cfg.resend_unsafe = b & 0x08 != 0;
    let quarantine = if b & 0x10 != 0 {
        Quarantine::ByContent
    } else {
        Quarantine::Wait
    };
    cfg.turnaround_ms = 1 + u32::from(input.u8() % 4);
    cfg.late_window_ms = u32::from(input.u16());
    cfg.duplicate_window_ms = u32::from(input.u16());
    let base = input.u32();
    let mut x = Exchange::new(cfg, quarantine);

    let mut clock: u64 = 0;
    let now = |c: u64| base.wrapping_add(c as u32);
    let mut phase = Phase::Idle;
    let mut cmd = Cmd {
        id: 0,
        resend: Resend::Safe,
        reply: Reply::Normal,
    };
    let mut sends = 0u8;
    let mut last_sent = 0u64;
    let mut lost_at: Option<u64> = None;
    // Earliest first send of the next command (turnaround, restart), and
    // the end of the stale windows.
    let mut not_before = 0u64;
    let mut stale_until: Option<u64> = None;
    let mut faulted = false;
    let mut commands = 0usize;
    let mut steps = 0usize;
    let max_steps = 64 + 8 * data.len();

    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        let op = input.next();
        let op = match op {
            Some(o) => o % 9,
            // Out of operations: poll, send and follow deadlines until done.
            None if matches!(phase, Phase::Idle | Phase::Done) => break,
            None => match phase {
                Phase::Running { sending: true } => 3,
                _ => 1,
            },
        };
        trace!("t={clock} op {op} phase {phase:?} sends {sends}");
        match op {
            // Start a command.
            0 if commands < 8 => {
                let pick = input.u8();
                let (id, resend, reply) = if pick & 0x80 == 0 {
                    let info: &MessageInfo =
                        catalogue::ALL[usize::from(pick) % catalogue::ALL.len()];
                    x.start(info, now(clock));
                    (info.id, info.resend, info.reply)
                } else {
                    let resend = if pick & 1 == 0 {
                        Resend::Safe
                    } else {
                        Resend::Unsafe
                    };
                    let reply = if pick & 2 == 0 {
                        Reply::Normal
                    } else {
                        Reply::None {
                            ready_after_ms: u32::from(input.u16()),
                        }
                    };
                    let id = 0x200 + u16::from(pick & 0x7C);
                    x.start_raw(id, resend, reply, now(clock));
                    (id, resend, reply)
                };
                cmd = Cmd { id, resend, reply };
                sends = 0;
                lost_at = None;
                faulted = false;
                commands += 1;
                phase = Phase::Running { sending: false };
                assert_eq!(x.id(), id);
                assert_eq!(x.sends(), 0);
                assert!(x.busy() && !x.awaiting() && !x.faulted());
            }
            // Poll.
            1 | 0 => {
                let due = x.poll(now(clock));
                trace!("  poll -> {due:?}");
                match due {
                    Due::Idle => assert_eq!(phase, Phase::Idle),
                    Due::Transmit { fresh } => {
                        match phase {
                            // A first send, or a resend after the timeout.
                            Phase::Running { sending: false } | Phase::Awaiting => {
                                assert!(fresh, "a new send not fresh")
                            }
                            Phase::Running { sending: true } => {
                                assert!(!fresh, "the same send fresh twice")
                            }
                            other => panic!("Transmit in {other:?}"),
                        }
                        if fresh {
                            sends += 1;
                            let limit = match (cmd.reply, cmd.resend) {
                                (Reply::None { .. }, _) => 1,
                                (_, Resend::Unsafe) if !cfg.resend_unsafe => 1,
                                _ => cfg.max_sends.max(1),
                            };
                            assert!(sends <= limit, "{sends} sends (limit {limit})");
                            if sends == 1 {
                                assert!(clock >= not_before, "sent at {clock} before {not_before}");
                                if quarantine == Quarantine::Wait {
                                    if let Some(u) = stale_until {
                                        assert!(
                                            clock >= u,
                                            "sent at {clock} inside a stale window (to {u})"
                                        );
                                    }
                                }
                            } else {
                                let early = lost_at.is_some();
                                assert!(
                                    clock >= last_sent + u64::from(cfg.timeout_ms) || early,
                                    "resent at {clock} after a send that ended at {last_sent}"
                                );
                                faulted = true;
                            }
                        }
                        assert_eq!(x.sends(), sends);
                        phase = Phase::Running { sending: true };
                    }
                    Due::WaitUntil(deadline) => {
                        let bound = u64::from(cfg.timeout_ms)
                            + u64::from(cfg.late_window_ms)
                            + u64::from(cfg.duplicate_window_ms)
                            + u64::from(cfg.turnaround_ms)
                            + 65_537;
                        let ahead = records::check_wait(now(clock), deadline, bound, false);
                        if phase == Phase::Awaiting && lost_at.is_none() {
                            assert_eq!(
                                clock + u64::from(ahead),
                                last_sent + u64::from(cfg.timeout_ms),
                                "the timeout does not run from sent"
                            );
                        }
                        if input.is_empty() {
                            clock += u64::from(ahead);
                        }
                    }
                    Due::Done(f) => {
                        if phase != Phase::Done {
                            // Ended by the timeout (a reply ends at the offer).
                            assert_eq!(phase, Phase::Awaiting, "{f:?} in {phase:?}");
                            let early = lost_at.is_some();
                            assert!(
                                clock >= last_sent + u64::from(cfg.timeout_ms) || early,
                                "{f:?} at {clock} after a send that ended at {last_sent}"
                            );
                            match f {
                                Finish::NoReplyExpected => {
                                    assert!(matches!(cmd.reply, Reply::None { .. }));
                                    // Finding F3 (fixed): a lost reply ended
                                    // it early as if none had come.
                                    assert!(clock >= last_sent + u64::from(cfg.timeout_ms));
                                }
                                Finish::OutcomeUnknown { .. }
                                    if matches!(cmd.reply, Reply::None { .. }) =>
                                {
                                    panic!("25BH-like command unknown without a broken reply")
                                }
                                Finish::TimedOut { sends: s } => {
                                    assert_eq!(cmd.resend, Resend::Safe);
                                    assert_eq!(s, sends);
                                }
                                Finish::OutcomeUnknown { sends: s } => {
                                    assert_eq!(cmd.resend, Resend::Unsafe);
                                    assert_eq!(s, sends);
                                }
                                other => panic!("{other:?} without a reply"),
                            }
                            // Every send's reply may still come (for 25BH its `&`).
                            let until = last_sent
                                + u64::from(cfg.timeout_ms)
                                + u64::from(cfg.late_window_ms);
                            stale_until = Some(stale_until.map_or(until, |u| u.max(until)));
                            if !matches!(f, Finish::NoReplyExpected) {
                                faulted = true;
                            }
                            phase = Phase::Done;
                        }
                        assert!(!x.busy() && !x.awaiting());
                    }
                }
            }
            // Advance the clock.
            2 => clock += u64::from(input.u16() % 8192),
            // The transmission ended.
            3 => {
                x.sent(now(clock));
                if phase == (Phase::Running { sending: true }) {
                    phase = Phase::Awaiting;
                    last_sent = clock;
                    lost_at = None;
                    assert!(x.awaiting());
                    if let Reply::None { ready_after_ms } = cmd.reply {
                        // The controller restarts: nothing before it is ready.
                        not_before = not_before.max(clock + u64::from(ready_after_ms));
                    }
                } else {
                    // Nothing in transmission: `sent` changes nothing.
                    assert_eq!(x.awaiting(), phase == Phase::Awaiting);
                }
            }
            // A frame arrives.
            4 | 5 => {
                let k = input.u8();
                let header = match k & 3 {
                    0 | 1 => Header::Response,
                    2 => Header::Error,
                    _ => Header::Command,
                };
                let st = if k & 4 == 0 {
                    station
                } else {
                    Station(input.u8())
                };
                let code = if k & 8 == 0 && header == Header::Response {
                    cmd.id
                } else {
                    input.u16() & 0xFFF
                };
                let content_ok = k & 16 == 0;
                let verdict = judge(station, cmd.id, header, st, code);
                let offer = x.offer_head(header, st, code, content_ok, now(clock));
                trace!("  offer {header:?} {st:?} {code:03X} {content_ok} -> {offer:?}");
                match (verdict, offer) {
                    (Verdict::Foreign, o) => {
                        assert_eq!(o, Offer::Foreign);
                        // A reply from this station to another ID while
                        // stale replies may come (F9): a late reply to an
                        // earlier command, whose copy may follow.
                        let open = stale_until.is_some_and(|u| clock < u);
                        if st == station && header != Header::Command && open {
                            stale_seen(&cfg, &mut stale_until, clock);
                        }
                    }
                    (_, Offer::Stale) => {
                        assert!(phase != Phase::Awaiting, "a stale verdict while awaited");
                        if matches!(phase, Phase::Running { .. }) {
                            faulted = true;
                        }
                        stale_seen(&cfg, &mut stale_until, clock);
                    }
                    (Verdict::Reply, Offer::Accepted) => {
                        assert_eq!(phase, Phase::Awaiting);
                        assert!(content_ok);
                        reply_taken(
                            &cfg,
                            &mut not_before,
                            &mut stale_until,
                            clock,
                            sends,
                            last_sent,
                        );
                        phase = Phase::Done;
                        assert_eq!(x.poll(now(clock)), Due::Done(Finish::Replied));
                    }
                    (Verdict::Reply, Offer::Mismatch) => {
                        assert_eq!(phase, Phase::Awaiting);
                        assert!(!content_ok);
                        faulted = true;
                        assert!(x.awaiting());
                    }
                    (Verdict::ErrorReply(c), Offer::Rejected(d)) => {
                        assert_eq!(phase, Phase::Awaiting);
                        assert_eq!(c, d);
                        reply_taken(
                            &cfg,
                            &mut not_before,
                            &mut stale_until,
                            clock,
                            sends,
                            last_sent,
                        );
                        phase = Phase::Done;
                        assert_eq!(x.poll(now(clock)), Due::Done(Finish::ErrorReply(c)));
                    }
                    (v, o) => panic!("verdict {v:?} offered as {o:?}"),
                }
            }
            // A broken frame / a lost reply.
            6 => {
                let awaiting = phase == Phase::Awaiting;
                let lost;
                if input.u8() & 1 == 0 {
                    x.reply_lost(now(clock));
                    lost = awaiting;
                } else {
                    let k = input.u8();
                    let header = if k & 1 == 0 {
                        Header::Response
                    } else {
                        Header::Error
                    };
                    let st = if k & 2 == 0 { station } else { Station(k) };
                    let code = if k & 4 == 0 {
                        cmd.id
                    } else {
                        input.u16() & 0xFFF
                    };
                    x.broken_frame(Some((header, st, code)), now(clock));
                    lost = awaiting && judge(station, cmd.id, header, st, code) != Verdict::Foreign;
                }
                if lost {
                    lost_at = Some(clock);
                    faulted = true;
                    if let Reply::None { .. } = cmd.reply {
                        // Answered with an error whose code is unreadable:
                        // the outcome is unknown, nothing more is owed.
                        phase = Phase::Done;
                        assert_eq!(
                            x.poll(now(clock)),
                            Due::Done(Finish::OutcomeUnknown { sends })
                        );
                    }
                }
            }
            // Abandon.
            7 => {
                x.abandon(now(clock));
                if phase == (Phase::Running { sending: true }) {
                    // The send in progress may have gone out just now.
                    last_sent = clock;
                }
                if matches!(phase, Phase::Running { .. } | Phase::Awaiting) && sends > 0 {
                    let until =
                        last_sent + u64::from(cfg.timeout_ms) + u64::from(cfg.late_window_ms);
                    stale_until = Some(stale_until.map_or(until, |u| u.max(until)));
                    faulted = true;
                }
                phase = Phase::Idle;
                assert!(!x.busy());
                assert_eq!(x.poll(now(clock)), Due::Idle);
            }
            // New settings between commands.
            8 => {
                if matches!(phase, Phase::Idle | Phase::Done) {
                    cfg.timeout_ms = 1 + u32::from(input.u8()) * 20;
                    cfg.turnaround_ms = 1 + u32::from(input.u8() % 4);
                    x.set_config(cfg);
                    assert_eq!(*x.config(), cfg);
                }
            }
            _ => {}
        }
        assert_eq!(x.faulted(), faulted, "faulted() in {phase:?}");
        // Stale replies are possible exactly inside the windows above.
        let open = stale_until.is_some_and(|u| clock < u);
        assert_eq!(
            x.stale_possible(now(clock)),
            open,
            "stale windows (model: {stale_until:?})"
        );
    }
});

/// A stale reply came at `clock`: a duplicate of it may follow, so the
/// stale window grows by the duplicate window.
fn stale_seen(cfg: &ExchangeConfig, stale_until: &mut Option<u64>, clock: u64) {
    if cfg.duplicate_window_ms > 0 {
        let d = clock + u64::from(cfg.duplicate_window_ms);
        *stale_until = Some(match *stale_until {
            Some(u) if clock < u => u.max(d),
            _ => d,
        });
    }
}

/// A reply (normal or `&`) ended the command at `clock`: the next command
/// waits for the turnaround (two ticks at least) and a duplicate window;
/// the replies to its other sends may come until their late window ends.
fn reply_taken(
    cfg: &ExchangeConfig,
    not_before: &mut u64,
    stale_until: &mut Option<u64>,
    clock: u64,
    sends: u8,
    last_sent: u64,
) {
    *not_before = (*not_before).max(clock + u64::from(cfg.turnaround_ms) + 1);
    let mut until = None;
    if sends > 1 {
        until = Some(last_sent + u64::from(cfg.timeout_ms) + u64::from(cfg.late_window_ms));
    }
    if cfg.duplicate_window_ms > 0 {
        let d = clock + u64::from(cfg.duplicate_window_ms);
        until = Some(until.map_or(d, |u: u64| u.max(d)));
    }
    if let Some(u) = until {
        *stale_until = Some(stale_until.map_or(u, |s| s.max(u)));
    }
}
