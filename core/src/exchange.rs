//! One command and its reply: the timeout-and-retry rules of chapter 5 of
//! the 2003 specification (2003 p. 62; the TTA's own chapter is lost and
//! the same rules are assumed), and the one reply matcher of the crate.
//!
//! Every engine ([`crate::client`], [`crate::transfer`],
//! [`crate::readback`], a bridge's pass-through) runs its commands through
//! an [`Exchange`]:
//!
//! - **Matching** ([`judge`]): a frame counts as the reply only if it has
//!   the normal- or error-response format and a correct SC (the decoders
//!   guarantee both), carries the command's station, and, for a normal
//!   response, the command's message ID (an error response has none). The
//!   owner adds what only it can check (the record count of a 26DH reply,
//!   the window of a 21FH reply) as `content_ok`.
//! - **Timing**: the reply must be complete within `timeout_ms` (3 s) after
//!   the command was *completely sent* ([`Exchange::sent`]); after a reply
//!   the next command waits `turnaround_ms` (1 ms, 2003 p. 8). On a
//!   millisecond tick "at least 1 ms" means two ticks: a reply completed
//!   late in tick `t` and a send early in tick `t + 1` can be only
//!   microseconds apart.
//! - **Retries**: after a timeout the command is sent again, up to
//!   `max_sends` sends in all (the spec allows 2 or 3 re-sends: 3 or 4
//!   sends). A command the catalogue marks [`Resend::Unsafe`] is sent
//!   once unless the caller opts in, and a timeout then means
//!   [`Finish::OutcomeUnknown`]: it may have run.
//! - **Error responses** are not re-sent: the spec asks the host to take
//!   appropriate action (2003 pp. 13, 66), not to repeat.
//! - **25BH** has no normal response: the exchange waits out the timeout
//!   for an error response, then reports [`Finish::NoReplyExpected`] and
//!   holds the next command until the controller is ready again (about
//!   10 s after the reset was sent, 2003 p. 50).
//! - **Late replies**: the protocol has no sequence numbers. A reply to an
//!   earlier send of the same command counts for it (once: the command is
//!   then finished). Replies that may still come after a command finished
//!   (one per extra send; one per send after giving up) are *stale*: with
//!   [`Quarantine::Wait`] the next command is held until no stale reply
//!   can arrive any more (`timeout_ms + late_window_ms` after the last
//!   send), and whatever arrives meanwhile is discarded. With
//!   [`Quarantine::ByContent`] the owner's `content_ok` must make stale
//!   replies impossible to accept (the transfer engine gives consecutive
//!   frames different record counts).

use crate::catalogue::{MessageInfo, Reply, Resend};
use crate::clock::{later, passed, reached};
use crate::frame::{Frame, Header, Station};

/// How a frame relates to the command whose reply is awaited.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Verdict {
    /// A normal response from the station with the command's ID.
    Reply,
    /// An error response from the station, with its code.
    ErrorReply(u16),
    /// Anything else: another station, another ID, a command.
    Foreign,
}

/// Chapter 5's reply conditions for a frame from `station` of kind
/// `header` carrying `code` (message ID, or error code for `&`), as the
/// answer to command `id` sent to `expected`. The frame's format and SC are
/// the decoder's job; this checks conditions 3 (station) and 4 (ID).
///
/// ```
/// use iai_protocol_b::exchange::{judge, Verdict};
/// use iai_protocol_b::frame::{Header, Station};
/// let s = Station(0x99);
/// assert_eq!(judge(s, 0x212, Header::Response, s, 0x212), Verdict::Reply);
/// assert_eq!(judge(s, 0x212, Header::Response, s, 0x215), Verdict::Foreign);
/// assert_eq!(judge(s, 0x212, Header::Error, s, 0xC74), Verdict::ErrorReply(0xC74));
/// assert_eq!(judge(s, 0x212, Header::Response, Station(0x01), 0x212), Verdict::Foreign);
/// ```
pub const fn judge(
    expected: Station,
    id: u16,
    header: Header,
    station: Station,
    code: u16,
) -> Verdict {
    if station.0 != expected.0 {
        return Verdict::Foreign;
    }
    match header {
        Header::Response if code == id => Verdict::Reply,
        Header::Error => Verdict::ErrorReply(code),
        _ => Verdict::Foreign,
    }
}

/// [`judge`] for a checked frame.
pub fn judge_frame(expected: Station, id: u16, frame: &Frame<'_>) -> Verdict {
    judge(expected, id, frame.header(), frame.station(), frame.code())
}

