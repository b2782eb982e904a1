//! The streaming frame decoder: push bytes in, get whole frames out.
//!
//! Like `httparse`, it never blocks and never allocates: it takes whatever
//! bytes the UART produced (one at a time or any slice) and answers
//! [`Event::NeedMore`] until a frame is complete. Its buffer is a const
//! generic `N` (default [`DEFAULT_CAPACITY`] = 2,051 bytes, the largest
//! frame a TTA accepts; it sends at most 2,048).
//!
//! Resynchronisation: bytes before a header byte (`!`, `#`, `&`, `%`) are
//! discarded and counted. A header byte inside a frame (outside the text
//! fields of 200H and 216H) means the frame lost its end: the cut frame is
//! reported as [`Error::Truncated`] and decoding restarts at the new header.
//! A bad checksum, a non-hex digit, CR without LF, LF without CR and an
//! over-long frame are each reported once, with a typed [`Error`]; the
//! bytes are dropped and the next valid frame decodes.
//!
//! Inside a text field every byte is text, header bytes and CR LF
//! included, and a cut 216H reply can announce up to 255 characters: its
//! "text" may swallow the frames that follow it. So when a frame that had
//! a text field fails, the decoder does not drop all of it: it decodes its
//! bytes again from the first header byte after its start, and the valid
//! frames among them come out as if nothing had happened. Those bytes are
//! replayed by the following calls, before any new input: call
//! [`FrameDecoder::decode`] until it answers [`Event::NeedMore`], even with
//! an empty input.
//!
//! ```
//! use iai_protocol_b::decoder::{Event, FrameDecoder};
//! let mut dec: FrameDecoder = FrameDecoder::new();
//! let mut input: &[u8] = b"noise#992322C\r\n";
//! let mut frames = 0;
//! loop {
//!     let d = dec.decode(input);
//!     input = &input[d.consumed..];
//!     match d.event {
//!         Event::NeedMore => break,
//!         Event::Frame(f) => { assert_eq!(f.as_bytes(), b"#992322C\r\n"); frames += 1 }
//!         Event::Error(e) => panic!("{e}"),
//!     }
//! }
//! assert_eq!(frames, 1);
//! assert_eq!(dec.stats().discarded_bytes, 5);
//! ```
//!
//! # Panic freedom
//! Every buffer access is bounds-checked with `get`; counters saturate.

use crate::checksum::BypassPolicy;
use crate::error::Error;
use crate::field::{decode_unsigned, move_within, FieldSpec};
use crate::frame::{self, Envelope, Frame, Header, Station, ENVELOPE_LEN};
use crate::limits;

/// Default capacity: the largest frame a controller sends or receives
/// ([`limits::LARGEST_FRAME`], the TTA's 2,051-byte receive buffer).
pub const DEFAULT_CAPACITY: usize = limits::LARGEST_FRAME;

/// What one step of decoding produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event<'d> {
    /// All input was used; no frame is complete yet.
    NeedMore,
    /// A complete, checked frame. It borrows the decoder until the next call.
    Frame(Frame<'d>),
    /// A broken frame was dropped; decoding goes on with the next byte.
    Error(Error),
}

