//! The one way in: an engine's [`Receiver`] turns bytes from the controller
//! into frames and offers each to the [`Line`], with the engine's [`Judge`]
//! verdict on its content. The receiver, not the engine, keeps the rules
//! every engine shares:
//! - a broken frame is reported to the line by what its envelope says (a
//!   copy of it may come whole; it may have been the reply);
//! - a reply the owner keeps ([`Verdict::keep`]) stays in the buffer until
//!   [`Receiver::release`]; bytes meanwhile are decoded by the line's own
//!   small decoder, so nothing is left unread and a fence can still be
//!   answered;
//! - bytes dropped half decoded before a send may have held a reply whose
//!   copy is still to come ([`Receiver::clear`]).

use super::overheard::{Passed, KEPT};
use super::{Heard, Line, Span};
use crate::checksum::BypassPolicy;
use crate::decoder::{Event, FrameDecoder, Received, Status};
use crate::frame::{Frame, Header};

/// What an engine says of a response from the station it is offered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Verdict {
    /// Its content answers the command (meaningful only for the command's
    /// reply: right station, header and ID, after the command was sent).
    pub(crate) fits: bool,
    /// The values it commits to (a record count, the positions it
    /// carries), for the copies the line expects of it.
    pub(crate) values: Span,
    /// Taken as the answer, it stays in the receiver for the owner.
    pub(crate) keep: bool,
}

impl Verdict {
    /// A frame that answers nothing and carries nothing known.
    pub(crate) const NOTHING: Verdict = Verdict {
        fits: false,
        values: Span::UNKNOWN,
        keep: false,
    };
}

/// An engine's check of a response's content against its command.
pub(crate) trait Judge {
    /// The verdict on `frame`, a checked response (`#`) from the station.
    fn judge(&mut self, frame: &Frame<'_>) -> Verdict;
    /// Whether frames with this envelope stream by to the engine itself
    /// (a transfer compares read-back replies as they arrive, without a
    /// buffer for them): the receiver leaves them alone.
    fn streams(&self, _header: Header, _code: u16) -> bool {
        false
    }
    /// Whether an error response taken as the command's reply stays in the
    /// receiver too (a bridge relays it).
    fn keeps_errors(&self) -> bool {
        false
    }
}

/// 32-bit FNV-1a of a frame's bytes: tells two frames apart (copies, two
/// replies that must agree) without keeping either.
pub(crate) fn fingerprint(bytes: &[u8]) -> u32 {
    fingerprint_more(FINGERPRINT_START, bytes)
}

/// The fingerprint's starting value.
pub(crate) const FINGERPRINT_START: u32 = 0x811C_9DC5;

/// The fingerprint of the bytes summed into `h` and then `bytes`.
pub(crate) fn fingerprint_more(h: u32, bytes: &[u8]) -> u32 {
    bytes
        .iter()
        .fold(h, |h, &b| (h ^ u32::from(b)).wrapping_mul(0x0100_0193))
}

/// Frames from the controller, up to `N` bytes each.
#[derive(Clone)]
pub(crate) struct Receiver<const N: usize> {
    frames: FrameDecoder<N>,
    /// The reply taken last is kept for the owner.
    held: bool,
}

impl<const N: usize> Receiver<N> {
    pub(crate) const fn new() -> Self {
        Receiver {
            frames: FrameDecoder::with_policy(BypassPolicy::Reject),
            held: false,
        }
    }

    /// Decodes `bytes` received at `now` up to the first frame (whole or
    /// broken) and offers it to `line`; `judge` rules on a response's
    /// content. Every byte is used: call again with the rest.
    pub(crate) fn receive<J: Judge + ?Sized>(
        &mut self,
        line: &mut Line,
        judge: &mut J,
        bytes: &[u8],
        now: u32,
    ) -> Received<Heard> {
        receive(&mut self.frames, &mut self.held, line, judge, bytes, now)
    }

    /// The reply kept for the owner.
    pub(crate) fn reply(&self) -> Option<Frame<'_>> {
        if self.held {
            self.frames.last_frame()
        } else {
            None
        }
    }

    /// The owner is done with the reply it kept: bytes go to the
    /// receiver's own buffer again.
    pub(crate) fn release(&mut self) {
        self.held = false;
        self.frames.reset();
    }

    /// Before a send at `now`: drops what is half decoded (it cannot
    /// answer the send, but it may have held a reply whose copy is still
    /// to come: the line hears of it) and any reply kept.
    pub(crate) fn clear(&mut self, line: &mut Line, now: u32) {
        if !self.held && self.frames.pending() > 0 {
            line.unread(now);
        }
        self.release();
    }
}

