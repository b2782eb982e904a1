//! Reading a position table back, window by window, with the position
//! queries (21FH; 22DH, and 209H for 3-digit tables).
//!
//! Each query asks for a window of position numbers; the controller returns
//! the defined records in it. Windows are sized so that a reply always
//! fits the controller's transmit buffer (24 records of 8 axes in a
//! 2,048-byte 21FH reply), so a short reply means "fewer defined records",
//! never "cut off"; they halve after a timeout and grow back after answers
//! (one planner with the transfer's read-back). A reply counts only if the line takes it
//! ([`crate::line`]): its SC, station and ID check out, it holds no more
//! records than asked, every record lies in the window, and nothing that
//! may still arrive could have passed for it.
//!
//! # Confirmed reads
//! The 8-bit SC lets some corruptions through (two bit flips that cancel).
//! With [`ReadBackConfig::confirm`] (the default) a window is delivered only
//! when two replies agree byte for byte, and the second provably answers
//! its own query: it is sent when no copy of any earlier reply that could
//! pass for it may still arrive. A first read may be answered by anything
//! the confirmation then rejects, so first reads of the next windows go on
//! while a confirmation waits; windows are still delivered in order. On a
//! line with a duplicate window, a window read empty waits out that window
//! before its confirmation (every empty reply looks alike).
//!
//! # Proven windows
//! A line that declared no copies may still repeat frames (a converter
//! nobody mentioned): a copy of an earlier reply can answer a query, and
//! the real reply then comes when nothing awaits it. So before a window is
//! delivered, a fence ([`Line::start_proof`]) is sent after its last reply:
//! once its echo is back, every reply owed before it has arrived. If the
//! line heard nothing it could not place since the last proof, the
//! window's replies were its own; otherwise every reply taken since is
//! read again, now that the line expects copies ([`Failure::Unconfirmed`]
//! after [`MAX_RECONFIRMS`] rounds).
//!
//! RAM: the reply decoder (`N` bytes, default 2,048, the TTA's transmit
//! limit), a 24-byte query, up to 16 windows in flight and counters.

use crate::clock::Clock;
use crate::decoder::{Received, Status};
use crate::engine::{self, Engine, Step};
use crate::error::{Error, Failure};
use crate::field::Reader;
use crate::frame::{Frame, Header};
use crate::limits;
use crate::line::{fingerprint, Claim, Command, Due, Heard, Judge, Line, Receiver, Span, Verdict};
use crate::position::{PositionRecord, PositionStream};
use crate::profile::Profile;
use crate::window::{write_query, Windows, QUERY_LEN};

/// Settings of a read-back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReadBackConfig {
    /// The query's response layout: [`PositionStream::QUERY_2_RESPONSE`]
    /// (21FH), `QUERY_3_RESPONSE` (22DH) or `QUERY_RESPONSE` (209H).
    pub stream: PositionStream,
    /// First position number to read.
    pub first: u16,
    /// Last position number to read (inclusive).
    pub last: u16,
    /// Largest response frame the controller sends (TTA 2,048).
    pub max_response: usize,
    /// Deliver a window only when two replies agree (see the module docs).
    /// Doubles the wire time.
    pub confirm: bool,
}

impl ReadBackConfig {
    /// Positions `first..=last` from a controller of `profile`, with the
    /// query that reads back its table write (21FH on a TTA, 209H on a
    /// 2003 X-SEL), confirmed.
    pub const fn new(profile: Profile, first: u16, last: u16) -> Self {
        ReadBackConfig {
            stream: profile.table_write().read_back(),
            first,
            last,
            max_response: profile.max_response_frame(),
            confirm: true,
        }
    }

