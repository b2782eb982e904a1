//! One line to a controller: the command on it, its reply, and every reply
//! that may still arrive.
//!
//! A line carries one conversation at a time (half duplex, 2003 p. 8), so
//! one [`Line`] is shared by every engine that talks over it
//! ([`crate::client::Client`], [`crate::transfer::Transfer`],
//! [`crate::readback::ReadBack`], a bridge's pass-through), each borrowing
//! it for its calls. What the line remembers outlives them: a new call,
//! a restarted or resumed engine, another engine, all see the same
//! memory.
//!
//! - **Matching**: a frame is the reply only if its station, header and
//!   ID fit the command, its SC checked (the decoders' job), it came after
//!   the command was completely sent, and the owner's content check
//!   passed (the receiver's offer). Within a command's resends, the first reply
//!   counts (a late reply to an earlier send answers the same command).
//! - **Timing** (chapter 5, 2003 p. 62): the reply is awaited `timeout_ms`
//!   after the end of transmission; up to `max_sends` sends of a command
//!   that is safe to repeat ([`Resend`]); an `&` is never resent; 25BH
//!   waits for an error reply only, then holds the line while the
//!   controller restarts; after a reply the next command waits
//!   `turnaround_ms` plus one tick.
//! - **What may still arrive** (the ledger): replies owed to sends that
//!   were not answered, until `timeout_ms + late_window_ms` after them,
//!   and copies of every reply seen, until `duplicate_window_ms` after it.
//!   A command goes out only when nothing in the ledger could pass for its
//!   reply.
//! - **Fences**: owed replies are settled by order, not time. Before the
//!   next command the line sends a 200H whose text is its own; once the
//!   echo is back, a controller that answers in order has nothing left
//!   to say about earlier commands. A line just opened knows nothing of
//!   its past, so its first command is fenced too. Copies are not settled
//!   by a fence: they keep their time.
//! - **Copies noticed** (order proves what time only guesses): a frame
//!   from the station that nothing explains (no reply owed, no copy
//!   expected, or the very bytes of a reply already taken) is
//!   [`Heard::Unplaced`]: the line repeats frames (a converter) or answers
//!   out of order. From then on it expects copies as if a duplicate window
//!   had been declared ([`Line::copy_window`]), and an engine that took
//!   replies since its last proof of order ([`Line::start_proof`]: a fence
//!   echoed with nothing unplaced before it) asks again or says its result
//!   is unconfirmed.
//!
//! Bytes reach the line one way: an engine's receiver decodes them,
//! asks the engine to judge a frame's content, and offers it here.

mod fence;
mod ledger;
mod overheard;
mod receiver;

pub(crate) use ledger::{Span, ANY_ID};
pub(crate) use receiver::{
    fingerprint, fingerprint_more, receive, Judge, Receiver, Verdict, FINGERPRINT_START,
};

use fence::{Fence, FENCE_TRIES};
use ledger::Ledger;

use crate::catalogue::{self, MessageInfo, Reply, Resend};
use crate::checksum::ChecksumMode;
use crate::clock::{later, passed};
use crate::error::{Error, Failure};
use crate::frame::{Frame, Header, Station};

/// The longest a hold may lie ahead (a quarter of the wrapping clock's
/// range, about 12 days): settings beyond it are cut to it.
const MAX_HORIZON_MS: u32 = 0x4000_0000;

/// The settings of a line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LineConfig {
    /// The controller's station.
    pub station: Station,
    /// Time a reply may take after the command was completely sent, ms
    /// (3,000, 2003 p. 62).
    pub timeout_ms: u32,
    /// Sends of one command before giving up: 3 or 4 per the spec (2 or 3
    /// re-sends); 0 is read as 1.
    pub max_sends: u8,
    /// Pause after a reply before the next command, ms (at least 1, 2003
    /// p. 8); one tick is added so that it holds on a millisecond tick.
    pub turnaround_ms: u32,
    /// How much later than its timeout a reply may still arrive, ms. The
    /// spec allows none; links with converters and slow controllers do.
    pub late_window_ms: u32,
    /// How long after a reply a copy of it may arrive (an echoing
    /// converter), ms; 0 for a line that never repeats a frame.
    pub duplicate_window_ms: u32,
    /// Resend commands the catalogue marks [`Resend::Unsafe`] after a
    /// timeout (a relative move may then run twice).
    pub resend_unsafe: bool,
    /// Checksum or `@@` on the commands (the controller's setting).
    pub checksum: ChecksumMode,
    /// Settle owed replies with 200H fences (see the module docs); off
    /// for a controller that does not answer 200H: the line then waits
    /// out `timeout_ms + late_window_ms` instead.
    pub fences: bool,
}

/// How long a reply may take after the command was completely sent, ms
/// (2003 p. 62).
pub const TIMEOUT_MS: u32 = 3_000;

/// Sends of one command before giving up (2003 p. 62: 2 or 3 re-sends).
pub const MAX_SENDS: u8 = 3;

