//! Reading a position table back in chunks with the position queries
//! (21FH, 22DH; 209H for 3-digit tables) to compare it with what was
//! written.
//!
//! Each query asks for a window of position numbers; the controller
//! returns the defined records in that window. The window is sized so that
//! the reply always fits the controller's transmit buffer (at 8 axes a
//! 21FH reply holds 24 records in 2,048 bytes), so a short reply means
//! "fewer defined records", never "cut off". Timeouts and retries follow
//! the same rules as the [transfer engine](crate::transfer).
//!
//! RAM: the reply decoder (`N` bytes, default 2,048, the TTA's transmit
//! limit), a 24-byte query and counters.

use crate::checksum::{BypassPolicy, ChecksumMode};
use crate::decoder::{Event, FrameDecoder};
use crate::error::Error;
use crate::exchange::{Due, Exchange};
use crate::field::{FieldSpec, Reader, Writer};
use crate::frame::{emit_envelope, emit_trailer, Frame, Header, Station};
use crate::position::PositionRecord;
use crate::stream::PositionStream;
use crate::transfer::TransferError;

/// Default reply buffer: the largest response a TTA sends.
pub const TTA_MAX_RESPONSE: usize = 2048;

/// Settings of a read-back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadBackConfig {
    /// Station addressed.
    pub station: Station,
    /// The query's response layout: [`PositionStream::QUERY_2_RESPONSE`]
    /// (21FH), `QUERY_3_RESPONSE` (22DH) or `QUERY_RESPONSE` (209H).
    pub stream: PositionStream,
    /// First position number to read.
    pub first: u16,
    /// Last position number to read (inclusive).
    pub last: u16,
    /// Largest response frame the controller sends (TTA 2,048).
    pub max_response: usize,
    /// Reply timeout, ms.
    pub timeout_ms: u32,
    /// Sends per query before giving up.
    pub max_tries: u8,
    /// Pause after a reply before the next query, ms.
    pub turnaround_ms: u32,
}

impl ReadBackConfig {
    /// 21FH from a TTA: positions `first..=last`, 3 s timeout, 3 tries.
    pub const fn tta(station: Station, first: u16, last: u16) -> Self {
        ReadBackConfig {
            station,
            stream: PositionStream::QUERY_2_RESPONSE,
            first,
            last,
            max_response: TTA_MAX_RESPONSE,
            timeout_ms: 3000,
            max_tries: 3,
            turnaround_ms: 1,
        }
    }

    /// Positions asked per query: as many 8-axis records as fit a reply.
    pub fn window(&self) -> u16 {
        let room = self.max_response.saturating_sub(self.stream.overhead());
        let per = room / self.stream.layout.record_len(crate::axis::MAX_AXES);
        u16::try_from(per.max(1)).unwrap_or(u16::MAX)
    }
}

/// Counters of a read-back.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadBackStats {
    /// Queries answered.
    pub queries: u32,
    /// Records received.
    pub records: u32,
    /// Queries sent again.
    pub retries: u32,
    /// Timeouts.
    pub timeouts: u32,
    /// Frames that were not the reply awaited, and broken frames.
    pub ignored: u32,
}

/// What the caller should do next.
#[derive(Debug)]
pub enum ReadStep<'a> {
    /// Send these bytes, then call [`ReadBack::sent`].
    Transmit(&'a [u8]),
    /// Feed received bytes to [`ReadBack::received`]; poll again by this tick.
    WaitUntil(u32),
    /// The records of one reply, in order. Poll again to go on.
    Records(ReplyRecords<'a>),
    /// Every window was read.
    Complete(ReadBackStats),
    /// The controller did not answer (or kept answering with an error).
    Failed(TransferError),
}

/// The records of one reply, decoded on demand (they were checked when
/// the reply arrived).
#[derive(Debug, Clone)]
pub struct ReplyRecords<'a> {
    r: Reader<'a>,
    left: u16,
    stream: PositionStream,
}

impl Iterator for ReplyRecords<'_> {
    type Item = PositionRecord;
    fn next(&mut self) -> Option<PositionRecord> {
        if self.left == 0 {
            return None;
        }
        self.left -= 1;
        self.stream.layout.read_record(&mut self.r).ok()
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Query { not_before: u32 },
    Exchange,
    Deliver { next: u32 },
    Complete,
    Failed(TransferError),
}

/// Reads positions `first..=last` back, window by window.
pub struct ReadBack<const N: usize = TTA_MAX_RESPONSE> {
    cfg: ReadBackConfig,
    /// Next window start; `u32` so that it can pass 0xFFFF.
    head: u32,
    asked: u16,
    query: [u8; 24],
    query_len: usize,
    exchange: Exchange,
    replies: FrameDecoder<N>,
    state: State,
    stats: ReadBackStats,
}