    /// Positions asked per query at most: as many 8-axis records as fit a
    /// reply.
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
    /// Records delivered.
    pub records: u32,
    /// Queries sent again after a timeout.
    pub retries: u32,
    /// Timeouts.
    pub timeouts: u32,
    /// Replies that came when none was awaited, or for another window.
    pub stale_replies: u32,
    /// Windows delivered after two replies agreed.
    pub windows_confirmed: u32,
    /// Confirming reads whose reply differed from the read before.
    pub disagreements: u32,
    /// Frames that were no reply to a query, and broken frames.
    pub ignored: u32,
    /// Times the windows in flight were read again because the line heard
    /// frames it could not place (see the module docs).
    pub reconfirmed: u32,
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

/// Windows queued at once by default: first reads that keep the line busy
/// while the oldest window's confirmation waits out a duplicate window.
/// 48 windows of 24 8-axis records (about 2,000 bytes each with the
/// query) take about 8.3 s at 115,200 baud, an 8 s window; the fault
/// suite's read with 10 % copies up to 8 s late took 1.98x the clean run
/// with 48, 3.01x with 16. An engine that reads one window at a time
/// needs 2.
pub const QUEUED: usize = 48;

/// Rounds of reading again after a proof found frames the line could not
/// place, before the read-back gives up ([`Failure::Unconfirmed`]).
pub const MAX_RECONFIRMS: u8 = 8;

/// A window of the queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Window {
    head: u32,
    asked: u16,
    /// The hash of a reply that awaits its confirmation.
    first: Option<u32>,
}