impl LineConfig {
    /// The spec's settings for `station`: [`TIMEOUT_MS`], [`MAX_SENDS`]
    /// sends, 1 ms turnaround, late replies allowed 3 s after their
    /// timeout, no copies, unsafe commands sent once, computed checksums,
    /// fences on.
    pub const fn new(station: Station) -> Self {
        LineConfig {
            station,
            timeout_ms: TIMEOUT_MS,
            max_sends: MAX_SENDS,
            turnaround_ms: 1,
            late_window_ms: 3_000,
            duplicate_window_ms: 0,
            resend_unsafe: false,
            checksum: ChecksumMode::Compute,
            fences: true,
        }
    }

    /// These settings with copies expected up to `ms` after a reply.
    pub const fn with_duplicate_window(mut self, ms: u32) -> Self {
        self.duplicate_window_ms = ms;
        self
    }

    /// The longest copy window the line learns by itself: twice the time a
    /// reply may take. The line cannot tell a copy later than that from
    /// the same question asked again and answered the same (a read-back's
    /// windows after a resume), and a window learned from those grew
    /// without end on a long run and held every command; a longer copy is
    /// caught by order instead (a proof's fence), or declared
    /// ([`LineConfig::with_duplicate_window`]).
    pub const fn learnable_copy_ms(&self) -> u32 {
        self.timeout_ms
            .saturating_add(self.late_window_ms)
            .saturating_mul(2)
    }

    /// The furthest ahead of the current tick that these settings ever
    /// place a hold.
    const fn horizon(&self) -> u32 {
        let sum = self
            .timeout_ms
            .saturating_add(self.late_window_ms)
            .saturating_add(self.duplicate_window_ms)
            .saturating_add(self.turnaround_ms)
            .saturating_add(2);
        let restart = catalogue::LONGEST_RESTART_MS;
        let h = if sum > restart { sum } else { restart };
        if h > MAX_HORIZON_MS {
            MAX_HORIZON_MS
        } else {
            h
        }
    }
}

/// Counters of a line.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LineStats {
    /// Commands started.
    pub commands: u32,
    /// Commands sent, resends included (fences not).
    pub sends: u32,
    /// Commands sent again after a timeout.
    pub resends: u32,
    /// Timeouts of commands and fences.
    pub timeouts: u32,
    /// Error responses taken as a command's reply.
    pub error_replies: u32,
    /// Replies with the command's ID whose content did not fit it.
    pub mismatches: u32,
    /// Replies that came when none was awaited, explained by a reply still
    /// owed or a copy still expected.
    pub stale: u32,
    /// Frames from the station that nothing explained: the line repeats
    /// frames or answers out of order ([`Heard::Unplaced`]).
    pub unplaced: u32,
    /// Frames for another station or command.
    pub foreign: u32,
    /// Broken frames, and bytes that may have held a reply dropped unread.
    pub line_errors: u32,
    /// Fences sent.
    pub fences: u32,
    /// Fences whose echo did not come (the line then waited instead).
    pub fences_failed: u32,
}

/// What the line needs now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Due {
    /// No command.
    Idle,
    /// Transmit [`Line::fence_bytes`], then report [`Line::sent`].
    Fence,
    /// Transmit the command, then report [`Line::sent`]; `fresh` on the
    /// first poll of each send (count it, reset the reply decoder).
    Send {
        /// First poll of this send.
        fresh: bool,
    },
    /// Nothing to do before this tick (feed received bytes meanwhile).
    WaitUntil(u32),
    /// The command is over: `Ok` when its reply was taken (or, for a
    /// command without normal response, when no error came).
    Done(Result<(), Failure>),
}

/// What a received frame meant on the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Heard {
    /// The command's reply: taken.
    Answer,
    /// An error response to the command, with its code: taken.
    Rejected(u16),
    /// The command's station and ID, but not its content (a 26DH count
    /// other than the records sent, a record outside the window asked).
    Mismatch,
    /// The echo of the line's fence.
    Fence,
    /// A frame from the station other than the awaited reply, explained
    /// by a reply still owed or a copy still expected.
    Stale,
    /// A frame from the station that nothing explains: a copy of a reply
    /// already taken, or a reply no command is owed. The line repeats
    /// frames; it now expects copies ([`Line::copy_window`]).
    Unplaced,
    /// Another station's frame, or a command.
    Foreign,
    /// A broken frame or noise was dropped.
    Broken(Error),
}

/// How much a command's reply has to prove.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) enum Claim {
    /// The reply is what the caller acts on: nothing that could pass for it
    /// may still arrive.
    Proof,
    /// A later command will check the reply (the first read of a confirmed
    /// read-back): only a copy that could pass as an error reply must be
    /// excluded, since it would stop the engine.
    Tentative,
}

/// A command as the line runs it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Command {
    pub(crate) id: u16,
    pub(crate) resend: Resend,
    pub(crate) reply: Reply,
    /// What a reply must carry to be taken (see [`Span`]).
    pub(crate) accepts: Span,
    pub(crate) claim: Claim,
    pub(crate) max_sends: u8,
}