/// How replies that may still arrive after a command finished are kept
/// from being taken for the next command's reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Quarantine {
    /// Hold the next command until no stale reply can arrive any more.
    Wait,
    /// Send at once; the owner's `content_ok` rejects stale replies.
    ByContent,
}

/// The longest a hold may lie ahead (a quarter of the wrapping clock's
/// range, about 12 days): settings beyond it are cut to it.
pub const MAX_HORIZON_MS: u32 = 0x4000_0000;

/// The chapter-5 settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ExchangeConfig {
    /// Station addressed.
    pub station: Station,
    /// Time a reply may take after the command was completely sent, ms
    /// (3,000, 2003 p. 62).
    pub timeout_ms: u32,
    /// Sends of one command before giving up: 3 or 4 per the spec (2 or 3
    /// re-sends); 0 is read as 1.
    pub max_sends: u8,
    /// Pause after a reply before the next command, ms (at least 1, 2003
    /// p. 8); one more tick is added so that the pause holds on a
    /// millisecond tick.
    pub turnaround_ms: u32,
    /// How much later than its timeout a reply may still arrive, ms. The
    /// spec allows none; links with converters and slow controllers do.
    pub late_window_ms: u32,
    /// How long after a reply a duplicate of it may arrive (an echoing
    /// converter), ms; 0 if the link never duplicates. With
    /// [`Quarantine::Wait`] every command waits this long after the last
    /// reply.
    pub duplicate_window_ms: u32,
    /// Resend commands the catalogue marks [`Resend::Unsafe`] after a
    /// timeout (a relative move may then run twice).
    pub resend_unsafe: bool,
}

impl ExchangeConfig {
    /// The furthest ahead of the current tick that these settings ever
    /// place a hold: a timeout plus a late window, a duplicate window, a
    /// turnaround (their sum, to be safe), or a controller's restart
    /// ([`Reply::None`]), whichever is longest.
    pub const fn horizon(&self) -> u32 {
        let sum = self
            .timeout_ms
            .saturating_add(self.late_window_ms)
            .saturating_add(self.duplicate_window_ms)
            .saturating_add(self.turnaround_ms)
            .saturating_add(1);
        let restart = crate::catalogue::LONGEST_RESTART_MS;
        let h = if sum > restart { sum } else { restart };
        // A hold must stay comparable on the wrapping clock.
        if h > MAX_HORIZON_MS {
            MAX_HORIZON_MS
        } else {
            h
        }
    }

    /// The spec's settings for `station`: 3 s timeout, 3 sends, 1 ms
    /// turnaround, late replies guarded for another 3 s, no duplicates
    /// expected, unsafe commands sent once.
    pub const fn new(station: Station) -> Self {
        ExchangeConfig {
            station,
            timeout_ms: 3_000,
            max_sends: 3,
            turnaround_ms: 1,
            late_window_ms: 3_000,
            duplicate_window_ms: 0,
            resend_unsafe: false,
        }
    }
}

/// How an exchange ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Finish {
    /// The normal response came (the owner holds it).
    Replied,
    /// An error response came, with this code; not re-sent.
    ErrorReply(u16),
    /// No valid reply after this many sends of a command that is safe to
    /// repeat: it may or may not have run.
    TimedOut {
        /// Sends made.
        sends: u8,
    },
    /// No valid reply to a command that is unsafe to repeat: it may have
    /// run (possibly more than once, if resending was allowed).
    OutcomeUnknown {
        /// Sends made.
        sends: u8,
    },
    /// A command without normal response (25BH) was sent and no error
    /// response came within the timeout.
    NoReplyExpected,
}

/// What the exchange needs now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Due {
    /// No command.
    Idle,
    /// Transmit the command; `fresh` on the first poll of each send.
    Transmit {
        /// First poll of this send (count it, reset the reply decoder).
        fresh: bool,
    },
    /// Nothing to do before this tick (feed received bytes meanwhile).
    WaitUntil(u32),
    /// The exchange is over.
    Done(Finish),
}

/// What a received frame did to the exchange.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Offer {
    /// It is the reply: the exchange finished with [`Finish::Replied`].
    Accepted,
    /// It is an error response to the command: finished with
    /// [`Finish::ErrorReply`].
    Rejected(u16),
    /// Station and ID match but the owner's content check failed (a 26DH
    /// count other than the records sent): not the reply.
    Mismatch,
    /// A reply (or error reply) while none is awaited: before the command
    /// was completely sent, after the exchange finished, or in quarantine.
    Stale,
    /// Not for this command at all.
    Foreign,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Phase {
    Idle,
    Ready,
    Sending,
    Await { deadline: u32 },
    Finished(Finish),
}