impl Window {
    fn span(&self) -> Span {
        Span {
            lo: self.head as u16,
            hi: (self.head + u32::from(self.asked.max(1)) - 1) as u16,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Choosing the next query.
    Plan,
    /// The query of window `at` of the queue is on the line; `confirming`
    /// if its reply is to confirm (or, unconfirmed, to be delivered).
    Query {
        at: usize,
        delivers: bool,
    },
    /// The front window's last reply is taken: a fence proves that no
    /// copy stood in for one of its replies; `started` once it is asked.
    Prove {
        started: bool,
    },
    /// The front window's reply is to be delivered.
    Deliver,
    Complete,
    Failed(Failure),
}

/// Reads positions `first..=last` back, window by window: replies of up to
/// `N` bytes, `Q` windows queued at once ([`QUEUED`]).
pub struct ReadBack<const N: usize = { limits::TTA.response }, const Q: usize = QUEUED> {
    cfg: ReadBackConfig,
    /// First position not queued yet; `u32` so that it can pass 0xFFFF.
    next: u32,
    queue: heapless::Deque<Window, Q>,
    windows: Windows,
    query: [u8; QUERY_LEN],
    query_len: usize,
    replies: Receiver<N>,
    /// Hash and records of the reply taken last.
    answer: Option<(u32, u16)>,
    /// The line's count of unplaced frames at the last proof (or start).
    proven: Option<u32>,
    /// Rounds read again since the last window was delivered.
    reconfirms: u8,
    state: State,
    stats: ReadBackStats,
}

impl<const N: usize, const Q: usize> ReadBack<N, Q> {
    /// A read-back with these settings.
    pub fn new(cfg: ReadBackConfig) -> Self {
        ReadBack {
            cfg,
            next: u32::from(cfg.first),
            queue: heapless::Deque::new(),
            windows: Windows::new(cfg.window()),
            query: [0; QUERY_LEN],
            query_len: 0,
            replies: Receiver::new(),
            answer: None,
            proven: None,
            reconfirms: 0,
            state: State::Plan,
            stats: ReadBackStats::default(),
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> ReadBackStats {
        self.stats
    }

    /// Decides the next step at tick `now`: a query to send, a wait, or the
    /// records of the next window in order (`Done(Ok(Some(records)))`;
    /// poll again to go on), until `Done(Ok(None))` after the last one.
    pub fn poll<'a>(
        &'a mut self,
        line: &'a mut Line,
        now: u32,
    ) -> Step<'a, Option<ReplyRecords<'a>>> {
        loop {
            match self.state {
                State::Plan => self.plan(line, now),
                State::Query { at, delivers } => match line.poll(now) {
                    Due::Fence => return Step::Transmit(line.fence_bytes()),
                    Due::Send { fresh } => {
                        if fresh {
                            self.replies.clear(line, now);
                            self.answer = None;
                            if line.sends() > 1 {
                                self.stats.retries += 1;
                                self.stats.timeouts += 1;
                                self.split(line, at);
                            }
                        }
                        return Step::Transmit(self.query.get(..self.query_len).unwrap_or(&[]));
                    }
                    Due::WaitUntil(t) => return Step::WaitUntil(t),
                    Due::Done(Ok(())) => self.answered(at, delivers),
                    Due::Done(Err(e)) => {
                        if !matches!(e, Failure::Controller { .. }) {
                            self.stats.timeouts += 1;
                        }
                        self.state = State::Failed(e);
                    }
                    Due::Idle => {
                        self.state = State::Failed(Failure::Timeout {
                            sends: line.sends(),
                        })
                    }
                },
                State::Prove { started: false } => {
                    line.start_proof(now);
                    self.state = State::Prove { started: true };
                }
                State::Prove { started: true } => match line.poll(now) {
                    Due::Fence => return Step::Transmit(line.fence_bytes()),
                    Due::WaitUntil(t) => return Step::WaitUntil(t),
                    Due::Done(Ok(())) => self.proved(line),
                    Due::Done(Err(e)) => self.state = State::Failed(e),
                    // Another engine took the line meanwhile: prove again.
                    Due::Send { .. } | Due::Idle => self.state = State::Prove { started: false },
                },
                State::Deliver => {
                    self.state = State::Plan;
                    self.reconfirms = 0;
                    self.windows.grow();
                    let Some(w) = self.queue.pop_front() else {
                        continue;
                    };
                    let stream = self.cfg.stream;
                    // The reply was checked on arrival; an empty list if it
                    // vanished.
                    let (r, left) = match self.replies.reply() {
                        Some(frame) => {
                            let mut r = frame.reader();
                            let count = stream.read_prefix(&mut r).map_or(0, |(_, c)| c);
                            (r, count)
                        }
                        None => (Reader::new(&[], 0), 0),
                    };
                    self.stats.records += u32::from(left);
                    return Step::Done(Ok(Some(ReplyRecords {
                        r,
                        left,
                        stream,
                        head: w.head as u16,
                        asked: w.asked,
                    })));
                }
                State::Complete => return Step::Done(Ok(None)),
                State::Failed(e) => return Step::Done(Err(e)),
            }
        }
    }

    /// Chooses the next query: the front window's confirmation once no
    /// copy could pass for it, else a first read of a window not read yet
    /// (queuing the next one), else the front's confirmation anyway (the
    /// line holds it until it is clear).
    fn plan(&mut self, line: &mut Line, now: u32) {
        if self.proven.is_none() {
            self.proven = Some(line.stats().unplaced);
        }
        let Some(front) = self.queue.front().copied() else {
            if !self.push_next() {
                self.state = State::Complete;
            }
            return;
        };
        if !self.cfg.confirm {
            self.begin(line, 0, Claim::Proof, true, now);
            return;
        }
        let id = self.cfg.stream.id;
        let confirmable = front.first.is_some();
        if confirmable && line.clear_at(id, front.span(), Claim::Proof, now) == now {
            self.begin(line, 0, Claim::Proof, true, now);
            return;
        }
        let unread = self.queue.iter().position(|w| w.first.is_none());
        let at = match unread {
            Some(at) => Some(at),
            None if self.push_next() => Some(self.queue.len() - 1),
            None => None,
        };
        match at {
            Some(at) => self.begin(line, at, Claim::Tentative, false, now),
            None => self.begin(line, 0, Claim::Proof, true, now),
        }
    }

    /// Queues the next window; `false` when every position is queued or
    /// the queue is full.
    fn push_next(&mut self) -> bool {
        let last = u32::from(self.cfg.last);
        if self.next > last || self.queue.is_full() {
            return false;
        }
        let asked = self.windows.span(last + 1 - self.next);
        let w = Window {
            head: self.next,
            asked,
            first: None,
        };
        self.next += u32::from(asked);
        self.queue.push_back(w).is_ok()
    }

    /// Starts the query of window `at` of the queue.
    fn begin(&mut self, line: &mut Line, at: usize, claim: Claim, delivers: bool, now: u32) {
        let Some(w) = self.queue.iter().nth(at).copied() else {
            self.state = State::Plan;
            return;
        };
        if let Err(e) = self.write_query(line, &w) {
            self.state = State::Failed(Failure::Protocol(e));
            return;
        }
        let cmd = Command::of(self.cfg.stream.id, w.span(), claim, line.config().max_sends);
        line.begin(cmd, now);
        self.state = State::Query { at, delivers };
    }

    fn write_query(&mut self, line: &Line, w: &Window) -> Result<(), Error> {
        let (station, checksum) = (line.config().station, line.config().checksum);
        let head = u16::try_from(w.head).map_err(|_| Error::ValueOutOfRange { offset: 6 })?;
        self.query_len = write_query(
            self.cfg.stream,
            station,
            checksum,
            head,
            w.asked,
            &mut self.query,
        )?;
        Ok(())
    }

    /// The query of window `at` timed out: ask its first half (a long reply
    /// is more likely hit by noise) and queue the rest right after it. A
    /// reply of the larger window still answers the smaller one exactly.
    fn split(&mut self, line: &mut Line, at: usize) {
        let Some(w) = self.queue.iter().nth(at).copied() else {
            return;
        };
        if w.asked <= 1 || self.queue.is_full() {
            return;
        }
        let half = self.windows.shrink(w.asked);
        let first = Window {
            asked: half,
            first: None,
            ..w
        };
        let rest = Window {
            head: w.head + u32::from(half),
            asked: w.asked - half,
            first: None,
        };
        // Rebuild the queue with the window split in place.
        let mut queue = heapless::Deque::new();
        for (i, x) in self.queue.iter().enumerate() {
            if i == at {
                let _ = queue.push_back(first);
                let _ = queue.push_back(rest);
            } else {
                let _ = queue.push_back(*x);
            }
        }
        self.queue = queue;
        if self.write_query(line, &first).is_ok() {
            line.accept(first.span());
        }
        if let State::Query { delivers, .. } = self.state {
            // A confirmation of the larger window confirms nothing now.
            self.state = State::Query {
                at,
                delivers: delivers && !self.cfg.confirm,
            };
        }
    }

    /// The query of window `at` was answered.
    fn answered(&mut self, at: usize, delivers: bool) {
        let Some((hash, _)) = self.answer else {
            self.state = State::Plan;
            return;
        };
        self.stats.queries += 1;
        let Some(w) = self.queue.iter_mut().nth(at) else {
            self.state = State::Plan;
            return;
        };
        if !delivers {
            w.first = Some(hash);
            self.windows.grow();
            self.state = State::Plan;
            return;
        }
        if !self.cfg.confirm {
            self.state = State::Prove { started: false };
            return;
        }
        if w.first == Some(hash) {
            self.stats.windows_confirmed += 1;
            self.state = State::Prove { started: false };
        } else {
            // This reply is provable: the next must agree with it.
            self.stats.disagreements += 1;
            w.first = Some(hash);
            self.state = State::Plan;
        }
    }

    /// The proof's echo is back: deliver the front window if nothing
    /// unplaced came since the last proof; else read again every window
    /// whose replies were taken since (the line now expects copies).
    fn proved(&mut self, line: &Line) {
        let unplaced = line.stats().unplaced;
        if self.proven.is_none_or(|p| p == unplaced) {
            self.proven = Some(unplaced);
            self.state = State::Deliver;
            return;
        }
        self.proven = Some(unplaced);
        self.reconfirms = self.reconfirms.saturating_add(1);
        self.stats.reconfirmed += 1;
        if self.reconfirms > MAX_RECONFIRMS {
            self.state = State::Failed(Failure::Unconfirmed { unplaced });
            return;
        }
        for w in self.queue.iter_mut() {
            w.first = None;
        }
        self.state = State::Plan;
    }

    /// The query was completely transmitted at `now`.
    pub fn sent(&mut self, line: &mut Line, now: u32) {
        line.sent(now);
    }

    /// After a failure: ask the same window again, with a fresh count of
    /// sends (what the failed query may still bring is the line's to
    /// settle).
    pub fn resume(&mut self) {
        if let State::Failed(e) = self.state {
            if !matches!(e, Failure::Protocol(_)) {
                self.state = State::Plan;
            }
        }
    }

    /// Bytes received at `now`. Returns at the first frame (or broken
    /// one); a reply to be delivered stays in the receiver until the next
    /// `poll` delivers it.
    pub fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        let (window, delivers) = match self.state {
            State::Query { at, delivers } => (self.queue.iter().nth(at).copied(), delivers),
            _ => (None, false),
        };
        let mut judge = WindowCheck {
            cfg: &self.cfg,
            window,
            delivers,
            judged: None,
        };
        let r = self.replies.receive(line, &mut judge, bytes, now);
        let judged = judge.judged;
        match r.status {
            Status::Complete(Heard::Answer) => self.answer = judged,
            Status::Complete(Heard::Mismatch | Heard::Stale | Heard::Unplaced) => {
                self.stats.stale_replies += 1
            }
            Status::Complete(Heard::Foreign | Heard::Broken(_)) => self.stats.ignored += 1,
            _ => {}
        }
        r
    }
}

/// A read-back's check of a reply: the records it carries lie in the
/// window asked, no more than asked.
struct WindowCheck<'c> {
    cfg: &'c ReadBackConfig,
    window: Option<Window>,
    delivers: bool,
    /// The fingerprint and record count of the last reply judged to fit.
    judged: Option<(u32, u16)>,
}

impl Judge for WindowCheck<'_> {
    fn judge(&mut self, f: &Frame<'_>) -> Verdict {
        let (check, values) = check_reply(self.cfg, self.window, f);
        self.judged = check.map(|n| (fingerprint(f.as_bytes()), n));
        Verdict {
            fits: check.is_some(),
            values,
            keep: self.delivers,
        }
    }
}