/// The result of [`FrameDecoder::decode`]: how much input was used and
/// what happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decoded<'d> {
    /// Bytes of the input consumed; feed the rest in the next call.
    pub consumed: usize,
    /// The event that stopped decoding.
    pub event: Event<'d>,
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
#[derive(Debug, Clone)]
pub struct FrameDecoder<const N: usize = DEFAULT_CAPACITY> {
    buf: [u8; N],
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
        }
    }

    /// The `@@` policy in force.
    pub fn policy(&self) -> BypassPolicy {
        self.policy
    }

    /// Changes the `@@` policy.
    pub fn set_policy(&mut self, policy: BypassPolicy) {
        self.policy = policy;
    }

    /// The buffer capacity (largest frame accepted).
    pub const fn capacity(&self) -> usize {
        N
    }

    /// Counters since creation.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Bytes held: the frame in progress and bytes waiting to be decoded
    /// again after a failed text frame.
    pub fn pending(&self) -> usize {
        let frame = match self.state {
            State::Done | State::Hunting => 0,
            _ => self.len,
        };
        frame + self.replay_len.saturating_sub(self.replay_pos)
    }

    /// The frame returned by the last call, until the next byte is pushed.
    pub fn last_frame(&self) -> Option<Frame<'_>> {
        if self.state != State::Done {
            return None;
        }
        let bytes = self.buf.get(..self.len)?;
        self.last.map(|env| Frame::from_parts(bytes, env))
    }

    /// After an [`Event::Error`] for a frame that ended with CR LF but
    /// failed its check (checksum, digits, layout of the envelope): its
    /// header, station and code, if they could be read. An engine awaiting
    /// a reply uses this to tell "my reply arrived broken" from noise.
    pub fn failed_envelope(&self) -> Option<(Header, Station, u16)> {
        self.failed
    }

    /// Drops any partial frame and bytes waiting to be decoded again
    /// (counted as discarded) and starts hunting.
    pub fn reset(&mut self) {
        self.discard(self.pending());
        self.len = 0;
        self.replay_pos = 0;
        self.replay_len = 0;
        self.state = State::Hunting;
    }

    /// Pushes one byte. If bytes of a failed text frame are waiting to be
    /// decoded again, `byte` joins them and they come first; call
    /// `decode(&[])` until [`Event::NeedMore`] to drain them.
    pub fn push(&mut self, byte: u8) -> Event<'_> {
        let outcome = if self.replay_pos < self.replay_len {
            match self.buf.get_mut(self.replay_len) {
                Some(slot) => {
                    *slot = byte;
                    self.replay_len += 1;
                }
                // Cannot happen: a replayed region is shorter than the buffer.
                None => self.discard(1),
            }
            self.replay()
        } else {
            self.step(byte)
        };
        match outcome {
            Step::More => Event::NeedMore,
            Step::Frame(env) => self.frame_event(env),
            Step::Error(e) => Event::Error(e),
        }
    }

    /// Steps the bytes waiting to be decoded again until an event.
    fn replay(&mut self) -> Step {
        while self.replay_pos < self.replay_len {
            let Some(&b) = self.buf.get(self.replay_pos) else {
                break;
            };
            self.replay_pos += 1;
            let outcome = self.step(b);
            if !matches!(outcome, Step::More) {
                return outcome;
            }
        }
        self.replay_pos = 0;
        self.replay_len = 0;
        Step::More
    }

    /// Consumes bytes from `input` until a frame or an error is ready or
    /// the input is used up. Call again with the rest of the input until
    /// it answers [`Event::NeedMore`] (bytes being decoded again after a
    /// failed text frame come out before new input, with `consumed` 0).
    pub fn decode(&mut self, input: &[u8]) -> Decoded<'_> {
        let mut consumed = 0;
        let mut outcome = self.replay();
        if matches!(outcome, Step::More) {
            for &b in input {
                consumed += 1;
                outcome = self.step(b);
                if !matches!(outcome, Step::More) {
                    break;
                }
            }
        }
        let event = match outcome {
            Step::More => Event::NeedMore,
            Step::Frame(env) => self.frame_event(env),
            Step::Error(e) => Event::Error(e),
        };
        Decoded { consumed, event }
    }

    fn frame_event(&self, env: Envelope) -> Event<'_> {
        let bytes = self.buf.get(..self.len).unwrap_or(&[]);
        Event::Frame(Frame::from_parts(bytes, env))
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
    fn recover(&mut self, e: Error, extra: Option<u8>) -> Option<Step> {
        self.text?;
        let frame = self.buf.get(1..self.len)?;
        let p = 1 + frame.iter().position(|&b| Header::from_byte(b).is_some())?;
        let kept = self.len - p;
        // Waiting bytes follow the failed frame's: move them up first.
        let waiting = self.replay_len.saturating_sub(self.replay_pos);
        let extra_len = usize::from(extra.is_some());
        let total = kept + extra_len + waiting;
        if total > N || (waiting > 0 && self.replay_pos < self.len) {
            return None;
        }
        let moved = move_within(&mut self.buf, self.replay_pos, waiting, kept + extra_len)
            && move_within(&mut self.buf, p, kept, 0);
        if !moved {
            return None;
        }
        if let (Some(x), Some(slot)) = (extra, self.buf.get_mut(kept)) {
            *slot = x;
        }
        self.replay_pos = 0;
        self.replay_len = total;
        self.len = 0;
        self.state = State::Hunting;
        Some(self.fail(e, p))
    }

    fn start(&mut self, byte: u8) {
        if let Some(slot) = self.buf.first_mut() {
            *slot = byte;
            self.len = 1;
            self.state = State::InFrame;
            self.text = None;
        } else {
            // N == 0: nothing can ever be buffered.
            self.len = 0;
            self.state = State::Hunting;
            self.discard(1);
        }
    }

    /// Appends a byte of the frame in progress; `false` if the buffer is full.
    fn store(&mut self, byte: u8) -> bool {
        match self.buf.get_mut(self.len) {
            Some(slot) => {
                *slot = byte;
                self.len += 1;
                if self.text.is_none() && (ENVELOPE_LEN..=TEXT_PROBE_MAX).contains(&self.len) {
                    let head = self.buf.first().copied().and_then(Header::from_byte);
                    let prefix = self.buf.get(..self.len).unwrap_or(&[]);
                    self.text = head.and_then(|h| frame::text_span(h, prefix));
                }
                true
            }
            None => false,
        }
    }

    fn step(&mut self, byte: u8) -> Step {
        self.failed = None;
        if self.state == State::Done {
            self.len = 0;
            self.state = State::Hunting;
        }
        let is_header = Header::from_byte(byte).is_some();
        match self.state {
            State::Hunting | State::Done => {
                if is_header {
                    self.start(byte);
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
                    if let Some(step) = self.recover(e, Some(byte)) {
                        return step;
                    }
                    self.start(byte);
                    return self.fail(e, cut);
                }
                if byte == b'\n' && !in_text {
                    if let Some(step) = self.recover(Error::MissingCarriageReturn, Some(byte)) {
                        return step;
                    }
                    let dropped = self.len + 1;
                    self.state = State::Hunting;
                    return self.fail(Error::MissingCarriageReturn, dropped);
                }
                if byte == b'\r' && !in_text {
                    self.state = State::SawCr;
                }
                self.store_or_overflow(byte)
            }
            State::SawCr => {
                if byte == b'\n' {
                    if let Step::Error(e) = self.store_or_overflow(byte) {
                        return Step::Error(e);
                    }
                    let bytes = self.buf.get(..self.len).unwrap_or(&[]);
                    match frame::validate(bytes, self.policy) {
                        Ok(env) => {
                            self.state = State::Done;
                            self.last = Some(env);
                            self.stats.frames = self.stats.frames.saturating_add(1);
                            Step::Frame(env)
                        }
                        Err(e) => {
                            self.failed = envelope_of(bytes);
                            if let Some(step) = self.recover(e, None) {
                                return step;
                            }
                            self.state = State::Hunting;
                            self.fail(e, self.len)
                        }
                    }
                } else {
                    let e = Error::MissingLineFeed { byte };
                    if let Some(step) = self.recover(e, Some(byte)) {
                        return step;
                    }
                    if is_header {
                        let dropped = self.len;
                        self.start(byte);
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

    fn store_or_overflow(&mut self, byte: u8) -> Step {
        if self.store(byte) {
            Step::More
        } else {
            let e = Error::FrameTooLong { limit: N };
            if let Some(step) = self.recover(e, Some(byte)) {
                return step;
            }
            let dropped = self.len + 1;
            self.state = State::Hunting;
            self.fail(e, dropped)
        }
    }
}

/// Header, station and code of a frame's first six bytes, if readable.
fn envelope_of(bytes: &[u8]) -> Option<(Header, Station, u16)> {
    let header = Header::from_byte(*bytes.first()?)?;
    let station = decode_unsigned(FieldSpec::hex(2), bytes.get(1..3)?, 1).ok()?;
    let code = decode_unsigned(FieldSpec::hex(3), bytes.get(3..6)?, 3).ok()?;
    Some((header, Station(station as u8), code as u16))
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
            match d.event {
                Event::NeedMore => return out,
                Event::Frame(f) => out.push(Ok(f.as_bytes().to_vec())),
                Event::Error(e) => out.push(Err(e)),
            }
        }
    }

    extern crate std;
    use std::vec::Vec;

    const SERVO_REPLY: &[u8] = b"#992322C\r\n";

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
                Event::NeedMore => {}
                Event::Frame(f) => got.push(Ok(f.as_bytes().to_vec())),
                Event::Error(e) => got.push(Err(e)),
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
