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
use crate::frame::{self, Envelope, Frame, Header, ENVELOPE_LEN};
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

    /// Bytes of the frame in progress.
    pub fn pending(&self) -> usize {
        match self.state {
            State::Done | State::Hunting => 0,
            _ => self.len,
        }
    }

    /// The frame returned by the last call, until the next byte is pushed.
    pub fn last_frame(&self) -> Option<Frame<'_>> {
        if self.state != State::Done {
            return None;
        }
        let bytes = self.buf.get(..self.len)?;
        self.last.map(|env| Frame::from_parts(bytes, env))
    }

    /// Drops any partial frame (counted as discarded) and starts hunting.
    pub fn reset(&mut self) {
        self.discard(self.pending());
        self.len = 0;
        self.state = State::Hunting;
    }

    /// Pushes one byte.
    pub fn push(&mut self, byte: u8) -> Event<'_> {
        match self.step(byte) {
            Step::More => Event::NeedMore,
            Step::Frame(env) => self.frame_event(env),
            Step::Error(e) => Event::Error(e),
        }
    }

    /// Consumes bytes from `input` until a frame or an error is ready or
    /// the input is used up. Call again with the rest of the input until
    /// it answers [`Event::NeedMore`].
    pub fn decode(&mut self, input: &[u8]) -> Decoded<'_> {
        let mut consumed = 0;
        let mut outcome = Step::More;
        for &b in input {
            consumed += 1;
            outcome = self.step(b);
            if !matches!(outcome, Step::More) {
                break;
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
                    self.start(byte);
                    return self.fail(Error::Truncated { len: cut }, cut);
                }
                if byte == b'\n' && !in_text {
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
                            self.state = State::Hunting;
                            self.fail(e, self.len)
                        }
                    }
                } else if is_header {
                    let dropped = self.len;
                    self.start(byte);
                    self.fail(Error::MissingLineFeed { byte }, dropped)
                } else {
                    let dropped = self.len + 1;
                    self.state = State::Hunting;
                    self.fail(Error::MissingLineFeed { byte }, dropped)
                }
            }
        }
    }

    fn store_or_overflow(&mut self, byte: u8) -> Step {
        if self.store(byte) {
            Step::More
        } else {
            let dropped = self.len + 1;
            self.state = State::Hunting;
            self.fail(Error::FrameTooLong { limit: N }, dropped)
        }
    }
}
