//! Reading a position table back, window by window, with the position
//! queries (21FH, 22DH; 209H for 3-digit tables).
//!
//! Each query asks for a window of position numbers; the controller returns
//! the defined records in it. The window is sized so that the reply always
//! fits the controller's transmit buffer (24 records of 8 axes in a 2,048-
//! byte 21FH reply), so a short reply means "fewer defined records", never
//! "cut off". Queries and replies go through the crate's one reply matcher
//! ([`crate::exchange`]): a reply counts only when its SC, station and ID
//! check out, it holds no more records than asked and every record lies in
//! the window, and it came after the query was completely sent.
//!
//! # Late and duplicated replies
//! A reply holding records belongs to one window only (windows do not
//! overlap), so a late one can never pass for another. After a timeout and
//! resend, the next query waits until the replies still owed can no longer
//! arrive (`timeout_ms + late_window_ms` after the last send), dropping
//! what comes meanwhile. An *empty* reply is the same for every window:
//!
//! - once this read-back has seen a late or duplicated reply, a query that
//!   follows an empty reply of the same message waits out
//!   `duplicate_window_ms` after it, so that its duplicate cannot pass for
//!   the next window's answer (a clean line never waits);
//! - if a reply holding records arrives for a window already answered
//!   empty (its duplicate came first), that window is read again and its
//!   records delivered then, marked [`ReplyRecords::reread`].
//!
//! A window whose reply keeps timing out is asked again at half the size
//! (a long reply is more likely hit by noise), and grows back as answers
//! come.
//!
//! Left unguarded: the very first duplicate on a line arriving while the
//! next window's query *and* its reply were both lost. Where reading back
//! verifies a write ([`crate::transfer::Verify`]), such a window reads as
//! missing records and is rewritten, never as a false success.
//!
//! # Confirmed reads
//! The 8-bit SC lets some corruptions through: two bit flips that cancel
//! in the sum (at one flipped bit per 1,000 bytes, several 2 KB replies in
//! a 20,000-record read). With [`ReadBackConfig::confirm`] (the default)
//! every window is read until two replies in a row are the same, byte for
//! byte, which doubles the wire time; without it the records are as
//! good as the SC.
//!
//! RAM: the reply decoder (`N` bytes, default 2,048, the TTA's transmit
//! limit), a 24-byte query, a few remembered windows and counters.

use crate::catalogue;
use crate::checksum::{BypassPolicy, ChecksumMode};
use crate::client::Received;
use crate::clock::{later, passed, reached};
use crate::decoder::{Event, FrameDecoder};
use crate::drive::{self, Engine, Want};
use crate::error::{Error, BRIDGE_CODES};
use crate::exchange::{Due, Exchange, ExchangeConfig, Finish, Offer, Quarantine};
use crate::field::{Reader, Writer};
use crate::frame::{emit_envelope, emit_trailer, Frame, Header, Station};
use crate::limits;
use crate::position::{PositionRecord, PositionStream};
use crate::transfer::TransferError;

/// Settings of a read-back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadBackConfig {
    /// Station, timeout, sends, turnaround, late and duplicate windows.
    pub exchange: ExchangeConfig,
    /// The query's response layout: [`PositionStream::QUERY_2_RESPONSE`]
    /// (21FH), `QUERY_3_RESPONSE` (22DH) or `QUERY_RESPONSE` (209H).
    pub stream: PositionStream,
    /// First position number to read.
    pub first: u16,
    /// Last position number to read (inclusive).
    pub last: u16,
    /// Largest response frame the controller sends (TTA 2,048).
    pub max_response: usize,
    /// Read every window twice and deliver it only when two replies in a
    /// row are the same: the 8-bit SC lets some corruptions through (two
    /// bit flips that cancel), and nothing else in a reply can catch them.
    /// Doubles the wire time.
    pub confirm: bool,
}

impl ReadBackConfig {
    /// 21FH from a TTA: positions `first..=last`, 3 s timeout, 3 sends,
    /// late replies guarded for 3 s after their timeout, duplicates for 3 s.
    pub const fn tta(station: Station, first: u16, last: u16) -> Self {
        let mut exchange = ExchangeConfig::new(station);
        exchange.duplicate_window_ms = exchange.timeout_ms;
        ReadBackConfig {
            exchange,
            stream: PositionStream::QUERY_2_RESPONSE,
            first,
            last,
            max_response: limits::TTA.response,
            confirm: true,
        }
    }

