//! The frame decoder one byte at a time and nothing else: every byte goes
//! through the whole state machine, the text span is looked for at every
//! length the catalogue may need, the frame is checked by
//! `Frame::new_checked`. The core's `decoder::FrameDecoder` takes short
//! cuts (plain body bytes stored without a step, the text span looked for
//! only where the frame's message can have one); this is what it must
//! give, event for event, counter for counter. Built from the core's
//! public items only, on a `Vec` of the same capacity.

use iai_protocol_b::catalogue::{text_span, TEXT_KNOWN_BY};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::DecoderStats;
use iai_protocol_b::error::Error;
use iai_protocol_b::frame::{read_envelope, Frame, Header, Station, ENVELOPE_LEN};

/// What one call gave: nothing yet, a checked frame (its bytes), or an error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reference {
    /// Every byte was used; nothing is complete.
    Partial,
    /// A frame passed its check: its bytes, header through LF.
    Frame(Vec<u8>),
    /// A broken frame was dropped.
    Error(Error),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Hunting,
    InFrame,
    SawCr,
    Done,
}

/// The reference decoder (see the module docs), with a `capacity`-byte
/// buffer.
#[derive(Debug, Clone)]
pub struct ReferenceDecoder {
    buf: Vec<u8>,
    len: usize,
    state: State,
    policy: BypassPolicy,
    text: Option<(usize, usize)>,
    /// The frame last returned checked out (valid while `state == Done`).
    last: bool,
    failed: Option<(Header, Station, u16)>,
    replay_pos: usize,
    replay_len: usize,
    stats: DecoderStats,
}

impl ReferenceDecoder {
    /// A decoder with a `capacity`-byte buffer and the given `@@` policy.
    pub fn new(capacity: usize, policy: BypassPolicy) -> Self {
        ReferenceDecoder {
            buf: vec![0; capacity],
            len: 0,
            state: State::Hunting,
            policy,
            text: None,
            last: false,
            failed: None,
            replay_pos: 0,
            replay_len: 0,
            stats: DecoderStats::default(),
        }
    }

    /// Counters since creation.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Bytes held: the frame in progress and bytes waiting to be decoded again.
    pub fn pending(&self) -> usize {
        let frame = match self.state {
            State::Done | State::Hunting => 0,
            _ => self.len,
        };
        frame + self.replay_len.saturating_sub(self.replay_pos)
    }

    /// The frame returned by the last call, until the next byte.
    pub fn last_frame(&self) -> Option<&[u8]> {
        (self.state == State::Done && self.last).then(|| &self.buf[..self.len])
    }

    /// The envelope of the frame that last failed its check.
    pub fn failed_envelope(&self) -> Option<(Header, Station, u16)> {
        self.failed
    }

    /// Drops any partial frame and bytes waiting, counted as discarded.
    pub fn reset(&mut self) {
        self.discard(self.pending());
        self.len = 0;
        self.replay_pos = 0;
        self.replay_len = 0;
        self.state = State::Hunting;
    }

    /// One byte, as `FrameDecoder::push`.
    pub fn push(&mut self, byte: u8) -> Reference {
        if self.replay_pos < self.replay_len {
            if self.replay_len < self.buf.len() {
                self.buf[self.replay_len] = byte;
                self.replay_len += 1;
            } else {
                self.discard(1);
            }
            self.replay()
        } else {
            self.step(byte)
        }
    }

    /// Bytes until an event, as `FrameDecoder::decode`: bytes consumed and
    /// what they gave.
    pub fn decode(&mut self, input: &[u8]) -> (usize, Reference) {
        let mut consumed = 0;
        let mut outcome = self.replay();
        if outcome == Reference::Partial {
            for &b in input {
                consumed += 1;
                outcome = self.step(b);
                if outcome != Reference::Partial {
                    break;
                }
            }
        }
        (consumed, outcome)
    }

    fn replay(&mut self) -> Reference {
        while self.replay_pos < self.replay_len {
            let b = self.buf[self.replay_pos];
            self.replay_pos += 1;
            let outcome = self.step(b);
            if outcome != Reference::Partial {
                return outcome;
            }
        }
        self.replay_pos = 0;
        self.replay_len = 0;
        Reference::Partial
    }