/// Checks a frame as the reply to the query of `window`: its number of
/// records if it is one, and the positions it carries (for the ledger).
fn check_reply(cfg: &ReadBackConfig, window: Option<Window>, f: &Frame<'_>) -> (Option<u16>, Span) {
    if f.header() != Header::Response || f.code() != cfg.stream.id {
        return (None, Span::UNKNOWN);
    }
    let mut r = f.reader();
    let Ok((_, count)) = cfg.stream.read_prefix(&mut r) else {
        return (None, Span::UNKNOWN);
    };
    let mut carried = Span::UNKNOWN;
    for _ in 0..count {
        let Ok(rec) = cfg.stream.layout.read_record(&mut r) else {
            return (None, Span::UNKNOWN);
        };
        let n = rec.number;
        carried = if carried == Span::UNKNOWN {
            Span::one(n)
        } else {
            Span {
                lo: carried.lo.min(n),
                hi: carried.hi.max(n),
            }
        };
    }
    if r.finish().is_err() {
        return (None, Span::UNKNOWN);
    }
    let fits = window.is_some_and(|w| count <= w.asked && carried.within(w.span()));
    (fits.then_some(count), carried)
}

impl<const N: usize, const Q: usize> ReadBack<N, Q> {
    /// Reads every window over a UART, blocking, handing each window's
    /// records to `sink` as they come, in order.
    pub fn run_blocking<U, C>(
        &mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
        sink: impl FnMut(ReplyRecords<'_>),
    ) -> Result<ReadBackStats, Failure<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        engine::run_blocking(&mut self.delivering(sink), line, uart, clock)
    }