    /// Positions asked per query: as many 8-axis records as fit a reply.
    pub const fn window(&self) -> u16 {
        self.stream.window(self.max_response)
    }
}

/// Counters of a read-back.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadBackStats {
    /// Queries answered.
    pub queries: u32,
    /// Records received (and delivered).
    pub records: u32,
    /// Queries sent again after a timeout.
    pub retries: u32,
    /// Timeouts.
    pub timeouts: u32,
    /// Replies that came when none was awaited, or for another window.
    pub stale_replies: u32,
    /// Windows read again because a reply holding records came after the
    /// window had been answered empty.
    pub rereads: u32,
    /// Queries held back so that a duplicated empty reply could not pass
    /// for their answer.
    pub guarded_queries: u32,
    /// Windows read twice with the same reply (confirmed reads).
    pub windows_confirmed: u32,
    /// Queries sent to confirm a window (those of confirmed reads beyond
    /// the first reply of each window).
    pub confirm_queries: u32,
    /// Frames that were no reply to a query, and broken frames.
    pub ignored: u32,
}

/// What the caller should do next.
#[derive(Debug)]
pub enum ReadStep<'a> {
    /// Send these bytes, then call [`ReadBack::sent`].
    Transmit(&'a [u8]),
    /// Feed received bytes to [`ReadBack::received`]; poll again by this tick.
    WaitUntil(u32),
    /// The records of one window, in order. Poll again to go on.
    Records(ReplyRecords<'a>),
    /// Every window was read.
    Complete(ReadBackStats),
    /// The controller did not answer (or answered with an error).
    Failed(TransferError),
}

/// The records of one window, decoded on demand (they were checked when
/// the reply arrived).
#[derive(Debug, Clone)]
pub struct ReplyRecords<'a> {
    r: Reader<'a>,
    left: u16,
    stream: PositionStream,
    head: u16,
    asked: u16,
    reread: bool,
}

impl ReplyRecords<'_> {
    /// The first position of the window.
    pub const fn head(&self) -> u16 {
        self.head
    }
    /// The number of positions the window spans.
    pub const fn asked(&self) -> u16 {
        self.asked
    }
    /// Whether this window was read before and answered empty by what
    /// turned out to be a duplicate: its records come out of order.
    pub const fn reread(&self) -> bool {
        self.reread
    }
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

/// What one call of [`ReadBack::received`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ReadEvent {
    /// All bytes used; nothing complete.
    NeedMore,
    /// The window's reply came (its records follow from `poll`).
    Answered {
        /// Records in it.
        records: u16,
    },
    /// An error response to the query.
    Rejected {
        /// Its code.
        code: u16,
    },
    /// A reply that came when none was awaited, or for another window.
    Stale,
    /// A valid frame that is no reply to the query.
    Foreign,
    /// A broken frame or noise was dropped.
    Broken(Error),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Query { not_before: Option<u32> },
    Exchange,
    Deliver,
    Complete,
    Failed(TransferError),
}

/// A window answered empty, remembered while a duplicate of another empty
/// reply could still have stood in for its answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct EmptyWindow {
    head: u32,
    asked: u16,
    until: u32,
}

/// Reads positions `first..=last` back, window by window.
pub struct ReadBack<const N: usize = { limits::TTA.response }> {
    cfg: ReadBackConfig,
    /// Next window start; `u32` so that it can pass 0xFFFF.
    head: u32,
    /// The window in flight.
    current_head: u32,
    asked: u16,
    /// Whether the window in flight is a re-read.
    rereading: bool,
    /// Positions asked per query now: halved after a timeout, grown back
    /// after each answer.
    window_limit: u16,
    query: [u8; 24],
    query_len: usize,
    exchange: Exchange,
    replies: FrameDecoder<N>,
    state: State,
    /// Windows answered empty within the duplicate window.
    empties: heapless::Deque<EmptyWindow, 8>,
    /// Windows to read again.
    rereads: heapless::Deque<(u32, u16), 4>,
    /// When the last empty reply came (for the duplicate guard).
    last_empty: Option<u32>,
    /// A late or duplicated reply was seen on this line.
    duplicates_seen: bool,
    /// Hash of the window's first reply, awaiting its confirmation.
    first_reply: Option<u32>,
    stats: ReadBackStats,
}