/// The state of one command/reply exchange (and of the stale replies the
/// previous ones may still produce).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Exchange {
    cfg: ExchangeConfig,
    quarantine: Quarantine,
    id: u16,
    resend: Resend,
    reply: Reply,
    phase: Phase,
    sends: u8,
    last_sent: u32,
    /// Earliest tick of the next send (turnaround, reset readiness).
    not_before: Option<u32>,
    /// Replies of finished commands that may still arrive, and until when.
    stale: u8,
    stale_until: u32,
    /// A fault was seen during the current command (timeout, resend,
    /// mismatch, stale frame): the transfer engine's "after a fault".
    faulted: bool,
    /// The furthest ahead of `now` any hold is ever set (see
    /// [`passed`]): a hold further ahead was set long ago.
    horizon: u32,
    /// Whether a taken reply starts the duplicate window (see
    /// [`Exchange::owner_guards_reply_copies`]).
    copies_of_taken: bool,
}

impl Exchange {
    /// An idle exchange.
    pub const fn new(cfg: ExchangeConfig, quarantine: Quarantine) -> Self {
        Exchange {
            cfg,
            quarantine,
            id: 0,
            resend: Resend::Safe,
            reply: Reply::Normal,
            phase: Phase::Idle,
            sends: 0,
            last_sent: 0,
            not_before: None,
            stale: 0,
            stale_until: 0,
            faulted: false,
            horizon: cfg.horizon(),
            copies_of_taken: true,
        }
    }

    /// The exchange for an owner that guards against copies of the
    /// replies it *takes* by itself (the transfer's count guard, the
    /// read-back's empty-window rule), so that it need not wait after every
    /// reply: a taken reply no longer starts the duplicate window. A
    /// stale reply still does, and the horizon still covers it.
    pub const fn owner_guards_reply_copies(mut self) -> Self {
        self.copies_of_taken = false;
        self
    }

    /// How far ahead of `now` a hold may lie (see [`passed`]).
    pub const fn horizon(&self) -> u32 {
        self.horizon
    }

    /// Whether hold `t` is over at `now`.
    const fn over(&self, now: u32, t: u32) -> bool {
        passed(now, t, self.horizon)
    }

    /// The hold on the next send, seen from `now` (`now` if none).
    const fn next_send(&self, now: u32) -> u32 {
        match self.not_before {
            Some(t) if !self.over(now, t) => t,
            _ => now,
        }
    }

    /// The settings.
    pub const fn config(&self) -> &ExchangeConfig {
        &self.cfg
    }

    /// Changes the settings (between commands).
    pub fn set_config(&mut self, cfg: ExchangeConfig) {
        self.cfg = cfg;
        self.horizon = self.horizon.max(cfg.horizon());
    }

    /// Begins a command described by `info`: its first send is due from
    /// `now`, after the turnaround, a pending reset and (with
    /// [`Quarantine::Wait`]) any stale replies.
    pub fn start(&mut self, info: &MessageInfo, now: u32) {
        self.start_raw(info.id, info.resend, info.reply, now);
    }

    /// [`Exchange::start`] for a command outside the catalogue (a bridge
    /// passing through what it does not know): its resend safety and reply
    /// kind are the caller's statement.
    pub fn start_raw(&mut self, id: u16, resend: Resend, reply: Reply, now: u32) {
        self.id = id;
        self.resend = resend;
        self.reply = reply;
        if let Reply::None { ready_after_ms } = reply {
            self.horizon = self.horizon.max(ready_after_ms.min(MAX_HORIZON_MS));
        }
        self.sends = 0;
        self.faulted = false;
        let mut at = self.next_send(now);
        if self.quarantine == Quarantine::Wait && self.stale_possible(now) {
            at = later(at, self.stale_until);
        }
        self.not_before = Some(at);
        self.phase = Phase::Ready;
    }

    /// Holds the first send of a command started but not yet sent until
    /// `t` (an owner that learnt of a reason to wait, such as a stale
    /// reply whose copy could answer it). No effect once it was sent.
    pub fn defer(&mut self, t: u32) {
        if self.phase == Phase::Ready {
            self.not_before = Some(match self.not_before {
                Some(nb) if !self.over(t, nb) => later(nb, t),
                _ => t,
            });
        }
    }

    /// The ID of the current (or last) command.
    pub const fn id(&self) -> u16 {
        self.id
    }

    /// Sends of the current command so far.
    pub const fn sends(&self) -> u8 {
        self.sends
    }