/// What [`Receiver::receive`] does, over a decoder and a "held" flag that
/// an engine may borrow (a bridge's one buffer holds the host's command,
/// then the controller's reply).
pub(crate) fn receive<const N: usize, J: Judge + ?Sized>(
    frames: &mut FrameDecoder<N>,
    held: &mut bool,
    line: &mut Line,
    judge: &mut J,
    bytes: &[u8],
    now: u32,
) -> Received<Heard> {
    if *held {
        return line.receive_held(bytes, now, |h, code| judge.streams(h, code));
    }
    let mut used = 0;
    loop {
        let start = used;
        let d = frames.decode(bytes.get(used..).unwrap_or(&[]));
        used += d.consumed;
        let status = match d.status {
            Status::Partial => {
                match frames.pending() {
                    // Nothing begun: every byte was dropped as noise.
                    0 => line.noise(bytes.get(start..used).unwrap_or(&[]), now),
                    _ => line.framing(),
                }
                Status::Partial
            }
            Status::Complete(Event::Error(e)) => {
                // The rest of the frame, up to its LF, is not noise.
                line.quiet();
                match frames.failed_envelope() {
                    Some((h, _, code)) if judge.streams(h, code) => continue,
                    envelope => {
                        line.broken(envelope, now);
                        Status::Complete(Heard::Broken(e))
                    }
                }
            }
            Status::Complete(Event::Frame(f)) => {
                line.framing();
                if judge.streams(f.header(), f.code()) {
                    continue;
                }
                let ours = f.header() == Header::Response && f.station() == line.cfg.station;
                let verdict = if ours {
                    judge.judge(&f)
                } else {
                    Verdict::NOTHING
                };
                let heard = line.offer(&f, verdict, now);
                *held = match heard {
                    Heard::Answer => verdict.keep,
                    Heard::Rejected(_) => judge.keeps_errors(),
                    _ => false,
                };
                Status::Complete(heard)
            }
        };
        return Received {
            consumed: used,
            status,
        };
    }
}

impl Line {
    /// Bytes received at `now` while no engine runs: heard as by an owner
    /// that keeps its reply (they answer nothing).
    pub(crate) fn listen(&mut self, mut bytes: &[u8], now: u32) {
        loop {
            let r = self.receive_held(bytes, now, |_, _| false);
            bytes = bytes.get(r.consumed..).unwrap_or(&[]);
            if r.status.is_partial() {
                return;
            }
        }
    }

    /// Bytes received at `now` while an owner keeps its reply: decoded in
    /// the line's small buffer and offered as answering nothing (a fence's
    /// echo still settles its fence). Frames whose envelope `streams` are
    /// the owner's to hear (it reads what they carry as they pass).
    pub(crate) fn receive_held(
        &mut self,
        bytes: &[u8],
        now: u32,
        streams: impl Fn(Header, u16) -> bool,
    ) -> Received<Heard> {
        let mut used = 0;
        let (consumed, status) = loop {
            let rest = bytes.get(used..).unwrap_or(&[]);
            let (consumed, status) = self.overheard.decode(rest);
            used += consumed;
            let envelope = match status {
                Status::Complete(Passed::Whole {
                    header,
                    station,
                    code,
                    ..
                }) => Some((header, station, code)),
                Status::Complete(Passed::Broken(envelope, _)) => envelope,
                Status::Partial => None,
            };
            if !envelope.is_some_and(|(h, _, code)| streams(h, code)) {
                break (used, status);
            }
            if used >= bytes.len() || consumed == 0 {
                break (used, Status::Partial);
            }
        };
        let mut body = [0u8; KEPT];
        let passed = match status {
            Status::Partial => None,
            Status::Complete(Passed::Broken(env, e)) => Some(Err((env, e))),
            Status::Complete(Passed::Whole {
                header,
                station,
                code,
                body: kept,
                print,
            }) => {
                let len = kept.map(|k| {
                    let n = k.len().min(KEPT);
                    if let (Some(dst), Some(src)) = (body.get_mut(..n), k.get(..n)) {
                        dst.copy_from_slice(src);
                    }
                    n
                });
                Some(Ok((header, station, code, len, print)))
            }
        };
        let status = match passed {
            None => Status::Partial,
            Some(Err((env, e))) => {
                self.broken(env, now);
                Status::Complete(Heard::Broken(e))
            }
            Some(Ok((h, s, c, len, print))) => {
                let body = len.and_then(|n| body.get(..n));
                Status::Complete(self.hear(h, s, c, body, Verdict::NOTHING, print, now))
            }
        };
        Received { consumed, status }
    }
}