impl Command {
    /// The command `id` under the catalogue's rules (an ID outside the
    /// catalogue is sent once and any normal response with it taken).
    pub(crate) fn of(id: u16, accepts: Span, claim: Claim, max_sends: u8) -> Self {
        let (resend, reply) =
            catalogue::request_rules(id).unwrap_or((Resend::Unsafe, Reply::Normal));
        Command {
            id,
            resend,
            reply,
            accepts,
            claim,
            max_sends,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Phase {
    Idle,
    /// Started, waiting for its (next) send.
    Ready,
    FenceSending,
    FenceAwait {
        deadline: u32,
    },
    Sending,
    Await {
        deadline: u32,
    },
    Finished(Result<(), Failure>),
}

/// One line to a controller (see the module docs). About 600 bytes.
#[derive(Debug, Clone)]
pub struct Line {
    cfg: LineConfig,
    cmd: Command,
    phase: Phase,
    sends: u8,
    last_sent: u32,
    /// Earliest tick of the next send (turnaround, restart).
    not_before: Option<u32>,
    faulted: bool,
    /// Nothing was started yet: the line's past is unknown.
    opened: bool,
    fence: Fence,
    fence_sent: u32,
    /// A fence failed: wait for owed replies instead until this tick.
    no_fence_until: Option<u32>,
    /// Fences sent in a row that got no echo.
    fence_misses: u8,
    ledger: Ledger,
    /// Replies taken lately (the last [`TAKEN`], in no order; a fixed
    /// array rather than a history ring, whose indexing the no-panic proof
    /// cannot see through): a frame with the same bytes is a copy.
    taken: [Option<Taken>; TAKEN],
    /// The slot the next reply taken goes to.
    taken_next: usize,
    /// The copy window the line learned from unplaced frames, ms.
    learned_copy_ms: u32,
    /// The longest time, ms, between a reply taken and an earlier one with
    /// the same bytes (a copy may have stood in for a reply).
    repeat_ms: u32,
    /// A proof of order was asked for ([`Line::start_proof`]).
    proving: bool,
    /// The proof's fence got no echo: it waits instead.
    proof_fence_failed: bool,
    /// How much longer than `timeout_ms` the current command's reply may
    /// take after its last byte (a receiver that takes a long frame in at
    /// a slower line's rate: [`crate::upload`]).
    reply_extra_ms: u32,
    /// Frames heard while the owner holds its reply, or no engine runs.
    overheard: overheard::Overheard,
    /// Bytes since the last LF that a receiver dropped as noise; `None`
    /// while the rest of a frame already accounted for is passing.
    noise: Option<u16>,
    stats: LineStats,
    horizon: u32,
}

#[cfg(feature = "defmt")]
impl defmt::Format for Line {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "Line {{ station: {}, phase: {}, stats: {} }}",
            self.cfg.station,
            self.phase,
            self.stats
        )
    }
}

/// Replies remembered as taken.
const TAKEN: usize = 8;

/// Bytes before the LF of the shortest reply with its header byte hit
/// (`&` or `#`, station, code, SC, CR: 9).
const NOISE_REPLY: u16 = 9;

/// A reply taken: its bytes' fingerprint, what it carried and when.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Taken {
    fingerprint: u32,
    id: u16,
    values: Span,
    at: u32,
}

impl Line {
    /// A line with these settings. `seed` makes its fence texts its own:
    /// give each start of a program a different one (the time of day, a
    /// boot counter, a chip's unique ID), and [`Line::stir`] in what
    /// varies later, so that a fence echo of an earlier run cannot pass
    /// for this run's.
    pub const fn new(cfg: LineConfig, seed: u32) -> Self {
        Line {
            cfg,
            cmd: Command {
                id: 0,
                resend: Resend::Safe,
                reply: Reply::Normal,
                accepts: Span::ANY,
                claim: Claim::Proof,
                max_sends: 1,
            },
            phase: Phase::Idle,
            sends: 0,
            last_sent: 0,
            not_before: None,
            faulted: false,
            opened: true,
            fence: Fence::new(seed),
            fence_sent: 0,
            no_fence_until: None,
            fence_misses: 0,
            ledger: Ledger::new(cfg.horizon()),
            taken: [None; TAKEN],
            taken_next: 0,
            learned_copy_ms: 0,
            repeat_ms: 0,
            proving: false,
            proof_fence_failed: false,
            reply_extra_ms: 0,
            overheard: overheard::Overheard::new(),
            noise: Some(0),
            stats: LineStats {
                commands: 0,
                sends: 0,
                resends: 0,
                timeouts: 0,
                error_replies: 0,
                mismatches: 0,
                stale: 0,
                unplaced: 0,
                foreign: 0,
                line_errors: 0,
                fences: 0,
                fences_failed: 0,
            },
            horizon: cfg.horizon(),
        }
    }

    /// The settings.
    pub const fn config(&self) -> &LineConfig {
        &self.cfg
    }

    /// Changes the settings (between commands); the ledger is kept.
    pub fn set_config(&mut self, cfg: LineConfig) {
        self.cfg = cfg;
        self.horizon = self.horizon.max(cfg.horizon());
        self.ledger.set_horizon(self.horizon);
    }

