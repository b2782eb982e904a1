//! The streaming frame decoder: push bytes in, get whole frames out.
//!
//! It never blocks and never allocates: it takes whatever bytes the UART
//! produced (one at a time or any slice) and answers [`Status::Partial`]
//! until a frame is complete. Its buffer is a const generic `N` (default
//! [`DEFAULT_CAPACITY`], the TTA's 2,051 bytes); every access is checked.
//!
//! Resynchronisation: bytes before a header byte (`!`, `#`, `&`, `%`) are
//! discarded and counted; a header byte inside a frame (outside a text
//! field) cuts it ([`Error::Truncated`]). A bad checksum, a non-hex digit,
//! a stray CR or LF and an over-long frame are reported once each, with a
//! typed [`Error`], and the next valid frame decodes.
//!
//! Inside a text field every byte is text, header bytes and CR LF
//! included, and a cut 216H reply can announce up to 255 characters: its
//! "text" may swallow the frames that follow it. So when a frame that had
//! a text field fails, the decoder does not drop all of it: it decodes its
//! bytes again from the first header byte after its start, and the valid
//! frames among them come out as if nothing had happened. Those bytes are
//! replayed by the following calls, before any new input: call
//! [`FrameDecoder::decode`] until it answers [`Status::Partial`], even with
//! an empty input.
//!
//! ```
//! use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
//! let mut dec: FrameDecoder = FrameDecoder::new();
//! let mut input: &[u8] = b"noise#992322C\r\n";
//! let mut frames = 0;
//! loop {
//!     let d = dec.decode(input);
//!     input = &input[d.consumed..];
//!     match d.status {
//!         Status::Partial => break,
//!         Status::Complete(Event::Frame(f)) => { assert_eq!(f.as_bytes(), b"#992322C\r\n"); frames += 1 }
//!         Status::Complete(Event::Error(e)) => panic!("{e}"),
//!     }
//! }
//! assert_eq!(frames, 1);
//! assert_eq!(dec.stats().discarded_bytes, 5);
//! ```

use crate::checksum::BypassPolicy;
use crate::error::Error;
use crate::field::move_within;
use crate::frame::{self, Envelope, Frame, Header, Station, ENVELOPE_LEN};
use crate::limits;

mod skip;
pub use skip::{FrameSkipper, Skipped};

/// Default capacity: the largest frame a controller sends or receives
/// ([`limits::LARGEST_FRAME`], the TTA's 2,051-byte receive buffer).
pub const DEFAULT_CAPACITY: usize = limits::LARGEST_FRAME;

/// What a push decoder, or the line, made of the bytes it was given: the
/// one "need more" shape of the crate (the frame and stream decoders, the
/// frame skipper, an engine's `received`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Status<T> {
    /// Every byte given was used and nothing is complete yet: give more.
    Partial,
    /// Something is complete.
    Complete(T),
}

impl<T> Status<T> {
    /// What is complete, if anything.
    pub fn complete(self) -> Option<T> {
        match self {
            Status::Partial => None,
            Status::Complete(t) => Some(t),
        }
    }

    /// Whether nothing is complete yet.
    pub const fn is_partial(&self) -> bool {
        matches!(self, Status::Partial)
    }
}

/// A complete step of frame decoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event<'d> {
    /// A complete, checked frame. It borrows the decoder until the next call.
    Frame(Frame<'d>),
    /// A broken frame was dropped; decoding goes on with the next byte.
    Error(Error),
}

/// The answer of a push decoder (and of an engine's `received`) to a slice
/// of input: how many bytes it used, and what they completed. Feed the rest
/// in the next call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Received<T> {
    /// Bytes of the input consumed.
    pub consumed: usize,
    /// What they completed.
    pub status: Status<T>,
}

/// Counters of what the decoder has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecoderStats {
    /// Valid frames returned.
    pub frames: u32,
    /// Errors reported.
    pub errors: u32,
    /// Bytes thrown away: noise between frames and the bytes of broken frames.
    pub discarded_bytes: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum State {
    /// Looking for a header byte.
    Hunting,
    /// Inside a frame.
    InFrame,
    /// Inside a frame, the last byte was CR.
    SawCr,
    /// A frame was returned; the buffer is cleared on the next byte.
    Done,
}

/// Text fields are located by the time this many bytes are buffered.
const TEXT_PROBE_MAX: usize = crate::catalogue::TEXT_KNOWN_BY;

/// Internal result of one byte, free of borrows.
enum Step {
    More,
    Frame(Envelope),
    Error(Error),
}

/// A push decoder of frames with an `N`-byte buffer.
///
/// Only the buffer depends on `N`: the decoding itself is one
/// non-generic body over a byte slice, so a program with decoders of
/// several capacities carries its code once.
#[derive(Clone)]
pub struct FrameDecoder<const N: usize = DEFAULT_CAPACITY> {
    buf: [u8; N],
    inner: Inner,
}

/// The decoder's state apart from its buffer.
#[derive(Debug, Clone)]
struct Inner {
    len: usize,
    state: State,
    policy: BypassPolicy,
    /// Frame offsets [start, end) of the text field, once known.
    text: Option<(usize, usize)>,
    /// Envelope of the frame last returned (valid while `state == Done`).
    last: Option<Envelope>,
    /// Envelope of the last frame that ended with CR LF but failed its
    /// check (cleared by the next byte).
    failed: Option<(Header, Station, u16)>,
    /// Bytes of a failed text frame still to decode again:
    /// `buf[replay_pos..replay_len]`.
    replay_pos: usize,
    replay_len: usize,
    stats: DecoderStats,
    /// The last frame length at which the text span is looked for: the
    /// largest any message needs until the envelope is read, then the
    /// one its message needs (see [`Inner::store`]).
    probe_until: usize,
    /// The length below which a plain byte (see [`plain`]) is stored
    /// without a step: the buffer's capacity while a frame's body is read
    /// with nothing else to watch (its text span found or known absent,
    /// no bytes waiting to be decoded again), else 0. Set from the fields
    /// above after every step.
    plain_until: usize,
}