impl<const N: usize> ReadBack<N> {
    /// A read-back with these settings.
    pub fn new(cfg: ReadBackConfig) -> Self {
        ReadBack {
            cfg,
            head: u32::from(cfg.first),
            current_head: u32::from(cfg.first),
            asked: 0,
            rereading: false,
            window_limit: cfg.window(),
            query: [0; 24],
            query_len: 0,
            exchange: Exchange::new(own_duplicates(cfg.exchange), Quarantine::Wait),
            replies: FrameDecoder::with_policy(BypassPolicy::Reject),
            state: State::Query { not_before: None },
            empties: heapless::Deque::new(),
            rereads: heapless::Deque::new(),
            last_empty: None,
            duplicates_seen: false,
            first_reply: None,
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
                    let reread = self.rereads.pop_front();
                    if reread.is_none() && self.head > u32::from(self.cfg.last) {
                        self.state = State::Complete;
                        continue;
                    }
                    if let Err(e) = self.build_query(reread) {
                        self.state = State::Failed(TransferError::Config(e));
                        continue;
                    }
                    let h = self.exchange.horizon();
                    let mut at = match not_before {
                        Some(t) if !passed(now, t, h) => t,
                        _ => now,
                    };
                    if let (true, Some(t)) = (self.duplicates_seen, self.last_empty) {
                        let clear = t.wrapping_add(self.cfg.exchange.duplicate_window_ms);
                        if !passed(now, clear, h) && !reached(at, clear) {
                            self.stats.guarded_queries += 1;
                            at = later(at, clear);
                        }
                    }
                    match catalogue::lookup(self.cfg.stream.id) {
                        Some(info) => self.exchange.start(info, at),
                        None => {
                            let id = self.cfg.stream.id;
                            self.state =
                                State::Failed(TransferError::Config(Error::UnknownMessageId {
                                    id,
                                }));
                            continue;
                        }
                    }
                    self.state = State::Exchange;
                }
                State::Exchange => match self.exchange.poll(now) {
                    Due::Transmit { fresh } => {
                        if fresh {
                            self.replies.reset();
                            if self.exchange.sends() > 1 {
                                self.stats.retries += 1;
                                self.stats.timeouts += 1;
                                self.shrink();
                            }
                        }
                        return ReadStep::Transmit(self.query.get(..self.query_len).unwrap_or(&[]));
                    }
                    Due::WaitUntil(t) => return ReadStep::WaitUntil(t),
                    Due::Done(Finish::Replied) => self.answered(now),
                    Due::Done(Finish::ErrorReply(code)) => {
                        let e = if BRIDGE_CODES.contains(&code) {
                            TransferError::Bridge { code }
                        } else {
                            TransferError::Controller { code }
                        };
                        self.state = State::Failed(e);
                    }
                    Due::Done(_) | Due::Idle => {
                        self.stats.timeouts += 1;
                        self.state = State::Failed(TransferError::Timeout);
                    }
                },
                State::Deliver => {
                    // The window came through: let it grow back.
                    let full = self.cfg.window();
                    let grown = self
                        .window_limit
                        .saturating_add((self.window_limit / 4).max(1));
                    self.window_limit = grown.min(full);
                    // Deliver once; the next poll moves on.
                    let turnaround = now.wrapping_add(self.cfg.exchange.turnaround_ms + 1);
                    self.first_reply = None;
                    self.state = State::Query {
                        not_before: Some(turnaround),
                    };
                    let window_head = self.current_head;
                    let asked = self.asked;
                    let reread = self.rereading;
                    if !reread {
                        self.head += u32::from(asked);
                    }
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
                    return ReadStep::Records(ReplyRecords {
                        r,
                        left,
                        stream,
                        head: window_head as u16,
                        asked,
                        reread,
                    });
                }
                State::Complete => return ReadStep::Complete(self.stats),
                State::Failed(e) => return ReadStep::Failed(e),
            }
        }
    }

    /// The window's reply came. Unconfirmed reads deliver it; confirmed
    /// ones ask the same window again until two replies in a row are the
    /// same, byte for byte.
    fn answered(&mut self, now: u32) {
        if !self.cfg.confirm {
            self.state = State::Deliver;
            return;
        }
        let hash = self.replies.last_frame().map(|f| fnv1a(f.as_bytes()));
        if hash.is_some() && hash == self.first_reply {
            self.first_reply = None;
            self.stats.windows_confirmed += 1;
            self.state = State::Deliver;
            return;
        }
        self.first_reply = hash;
        self.stats.confirm_queries += 1;
        // Ask again, after the turnaround; on a line that has shown
        // duplicates, after the first reply's duplicate window too, so that
        // a copy of it cannot confirm it.
        let mut at = now.wrapping_add(self.cfg.exchange.turnaround_ms + 1);
        if self.duplicates_seen {
            at = later(at, now.wrapping_add(self.cfg.exchange.duplicate_window_ms));
        }
        match catalogue::lookup(self.cfg.stream.id) {
            Some(info) => {
                self.exchange.start(info, at);
                self.state = State::Exchange;
            }
            None => {
                let id = self.cfg.stream.id;
                self.state = State::Failed(TransferError::Config(Error::UnknownMessageId { id }));
            }
        }
    }

    /// The query was completely transmitted at `now`.
    pub fn sent(&mut self, now: u32) {
        self.exchange.sent(now);
    }

    /// After [`ReadStep::Failed`]: ask the same window again, with a fresh
    /// count of sends.
    pub fn resume(&mut self, now: u32) {
        if let State::Failed(e) = self.state {
            if !matches!(e, TransferError::Config(_)) {
                if self.rereading {
                    let _ = self.rereads.push_front((self.current_head, self.asked));
                }
                self.state = State::Query {
                    not_before: Some(now),
                };
            }
        }
    }

    /// Bytes received at `now`. Returns at the first event; on
    /// [`ReadEvent::Answered`] the reply stays readable until the next
    /// `poll` delivers it, so feed the rest of the input after that poll.
    pub fn received(&mut self, bytes: &[u8], now: u32) -> Received<ReadEvent> {
        let answered = self.state == State::Exchange
            && matches!(self.exchange.finished(), Some(Finish::Replied));
        if self.state == State::Deliver || answered {
            // The reply is held for delivery (by the next poll): take
            // nothing more yet, or the next frame would overwrite it.
            return Received {
                consumed: 0,
                event: ReadEvent::NeedMore,
            };
        }
        let window = (self.current_head, self.asked);
        let d = self.replies.decode(bytes);
        let seen = match d.event {
            Event::NeedMore => Err(None),
            Event::Error(e) => Err(Some(e)),
            Event::Frame(f) => Ok(Seen::of(&self.cfg, window, &f)),
        };
        let consumed = d.consumed;
        let event = match seen {
            Err(None) => ReadEvent::NeedMore,
            Err(Some(e)) => {
                self.stats.ignored += 1;
                if self.state == State::Exchange {
                    let envelope = self.replies.failed_envelope();
                    self.exchange.broken_frame(envelope, now);
                }
                ReadEvent::Broken(e)
            }
            Ok(seen) => self.frame(seen, window, now),
        };
        Received { consumed, event }
    }

    fn frame(&mut self, seen: Seen, window: (u32, u16), now: u32) -> ReadEvent {
        let offer = if self.state == State::Exchange {
            self.exchange.offer_head(
                seen.header,
                seen.station,
                seen.code,
                seen.check.is_some(),
                now,
            )
        } else if crate::exchange::judge(
            self.cfg.exchange.station,
            self.cfg.stream.id,
            seen.header,
            seen.station,
            seen.code,
        ) == crate::exchange::Verdict::Foreign
        {
            Offer::Foreign
        } else {
            Offer::Stale
        };
        match offer {
            Offer::Accepted => {
                let records = seen.check.unwrap_or(0);
                self.stats.queries += 1;
                self.stats.records += u32::from(records);
                // Entries expire in the order they were made.
                let h = self.exchange.horizon();
                while self
                    .empties
                    .front()
                    .is_some_and(|e| passed(now, e.until, h))
                {
                    self.empties.pop_front();
                }
                if records == 0 {
                    self.last_empty = Some(now);
                    let until = now.wrapping_add(self.cfg.exchange.duplicate_window_ms);
                    if self.empties.is_full() {
                        self.empties.pop_front();
                    }
                    let _ = self.empties.push_back(EmptyWindow {
                        head: window.0,
                        asked: window.1,
                        until,
                    });
                }
                ReadEvent::Answered { records }
            }
            Offer::Rejected(code) => ReadEvent::Rejected { code },
            Offer::Mismatch | Offer::Stale => {
                self.stats.stale_replies += 1;
                self.duplicates_seen = true;
                if let Some(n) = seen.first_record {
                    self.reopen(n, now);
                }
                ReadEvent::Stale
            }
            Offer::Foreign => {
                self.stats.ignored += 1;
                ReadEvent::Foreign
            }
        }
    }

    /// A reply that is not the awaited one holds a record of a window that
    /// was answered empty: that answer was a duplicate; read it again.
    fn reopen(&mut self, number: u16, now: u32) {
        let n = u32::from(number);
        let h = self.exchange.horizon();
        let hit = self.empties.iter().position(|e| {
            !passed(now, e.until, h) && n >= e.head && n < e.head + u32::from(e.asked)
        });
        let Some(i) = hit else { return };
        let mut kept = heapless::Deque::new();
        for (j, w) in self.empties.iter().enumerate() {
            if j == i {
                // Reopened once: one surplus reply, one re-read.
                if self.rereads.push_back((w.head, w.asked)).is_ok() {
                    self.stats.rereads += 1;
                }
            } else {
                let _ = kept.push_back(*w);
            }
        }
        self.empties = kept;
    }

    /// Feeds all of `bytes` until the window's reply is complete or the
    /// bytes run out; returns the bytes used (the rest follow the reply).
    pub fn received_all(&mut self, bytes: &[u8], now: u32) -> usize {
        let mut used = 0;
        loop {
            let r = self.received(bytes.get(used..).unwrap_or(&[]), now);
            used += r.consumed;
            match r.event {
                ReadEvent::NeedMore | ReadEvent::Answered { .. } => return used,
                _ => {}
            }
        }
    }

    fn build_query(&mut self, reread: Option<(u32, u16)>) -> Result<(), Error> {
        let cfg = self.cfg;
        let (head, asked) = match reread {
            Some(w) => w,
            None => {
                let left = u32::from(cfg.last) + 1 - self.head;
                (self.head, left.min(u32::from(self.window_limit)) as u16)
            }
        };
        self.rereading = reread.is_some();
        self.first_reply = None;
        self.current_head = head;
        self.asked = asked.max(1);
        self.write_query()
    }

    fn write_query(&mut self) -> Result<(), Error> {
        let cfg = self.cfg;
        let mut w = Writer::new(&mut self.query);
        emit_envelope(&mut w, Header::Command, cfg.exchange.station, cfg.stream.id)?;
        let head16 =
            u16::try_from(self.current_head).map_err(|_| Error::ValueOutOfRange { offset: 6 })?;
        cfg.stream.write_query(&mut w, head16, self.asked)?;
        emit_trailer(&mut w, ChecksumMode::Compute)?;
        self.query_len = w.len();
        Ok(())
    }

    /// A query timed out: ask the same head for half the window (a long
    /// reply is more likely hit by noise). A reply to the larger window
    /// still answers it exactly: it lists every record of the smaller one.
    fn shrink(&mut self) {
        if self.asked > 1 {
            self.asked /= 2;
            self.window_limit = self.asked;
            if self.write_query().is_err() {
                self.state = State::Failed(TransferError::Config(Error::BufferTooSmall));
            }
        }
    }
}