impl<const N: usize> ReadBack<N> {
    /// A read-back with these settings.
    pub fn new(cfg: ReadBackConfig) -> Self {
        ReadBack {
            cfg,
            head: u32::from(cfg.first),
            asked: 0,
            query: [0; 24],
            query_len: 0,
            exchange: Exchange::new(),
            replies: FrameDecoder::with_policy(BypassPolicy::Reject),
            state: State::Query { not_before: 0 },
            stats: ReadBackStats::default(),
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> ReadBackStats {
        self.stats
    }

    /// Decides the next step at tick `now`.
    pub fn poll(&mut self, now: u32) -> ReadStep<'_> {
        loop {
            match self.state {
                State::Query { not_before } => {
                    if self.head > u32::from(self.cfg.last) {
                        self.state = State::Complete;
                        continue;
                    }
                    if let Err(e) = self.build_query() {
                        self.state = State::Failed(TransferError::Config(e));
                        continue;
                    }
                    self.exchange.start(not_before);
                    self.state = State::Exchange;
                }
                State::Exchange => match self.exchange.poll(now) {
                    Due::Transmit { fresh } => {
                        if fresh {
                            self.replies.reset();
                        }
                        return ReadStep::Transmit(self.query.get(..self.query_len).unwrap_or(&[]));
                    }
                    Due::WaitUntil(t) => return ReadStep::WaitUntil(t),
                    Due::TimedOut => {
                        self.stats.timeouts += 1;
                        self.retry_or_fail(now, TransferError::Timeout);
                    }
                    Due::Idle => self.state = State::Failed(TransferError::Timeout),
                },
                State::Deliver { next } => {
                    // Deliver once; the next poll moves on.
                    self.state = State::Query {
                        not_before: now.wrapping_add(self.cfg.turnaround_ms),
                    };
                    self.head = next;
                    let stream = self.cfg.stream;
                    // The reply was checked on arrival; an empty list if it vanished.
                    let (r, left) = match self.replies.last_frame() {
                        Some(frame) => {
                            let mut r = frame.reader();
                            let count = stream.read_prefix(&mut r).map_or(0, |(_, c)| c);
                            (r, count)
                        }
                        None => (Reader::new(&[], 0), 0),
                    };
                    return ReadStep::Records(ReplyRecords { r, left, stream });
                }
                State::Complete => return ReadStep::Complete(self.stats),
                State::Failed(e) => return ReadStep::Failed(e),
            }
        }
    }

    /// The query was completely transmitted at `now`.
    pub fn sent(&mut self, now: u32) {
        self.exchange.sent(now, self.cfg.timeout_ms);
    }

    /// Bytes received at `now`. Stops at the awaited reply, so that its
    /// records stay readable until the next `poll`; returns the bytes used.
    pub fn received(&mut self, bytes: &[u8], now: u32) -> usize {
        let mut used = 0;
        while used < bytes.len() {
            if !(self.state == State::Exchange && self.exchange.awaiting()) {
                self.stats.ignored += 1;
                return bytes.len();
            }
            let d = self.replies.decode(bytes.get(used..).unwrap_or(&[]));
            used += d.consumed;
            match d.event {
                Event::NeedMore => break,
                Event::Error(_) => self.stats.ignored += 1,
                Event::Frame(f) => match check_reply(&self.cfg, self.head, self.asked, &f) {
                    Reply::Records { count, next } => {
                        self.stats.queries += 1;
                        self.stats.records += u32::from(count);
                        self.exchange.finish();
                        self.state = State::Deliver { next };
                        return used;
                    }
                    Reply::Error(code) => {
                        self.retry_or_fail(now, TransferError::ErrorResponse { code });
                    }
                    Reply::NotOurs => self.stats.ignored += 1,
                },
            }
        }
        used
    }

    fn retry_or_fail(&mut self, at: u32, why: TransferError) {
        if self
            .exchange
            .retry(at.wrapping_add(self.cfg.turnaround_ms), self.cfg.max_tries)
        {
            self.stats.retries += 1;
        } else {
            self.state = State::Failed(why);
        }
    }

    fn build_query(&mut self) -> Result<(), Error> {
        let cfg = self.cfg;
        let left = u32::from(cfg.last) + 1 - self.head;
        self.asked = u16::try_from(left.min(u32::from(cfg.window()))).unwrap_or(1);
        let width = cfg.stream.count_width;
        let mut w = Writer::new(&mut self.query);
        emit_envelope(&mut w, Header::Command, cfg.station, cfg.stream.id)?;
        if cfg.stream.reserved {
            w.put(b"00")?;
        }
        w.unsigned(FieldSpec::hex(width), u64::from(self.head))?;
        w.unsigned(FieldSpec::hex(width), u64::from(self.asked))?;
        emit_trailer(&mut w, ChecksumMode::Compute)?;
        self.query_len = w.len();
        Ok(())
    }
}

enum Reply {
    Records { count: u16, next: u32 },
    Error(u16),
    NotOurs,
}

/// Checks a frame as the reply to the query of window `head..head+asked`.
fn check_reply(cfg: &ReadBackConfig, head: u32, asked: u16, f: &Frame<'_>) -> Reply {
    if f.station() != cfg.station {
        return Reply::NotOurs;
    }
    match f.header() {
        Header::Error => return Reply::Error(f.code()),
        Header::Response if f.code() == cfg.stream.id => {}
        _ => return Reply::NotOurs,
    }
    let mut r = f.reader();
    let Ok((_, count)) = cfg.stream.read_prefix(&mut r) else {
        return Reply::NotOurs;
    };
    if count > asked {
        return Reply::NotOurs;
    }
    let end = head + u32::from(asked);
    for _ in 0..count {
        match cfg.stream.layout.read_record(&mut r) {
            Ok(rec) if u32::from(rec.number) >= head && u32::from(rec.number) < end => {}
            _ => return Reply::NotOurs,
        }
    }
    if r.finish().is_err() {
        return Reply::NotOurs;
    }
    Reply::Records { count, next: end }
}