    /// Counters so far.
    pub const fn stats(&self) -> LineStats {
        self.stats
    }

    /// Mixes `entropy` into the texts of the fences to come (the one in
    /// flight keeps its text): a tick of something outside (a host's first
    /// byte, a timer at a pin change), so that two starts with the same
    /// seed still fence differently.
    pub fn stir(&mut self, entropy: u32) {
        self.fence.stir(entropy);
    }

    /// How long after a reply a copy of it is expected, ms: the declared
    /// duplicate window, or the one the line learned from frames it could
    /// not place, if longer.
    pub const fn copy_window(&self) -> u32 {
        if self.learned_copy_ms > self.cfg.duplicate_window_ms {
            self.learned_copy_ms
        } else {
            self.cfg.duplicate_window_ms
        }
    }

    /// Whether the line has shown that it repeats frames (an unplaced frame
    /// was heard).
    pub const fn repeats(&self) -> bool {
        self.stats.unplaced > 0
    }

    /// Begins a proof of order: a fence, sent even when nothing is owed.
    /// Once its echo is back ([`Due::Done`] `Ok`), every reply to a command
    /// sent before it has arrived (the controller answers in order); if no
    /// frame was [`Heard::Unplaced`] since a reply was taken, that reply was
    /// no copy. A line without fences waits out the replies instead.
    pub fn start_proof(&mut self, now: u32) {
        self.abandon(now);
        self.cmd = Command {
            id: catalogue::TEST_CALL.id,
            resend: Resend::Safe,
            reply: Reply::Normal,
            accepts: Span::ANY,
            claim: Claim::Proof,
            max_sends: 1,
        };
        self.sends = 0;
        self.faulted = false;
        self.proving = true;
        self.proof_fence_failed = false;
        self.opened = false;
        self.phase = Phase::Ready;
    }

    /// Begins command `info` (its first send is due from `now`, when
    /// nothing that may still arrive could pass for its reply). A command
    /// still running is abandoned: its replies are owed.
    pub fn start(&mut self, info: &MessageInfo, now: u32) {
        let cmd = Command {
            id: info.id,
            resend: info.resend,
            reply: info.reply,
            accepts: Span::ANY,
            claim: Claim::Proof,
            max_sends: self.cfg.max_sends,
        };
        self.begin(cmd, now);
    }

    /// [`Line::start`] for a command known by its ID only (a bridge passing
    /// on what a host sent), sent at most `max_sends` times; an ID outside
    /// the catalogue is sent once.
    pub fn start_raw(&mut self, id: u16, max_sends: u8, now: u32) {
        self.begin(Command::of(id, Span::ANY, Claim::Proof, max_sends), now);
    }

    pub(crate) fn begin(&mut self, cmd: Command, now: u32) {
        self.abandon(now);
        self.proving = false;
        self.reply_extra_ms = 0;
        if core::mem::take(&mut self.opened) {
            // The past is unknown: a reply to anything sent before may
            // still come, and a copy of anything received before.
            let owed = self.late_horizon(now);
            self.ledger.owe(owed, now);
            self.copy_possible(ANY_ID, Span::UNKNOWN, now);
        }
        self.cmd = cmd;
        self.sends = 0;
        self.faulted = false;
        self.stats.commands += 1;
        self.phase = Phase::Ready;
    }

    /// The current command's reply must now carry `accepts` (a frame or
    /// window cut shorter before its resend).
    pub(crate) fn accept(&mut self, accepts: Span) {
        self.cmd.accepts = accepts;
    }

    /// The ID of the current (or last) command.
    pub const fn id(&self) -> u16 {
        self.cmd.id
    }

    /// Sends of the current command so far.
    pub const fn sends(&self) -> u8 {
        self.sends
    }

    /// Whether something abnormal happened since the current command
    /// started: a timeout, a resend, a reply with the wrong content, a
    /// stale reply, or a reply to another send still owed at its end.
    pub const fn faulted(&self) -> bool {
        self.faulted
    }

    /// Whether the command's reply is awaited now (it was completely sent).
    pub const fn awaiting(&self) -> bool {
        matches!(self.phase, Phase::Await { .. })
    }

    /// Whether a command is in progress (not idle, not finished).
    pub const fn busy(&self) -> bool {
        !matches!(self.phase, Phase::Idle | Phase::Finished(_))
    }

    /// Whether the line has an answer for its current command (and
    /// received bytes should wait until the owner took it).
    pub const fn answered(&self) -> bool {
        matches!(self.phase, Phase::Finished(Ok(())))
    }

    /// The fence to transmit after [`Due::Fence`].
    pub fn fence_bytes(&self) -> &[u8] {
        self.fence.bytes()
    }

    fn over(&self, now: u32, t: u32) -> bool {
        passed(now, t, self.horizon)
    }

    /// The hold on the next send, seen from `now` (`now` if none).
    fn next_send(&self, now: u32) -> u32 {
        match self.not_before {
            Some(t) if !self.over(now, t) => t,
            _ => now,
        }
    }

