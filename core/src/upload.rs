//! A position table sent as one command, however long: what a host does
//! through a bridge that splits it into controller-sized chunks, reads
//! every chunk back, and answers once (a 26DH may carry 20,000 records,
//! 1.64 MB, TTA p. 60).
//!
//! The frame is encoded as it goes out ([`crate::table`]'s encoder, a
//! 512-byte piece at a time), so a table of any size costs no more RAM.
//! Its reply is matched by the [`Line`] like any other: the first reply
//! with the command's station and ID after its last byte, whose count is
//! exactly the records sent; an `&` ends it with the code. The reply's
//! timeout runs from the last byte, plus [`UploadConfig::intake_ms`] less
//! the time the sending took: a receiver behind a buffering link (a TCP
//! gateway) takes the bytes in at its own line's rate, after the sender
//! has written them all. A timeout sends the whole frame again, within
//! the line's sends (26DH is safe to repeat: position writes are
//! idempotent).

use core::borrow::Borrow;

use crate::decoder::Received;
use crate::engine::{Engine, Step};
use crate::error::{Error, Failure};
use crate::frame::Frame;
use crate::line::{Claim, Command, Due, Heard, Judge, Line, Receiver, Span, Verdict};
use crate::position::{PositionRecord, PositionStream};
use crate::table::PositionStreamEncoder;

/// Bytes encoded and handed out per transmission step.
const PIECE: usize = 512;

/// Settings of an upload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UploadConfig {
    /// The write message (26DH on a TTA).
    pub stream: PositionStream,
    /// Start number of a range write; ignored by the others.
    pub start: u16,
    /// The time the receiver may need to take the whole frame in, ms,
    /// counted from the first byte sent: beyond the time the sending took,
    /// the reply may come that much later (0 on a line that delivers each
    /// byte as it is sent).
    pub intake_ms: u32,
}

/// How far an upload has come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// On the line (the line says whether it is being sent or awaited).
    Running,
    Complete(u16),
    Failed(Failure),
}

/// A table sent as one command of `count` records from `records` (cloned
/// for each send: the frame is encoded again).
pub struct Upload<I> {
    cfg: UploadConfig,
    records: I,
    count: u16,
    encoder: Option<PositionStreamEncoder<I>>,
    piece: [u8; PIECE],
    piece_len: usize,
    /// When the send in progress began.
    started_at: u32,
    /// Bytes sent, resends included.
    sent_bytes: u64,
    /// The transmission in progress is a fence.
    fencing: bool,
    replies: Receiver<32>,
    state: State,
}

impl<I> Upload<I>
where
    I: Iterator + Clone,
    I::Item: Borrow<PositionRecord>,
{
    /// An upload of the `count` records of `records`, started on `line` at
    /// `now` (whatever it was doing is abandoned: its replies are owed).
    pub fn start(
        cfg: UploadConfig,
        records: I,
        count: u16,
        line: &mut Line,
        now: u32,
    ) -> Result<Self, Error> {
        if count > cfg.stream.max_records {
            return Err(Error::ValueOutOfRange { offset: 0 });
        }
        let max_sends = line.config().max_sends;
        let cmd = Command::of(cfg.stream.id, Span::one(count), Claim::Proof, max_sends);
        line.begin(cmd, now);
        Ok(Upload {
            cfg,
            records,
            count,
            encoder: None,
            piece: [0; PIECE],
            piece_len: 0,
            started_at: now,
            sent_bytes: 0,
            fencing: false,
            replies: Receiver::new(),
            state: State::Running,
        })
    }

    /// Bytes sent so far, resends included.
    pub const fn bytes_sent(&self) -> u64 {
        self.sent_bytes
    }

    /// The next piece of the frame into `piece`; `Ok(0)` once it is all out.
    fn fill(&mut self) -> Result<usize, Failure> {
        let Some(enc) = self.encoder.as_mut() else {
            return Ok(0);
        };
        match enc.read(&mut self.piece) {
            Ok(n) => {
                self.piece_len = n;
                Ok(n)
            }
            Err(error) => Err(Failure::InvalidRecord {
                index: u32::from(enc.records_emitted()),
                error,
            }),
        }
    }
}

/// The check of an upload's reply: exactly its count (and its start).
struct CountCheck {
    stream: PositionStream,
    start: u16,
    count: u16,
}

impl Judge for CountCheck {
    fn judge(&mut self, f: &Frame<'_>) -> Verdict {
        let reply = (f.code() == self.stream.id)
            .then(|| self.stream.parse_reply(f).ok())
            .flatten();
        let fits = reply.is_some_and(|(start, count)| {
            (self.stream.start_width == 0 || start == self.start) && count == self.count
        });
        Verdict {
            fits,
            values: reply.map_or(Span::UNKNOWN, |(_, n)| Span::one(n)),
            keep: false,
        }
    }
}

impl<I> Engine for Upload<I>
where
    I: Iterator + Clone,
    I::Item: Borrow<PositionRecord>,
{
    /// The count the reply confirmed.
    type Output = u16;

    fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, u16> {
        loop {
            match self.state {
                State::Complete(n) => return Step::Done(Ok(n)),
                State::Failed(e) => return Step::Done(Err(e)),
                State::Running => {}
            }
            return match line.poll(now) {
                Due::Fence => {
                    self.fencing = true;
                    Step::Transmit(line.fence_bytes())
                }
                Due::Send { fresh } => {
                    self.fencing = false;
                    if fresh {
                        self.replies.clear(line, now);
                        let enc = PositionStreamEncoder::new(
                            self.cfg.stream,
                            line.config().station,
                            self.cfg.start,
                            self.count,
                            self.records.clone(),
                        );
                        match enc {
                            Ok(e) => self.encoder = Some(e),
                            Err(e) => {
                                line.abandon(now);
                                self.state = State::Failed(Failure::Protocol(e));
                                continue;
                            }
                        }
                        self.piece_len = 0;
                        self.started_at = now;
                    }
                    if self.piece_len == 0 {
                        if let Err(e) = self.fill() {
                            line.abandon(now);
                            self.state = State::Failed(e);
                            continue;
                        }
                    }
                    Step::Transmit(self.piece.get(..self.piece_len).unwrap_or(&[]))
                }
                Due::WaitUntil(t) => Step::WaitUntil(t),
                Due::Done(Ok(())) => {
                    self.state = State::Complete(self.count);
                    continue;
                }
                Due::Done(Err(e)) => {
                    self.state = State::Failed(e);
                    continue;
                }
                Due::Idle => {
                    self.state = State::Failed(Failure::Timeout {
                        sends: line.sends(),
                    });
                    continue;
                }
            };
        }
    }

    fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        let mut judge = CountCheck {
            stream: self.cfg.stream,
            start: self.cfg.start,
            count: self.count,
        };
        self.replies.receive(line, &mut judge, bytes, now)
    }

    fn sent(&mut self, line: &mut Line, now: u32) {
        if core::mem::take(&mut self.fencing) {
            line.sent(now);
            return;
        }
        self.sent_bytes += self.piece_len as u64;
        self.piece_len = 0;
        match self.fill() {
            // The last byte is out: the reply's timeout starts.
            Ok(0) => {
                let took = now.wrapping_sub(self.started_at);
                line.sent_allowing(now, self.cfg.intake_ms.saturating_sub(took));
            }
            Ok(_) => {}
            Err(e) => {
                line.abandon(now);
                self.state = State::Failed(e);
            }
        }
    }
}