impl<const N: usize> core::fmt::Debug for FrameDecoder<N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let i = &self.inner;
        f.debug_struct("FrameDecoder")
            .field("buf", &self.buf)
            .field("len", &i.len)
            .field("state", &i.state)
            .field("policy", &i.policy)
            .field("text", &i.text)
            .field("last", &i.last)
            .field("failed", &i.failed)
            .field("replay_pos", &i.replay_pos)
            .field("replay_len", &i.replay_len)
            .field("stats", &i.stats)
            .finish()
    }
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// A decoder with the default `@@` policy ([`BypassPolicy::CommandsOnly`]).
    pub const fn new() -> Self {
        Self::with_policy(BypassPolicy::CommandsOnly)
    }

    /// A decoder with the given `@@` policy.
    pub const fn with_policy(policy: BypassPolicy) -> Self {
        FrameDecoder {
            buf: [0; N],
            inner: Inner {
                len: 0,
                state: State::Hunting,
                policy,
                text: None,
                last: None,
                failed: None,
                replay_pos: 0,
                replay_len: 0,
                stats: DecoderStats {
                    frames: 0,
                    errors: 0,
                    discarded_bytes: 0,
                },
                probe_until: TEXT_PROBE_MAX,
                plain_until: 0,
            },
        }
    }

    /// The `@@` policy in force.
    pub fn policy(&self) -> BypassPolicy {
        self.inner.policy
    }

    /// Changes the `@@` policy.
    pub fn set_policy(&mut self, policy: BypassPolicy) {
        self.inner.policy = policy;
    }

    /// The buffer capacity (largest frame accepted).
    pub const fn capacity(&self) -> usize {
        N
    }

    /// Counters since creation.
    pub fn stats(&self) -> DecoderStats {
        self.inner.stats
    }

    /// Bytes held: the frame in progress and bytes waiting to be decoded
    /// again after a failed text frame.
    pub fn pending(&self) -> usize {
        self.inner.pending()
    }

    /// The frame returned by the last call, until the next byte is pushed.
    pub fn last_frame(&self) -> Option<Frame<'_>> {
        self.inner.last_frame(&self.buf)
    }

    /// After an [`Event::Error`] for a frame that ended with CR LF but
    /// failed its check (checksum, digits, layout of the envelope), or that
    /// outgrew the buffer: its header, station and code, if they could be
    /// read. An engine awaiting a reply uses this to tell "my reply arrived
    /// broken" from noise.
    pub fn failed_envelope(&self) -> Option<(Header, Station, u16)> {
        self.inner.failed
    }

    /// Drops any partial frame and bytes waiting to be decoded again
    /// (counted as discarded) and starts hunting.
    pub fn reset(&mut self) {
        self.inner.reset();
    }

    /// Pushes one byte. If bytes of a failed text frame are waiting to be
    /// decoded again, `byte` joins them and they come first; call
    /// `decode(&[])` until [`Status::Partial`] to drain them.
    #[inline]
    pub fn push(&mut self, byte: u8) -> Status<Event<'_>> {
        if self.inner.store_plain(&mut self.buf, byte) {
            return Status::Partial;
        }
        let outcome = self.inner.push(&mut self.buf, byte);
        self.event(outcome)
    }

    /// Consumes bytes from `input` until a frame or an error is ready or
    /// the input is used up. Call again with the rest of the input until
    /// it answers [`Status::Partial`] (bytes being decoded again after a
    /// failed text frame come out before new input, with `consumed` 0).
    pub fn decode(&mut self, input: &[u8]) -> Received<Event<'_>> {
        let (consumed, outcome) = self.inner.decode(&mut self.buf, input);
        Received {
            consumed,
            status: self.event(outcome),
        }
    }

    fn event(&self, outcome: Step) -> Status<Event<'_>> {
        self.inner.event(&self.buf, outcome)
    }

    /// The buffer, for an owner that lends it out between frames (a
    /// transfer's frame buffer is its decoder's while no transfer runs).
    /// It resets the decoder: the frame in progress is dropped.
    pub(crate) fn take_buffer(&mut self) -> &mut [u8; N] {
        self.inner.reset();
        &mut self.buf
    }

    /// The buffer as it is, for the owner that took it with
    /// [`FrameDecoder::take_buffer`] and has not decoded since.
    pub(crate) fn buffer(&mut self) -> &mut [u8; N] {
        &mut self.buf
    }

    /// [`FrameDecoder::buffer`], to read.
    pub(crate) fn buffer_ref(&self) -> &[u8; N] {
        &self.buf
    }
}