    /// This read-back as an [`Engine`] that hands each window's records to
    /// `sink`, in order, and ends with the counters: what a driver loop
    /// runs.
    pub fn delivering<'r, F: FnMut(ReplyRecords<'_>) + 'r>(
        &'r mut self,
        sink: F,
    ) -> impl Engine<Output = ReadBackStats> + 'r {
        Reading { rb: self, sink }
    }

    /// [`ReadBack::run_blocking`] over an `embedded-io-async` UART,
    /// sleeping at most `poll_ms` between checks while it waits.
    #[cfg(feature = "async")]
    pub async fn run_async<U, C>(
        &mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
        poll_ms: u32,
        sink: impl FnMut(ReplyRecords<'_>),
    ) -> Result<ReadBackStats, Failure<U::Error>>
    where
        U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
        C: crate::clock::AsyncClock,
    {
        engine::run_async(&mut self.delivering(sink), line, uart, clock, poll_ms).await
    }
}

/// A read-back with somewhere to put its records: what the loops drive.
struct Reading<'r, const N: usize, const Q: usize, F> {
    rb: &'r mut ReadBack<N, Q>,
    sink: F,
}

impl<const N: usize, const Q: usize, F: FnMut(ReplyRecords<'_>)> Engine for Reading<'_, N, Q, F> {
    type Output = ReadBackStats;
    fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, ReadBackStats> {
        if self.rb.state == State::Complete {
            return Step::Done(Ok(self.rb.stats));
        }
        match self.rb.poll(line, now) {
            Step::Transmit(bytes) => Step::Transmit(bytes),
            Step::WaitUntil(t) => Step::WaitUntil(t),
            Step::Idle => Step::Idle,
            Step::Done(Ok(Some(records))) => {
                (self.sink)(records);
                Step::WaitUntil(now)
            }
            // Complete: the next poll gives the counters.
            Step::Done(Ok(None)) => Step::WaitUntil(now),
            Step::Done(Err(e)) => Step::Done(Err(e)),
        }
    }
    fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        self.rb.received(line, bytes, now)
    }
    fn sent(&mut self, line: &mut Line, now: u32) {
        self.rb.sent(line, now);
    }
}

#[cfg(test)]
mod tests;