    fn discard(&mut self, n: usize) {
        let n = u32::try_from(n).unwrap_or(u32::MAX);
        self.stats.discarded_bytes = self.stats.discarded_bytes.saturating_add(n);
    }

    fn fail(&mut self, e: Error, dropped: usize) -> Reference {
        self.discard(dropped);
        self.stats.errors = self.stats.errors.saturating_add(1);
        Reference::Error(e)
    }

    fn recover(&mut self, e: Error, extra: Option<u8>) -> Option<Reference> {
        self.text?;
        let frame = self.buf.get(1..self.len)?;
        let p = 1 + frame.iter().position(|&b| Header::from_byte(b).is_some())?;
        let kept = self.len - p;
        let waiting = self.replay_len.saturating_sub(self.replay_pos);
        let extra_len = usize::from(extra.is_some());
        let total = kept + extra_len + waiting;
        if total > self.buf.len() || (waiting > 0 && self.replay_pos < self.len) {
            return None;
        }
        self.buf.copy_within(p..p + kept, 0);
        let from = self.replay_pos;
        self.buf.copy_within(from..from + waiting, kept + extra_len);
        if let Some(x) = extra {
            self.buf[kept] = x;
        }
        self.replay_pos = 0;
        self.replay_len = total;
        self.len = 0;
        self.state = State::Hunting;
        Some(self.fail(e, p))
    }

    fn start(&mut self, byte: u8) {
        if self.buf.is_empty() {
            self.len = 0;
            self.state = State::Hunting;
            self.discard(1);
        } else {
            self.buf[0] = byte;
            self.len = 1;
            self.state = State::InFrame;
            self.text = None;
        }
    }

    fn store(&mut self, byte: u8) -> bool {
        if self.len >= self.buf.len() {
            return false;
        }
        self.buf[self.len] = byte;
        self.len += 1;
        if self.text.is_none() && (ENVELOPE_LEN..=TEXT_KNOWN_BY).contains(&self.len) {
            let head = Header::from_byte(self.buf[0]);
            self.text = head.and_then(|h| text_span(h, &self.buf[..self.len]));
        }
        true
    }

    fn step(&mut self, byte: u8) -> Reference {
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
                Reference::Partial
            }
            State::InFrame => {
                let in_text = self
                    .text
                    .is_some_and(|(s, e)| self.len >= s && self.len < e);
                if is_header && !in_text {
                    let cut = self.len;
                    let e = Error::Truncated { len: cut };
                    if let Some(r) = self.recover(e, Some(byte)) {
                        return r;
                    }
                    self.start(byte);
                    return self.fail(e, cut);
                }
                if byte == b'\n' && !in_text {
                    if let Some(r) = self.recover(Error::MissingCarriageReturn, Some(byte)) {
                        return r;
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
                    if let Reference::Error(e) = self.store_or_overflow(byte) {
                        return Reference::Error(e);
                    }
                    let bytes = &self.buf[..self.len];
                    match Frame::new_checked(bytes, self.policy) {
                        Ok(_) => {
                            self.state = State::Done;
                            self.last = true;
                            self.stats.frames = self.stats.frames.saturating_add(1);
                            Reference::Frame(bytes.to_vec())
                        }
                        Err(e) => {
                            self.failed = read_envelope(bytes);
                            if let Some(r) = self.recover(e, None) {
                                return r;
                            }
                            self.state = State::Hunting;
                            self.fail(e, self.len)
                        }
                    }
                } else {
                    let e = Error::MissingLineFeed { byte };
                    if let Some(r) = self.recover(e, Some(byte)) {
                        return r;
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

    fn store_or_overflow(&mut self, byte: u8) -> Reference {
        if self.store(byte) {
            Reference::Partial
        } else {
            self.failed = read_envelope(&self.buf);
            let e = Error::FrameTooLong {
                limit: self.buf.len(),
            };
            if let Some(r) = self.recover(e, Some(byte)) {
                return r;
            }
            let dropped = self.len + 1;
            self.state = State::Hunting;
            self.fail(e, dropped)
        }
    }
}