impl Inner {
    fn event<'b>(&self, buf: &'b [u8], outcome: Step) -> Status<Event<'b>> {
        match outcome {
            Step::More => Status::Partial,
            Step::Frame(env) => {
                let bytes = buf.get(..self.len).unwrap_or(&[]);
                Status::Complete(Event::Frame(Frame::from_parts(bytes, env)))
            }
            Step::Error(e) => Status::Complete(Event::Error(e)),
        }
    }

    fn pending(&self) -> usize {
        let frame = match self.state {
            State::Done | State::Hunting => 0,
            _ => self.len,
        };
        frame + self.replay_len.saturating_sub(self.replay_pos)
    }

    fn last_frame<'b>(&self, buf: &'b [u8]) -> Option<Frame<'b>> {
        if self.state != State::Done {
            return None;
        }
        let bytes = buf.get(..self.len)?;
        self.last.map(|env| Frame::from_parts(bytes, env))
    }

    fn reset(&mut self) {
        self.discard(self.pending());
        self.len = 0;
        self.replay_pos = 0;
        self.replay_len = 0;
        self.state = State::Hunting;
        self.plain_until = 0;
    }

    /// Stores `byte` if it is plain and the frame's body is being read
    /// with nothing else to watch: the whole of a [`Inner::step`] for such
    /// a byte, in a few instructions. `false` if the byte needs the step.
    #[inline(always)]
    fn store_plain(&mut self, buf: &mut [u8], byte: u8) -> bool {
        if self.len < self.plain_until && plain(byte) {
            if let Some(slot) = buf.get_mut(self.len) {
                *slot = byte;
                self.len += 1;
                return true;
            }
        }
        false
    }

    /// [`Inner::store_plain`] for the leading plain bytes of `input`, as
    /// many as the buffer takes: a run of a body copied in one loop.
    /// Returns how many it stored.
    fn store_run(&mut self, buf: &mut [u8], input: &[u8]) -> usize {
        let end = self.plain_until.min(buf.len());
        let Some(room) = buf.get_mut(self.len..end) else {
            return 0;
        };
        let mut n = 0;
        for (slot, &b) in room.iter_mut().zip(input) {
            if !plain(b) {
                break;
            }
            *slot = b;
            n += 1;
        }
        self.len += n;
        n
    }

    /// Sets `plain_until` from the state (see its docs).
    fn watch(&mut self, capacity: usize) {
        let body = self.state == State::InFrame
            && self.replay_pos >= self.replay_len
            && self.failed.is_none()
            && (self.text.is_some() || self.len >= self.probe_until);
        self.plain_until = if body { capacity } else { 0 };
    }

    fn push(&mut self, buf: &mut [u8], byte: u8) -> Step {
        if self.replay_pos < self.replay_len {
            match buf.get_mut(self.replay_len) {
                Some(slot) => {
                    *slot = byte;
                    self.replay_len += 1;
                }
                // Cannot happen: a replayed region is shorter than the buffer.
                None => self.discard(1),
            }
            self.replay(buf)
        } else {
            self.step(buf, byte)
        }
    }

    fn decode(&mut self, buf: &mut [u8], input: &[u8]) -> (usize, Step) {
        let mut consumed = 0;
        let mut outcome = self.replay(buf);
        if matches!(outcome, Step::More) {
            while let Some(&b) = input.get(consumed) {
                let run = self.store_run(buf, input.get(consumed..).unwrap_or(&[]));
                if run > 0 {
                    consumed += run;
                    continue;
                }
                consumed += 1;
                outcome = self.step(buf, b);
                if !matches!(outcome, Step::More) {
                    break;
                }
            }
        }
        (consumed, outcome)
    }

    /// Steps the bytes waiting to be decoded again until an event.
    fn replay(&mut self, buf: &mut [u8]) -> Step {
        while self.replay_pos < self.replay_len {
            let Some(&b) = buf.get(self.replay_pos) else {
                break;
            };
            self.replay_pos += 1;
            let outcome = self.step(buf, b);
            if !matches!(outcome, Step::More) {
                return outcome;
            }
        }
        self.replay_pos = 0;
        self.replay_len = 0;
        self.watch(buf.len());
        Step::More
    }

    fn discard(&mut self, n: usize) {
        let n = u32::try_from(n).unwrap_or(u32::MAX);
        self.stats.discarded_bytes = self.stats.discarded_bytes.saturating_add(n);
    }

    fn fail(&mut self, e: Error, dropped: usize) -> Step {
        self.discard(dropped);
        self.stats.errors = self.stats.errors.saturating_add(1);
        Step::Error(e)
    }

    /// The frame in `buf[..len]` failed. If it had a text field and a header
    /// byte follows its start, sets its bytes from there (and `extra`, the
    /// byte that broke it, if it was not stored) up to be decoded again,
    /// ahead of any bytes still waiting; `true` if it did.
    fn recover(&mut self, buf: &mut [u8], e: Error, extra: Option<u8>) -> Option<Step> {
        self.text?;
        let frame = buf.get(1..self.len)?;
        let p = 1 + frame.iter().position(|&b| Header::from_byte(b).is_some())?;
        let kept = self.len - p;
        // Waiting bytes follow the failed frame's: move them up first.
        let waiting = self.replay_len.saturating_sub(self.replay_pos);
        let extra_len = usize::from(extra.is_some());
        let total = kept + extra_len + waiting;
        // Never holds (equivalent mutants): the header lies 6+ bytes in, and the frame trails the replay cursor.
        if total > buf.len() || (waiting > 0 && self.replay_pos < self.len) {
            return None;
        }
        // The failed frame's bytes first: the waiting ones land where they
        // were (`kept + extra_len <= len <= replay_pos`).
        let moved = move_within(buf, p, kept, 0)
            && move_within(buf, self.replay_pos, waiting, kept + extra_len);
        if !moved {
            return None;
        }
        if let (Some(x), Some(slot)) = (extra, buf.get_mut(kept)) {
            *slot = x;
        }
        self.replay_pos = 0;
        self.replay_len = total;
        self.len = 0;
        self.state = State::Hunting;
        Some(self.fail(e, p))
    }

    fn start(&mut self, buf: &mut [u8], byte: u8) {
        if let Some(slot) = buf.first_mut() {
            *slot = byte;
            self.len = 1;
            self.state = State::InFrame;
            self.text = None;
            self.probe_until = TEXT_PROBE_MAX;
        } else {
            // N == 0: nothing can ever be buffered.
            self.len = 0;
            self.state = State::Hunting;
            self.discard(1);
        }
    }

    /// Appends a byte of the frame in progress; `false` if the buffer is full.
    ///
    /// The text span is looked for at every length from the envelope's
    /// to the one at which the frame's message can first locate it
    /// ([`probe_until`]); after that the answer cannot change, and a
    /// message without a text field is not looked for at all.
    fn store(&mut self, buf: &mut [u8], byte: u8) -> bool {
        match buf.get_mut(self.len) {
            Some(slot) => {
                *slot = byte;
                self.len += 1;
                if self.len == ENVELOPE_LEN {
                    self.probe_until = probe_until(buf.get(..ENVELOPE_LEN).unwrap_or(&[]));
                }
                // Finding the span again finds the same one: `||` here is an equivalent mutant.
                if self.text.is_none() && (ENVELOPE_LEN..=self.probe_until).contains(&self.len) {
                    let head = buf.first().copied().and_then(Header::from_byte);
                    let prefix = buf.get(..self.len).unwrap_or(&[]);
                    self.text = head.and_then(|h| crate::catalogue::text_span(h, prefix));
                }
                true
            }
            None => false,
        }
    }

    /// One byte through the state machine; then what the next plain
    /// bytes may skip.
    fn step(&mut self, buf: &mut [u8], byte: u8) -> Step {
        let outcome = self.step_byte(buf, byte);
        self.watch(buf.len());
        outcome
    }

    fn step_byte(&mut self, buf: &mut [u8], byte: u8) -> Step {
        self.failed = None;
        if self.state == State::Done {
            self.len = 0;
            self.state = State::Hunting;
        }
        let is_header = Header::from_byte(byte).is_some();
        match self.state {
            State::Hunting | State::Done => {
                if is_header {
                    self.start(buf, byte);
                } else {
                    self.discard(1);
                }
                Step::More
            }
            State::InFrame => {
                let in_text = self
                    .text
                    .is_some_and(|(s, e)| self.len >= s && self.len < e);
                if is_header && !in_text {
                    let cut = self.len;
                    let e = Error::Truncated { len: cut };
                    if let Some(step) = self.recover(buf, e, Some(byte)) {
                        return step;
                    }
                    self.start(buf, byte);
                    return self.fail(e, cut);
                }
                if byte == b'\n' && !in_text {
                    if let Some(step) = self.recover(buf, Error::MissingCarriageReturn, Some(byte))
                    {
                        return step;
                    }
                    let dropped = self.len + 1;
                    self.state = State::Hunting;
                    return self.fail(Error::MissingCarriageReturn, dropped);
                }
                if byte == b'\r' && !in_text {
                    self.state = State::SawCr;
                }
                self.store_or_overflow(buf, byte)
            }
            State::SawCr => {
                if byte == b'\n' {
                    if let Step::Error(e) = self.store_or_overflow(buf, byte) {
                        return Step::Error(e);
                    }
                    let bytes = buf.get(..self.len).unwrap_or(&[]);
                    match frame::validate(bytes, self.policy) {
                        Ok(env) => {
                            self.state = State::Done;
                            self.last = Some(env);
                            self.stats.frames = self.stats.frames.saturating_add(1);
                            Step::Frame(env)
                        }
                        Err(e) => {
                            self.failed = frame::read_envelope(bytes);
                            if let Some(step) = self.recover(buf, e, None) {
                                return step;
                            }
                            self.state = State::Hunting;
                            self.fail(e, self.len)
                        }
                    }
                } else {
                    let e = Error::MissingLineFeed { byte };
                    if let Some(step) = self.recover(buf, e, Some(byte)) {
                        return step;
                    }
                    if is_header {
                        let dropped = self.len;
                        self.start(buf, byte);
                        self.fail(e, dropped)
                    } else {
                        let dropped = self.len + 1;
                        self.state = State::Hunting;
                        self.fail(e, dropped)
                    }
                }
            }
        }
    }

    fn store_or_overflow(&mut self, buf: &mut [u8], byte: u8) -> Step {
        if self.store(buf, byte) {
            Step::More
        } else {
            // What it was can still be told by its envelope.
            self.failed = frame::read_envelope(buf);
            let e = Error::FrameTooLong { limit: buf.len() };
            if let Some(step) = self.recover(buf, e, Some(byte)) {
                return step;
            }
            let dropped = self.len + 1;
            self.state = State::Hunting;
            self.fail(e, dropped)
        }
    }
}