    /// Whether something abnormal happened during the current command: a
    /// timeout, a resend, a reply with the wrong content or a stale one.
    pub const fn faulted(&self) -> bool {
        self.faulted
    }

    /// How the current command ended, if it has.
    pub const fn finished(&self) -> Option<Finish> {
        match self.phase {
            Phase::Finished(f) => Some(f),
            _ => None,
        }
    }

    /// Whether a reply is awaited now (the command was completely sent).
    pub const fn awaiting(&self) -> bool {
        matches!(self.phase, Phase::Await { .. })
    }

    /// Whether a command is in progress (not idle, not finished).
    pub const fn busy(&self) -> bool {
        matches!(
            self.phase,
            Phase::Ready | Phase::Sending | Phase::Await { .. }
        )
    }

    /// Sends this command may take: 1 for an unsafe one unless allowed.
    fn send_limit(&self) -> u8 {
        let max = self.cfg.max_sends.max(1);
        match (self.resend, self.reply) {
            (_, Reply::None { .. }) => 1,
            (Resend::Unsafe, _) if !self.cfg.resend_unsafe => 1,
            _ => max,
        }
    }

    /// Decides what is due at tick `now`.
    pub fn poll(&mut self, now: u32) -> Due {
        match self.phase {
            Phase::Idle => Due::Idle,
            Phase::Finished(f) => Due::Done(f),
            Phase::Ready if self.next_send(now) != now => Due::WaitUntil(self.next_send(now)),
            Phase::Ready => {
                self.sends = self.sends.saturating_add(1);
                self.phase = Phase::Sending;
                Due::Transmit { fresh: true }
            }
            Phase::Sending => Due::Transmit { fresh: false },
            Phase::Await { deadline } if !self.over(now, deadline) => Due::WaitUntil(deadline),
            Phase::Await { .. } => self.timed_out(now),
        }
    }

    fn timed_out(&mut self, now: u32) -> Due {
        if let Reply::None { .. } = self.reply {
            // Its error response may still come late, like any reply.
            return self.finish(Finish::NoReplyExpected, now, 1);
        }
        self.faulted = true;
        if self.sends < self.send_limit() {
            self.phase = Phase::Ready;
            self.not_before = Some(now);
            return self.poll(now);
        }
        let f = match self.resend {
            Resend::Safe => Finish::TimedOut { sends: self.sends },
            Resend::Unsafe => Finish::OutcomeUnknown { sends: self.sends },
        };
        let pending = self.sends;
        self.finish(f, now, pending)
    }

    /// The command was completely transmitted at tick `now`: the timeout
    /// starts.
    pub fn sent(&mut self, now: u32) {
        if self.phase == Phase::Sending {
            self.last_sent = now;
            self.phase = Phase::Await {
                deadline: now.wrapping_add(self.cfg.timeout_ms),
            };
            if let Reply::None { ready_after_ms } = self.reply {
                // The controller restarts: nothing before it is ready again.
                self.not_before = Some(now.wrapping_add(ready_after_ms));
            }
        }
    }

    /// A checked frame from the controller arrived at `now`. `content_ok`
    /// is the owner's check of a normal response's body (always `true` if
    /// it has none).
    pub fn offer(&mut self, frame: &Frame<'_>, content_ok: bool, now: u32) -> Offer {
        self.offer_head(
            frame.header(),
            frame.station(),
            frame.code(),
            content_ok,
            now,
        )
    }

    /// [`Exchange::offer`] for a frame known by its envelope (a frame
    /// checked record by record by a stream decoder).
    pub fn offer_head(
        &mut self,
        header: Header,
        station: Station,
        code: u16,
        content_ok: bool,
        now: u32,
    ) -> Offer {
        let verdict = judge(self.cfg.station, self.id, header, station, code);
        if verdict == Verdict::Foreign {
            // A reply from our controller to another ID while replies to
            // earlier commands may still come: a late reply to one of
            // them, and a copy of it may follow.
            if station == self.cfg.station && header != Header::Command && self.stale_possible(now)
            {
                self.stale_seen(now);
            }
            return Offer::Foreign;
        }
        if !self.awaiting() {
            if self.busy() {
                self.faulted = true;
            }
            self.stale_seen(now);
            return Offer::Stale;
        }
        match verdict {
            Verdict::Reply if content_ok => {
                let pending = self.sends.saturating_sub(1);
                self.finish(Finish::Replied, now, pending);
                Offer::Accepted
            }
            Verdict::Reply => {
                self.faulted = true;
                Offer::Mismatch
            }
            Verdict::ErrorReply(code) => {
                let pending = self.sends.saturating_sub(1);
                self.finish(Finish::ErrorReply(code), now, pending);
                Offer::Rejected(code)
            }
            Verdict::Foreign => Offer::Foreign,
        }
    }