    /// Sends this command may take.
    fn send_limit(&self) -> u8 {
        let max = self.cmd.max_sends.max(1);
        match (self.cmd.resend, self.cmd.reply) {
            (_, Reply::None { .. }) => 1,
            (Resend::Unsafe, _) if !self.cfg.resend_unsafe => 1,
            _ => max,
        }
    }

    /// The first tick, from `now`, at which no copy in the ledger could
    /// pass for the reply of a command `id` accepting `accepts` (owed
    /// replies are the fence's business).
    pub(crate) fn clear_at(&mut self, id: u16, accepts: Span, claim: Claim, now: u32) -> u32 {
        self.ledger.prune(now);
        self.ledger
            .clear_at(id, accepts, claim == Claim::Tentative, now)
    }

    /// Decides what is due at tick `now`.
    pub fn poll(&mut self, now: u32) -> Due {
        loop {
            return match self.phase {
                Phase::Idle => Due::Idle,
                Phase::Finished(r) => Due::Done(r),
                Phase::Ready => {
                    let hold = self.next_send(now);
                    if hold != now {
                        return Due::WaitUntil(hold);
                    }
                    self.ledger.prune(now);
                    let owed = self.ledger.owed(now);
                    if owed.is_some() || self.proving {
                        // A proof whose fence failed proves by waiting, as
                        // without fences, rather than fence again.
                        let fence_ok = self.cfg.fences
                            && self.no_fence_until.is_none_or(|t| self.over(now, t))
                            && !(self.proving && self.proof_fence_failed);
                        if !fence_ok {
                            if let Some(t) = owed {
                                return Due::WaitUntil(t);
                            }
                            // No fence proves the order: the replies to the
                            // last command are waited out instead.
                            let until = self.late_horizon(self.last_sent);
                            if !self.over(now, until) {
                                return Due::WaitUntil(until);
                            }
                            self.proving = false;
                            self.phase = Phase::Finished(Ok(()));
                            continue;
                        }
                        self.fence.next(self.cfg.station, self.cfg.checksum);
                        self.stats.fences += 1;
                        self.phase = Phase::FenceSending;
                        return Due::Fence;
                    }
                    let clear = self.clear_at(self.cmd.id, self.cmd.accepts, self.cmd.claim, now);
                    if clear != now {
                        return Due::WaitUntil(clear);
                    }
                    self.sends = self.sends.saturating_add(1);
                    self.stats.sends += 1;
                    if self.sends > 1 {
                        self.stats.resends += 1;
                    }
                    self.phase = Phase::Sending;
                    Due::Send { fresh: true }
                }
                Phase::FenceSending => Due::Fence,
                Phase::FenceAwait { deadline } if !self.over(now, deadline) => {
                    Due::WaitUntil(deadline)
                }
                Phase::FenceAwait { .. } => {
                    // No echo (or an `&`): the fence's own reply is owed, and
                    // a new fence settles it. After `FENCE_TRIES` in a row
                    // the controller may not answer 200H: what it owes is
                    // waited out.
                    self.stats.timeouts += 1;
                    self.stats.fences_failed += 1;
                    self.faulted = true;
                    let until = self.late_horizon(self.fence_sent);
                    self.ledger.owe(until, now);
                    self.fence_misses = self.fence_misses.saturating_add(1);
                    if self.fence_misses >= FENCE_TRIES {
                        self.fence_misses = 0;
                        self.proof_fence_failed = self.proving;
                        self.no_fence_until = self.ledger.owed(now);
                    }
                    self.phase = Phase::Ready;
                    continue;
                }
                Phase::Sending => Due::Send { fresh: false },
                Phase::Await { deadline } if !self.over(now, deadline) => Due::WaitUntil(deadline),
                Phase::Await { .. } => {
                    if let Reply::None { .. } = self.cmd.reply {
                        // Its error response may still come late.
                        self.finish(Ok(()), now, 1);
                        continue;
                    }
                    self.faulted = true;
                    self.stats.timeouts += 1;
                    if self.sends < self.send_limit() {
                        self.phase = Phase::Ready;
                        self.not_before = Some(now);
                        continue;
                    }
                    let sends = self.sends;
                    let f = match self.cmd.resend {
                        Resend::Safe => Failure::Timeout { sends },
                        Resend::Unsafe => Failure::OutcomeUnknown { sends },
                    };
                    self.finish(Err(f), now, sends);
                    continue;
                }
            };
        }
    }

    /// The first tick after which no reply to a send at `sent` can arrive.
    fn late_horizon(&self, sent: u32) -> u32 {
        sent.wrapping_add(self.cfg.timeout_ms)
            .wrapping_add(self.reply_extra_ms)
            .wrapping_add(self.cfg.late_window_ms)
            .wrapping_add(1)
    }

    /// [`Line::sent`] for a command whose reply may take `extra_ms` longer
    /// than the timeout after its last byte (cut to the line's longest
    /// hold); it and its late replies are owed that much longer.
    pub(crate) fn sent_allowing(&mut self, now: u32, extra_ms: u32) {
        let extra = extra_ms.min(MAX_HORIZON_MS / 4);
        self.reply_extra_ms = extra;
        let cfg = LineConfig {
            timeout_ms: self.cfg.timeout_ms.saturating_add(extra),
            ..self.cfg
        };
        self.horizon = self.horizon.max(cfg.horizon());
        self.ledger.set_horizon(self.horizon);
        self.sent(now);
    }