/// Whether `byte` is plain: neither a header byte nor CR nor LF, so that
/// inside a frame's body, text or not, it is only stored.
#[inline(always)]
fn plain(byte: u8) -> bool {
    // Every byte that is not plain is below `'\''`: one comparison for
    // the digits of a body.
    byte > b'&' || !(Header::from_byte(byte).is_some() || byte == b'\r' || byte == b'\n')
}

// No header byte lies above `'&'`, as [`plain`] takes for granted.
const _: () = {
    let mut b = b'&';
    while b < u8::MAX {
        b += 1;
        assert!(Header::from_byte(b).is_none());
    }
};

/// The last frame length at which the text span of the frame whose
/// envelope is `envelope` is looked for, or 0 if it has none: where
/// [`text_span`](crate::catalogue::text_span) first locates it, the span's
/// start (a fixed span is located from the envelope, a counted one once
/// its count, the two digits before its start, has come). Found by asking
/// `text_span` of the envelope followed by `'0'` digits, a count of 0: the
/// decoder then links only the catalogue's text table, as the frame check
/// does, not the whole catalogue (about 4 KB of flash on a Cortex-M0+).
fn probe_until(envelope: &[u8]) -> usize {
    let mut prefix = [b'0'; TEXT_PROBE_MAX];
    let head = envelope.first().copied().and_then(Header::from_byte);
    match (
        head,
        prefix.get_mut(..ENVELOPE_LEN),
        envelope.get(..ENVELOPE_LEN),
    ) {
        (Some(head), Some(dst), Some(src)) => {
            dst.copy_from_slice(src);
            crate::catalogue::text_span(head, &prefix)
                .map_or(0, |(start, _)| start.clamp(ENVELOPE_LEN, TEXT_PROBE_MAX))
        }
        _ => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every event of `input` fed in one piece, as `(frame bytes | error)`.
    fn events<const N: usize>(
        dec: &mut FrameDecoder<N>,
        mut input: &[u8],
    ) -> Vec<Result<Vec<u8>, Error>> {
        let mut out = Vec::new();
        loop {
            let d = dec.decode(input);
            input = &input[d.consumed..];
            match d.status {
                Status::Partial => return out,
                Status::Complete(Event::Frame(f)) => out.push(Ok(f.as_bytes().to_vec())),
                Status::Complete(Event::Error(e)) => out.push(Err(e)),
            }
        }
    }

    extern crate std;
    use std::vec::Vec;

    const SERVO_REPLY: &[u8] = b"#992322C\r\n";

    /// A decoder keeps its `@@` policy: `#99232@@` (a 232H reply with `@@`
    /// for its SC) passes only where responses may carry `@@`.
    #[test]
    fn a_decoder_keeps_its_bypass_policy() {
        let reply: &[u8] = b"#99232@@\r\n";
        let decode = |dec: &mut FrameDecoder<16>| {
            dec.decode(reply)
                .status
                .map_frame(|f| f.as_bytes().to_vec())
        };
        let mut dec = FrameDecoder::<16>::default();
        assert_eq!(dec.policy(), BypassPolicy::CommandsOnly);
        assert_eq!(decode(&mut dec), Err(Some(Error::ChecksumBypassRejected)));
        dec.set_policy(BypassPolicy::Accept);
        assert_eq!(dec.policy(), BypassPolicy::Accept);
        assert_eq!(decode(&mut dec), Ok(reply.to_vec()));
        let mut dec = FrameDecoder::<16>::with_policy(BypassPolicy::Accept);
        assert_eq!(decode(&mut dec), Ok(reply.to_vec()));
        assert_eq!(dec.stats().frames, 1);
        dec.set_policy(BypassPolicy::Reject);
        assert_eq!(decode(&mut dec), Err(Some(Error::ChecksumBypassRejected)));
    }

    /// A buffer taken by its owner drops the frame in progress (counted as
    /// discarded); the decoder then decodes in it again from scratch.
    #[test]
    fn a_taken_buffer_drops_the_frame_in_progress() {
        let mut dec = FrameDecoder::<16>::new();
        assert_eq!(dec.decode(b"!992").status, Status::Partial);
        assert_eq!(dec.pending(), 4);
        dec.take_buffer().fill(b'%');
        assert_eq!(dec.pending(), 0);
        assert_eq!(dec.stats().discarded_bytes, 4);
        let d = dec.decode(SERVO_REPLY);
        assert_eq!(d.consumed, SERVO_REPLY.len());
        assert_eq!(
            d.status.map_frame(|f| f.as_bytes().to_vec()),
            Ok(SERVO_REPLY.to_vec())
        );
    }

    /// `{:?}` of a decoder shows its buffer and state: after `!9` of a
    /// frame, two bytes held and the rest of the buffer still zero.
    #[test]
    fn a_frame_decoder_debugs_as_its_buffer_and_state() {
        let mut dec: FrameDecoder<4> = FrameDecoder::new();
        assert_eq!(dec.decode(b"!9").status, Status::Partial);
        let shown = std::format!("{dec:?}");
        assert!(
            shown.starts_with("FrameDecoder { buf: [33, 57, 0, 0], len: 2, state: InFrame, "),
            "{shown}"
        );
        assert!(
            shown.ends_with(
                "replay_pos: 0, replay_len: 0, stats: DecoderStats { frames: 0, errors: 0, discarded_bytes: 0 } }"
            ),
            "{shown}"
        );
    }

    impl<'d> Status<Event<'d>> {
        /// `Ok(frame)`, `Err(Some(error))` or `Err(None)` (need more).
        fn map_frame<T>(self, f: impl FnOnce(Frame<'d>) -> T) -> Result<T, Option<Error>> {
            match self {
                Status::Partial => Err(None),
                Status::Complete(Event::Frame(fr)) => Ok(f(fr)),
                Status::Complete(Event::Error(e)) => Err(Some(e)),
            }
        }
    }

    /// The text span is looked for up to its start where the catalogue
    /// gives the message one for that header (fixed: commands and
    /// replies; counted: replies), and not at all otherwise.
    #[test]
    fn the_text_span_is_looked_for_up_to_where_its_message_has_it() {
        use crate::catalogue::{TextField, ALL};
        for m in ALL {
            for header in [Header::Command, Header::Response, Header::Error] {
                let env = std::format!("{}99{:03X}", header.byte() as char, m.id);
                let want = match (m.text, header) {
                    (Some(TextField::Fixed { start, .. }), Header::Command | Header::Response) => {
                        start
                    }
                    (Some(TextField::CountedInResponse { start }), Header::Response) => start,
                    _ => 0,
                };
                assert_eq!(probe_until(env.as_bytes()), want, "{env}");
            }
        }
        assert_eq!(probe_until(b"!99G00"), 0, "a code that is not hex");
    }

    #[test]
    fn golden_frame_after_noise() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        assert_eq!(
            events(&mut dec, b"xx#992322C\r\n"),
            [Ok(SERVO_REPLY.to_vec())]
        );
        assert_eq!(dec.stats().discarded_bytes, 2);
        assert_eq!(dec.stats().frames, 1);
    }

    #[test]
    fn a_cut_216h_reply_announcing_255_characters_does_not_swallow_what_follows() {
        // A 216H reply cut at 95 bytes whose message count is FF: its "text"
        // would run over the next 255 bytes, 21 valid frames among them.
        let mut cut = b"#99216".to_vec();
        cut.extend_from_slice(&[b'0'; 82]);
        cut.extend_from_slice(b"FF");
        cut.extend_from_slice(b"ABCDE");
        assert_eq!(cut.len(), 95);
        // 26 replies: the text span (90..345) takes the first 25, and the
        // 26th's header, just after it, shows the 216H frame was cut.
        let mut input = cut.clone();
        for _ in 0..26 {
            input.extend_from_slice(SERVO_REPLY);
        }
        let mut dec: FrameDecoder = FrameDecoder::new();
        let got = events(&mut dec, &input);
        assert_eq!(got.first(), Some(&Err(Error::Truncated { len: 345 })));
        let frames: Vec<_> = got.iter().filter(|e| e.is_ok()).collect();
        assert_eq!(frames.len(), 26, "{got:?}");
        assert!(frames.iter().all(|f| f.as_deref() == Ok(SERVO_REPLY)));
        // Every byte is accounted for: in a frame, discarded, or held.
        let s = dec.stats();
        assert_eq!(s.discarded_bytes, 95);
        assert_eq!(dec.pending(), 0);
    }

    #[test]
    fn the_same_stream_byte_by_byte_gives_the_same_frames() {
        let mut input = b"#99216".to_vec();
        input.extend_from_slice(&[b'0'; 82]);
        input.extend_from_slice(b"0A");
        input.extend_from_slice(SERVO_REPLY);
        input.extend_from_slice(b"!99215\r\n");
        input.extend_from_slice(SERVO_REPLY);
        let mut whole: FrameDecoder = FrameDecoder::new();
        let expected = events(&mut whole, &input);
        let mut bytewise: FrameDecoder = FrameDecoder::new();
        let mut got = Vec::new();
        for &b in &input {
            match bytewise.push(b) {
                Status::Partial => {}
                Status::Complete(Event::Frame(f)) => got.push(Ok(f.as_bytes().to_vec())),
                Status::Complete(Event::Error(e)) => got.push(Err(e)),
            }
            got.extend(events(&mut bytewise, &[]));
        }
        assert_eq!(got, expected);
        let servo = Ok(SERVO_REPLY.to_vec());
        assert_eq!(
            expected,
            [
                Err(Error::Truncated { len: 100 }),
                servo.clone(),
                Err(Error::FrameTooShort { len: 8 }),
                servo
            ]
        );
    }

    #[test]
    fn a_bad_200h_does_not_take_the_next_frame_with_it() {
        // The test string holds a header byte and the frame's SC is wrong;
        // the valid reply inside it must still come out.
        let input = b"!99200AB#992322C\r\n";
        let mut dec: FrameDecoder = FrameDecoder::new();
        let got = events(&mut dec, input);
        assert!(got.contains(&Ok(SERVO_REPLY.to_vec())), "{got:?}");
    }
}

#[cfg(test)]
mod golden {
    use super::*;
    use crate::checksum::{Checksum, ChecksumField};
    use crate::frame::{Header, Station};

    /// 2003 p. 10: a 209H query and its checksum.
    const P10: &[u8] = b"!9920900100554\r\n";
    /// A 232H response without data.
    const R232: &[u8] = b"#992322C\r\n";

    /// `head` + its SC + CR LF, in `buf`; the frame's length.
    fn framed(head: &[u8], buf: &mut [u8; 128]) -> usize {
        let n = head.len();
        buf[..n].copy_from_slice(head);
        let sc = Checksum::of(head);
        let hex = b"0123456789ABCDEF";
        buf[n..n + 4].copy_from_slice(&[
            hex[usize::from(sc >> 4)],
            hex[usize::from(sc & 0xF)],
            b'\r',
            b'\n',
        ]);
        n + 4
    }

    /// Feeds `input` whole, collecting up to 8 events (frames as their
    /// lengths) and the bytes consumed by each call.
    fn events<const N: usize>(
        dec: &mut FrameDecoder<N>,
        mut input: &[u8],
    ) -> ([Option<Result<usize, Error>>; 8], usize) {
        let mut out = [None; 8];
        let mut k = 0;
        while !input.is_empty() {
            let d = dec.decode(input);
            assert!(d.consumed >= 1 && d.consumed <= input.len());
            input = &input[d.consumed..];
            let ev = match d.status {
                Status::Partial => {
                    assert!(input.is_empty(), "Partial with input left");
                    break;
                }
                Status::Complete(Event::Frame(f)) => Ok(f.len()),
                Status::Complete(Event::Error(e)) => Err(e),
            };
            out[k] = Some(ev);
            k += 1;
        }
        (out, k)
    }

    #[test]
    fn one_frame_byte_by_byte() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        assert_eq!(dec.capacity(), DEFAULT_CAPACITY);
        let (last, head) = P10.split_last().unwrap();
        for (i, &b) in head.iter().enumerate() {
            assert_eq!(dec.push(b), Status::Partial);
            assert_eq!(dec.pending(), i + 1);
            assert_eq!(dec.last_frame(), None);
        }
        match dec.push(*last) {
            Status::Complete(Event::Frame(f)) => {
                assert_eq!(f.as_bytes(), P10);
                assert_eq!(f.station(), Station(0x99));
                assert_eq!(f.code(), 0x209);
                assert_eq!(f.body(), b"001005");
                assert_eq!(f.checksum(), ChecksumField::Sum(0x54));
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(dec.pending(), 0);
        assert_eq!(dec.last_frame().map(|f| f.len()), Some(P10.len()));
        assert_eq!(
            dec.stats(),
            DecoderStats {
                frames: 1,
                errors: 0,
                discarded_bytes: 0
            }
        );
        // The next byte clears the frame.
        assert_eq!(dec.push(b'x'), Status::Partial);
        assert_eq!(dec.last_frame(), None);
        assert_eq!(dec.stats().discarded_bytes, 1);
    }

    #[test]
    fn frames_back_to_back_after_noise() {
        let mut input = [0u8; 64];
        let parts: [&[u8]; 4] = [b"\r\nxyz", P10, R232, P10];
        let mut n = 0;
        for p in parts {
            input[n..n + p.len()].copy_from_slice(p);
            n += p.len();
        }
        let mut dec: FrameDecoder = FrameDecoder::default();
        let d = dec.decode(&input[..n]);
        assert_eq!(d.consumed, 5 + P10.len());
        assert!(matches!(d.status, Status::Complete(Event::Frame(f)) if f.as_bytes() == P10));
        let (ev, k) = events(&mut dec, &input[5 + P10.len()..n]);
        assert_eq!(k, 2);
        assert_eq!(ev[0], Some(Ok(R232.len())));
        assert_eq!(ev[1], Some(Ok(P10.len())));
        assert_eq!(dec.stats().frames, 3);
        assert_eq!(dec.stats().discarded_bytes, 5);
        assert_eq!(dec.stats().errors, 0);
    }

    #[test]
    fn a_header_inside_a_frame_cuts_it() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, k) = events(&mut dec, b"!99209001#992322C\r\n");
        assert_eq!(k, 2);
        assert_eq!(ev[0], Some(Err(Error::Truncated { len: 9 })));
        assert_eq!(ev[1], Some(Ok(R232.len())));
        assert_eq!(
            dec.stats(),
            DecoderStats {
                frames: 1,
                errors: 1,
                discarded_bytes: 9
            }
        );
        for h in [b'!', b'&', b'%'] {
            let mut dec: FrameDecoder = FrameDecoder::new();
            let (ev, _) = events(&mut dec, &[b'#', b'9', h]);
            assert_eq!(ev[0], Some(Err(Error::Truncated { len: 2 })));
            assert_eq!(dec.pending(), 1, "the new header starts a frame");
        }
    }

    #[test]
    fn line_end_errors() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, k) = events(&mut dec, b"!99209\n");
        assert_eq!((ev[0], k), (Some(Err(Error::MissingCarriageReturn)), 1));
        assert_eq!(dec.stats().discarded_bytes, 7);
        assert_eq!(dec.pending(), 0);

        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, _) = events(&mut dec, b"!99209\rX");
        assert_eq!(ev[0], Some(Err(Error::MissingLineFeed { byte: b'X' })));
        assert_eq!(dec.stats().discarded_bytes, 8);
        assert_eq!(dec.pending(), 0);

        // CR then a header byte: the header starts the next frame.
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, k) = events(&mut dec, b"!99209\r#992322C\r\n");
        assert_eq!(k, 2);
        assert_eq!(ev[0], Some(Err(Error::MissingLineFeed { byte: b'#' })));
        assert_eq!(ev[1], Some(Ok(R232.len())));
        assert_eq!(dec.stats().discarded_bytes, 7);
        assert_eq!(dec.stats().errors, 1);
    }

    #[test]
    fn checks_of_the_whole_frame() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, k) = events(&mut dec, b"!9920900100555\r\n#992322C\r\n");
        assert_eq!(k, 2);
        assert_eq!(
            ev[0],
            Some(Err(Error::ChecksumMismatch {
                computed: 0x54,
                received: 0x55
            }))
        );
        assert_eq!(ev[1], Some(Ok(R232.len())));
        assert_eq!(dec.stats().discarded_bytes, 16);

        let (ev, _) = events(&mut dec, b"!99\r\n");
        assert_eq!(ev[0], Some(Err(Error::FrameTooShort { len: 5 })));
        let (ev, _) = events(&mut dec, b"!992090010G554\r\n");
        assert_eq!(
            ev[0],
            Some(Err(Error::InvalidHexDigit {
                offset: 10,
                byte: b'G'
            }))
        );
        assert_eq!(dec.stats().errors, 3);
    }

    #[test]
    fn bypass_policy() {
        let bypass: &[u8] = b"!992000123456789@@\r\n";
        let mut dec: FrameDecoder = FrameDecoder::new();
        assert_eq!(dec.policy(), BypassPolicy::CommandsOnly);
        let (ev, _) = events(&mut dec, bypass);
        assert_eq!(ev[0], Some(Ok(bypass.len())));
        dec.set_policy(BypassPolicy::Reject);
        assert_eq!(dec.policy(), BypassPolicy::Reject);
        let (ev, _) = events(&mut dec, bypass);
        assert_eq!(ev[0], Some(Err(Error::ChecksumBypassRejected)));
        let mut dec: FrameDecoder = FrameDecoder::with_policy(BypassPolicy::Accept);
        let (ev, _) = events(&mut dec, b"#99232@@\r\n");
        assert_eq!(ev[0], Some(Ok(10)));
    }

    #[test]
    fn text_fields_may_hold_any_byte() {
        // 200H: ten raw characters, here header bytes, CR and LF.
        let mut buf = [0u8; 128];
        let n = framed(b"!99200!#&%\r\n\r\nAB", &mut buf);
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, k) = events(&mut dec, &buf[..n]);
        assert_eq!((ev[0], k), (Some(Ok(n)), 1));
        assert_eq!(
            dec.last_frame().map(|f| f.body()),
            Some(&b"!#&%\r\n\r\nAB"[..])
        );

        // 216H response: the message length is known at offset 90.
        // The recorded 94-byte response (fixture `ex5-216H-response-94-bytes`) up to its message
        // count, then a 5-character message.
        let recorded = b"#99216C74000000010000000500000002FFFFFFFD0000000000000000000000000000000000000000000000000C2";
        let mut msg = [0u8; 95];
        msg[..88].copy_from_slice(&recorded[..88]);
        msg[88..].copy_from_slice(b"05!\r\n#%");
        let n = framed(&msg, &mut buf);
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, k) = events(&mut dec, &buf[..n]);
        assert_eq!((ev[0], k), (Some(Ok(n)), 1));

        // After the text a header byte cuts the frame again.
        let mut msg = [0u8; 96];
        msg[..95].copy_from_slice(&buf[..95]);
        msg[95] = b'!';
        let (ev, _) = events(&mut dec, &msg);
        assert_eq!(ev[0], Some(Err(Error::Truncated { len: 95 })));
    }

    #[test]
    fn a_frame_longer_than_the_buffer() {
        let mut dec: FrameDecoder<12> = FrameDecoder::new();
        assert_eq!(dec.capacity(), 12);
        let (ev, k) = events(&mut dec, b"!9920900100554\r\n#992322C\r\n");
        assert_eq!(ev[0], Some(Err(Error::FrameTooLong { limit: 12 })));
        assert_eq!(ev[1], Some(Ok(R232.len())));
        assert_eq!(k, 2);
        assert_eq!(dec.stats().discarded_bytes, 16);
        // Exactly the capacity fits.
        let mut dec: FrameDecoder<10> = FrameDecoder::new();
        let (ev, _) = events(&mut dec, R232);
        assert_eq!(ev[0], Some(Ok(10)));
        let mut dec: FrameDecoder<9> = FrameDecoder::new();
        let (ev, _) = events(&mut dec, R232);
        assert_eq!(ev[0], Some(Err(Error::FrameTooLong { limit: 9 })));
    }

    #[test]
    fn the_envelope_of_a_frame_that_failed_its_check() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, _) = events(&mut dec, b"!9920900100555\r\n");
        assert!(matches!(ev[0], Some(Err(Error::ChecksumMismatch { .. }))));
        assert_eq!(
            dec.failed_envelope(),
            Some((Header::Command, Station(0x99), 0x209))
        );
        assert_eq!(dec.push(b'x'), Status::Partial);
        assert_eq!(dec.failed_envelope(), None, "forgotten at the next byte");
        // An unreadable envelope, and errors before CR LF, leave nothing.
        for bad in [&b"!9G209001005@@\r\n"[..], b"#99232\r\r", b"#99232\n"] {
            let mut dec: FrameDecoder = FrameDecoder::new();
            let (ev, _) = events(&mut dec, bad);
            assert!(matches!(ev[0], Some(Err(_))), "{bad:?}");
            assert_eq!(dec.failed_envelope(), None, "{bad:?}");
        }
    }

    /// A 200H whose ten text characters swallow the start of a valid reply
    /// fails; the reply is decoded again from its header byte.
    const SWALLOWED: &[u8] = b"!99200AB#992322C\r\n";

    #[test]
    fn a_swallowed_reply_is_decoded_again_and_counted_as_pending() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let d = dec.decode(SWALLOWED);
        assert_eq!(d.consumed, SWALLOWED.len());
        assert_eq!(
            d.status,
            Status::Complete(Event::Error(Error::BodyTooShort { offset: 14 }))
        );
        assert_eq!(
            dec.pending(),
            R232.len(),
            "the reply waits to be decoded again"
        );
        assert_eq!(dec.stats().discarded_bytes, 8);
        let d = dec.decode(b"");
        assert_eq!(d.consumed, 0);
        assert!(matches!(d.status, Status::Complete(Event::Frame(f)) if f.as_bytes() == R232));
        assert_eq!(dec.pending(), 0);
        assert_eq!(dec.decode(b"").status, Status::Partial);
    }

    #[test]
    fn a_pushed_byte_joins_the_bytes_decoded_again() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (last, head) = SWALLOWED.split_last().unwrap();
        for &b in head {
            assert_eq!(dec.push(b), Status::Partial);
        }
        assert_eq!(
            dec.push(*last),
            Status::Complete(Event::Error(Error::BodyTooShort { offset: 14 }))
        );
        // The next byte comes after the waiting reply, which comes out first.
        assert!(
            matches!(dec.push(b'!'), Status::Complete(Event::Frame(f)) if f.as_bytes() == R232)
        );
        assert_eq!(dec.decode(b"").status, Status::Partial);
        assert_eq!(dec.pending(), 1, "the '!' starts the next frame");
        let (ev, _) = events(&mut dec, b"99209001005@@\r\n");
        assert_eq!(ev[0], Some(Ok(16)));
    }

    #[test]
    fn a_reply_swallowed_twice_still_comes_out() {
        // The first 200H's text holds a second 200H whose text holds the
        // reply's start.
        let input = b"!99200AB!99200CD#992322C\r\n";
        let mut dec: FrameDecoder = FrameDecoder::new();
        let (ev, k) = events(&mut dec, input);
        assert_eq!(k, 2, "{ev:?}");
        assert_eq!(ev[0], Some(Err(Error::Truncated { len: 16 })));
        assert_eq!(ev[1], Some(Err(Error::BodyTooShort { offset: 14 })));
        // The reply waits to be decoded again.
        assert_eq!(dec.pending(), R232.len());
        assert!(
            matches!(dec.decode(b"").status, Status::Complete(Event::Frame(f)) if f.as_bytes() == R232)
        );
        assert_eq!(dec.decode(b"").status, Status::Partial);
        assert_eq!(dec.stats().frames, 1);
        assert_eq!(dec.pending(), 0);
        // Every byte is accounted for: in the frame or discarded.
        assert_eq!(
            dec.stats().discarded_bytes as usize,
            input.len() - R232.len()
        );
        // The same byte by byte.
        let mut bytewise: FrameDecoder = FrameDecoder::new();
        let mut frames = 0;
        for &b in &input[..] {
            if let Status::Complete(Event::Frame(_)) = bytewise.push(b) {
                frames += 1;
            }
            while let Status::Complete(Event::Frame(_)) | Status::Complete(Event::Error(_)) =
                bytewise.decode(b"").status
            {
                frames += usize::from(bytewise.last_frame().is_some());
            }
        }
        assert_eq!(frames, 1);
        assert_eq!(bytewise.stats(), dec.stats());
    }

    /// A cut 216H announcing 255 characters swallows a 200H whose own
    /// text swallows an error frame's start: the 200H fails while bytes of
    /// the 216H still wait to be decoded again, and both sets come out in
    /// order, every byte a frame's or discarded.
    #[test]
    fn a_failure_while_bytes_wait_to_be_decoded_again() {
        let mut input = [0u8; 400];
        let mut n = 0;
        let mut put = |b: &[u8]| {
            input[n..n + b.len()].copy_from_slice(b);
            n += b.len();
        };
        put(b"#99216");
        put(&[b'0'; 82]);
        put(b"FF");
        // The 216H's text (offsets 90..345): a 200H whose ten characters
        // hold '&', then a header byte that cuts the 200H, then a reply.
        put(b"!99200AB&DEFGHIJ#992322C\r\n");
        put(&[b'x'; 345 - 90 - 26]);
        // After the text: a reply that cuts the 216H.
        put(R232);
        let input = &input[..n];

        let mut dec: FrameDecoder = FrameDecoder::new();
        let mut frames = 0;
        let mut errors = [None; 8];
        let mut k = 0;
        let mut rest = input;
        loop {
            let d = dec.decode(rest);
            rest = &rest[d.consumed..];
            match d.status {
                Status::Partial if rest.is_empty() => break,
                Status::Partial => {}
                Status::Complete(Event::Frame(f)) => {
                    assert_eq!(f.as_bytes(), R232);
                    frames += 1;
                }
                Status::Complete(Event::Error(e)) => {
                    errors[k] = Some(e);
                    k += 1;
                }
            }
        }
        assert_eq!(frames, 2, "{errors:?}");
        assert_eq!(
            &errors[..k],
            &[
                Some(Error::Truncated { len: 345 }),
                Some(Error::Truncated { len: 16 }),
                Some(Error::Truncated { len: 8 }),
            ]
        );
        assert_eq!(dec.pending(), 0);
        let s = dec.stats();
        assert_eq!(s.discarded_bytes as usize, n - 2 * R232.len());
        assert_eq!((s.frames, s.errors), (2, 3));

        // Byte by byte, draining after each: the same counts.
        let mut bytewise: FrameDecoder = FrameDecoder::new();
        for &b in input {
            let _ = bytewise.push(b);
            while !matches!(bytewise.decode(b"").status, Status::Partial) {}
        }
        assert_eq!(bytewise.stats(), s);
        assert_eq!(bytewise.pending(), 0);
    }

    /// As above, but the 200H ends with CR LF (and a wrong checksum) inside
    /// the bytes decoded again: its own failed bytes go back ahead of the
    /// ones still waiting.
    #[test]
    fn a_checked_failure_while_bytes_wait_to_be_decoded_again() {
        let mut input = [0u8; 400];
        let mut n = 0;
        let mut put = |b: &[u8]| {
            input[n..n + b.len()].copy_from_slice(b);
            n += b.len();
        };
        put(b"#99216");
        put(&[b'0'; 82]);
        put(b"FF");
        put(b"!99200AB&DEFGHIJ00\r\n#992322C\r\n");
        put(&[b'x'; 345 - 90 - 30]);
        put(R232);
        let input = &input[..n];
        let mut dec: FrameDecoder = FrameDecoder::new();
        let mut seen = [None; 8];
        let mut k = 0;
        let mut rest = input;
        loop {
            let d = dec.decode(rest);
            rest = &rest[d.consumed..];
            let ev = match d.status {
                Status::Partial if rest.is_empty() => break,
                Status::Partial => continue,
                Status::Complete(Event::Frame(f)) => Ok(f.len()),
                Status::Complete(Event::Error(e)) => Err(e),
            };
            seen[k] = Some(ev);
            k += 1;
        }
        assert_eq!(
            &seen[..k],
            &[
                Some(Err(Error::Truncated { len: 345 })),
                Some(Err(Error::ChecksumMismatch {
                    computed: Checksum::of(b"!99200AB&DEFGHIJ"),
                    received: 0
                })),
                // "&DEFGHIJ00\r\n": an error frame whose code is not hex.
                Some(Err(Error::InvalidHexDigit {
                    offset: 4,
                    byte: b'G'
                })),
                Some(Ok(R232.len())),
                Some(Ok(R232.len())),
            ]
        );
        assert_eq!(dec.pending(), 0);
        assert_eq!(dec.stats().discarded_bytes as usize, n - 2 * R232.len());
    }

    #[test]
    fn reset_and_an_empty_buffer() {
        let mut dec: FrameDecoder = FrameDecoder::new();
        assert_eq!(dec.decode(b"!992").status, Status::Partial);
        assert_eq!(dec.pending(), 4);
        dec.reset();
        assert_eq!(dec.pending(), 0);
        assert_eq!(dec.stats().discarded_bytes, 4);
        let (ev, _) = events(&mut dec, b"09001005");
        assert_eq!(ev[0], None, "no frame starts without a header");
        assert_eq!(dec.stats().discarded_bytes, 12);
        let (ev, _) = events(&mut dec, P10);
        assert_eq!(ev[0], Some(Ok(P10.len())));
        dec.reset();
        assert_eq!(
            dec.stats().discarded_bytes,
            12,
            "a returned frame is not discarded"
        );

        let mut none: FrameDecoder<0> = FrameDecoder::new();
        let (ev, _) = events(&mut none, R232);
        assert_eq!(ev[0], None);
        assert_eq!(none.stats().discarded_bytes, 10);
        assert_eq!(none.pending(), 0);
    }
}