    /// A stale reply arrived at `now`: a duplicate of it may follow within
    /// the duplicate window, like a copy of any reply. The quarantine
    /// grows by that much (with [`Quarantine::Wait`], a command not yet
    /// sent waits for it too).
    fn stale_seen(&mut self, now: u32) {
        if self.cfg.duplicate_window_ms == 0 {
            return;
        }
        let until = now.wrapping_add(self.cfg.duplicate_window_ms);
        self.stale_until = if self.stale_possible(now) {
            later(self.stale_until, until)
        } else {
            until
        };
        self.stale = self.stale.saturating_add(1);
        if self.quarantine == Quarantine::Wait && self.phase == Phase::Ready {
            self.not_before = Some(later(self.next_send(now), self.stale_until));
        }
    }

    /// Ends the command; `pending` replies may still come.
    fn finish(&mut self, f: Finish, now: u32, pending: u8) -> Due {
        self.phase = Phase::Finished(f);
        // More than one send: the replies to the others may still come.
        // (After 25BH, the one pending is its possible error response.)
        if !matches!(f, Finish::NoReplyExpected) {
            self.faulted |= pending > 0;
        }
        let mut until = now;
        let mut stale = 0;
        if pending > 0 {
            stale = pending;
            until = self
                .last_sent
                .wrapping_add(self.cfg.timeout_ms)
                .wrapping_add(self.cfg.late_window_ms);
        }
        if matches!(f, Finish::Replied | Finish::ErrorReply(_)) {
            if self.copies_of_taken && self.cfg.duplicate_window_ms > 0 {
                stale = stale.saturating_add(1);
                until = later(until, now.wrapping_add(self.cfg.duplicate_window_ms));
            }
            let turnaround = now.wrapping_add(self.cfg.turnaround_ms).wrapping_add(1);
            self.not_before = Some(later(self.next_send(now), turnaround));
        }
        // Stale replies of older commands are still possible until their
        // own window closes.
        if self.stale_possible(now) {
            stale = stale.saturating_add(self.stale);
            until = later(until, self.stale_until);
        }
        self.stale = stale;
        self.stale_until = until;
        Due::Done(f)
    }

    /// The awaited reply arrived broken (it ended with CR LF, carried this
    /// command's station and ID, and failed its checksum or layout): the
    /// controller answers each command once, so no valid reply will come.
    /// The command is treated as timed out as soon as the turnaround has
    /// passed, instead of `timeout_ms` later. (Resending before the
    /// timeout is an **inference** from the half-duplex rules, 2003 p. 8:
    /// after its reply the controller is ready for the next command.)
    ///
    /// After a resend, or while a reply to an older command may still
    /// come, a broken frame may be one of those late replies and the
    /// awaited one may still arrive. Then the timeout is cut short only if
    /// another send is left (an extra send costs at most a stale reply);
    /// the last send keeps its full timeout, so that a stranger's broken
    /// reply cannot end the command as timed out.
    ///
    /// A command without normal response (25BH) that gets a broken frame
    /// was answered with an error whose code cannot be read: it ends as
    /// [`Finish::OutcomeUnknown`] (not resent, not reported as sent).
    pub fn reply_lost(&mut self, now: u32) {
        if let Phase::Await { deadline } = self.phase {
            self.faulted = true;
            if let Reply::None { .. } = self.reply {
                self.finish(Finish::OutcomeUnknown { sends: self.sends }, now, 0);
                return;
            }
            let ambiguous = self.sends > 1 || self.stale_possible(now);
            if ambiguous && self.sends >= self.cfg.max_sends {
                return;
            }
            let soon = now.wrapping_add(self.cfg.turnaround_ms).wrapping_add(1);
            if reached(deadline, soon) {
                self.phase = Phase::Await { deadline: soon };
            }
        }
    }

    /// A frame ended broken; `envelope` is what could be read of it
    /// ([`crate::decoder::FrameDecoder::failed_envelope`]). If it was this
    /// command's reply, see [`Exchange::reply_lost`].
    pub fn broken_frame(&mut self, envelope: Option<(Header, Station, u16)>, now: u32) {
        if let Some((header, station, code)) = envelope {
            if judge(self.cfg.station, self.id, header, station, code) != Verdict::Foreign {
                self.reply_lost(now);
            }
        }
    }