    /// The command (or fence) was completely transmitted at tick `now`:
    /// its timeout starts.
    pub fn sent(&mut self, now: u32) {
        match self.phase {
            Phase::FenceSending => {
                self.fence_sent = now;
                self.phase = Phase::FenceAwait {
                    deadline: now.wrapping_add(self.cfg.timeout_ms),
                };
            }
            Phase::Sending => {
                self.last_sent = now;
                self.phase = Phase::Await {
                    deadline: now
                        .wrapping_add(self.cfg.timeout_ms)
                        .wrapping_add(self.reply_extra_ms),
                };
                if let Reply::None { ready_after_ms } = self.cmd.reply {
                    // The controller restarts: nothing before it is ready.
                    self.not_before = Some(now.wrapping_add(ready_after_ms));
                }
            }
            _ => {}
        }
    }

    /// A checked frame arrived at `now`, with its owner's verdict on its
    /// content (see [`Receiver`]).
    pub(crate) fn offer(&mut self, frame: &Frame<'_>, verdict: Verdict, now: u32) -> Heard {
        let (h, s, c) = (frame.header(), frame.station(), frame.code());
        let print = fingerprint(frame.as_bytes());
        self.hear(h, s, c, Some(frame.body()), verdict, print, now)
    }

    /// [`Line::offer`] for a frame known by its envelope (its body streamed
    /// by: a transfer's read-back reply), with the verdict on its content
    /// and the fingerprint of its bytes.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn hear(
        &mut self,
        header: Header,
        station: Station,
        code: u16,
        body: Option<&[u8]>,
        verdict: Verdict,
        print: u32,
        now: u32,
    ) -> Heard {
        if station != self.cfg.station || header == Header::Command {
            self.stats.foreign += 1;
            return Heard::Foreign;
        }
        let values = verdict.values;
        let id = if header == Header::Error {
            ANY_ID
        } else {
            code
        };
        if header == Header::Response && code == catalogue::TEST_CALL.id {
            let echo = body.is_some_and(|b| self.fence.is_echo(b));
            if echo && matches!(self.phase, Phase::FenceAwait { .. }) {
                let seq = Span::one(self.fence.seq);
                self.copy_possible(id, seq, now);
                self.took(print, id, seq, now);
                self.ledger.settle_owed();
                self.no_fence_until = None;
                self.fence_misses = 0;
                self.not_before = Some(self.turnaround_after(now));
                if core::mem::take(&mut self.proving) {
                    self.phase = Phase::Finished(Ok(()));
                } else {
                    self.phase = Phase::Ready;
                }
                return Heard::Fence;
            }
        }
        let for_command = match header {
            Header::Error => true,
            _ => header == Header::Response && code == self.cmd.id && !self.proving,
        };
        if for_command && self.awaiting() {
            let pending = self.sends.saturating_sub(1);
            if header == Header::Error {
                self.copy_possible(id, values, now);
                self.took(print, id, values, now);
                self.stats.error_replies += 1;
                self.finish(
                    Err(Failure::Controller { code, detail: None }),
                    now,
                    pending,
                );
                self.replied(now);
                return Heard::Rejected(code);
            }
            if verdict.fits {
                self.copy_possible(id, values, now);
                self.took(print, id, values, now);
                self.finish(Ok(()), now, pending);
                self.replied(now);
                return Heard::Answer;
            }
        }
        if self.busy() {
            self.faulted = true;
        }
        if self.fence_refused(header) {
            self.end_fence(now);
        }
        // The command's ID but not its content: the controller's answer to
        // something else, or a copy; the command goes on waiting.
        let heard = if for_command && self.awaiting() {
            self.stats.mismatches += 1;
            Heard::Mismatch
        } else if self.ledger.owed(now).is_some()
            || self.ledger.expects(id, values, now)
            || self.fence_refused(header)
            || (for_command && self.between_sends())
        {
            self.stats.stale += 1;
            Heard::Stale
        } else {
            self.unplaced(Some(print), now);
            Heard::Unplaced
        };
        self.copy_possible(id, values, now);
        heard
    }

    /// Whether a frame with `header` may be the fence's own reply: a
    /// controller that does not answer 200H refuses it with an `&` (its
    /// echo is matched by its text).
    fn fence_refused(&self, header: Header) -> bool {
        header == Header::Error && matches!(self.phase, Phase::FenceAwait { .. })
    }

    /// An `&` or a broken frame came while a fence awaits its echo: the
    /// controller refused the fence, or its echo broke on the line (or an
    /// earlier command's reply came late). Rather than wait out the timeout
    /// for an echo that may never come, the fence ends at the turnaround
    /// and a new one follows ([`FENCE_TRIES`]); its echo settles the
    /// first's too.
    fn end_fence(&mut self, now: u32) {
        if let Phase::FenceAwait { deadline } = self.phase {
            let soon = self.turnaround_after(now);
            if !self.over(now, deadline) && crate::clock::reached(deadline, soon) {
                self.phase = Phase::FenceAwait { deadline: soon };
            }
        }
    }

    /// Whether the command was sent and is not awaited now (its timeout
    /// passed, it is sent again or waits to be): a reply to an earlier
    /// send may still come, owed though not yet in the ledger.
    fn between_sends(&self) -> bool {
        match self.phase {
            // The send on the wire is not one of them.
            Phase::Sending => self.sends > 1,
            Phase::Ready | Phase::FenceSending | Phase::FenceAwait { .. } => self.sends > 0,
            Phase::Idle | Phase::Await { .. } | Phase::Finished(_) => false,
        }
    }

    /// Remembers a reply taken at `now`.
    fn took(&mut self, print: u32, id: u16, values: Span, now: u32) {
        let same = self
            .taken
            .iter()
            .flatten()
            .filter(|t| t.fingerprint == print);
        if let Some(after) = same.map(|t| now.wrapping_sub(t.at)).min() {
            // Later than a copy the line learns of: the same question
            // asked again, answered the same.
            if after <= self.cfg.learnable_copy_ms() {
                self.repeat_ms = self.repeat_ms.max(after);
            }
        }
        if let Some(slot) = self.taken.get_mut(self.taken_next) {
            *slot = Some(Taken {
                fingerprint: print,
                id,
                values,
                at: now,
            });
        }
        self.taken_next = (self.taken_next + 1) % TAKEN;
    }

    /// A frame nothing explains arrived at `now`: the line repeats frames.
    /// It learns a copy window: twice the lateness of a copy whose original
    /// it took, or of the latest reply taken with the bytes of an earlier
    /// one (a copy may have stood in for it: this frame is then the reply
    /// displaced), or else the time a reply may take; every reply taken
    /// within it may still be copied. At most
    /// [`LineConfig::learnable_copy_ms`]: a longer one is declared.
    fn unplaced(&mut self, print: Option<u32>, now: u32) {
        self.stats.unplaced += 1;
        let late = self
            .taken
            .iter()
            .flatten()
            .filter(|t| Some(t.fingerprint) == print)
            .map(|t| now.wrapping_sub(t.at))
            .min();
        let late = late.or((self.repeat_ms > 0).then_some(self.repeat_ms));
        let window = match late {
            Some(l) => l.saturating_mul(2).max(1),
            None => self.cfg.timeout_ms.saturating_add(self.cfg.late_window_ms),
        }
        .min(self.cfg.learnable_copy_ms());
        if window > self.learned_copy_ms {
            self.learned_copy_ms = window;
            let cfg = LineConfig {
                duplicate_window_ms: window,
                ..self.cfg
            };
            self.horizon = self.horizon.max(cfg.horizon());
            self.ledger.set_horizon(self.horizon);
        }
        let window = self.copy_window();
        let taken = self.taken;
        for t in taken.iter().flatten() {
            let until = t.at.wrapping_add(window).wrapping_add(1);
            if !self.over(now, until) {
                self.ledger.copy(t.id, t.values, until, now);
            }
        }
    }

    /// A reply of `id` carrying `values` arrived at `now`: its copy may
    /// follow within the duplicate window.
    fn copy_possible(&mut self, id: u16, values: Span, now: u32) {
        let dup = self.copy_window();
        if dup > 0 {
            let until = now.wrapping_add(dup).wrapping_add(1);
            self.ledger.copy(id, values, until, now);
        }
    }

    fn turnaround_after(&self, now: u32) -> u32 {
        now.wrapping_add(self.cfg.turnaround_ms).wrapping_add(1)
    }

    /// A frame ended broken at `now`; `envelope` is what could be read of
    /// it ([`crate::decoder::FrameDecoder::failed_envelope`]). A copy of
    /// it may come whole. If it was the awaited reply, the controller will
    /// not answer again: the command is resent as soon as the turnaround
    /// has passed (an **inference** from the half-duplex rules, 2003 p. 8),
    /// unless it may be an earlier send's late reply on the last send. A
    /// broken frame of the station that nothing explains is unplaced: it
    /// may have been a copy or a reply out of order (while a reply is
    /// awaited, it may be that reply with its ID hit: no evidence).
    pub(crate) fn broken(&mut self, envelope: Option<(Header, Station, u16)>, now: u32) {
        self.stats.line_errors += 1;
        if envelope.is_none_or(|(h, s, _)| s == self.cfg.station && h != Header::Command) {
            // It may have been the fence's echo, broken.
            self.end_fence(now);
        }
        let ours = match envelope {
            Some((h, s, code)) if s == self.cfg.station && h != Header::Command => {
                let id = if h == Header::Error { ANY_ID } else { code };
                let awaited =
                    self.awaiting() && !self.proving && (h == Header::Error || code == self.cmd.id);
                let fence = (code == catalogue::TEST_CALL.id
                    && matches!(self.phase, Phase::FenceAwait { .. }))
                    || self.fence_refused(h);
                let for_command = h == Header::Error || code == self.cmd.id;
                // While a reply is awaited, a broken frame of the station
                // may be that reply with its ID hit: its envelope is as
                // broken as the rest, so it proves nothing out of place.
                let explained = awaited
                    || (self.awaiting() && !self.proving)
                    || fence
                    || (for_command && !self.proving && self.between_sends())
                    || self.ledger.owed(now).is_some()
                    || self.ledger.expects(id, Span::UNKNOWN, now);
                if !explained {
                    self.unplaced(None, now);
                }
                self.copy_possible(id, Span::UNKNOWN, now);
                awaited
            }
            Some(_) => false,
            None => {
                self.copy_possible(ANY_ID, Span::UNKNOWN, now);
                // It may have been the awaited reply, broken before its ID
                // (not an error reply to a command without a normal one:
                // that needs its envelope).
                self.awaiting() && !self.proving && !matches!(self.cmd.reply, Reply::None { .. })
            }
        };
        if !ours {
            return;
        }
        let Phase::Await { deadline } = self.phase else {
            return;
        };
        self.faulted = true;
        if let Reply::None { .. } = self.cmd.reply {
            // Answered with an error whose code cannot be read.
            let sends = self.sends;
            self.finish(Err(Failure::OutcomeUnknown { sends }), now, 0);
            return;
        }
        // Noise (no envelope) may be no reply at all: on the last send, the
        // reply is still waited for, as for an earlier send's late one.
        let ambiguous = envelope.is_none() || self.sends > 1 || self.ledger.owed(now).is_some();
        if ambiguous && self.sends >= self.send_limit() {
            return;
        }
        let soon = self.turnaround_after(now);
        // A deadline already over (even one passed more than 2^31 ms ago,
        // with no poll since) stays: the poll times out at once.
        if !self.over(now, deadline) && crate::clock::reached(deadline, soon) {
            self.phase = Phase::Await { deadline: soon };
        }
    }

    /// `bytes` received at `now` were dropped as noise (no frame began in
    /// them). A run of them ended by LF that is as long as a short reply
    /// may have been one whose header byte was hit, which no decoder can
    /// see as a frame: it is a broken frame of unknown envelope (the
    /// awaited reply is then sent for again at the turnaround).
    pub(crate) fn noise(&mut self, bytes: &[u8], now: u32) {
        for &b in bytes {
            if b != b'\n' {
                self.noise = self.noise.map(|n| n.saturating_add(1));
                continue;
            }
            if self.noise.is_some_and(|n| n >= NOISE_REPLY) {
                self.broken(None, now);
            }
            self.noise = Some(0);
        }
    }

    /// A frame began (or ended whole): what came before it is no reply.
    pub(crate) fn framing(&mut self) {
        self.noise = Some(0);
    }

    /// The rest of a frame already accounted for (broken, or streamed to
    /// its owner) passes as noise up to its LF.
    pub(crate) fn quiet(&mut self) {
        self.noise = None;
    }

    /// Bytes that may have held a reply were dropped unread at `now` (an
    /// engine clearing its decoder before a send): a copy of whatever they
    /// held may still come.
    pub(crate) fn unread(&mut self, now: u32) {
        self.stats.line_errors += 1;
        self.copy_possible(ANY_ID, Span::UNKNOWN, now);
    }

    /// Forgets the current command: the replies to its sends are owed.
    pub fn abandon(&mut self, now: u32) {
        match self.phase {
            Phase::FenceSending | Phase::FenceAwait { .. } => {
                // The fence may have gone out; what it was to settle is
                // still owed.
                let until = self.late_horizon(now);
                self.ledger.owe(until, now);
            }
            Phase::Sending => {
                // It may have gone out by now.
                self.last_sent = now;
                let sends = self.sends;
                self.finish(Err(Failure::Timeout { sends }), now, sends);
            }
            Phase::Ready | Phase::Await { .. } => {
                let sends = self.sends;
                self.finish(Err(Failure::Timeout { sends }), now, sends);
            }
            Phase::Idle | Phase::Finished(_) => {}
        }
        self.phase = Phase::Idle;
    }

    /// Ends the command; `pending` replies to its sends may still come.
    fn finish(&mut self, r: Result<(), Failure>, now: u32, pending: u8) {
        self.phase = Phase::Finished(r);
        let no_reply = matches!(self.cmd.reply, Reply::None { .. });
        if pending > 0 {
            let until = self.late_horizon(self.last_sent);
            self.ledger.owe(until, now);
            self.faulted |= !no_reply;
        }
    }

    /// A reply was taken at `now`: the turnaround holds the next send
    /// (2003 p. 8), after any reply, an `&` to a command without normal
    /// response too.
    fn replied(&mut self, now: u32) {
        self.not_before = Some(later(self.next_send(now), self.turnaround_after(now)));
    }
}

#[cfg(test)]
impl Line {
    /// A line whose past is known: for tests that start mid-conversation.
    pub(crate) fn known(cfg: LineConfig) -> Self {
        let mut l = Line::new(cfg, 0x12_3456);
        l.opened = false;
        l
    }
}

#[cfg(test)]
mod tests;