/// The exchange settings without the duplicate window: the read-back
/// applies that itself, only where a duplicate could pass for an answer
/// and only once the line has shown one (see the module docs).
const fn own_duplicates(mut cfg: ExchangeConfig) -> ExchangeConfig {
    cfg.duplicate_window_ms = 0;
    cfg
}

/// 32-bit FNV-1a: tells two replies apart (a confirmed read compares the
/// hashes of consecutive replies, not kept copies of them).
fn fnv1a(bytes: &[u8]) -> u32 {
    bytes.iter().fold(0x811C_9DC5, |h, &b| {
        (h ^ u32::from(b)).wrapping_mul(0x0100_0193)
    })
}

impl<const N: usize> ReadBack<N> {
    /// Reads every window over a UART, blocking, handing each window's
    /// records to `sink` as they come.
    pub fn run_blocking<U, C>(
        &mut self,
        uart: &mut U,
        clock: &mut C,
        sink: impl FnMut(ReplyRecords<'_>),
    ) -> Result<ReadBackStats, TransferError<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: crate::clock::Clock,
    {
        let mut reading = Reading { rb: self, sink };
        drive::run_blocking(&mut reading, uart, clock).map_err(TransferError::from_stop)
    }

    /// [`ReadBack::run_blocking`] over an `embedded-io-async` UART,
    /// sleeping at most `poll_ms` between checks while it waits.
    #[cfg(feature = "async")]
    pub async fn run_async<U, C>(
        &mut self,
        uart: &mut U,
        clock: &mut C,
        poll_ms: u32,
        sink: impl FnMut(ReplyRecords<'_>),
    ) -> Result<ReadBackStats, TransferError<U::Error>>
    where
        U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
        C: crate::clock::AsyncClock,
    {
        let mut reading = Reading { rb: self, sink };
        drive::run_async(&mut reading, uart, clock, poll_ms)
            .await
            .map_err(TransferError::from_stop)
    }
}

/// A read-back with somewhere to put its records: what the flavours drive.
struct Reading<'r, const N: usize, F> {
    rb: &'r mut ReadBack<N>,
    sink: F,
}

impl<const N: usize, F: FnMut(ReplyRecords<'_>)> Engine for Reading<'_, N, F> {
    type Output = ReadBackStats;
    type Error = TransferError;
    fn feed(&mut self, bytes: &[u8], now: u32) {
        // What follows a window's reply arrived before the next query was
        // sent: it can be no reply to it.
        self.rb.received_all(bytes, now);
    }
    fn want(&mut self, now: u32) -> Want<'_, Result<ReadBackStats, TransferError>> {
        match self.rb.poll(now) {
            ReadStep::Transmit(bytes) => Want::Transmit(bytes),
            ReadStep::WaitUntil(t) => Want::WaitUntil(t),
            ReadStep::Records(records) => {
                (self.sink)(records);
                Want::WaitUntil(now)
            }
            ReadStep::Complete(stats) => Want::Done(Ok(stats)),
            ReadStep::Failed(e) => Want::Done(Err(e)),
        }
    }
    fn sent(&mut self, now: u32) {
        self.rb.sent(now);
    }
}

/// What [`ReadBack`] needs of a frame after the decoder moves on.
#[derive(Debug, Clone, Copy)]
struct Seen {
    header: Header,
    station: Station,
    code: u16,
    /// Records, if it is a valid reply to the window in flight.
    check: Option<u16>,
    /// The first record's position, if it is a reply holding records.
    first_record: Option<u16>,
}

impl Seen {
    fn of(cfg: &ReadBackConfig, window: (u32, u16), f: &Frame<'_>) -> Self {
        let first_record = (f.header() == Header::Response && f.code() == cfg.stream.id)
            .then(|| {
                let mut r = f.reader();
                let (_, count) = cfg.stream.read_prefix(&mut r).ok()?;
                if count == 0 {
                    return None;
                }
                cfg.stream
                    .layout
                    .read_record(&mut r)
                    .ok()
                    .map(|rec| rec.number)
            })
            .flatten();
        Seen {
            header: f.header(),
            station: f.station(),
            code: f.code(),
            check: check_reply(cfg, window, f),
            first_record,
        }
    }
}

/// Checks a frame as the reply to the query of window `(head, asked)`:
/// the number of records if it is one.
fn check_reply(cfg: &ReadBackConfig, (head, asked): (u32, u16), f: &Frame<'_>) -> Option<u16> {
    if f.header() != Header::Response || f.code() != cfg.stream.id {
        return None;
    }
    let mut r = f.reader();
    let (_, count) = cfg.stream.read_prefix(&mut r).ok()?;
    if count > asked {
        return None;
    }
    let end = head + u32::from(asked);
    for _ in 0..count {
        let rec = cfg.stream.layout.read_record(&mut r).ok()?;
        let n = u32::from(rec.number);
        if n < head || n >= end {
            return None;
        }
    }
    r.finish().ok()?;
    Some(count)
}