    /// Forgets the current command (its replies become stale).
    pub fn abandon(&mut self, now: u32) {
        if self.busy() {
            if self.phase == Phase::Sending {
                // The command may have gone out by now: its replies can
                // come until a timeout and a late window from now.
                self.last_sent = now;
            }
            let pending = self.sends;
            self.finish(Finish::TimedOut { sends: pending }, now, pending);
        }
        self.phase = Phase::Idle;
    }

    /// Whether stale replies may still arrive at `now`.
    pub const fn stale_possible(&self, now: u32) -> bool {
        self.stale > 0 && !self.over(now, self.stale_until)
    }

    /// When no reply to an earlier command (or send) can arrive any more:
    /// `now` if none can.
    pub const fn quiet_from(&self, now: u32) -> u32 {
        if self.stale_possible(now) {
            self.stale_until
        } else {
            now
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalogue;
    use crate::checksum::BypassPolicy;

    const S: Station = Station(0x99);

    fn frame(bytes: &[u8]) -> Frame<'_> {
        Frame::new_checked(bytes, BypassPolicy::Reject).unwrap()
    }

    fn exchange() -> Exchange {
        Exchange::new(ExchangeConfig::new(S), Quarantine::Wait)
    }

    #[test]
    fn a_reply_counts_only_after_the_command_was_sent() {
        let mut x = exchange();
        x.start(&catalogue::SYSTEM_STATUS_QUERY, 0);
        assert_eq!(x.poll(0), Due::Transmit { fresh: true });
        assert_eq!(x.poll(0), Due::Transmit { fresh: false });
        let f = frame(b"#99215000000000000000FD\r\n");
        // Before `sent`: stale, not the reply.
        assert_eq!(x.offer(&f, true, 0), Offer::Stale);
        x.sent(10);
        assert_eq!(x.poll(11), Due::WaitUntil(3_010));
        assert_eq!(x.offer(&f, true, 12), Offer::Accepted);
        assert_eq!(x.poll(12), Due::Done(Finish::Replied));
    }

    #[test]
    fn timeout_runs_from_the_end_of_transmission_and_resends_up_to_the_limit() {
        let mut x = exchange();
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        assert_eq!(x.poll(0), Due::Transmit { fresh: true });
        // A slow line: each send takes 2 s to transmit.
        let mut end = 2_000;
        for send in 1..=3u8 {
            assert_eq!(x.sends(), send);
            x.sent(end);
            assert_eq!(x.poll(end + 2_999), Due::WaitUntil(end + 3_000));
            let due = x.poll(end + 3_000);
            if send < 3 {
                assert_eq!(due, Due::Transmit { fresh: true });
                end += 5_000;
            } else {
                assert_eq!(due, Due::Done(Finish::TimedOut { sends: 3 }));
            }
        }
        assert!(x.faulted());
    }

    #[test]
    fn an_unsafe_command_is_sent_once_and_its_timeout_is_an_unknown_outcome() {
        let mut x = exchange();
        x.start(&catalogue::RELATIVE_MOVE, 0);
        assert_eq!(x.poll(0), Due::Transmit { fresh: true });
        x.sent(5);
        assert_eq!(
            x.poll(3_005),
            Due::Done(Finish::OutcomeUnknown { sends: 1 })
        );
        // Opting in allows the resends.
        let mut cfg = ExchangeConfig::new(S);
        cfg.resend_unsafe = true;
        let mut x = Exchange::new(cfg, Quarantine::Wait);
        x.start(&catalogue::RELATIVE_MOVE, 0);
        x.poll(0);
        x.sent(5);
        assert_eq!(x.poll(3_005), Due::Transmit { fresh: true });
    }

    #[test]
    fn an_error_reply_finishes_without_a_resend() {
        let mut x = exchange();
        x.start(&catalogue::ABSOLUTE_MOVE, 0);
        x.poll(0);
        x.sent(1);
        let f = frame(b"&99C7446\r\n");
        assert_eq!(x.offer(&f, true, 2), Offer::Rejected(0xC74));
        assert_eq!(x.poll(3), Due::Done(Finish::ErrorReply(0xC74)));
        assert_eq!(x.sends(), 1);
    }

    #[test]
    fn after_a_resend_the_next_command_waits_until_no_stale_reply_can_come() {
        let mut x = exchange();
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        x.poll(0);
        x.sent(0);
        assert_eq!(x.poll(3_000), Due::Transmit { fresh: true });
        x.sent(3_010);
        // The late reply to the first send arrives: taken once.
        let f = frame(b"#992122A\r\n");
        assert_eq!(x.offer(&f, true, 3_020), Offer::Accepted);
        // The reply to the second send may still come until 3,010 + 3,000 + 3,000.
        assert!(x.stale_possible(9_009));
        assert!(!x.stale_possible(9_010));
        x.start(&catalogue::AXIS_STATUS_QUERY, 3_021);
        assert_eq!(x.poll(3_021), Due::WaitUntil(9_010));
        // It arrives meanwhile: stale, never the next command's reply.
        assert_eq!(x.offer(&f, true, 3_500), Offer::Stale);
        assert_eq!(x.poll(9_010), Due::Transmit { fresh: true });
    }

    #[test]
    fn a_broken_reply_is_resent_after_the_turnaround_not_the_timeout() {
        let mut x = exchange();
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        x.poll(0);
        x.sent(100);
        x.reply_lost(150);
        assert_eq!(x.poll(151), Due::WaitUntil(152));
        assert_eq!(x.poll(152), Due::Transmit { fresh: true });
        assert_eq!(x.sends(), 2);
    }

    #[test]
    fn on_the_last_send_a_broken_frame_may_be_an_earlier_sends_late_reply() {
        let mut x = exchange();
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        x.poll(0);
        x.sent(0);
        assert_eq!(x.poll(3_000), Due::Transmit { fresh: true });
        x.sent(3_010);
        // Broken: a late reply to the first send, or the second's? A third
        // send is left: resend after the turnaround.
        x.reply_lost(4_000);
        assert_eq!(x.poll(4_002), Due::Transmit { fresh: true });
        x.sent(4_010);
        // The last send: its timeout stands, and its reply is taken.
        x.reply_lost(4_500);
        assert_eq!(x.poll(4_502), Due::WaitUntil(7_010));
        assert!(x.faulted());
        assert_eq!(
            x.offer(&frame(b"#992122A\r\n"), true, 4_600),
            Offer::Accepted
        );
    }

    #[test]
    fn the_turnaround_is_two_ticks() {
        let mut x = exchange();
        x.start(&catalogue::SERVO_ON_OFF, 0);
        x.poll(0);
        x.sent(0);
        assert_eq!(x.offer(&frame(b"#992322C\r\n"), true, 7), Offer::Accepted);
        x.start(&catalogue::SERVO_ON_OFF, 7);
        assert_eq!(x.poll(8), Due::WaitUntil(9));
        assert_eq!(x.poll(9), Due::Transmit { fresh: true });
    }

    #[test]
    fn software_reset_waits_for_an_error_reply_then_holds_the_line_10_s() {
        let mut x = exchange();
        x.start(&catalogue::SOFTWARE_RESET, 0);
        x.poll(0);
        x.sent(100);
        assert_eq!(x.poll(3_100), Due::Done(Finish::NoReplyExpected));
        assert_eq!(x.sends(), 1);
        x.start(&catalogue::SYSTEM_STATUS_QUERY, 3_100);
        assert_eq!(x.poll(3_100), Due::WaitUntil(10_100));
    }

    #[test]
    fn a_late_error_reply_to_software_reset_is_stale_for_the_next_command() {
        let mut cfg = ExchangeConfig::new(S);
        cfg.late_window_ms = 20_000;
        let mut x = Exchange::new(cfg, Quarantine::Wait);
        x.start(&catalogue::SOFTWARE_RESET, 0);
        x.poll(0);
        x.sent(100);
        assert_eq!(x.poll(3_100), Due::Done(Finish::NoReplyExpected));
        // The next command waits out the late window, not only the restart.
        x.start(&catalogue::SYSTEM_STATUS_QUERY, 3_100);
        assert_eq!(x.poll(10_100), Due::WaitUntil(23_100));
        assert_eq!(x.offer(&frame(b"&99C7446\r\n"), true, 12_000), Offer::Stale);
        assert_eq!(x.poll(23_100), Due::Transmit { fresh: true });
    }

    #[test]
    fn a_command_abandoned_while_it_is_sent_is_quarantined_from_then() {
        let mut x = exchange();
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        x.poll(0);
        x.sent(50);
        x.poll(3_050);
        // The resend is being transmitted when the owner gives up at 4,000.
        assert_eq!(x.poll(3_050), Due::Transmit { fresh: false });
        x.abandon(4_000);
        x.start(&catalogue::AXIS_STATUS_QUERY, 4_000);
        assert_eq!(x.poll(4_000), Due::WaitUntil(10_000));
    }

    #[test]
    fn a_first_command_after_tick_2_31_goes_out_at_once() {
        // A bridge idle since boot sends its first command on day 25.
        for now in [0x8000_0000u32, 0x8000_0001, u32::MAX - 5_000, u32::MAX] {
            let mut x = exchange();
            x.start(&catalogue::AXIS_STATUS_QUERY, now);
            assert_eq!(x.poll(now), Due::Transmit { fresh: true }, "{now:#x}");
        }
    }

    #[test]
    fn holds_set_long_ago_are_over() {
        let mut x = exchange();
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        x.poll(0);
        x.sent(0);
        assert_eq!(x.offer(&frame(b"#992122A\r\n"), true, 10), Offer::Accepted);
        // Idle for 30 days: the turnaround hold at 12 now seems to lie
        // 19 days ahead on the wrapping clock.
        let later = 12u32.wrapping_add(30 * 86_400_000);
        x.start(&catalogue::AXIS_STATUS_QUERY, later);
        assert_eq!(x.poll(later), Due::Transmit { fresh: true });
    }

    #[test]
    fn a_broken_error_reply_to_a_reset_is_not_a_sent_reset() {
        let mut x = exchange();
        x.start(&catalogue::SOFTWARE_RESET, 0);
        x.poll(0);
        x.sent(10);
        x.broken_frame(Some((Header::Error, S, 0x027)), 11);
        assert_eq!(x.poll(13), Due::Done(Finish::OutcomeUnknown { sends: 1 }));
    }

    #[test]
    fn a_duplicate_of_a_late_reply_is_held_back_too() {
        let mut cfg = ExchangeConfig::new(S);
        cfg.duplicate_window_ms = 3_000;
        let mut x = Exchange::new(cfg, Quarantine::Wait);
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        x.poll(0);
        x.sent(0);
        // No reply in time; the resend's reply is taken at 3,050.
        assert_eq!(x.poll(3_000), Due::Transmit { fresh: true });
        x.sent(3_010);
        let f = frame(b"#992122A\r\n");
        assert_eq!(x.offer(&f, true, 3_050), Offer::Accepted);
        // The next command waits for the first send's late reply
        // (3,010 + 3,000 + 3,000).
        x.start(&catalogue::AXIS_STATUS_QUERY, 3_060);
        assert_eq!(x.poll(3_060), Due::WaitUntil(9_010));
        // It comes at 9,000: a copy of it may come until 12,000.
        assert_eq!(x.offer(&f, true, 9_000), Offer::Stale);
        assert_eq!(x.poll(9_010), Due::WaitUntil(12_000));
        assert_eq!(x.offer(&f, true, 11_000), Offer::Stale);
        assert_eq!(x.poll(12_000), Due::WaitUntil(14_000));
        assert_eq!(x.poll(14_000), Due::Transmit { fresh: true });
    }

    #[test]
    fn a_late_reply_to_a_command_with_another_id_holds_back_its_copy() {
        // A 212H is given up; its late reply arrives while a 216H waits,
        // so it is foreign there. A copy of it must not answer the next
        // 212H.
        let mut cfg = ExchangeConfig::new(S);
        cfg.duplicate_window_ms = 3_000;
        let mut x = Exchange::new(cfg, Quarantine::Wait);
        x.start(&catalogue::AXIS_STATUS_QUERY, 0);
        x.poll(0);
        x.sent(0);
        x.abandon(10);
        x.start(&catalogue::ERROR_DETAIL_QUERY, 10);
        assert_eq!(x.poll(10), Due::WaitUntil(6_000));
        let late = frame(b"#992122A\r\n");
        assert_eq!(x.offer(&late, true, 5_000), Offer::Foreign);
        x.abandon(5_000);
        x.start(&catalogue::AXIS_STATUS_QUERY, 5_000);
        // Its copy may come until 5,000 + 3,000.
        assert_eq!(x.poll(5_000), Due::WaitUntil(8_000));
        assert_eq!(x.offer(&late, true, 7_000), Offer::Stale);
        assert_eq!(x.poll(8_000), Due::WaitUntil(10_000));
        assert_eq!(x.poll(10_000), Due::Transmit { fresh: true });
    }

    #[test]
    fn wrong_station_or_id_is_foreign_and_wrong_content_is_a_mismatch() {
        let mut x = exchange();
        x.start(&catalogue::SERVO_ON_OFF, 0);
        x.poll(0);
        x.sent(0);
        assert_eq!(x.offer(&frame(b"#012321B\r\n"), true, 1), Offer::Foreign);
        assert_eq!(x.offer(&frame(b"#992332D\r\n"), true, 1), Offer::Foreign);
        assert_eq!(x.offer(&frame(b"#992322C\r\n"), false, 1), Offer::Mismatch);
        assert!(x.awaiting());
        assert!(x.faulted());
    }
}
