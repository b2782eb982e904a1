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
//! With [`ReadBackConfig::confirm`] (the default) every record is read
//! twice and delivered only when both replies agree on it, and the second
//! provably answers its own query: it is sent when no reply that may still
//! arrive could pass for it. Each window is read once ("first read"); the
//! query whose reply is delivered starts at the first position not
//! delivered and ends at the middle or the end of a window read, so that
//! its records are compared half window by half window with the first
//! reads' (a fingerprint per half). On a line that repeats frames a copy of
//! a first read could pass for a second read of the same window, but not
//! for one shifted by half a window: the same records, asked by a question
//! no earlier reply answers. The engine asks the longest such query that
//! nothing could pass for, first reading ahead so that it can span a whole
//! window; windows are still delivered in order. Only when every choice
//! could still be answered by a copy (a window read empty: every empty
//! reply looks alike) does the line wait the copies out. While a reply is
//! kept for delivery, replies that pass meanwhile (copies, late ones) are
//! read as they stream by, so that the line knows which positions their
//! own copies would carry.
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
//! limit), a position-stream decoder for replies passing while one is
//! kept, a 24-byte query, `Q` windows in flight ([`QUEUED`]) and counters.

use crate::checksum::BypassPolicy;
use crate::clock::Clock;
use crate::decoder::{Received, Status};
use crate::engine::{self, Engine, Step};
use crate::error::{Error, Failure};
use crate::field::Reader;
use crate::frame::{Frame, Header, Station};
use crate::limits;
use crate::line::{
    fingerprint_more, Claim, Command, Due, Heard, Judge, Line, Receiver, Span, Verdict,
    FINGERPRINT_START,
};
use crate::position::{PositionRecord, PositionStream};
use crate::profile::Profile;
use crate::table::{PositionStreamDecoder, StreamEvent};
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

/// Windows queued at once by default: a confirmation spans at most two
/// windows' halves, and a window split after a timeout takes one more
/// place. An engine that reads one window at a time needs 2.
pub const QUEUED: usize = 4;

/// Rounds of reading again after a proof found frames the line could not
/// place, before the read-back gives up ([`Failure::Unconfirmed`]).
pub const MAX_RECONFIRMS: u8 = 8;

/// A window of the queue: positions `head..head + asked`, read first by
/// one query; confirmations compare its halves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Window {
    head: u32,
    asked: u16,
    /// The fingerprints of the records its first reply carried in each
    /// half (`head..mid`, `mid..end`), once read.
    prints: Option<[u32; 2]>,
}

impl Window {
    /// Where its second half begins.
    fn mid(&self) -> u32 {
        self.head + u32::from(self.asked / 2)
    }
    /// The first position after it.
    fn end(&self) -> u32 {
        self.head + u32::from(self.asked.max(1))
    }
    /// Its halves, as position ranges `lo..hi` (the first is empty for a
    /// window of one position).
    fn halves(&self) -> [(u32, u32); 2] {
        [(self.head, self.mid()), (self.mid(), self.end())]
    }
}

/// Positions `lo..hi` (`lo < hi`) as a span.
fn span(lo: u32, hi: u32) -> Span {
    Span {
        lo: lo as u16,
        hi: hi.saturating_sub(1) as u16,
    }
}

/// A query of the read-back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ask {
    /// The first read of window `at` of the queue.
    First { at: usize },
    /// The query whose reply is delivered once it agrees with the first
    /// reads (or, unconfirmed, at once): positions `lo..hi`.
    Deliver { lo: u32, hi: u32 },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Choosing the next query.
    Plan,
    /// The query is on the line.
    Query(Ask),
    /// The reply of positions `lo..hi` is to be delivered: a fence proves
    /// that no copy stood in for one of the replies it rests on; `started`
    /// once it is asked.
    Prove {
        started: bool,
        lo: u32,
        hi: u32,
    },
    /// The reply of positions `lo..hi` is to be delivered.
    Deliver {
        lo: u32,
        hi: u32,
    },
    Complete,
    Failed(Failure),
}

/// Reads positions `first..=last` back, window by window: replies of up to
/// `N` bytes, `Q` windows queued at once ([`QUEUED`]).
pub struct ReadBack<const N: usize = { limits::TTA.response }, const Q: usize = QUEUED> {
    cfg: ReadBackConfig,
    /// First position not queued yet; `u32` so that it can pass 0xFFFF.
    next: u32,
    /// First position not delivered yet.
    delivered: u32,
    queue: heapless::Deque<Window, Q>,
    windows: Windows,
    query: [u8; QUERY_LEN],
    query_len: usize,
    replies: Receiver<N>,
    /// Replies heard while one is kept for delivery.
    passing: Passing,
    /// The reply taken last: its records, and for a first read the
    /// fingerprints of its window's halves.
    answer: Option<[u32; 2]>,
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
            delivered: u32::from(cfg.first),
            queue: heapless::Deque::new(),
            windows: Windows::new(cfg.window()),
            query: [0; QUERY_LEN],
            query_len: 0,
            replies: Receiver::new(),
            passing: Passing::new(),
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
                State::Query(ask) => match line.poll(now) {
                    Due::Fence => return Step::Transmit(line.fence_bytes()),
                    Due::Send { fresh } => {
                        if fresh {
                            self.passing.stop(line, self.cfg.stream, now);
                            self.replies.clear(line, now);
                            self.answer = None;
                            if line.sends() > 1 {
                                self.stats.retries += 1;
                                self.stats.timeouts += 1;
                                self.split(line, ask);
                            }
                        }
                        return Step::Transmit(self.query.get(..self.query_len).unwrap_or(&[]));
                    }
                    Due::WaitUntil(t) => return Step::WaitUntil(t),
                    Due::Done(Ok(())) => self.answered(ask),
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
                State::Prove {
                    started: false,
                    lo,
                    hi,
                } => {
                    line.start_proof(now);
                    self.state = State::Prove {
                        started: true,
                        lo,
                        hi,
                    };
                }
                State::Prove { started: true, .. } => match line.poll(now) {
                    Due::Fence => return Step::Transmit(line.fence_bytes()),
                    Due::WaitUntil(t) => return Step::WaitUntil(t),
                    Due::Done(Ok(())) => self.proved(line),
                    Due::Done(Err(e)) => self.state = State::Failed(e),
                    // Another engine took the line meanwhile: prove again.
                    Due::Send { .. } | Due::Idle => {
                        if let State::Prove { lo, hi, .. } = self.state {
                            self.state = State::Prove {
                                started: false,
                                lo,
                                hi,
                            };
                        }
                    }
                },
                State::Deliver { lo, hi } => {
                    self.state = State::Plan;
                    self.reconfirms = 0;
                    self.windows.grow();
                    self.delivered = hi;
                    while self.queue.front().is_some_and(|w| w.end() <= hi) {
                        self.queue.pop_front();
                    }
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
                        head: lo as u16,
                        asked: hi.saturating_sub(lo) as u16,
                    })));
                }
                State::Complete => return Step::Done(Ok(None)),
                State::Failed(e) => return Step::Done(Err(e)),
            }
        }
    }

    /// Chooses the next query.
    fn plan(&mut self, line: &mut Line, now: u32) {
        if self.proven.is_none() {
            self.proven = Some(line.stats().unplaced);
        }
        if self.queue.is_empty() && !self.push_next() {
            self.state = State::Complete;
            return;
        }
        if !self.cfg.confirm {
            if let Some(w) = self.queue.front().copied() {
                let ask = Ask::Deliver {
                    lo: w.head,
                    hi: w.end(),
                };
                self.begin(line, ask, Claim::Proof, now);
            }
            return;
        }
        self.plan_confirmation(line, now);
    }

    /// Confirmed reads: the next confirmation starts at the first position
    /// not delivered and ends at a half of a window read once, at most a
    /// window long. Of those no copy could pass for, the longest; before
    /// it, the first reads that let it reach a whole window. A copy of a
    /// first read can pass for a confirmation of the same window, but not
    /// for one shifted by half a window: the same records, asked by a
    /// different question. Only when every choice could still be answered
    /// by a copy does a first read go ahead, or the line wait.
    fn plan_confirmation(&mut self, line: &mut Line, now: u32) {
        let id = self.cfg.stream.id;
        let from = self.delivered;
        let limit = u32::from(self.windows.span(u32::MAX));
        let mut reach = from;
        let mut longest_clear = None;
        let mut soonest: Option<(u32, u32)> = None;
        let mut unread = None;
        for (i, w) in self.queue.iter().enumerate() {
            if w.prints.is_none() {
                unread = Some(i);
                break;
            }
            for b in [w.mid(), w.end()] {
                // The first end is always a choice (a window queued before
                // the windows shrank may be longer than the limit).
                if b <= from || (b - from > limit && reach > from) {
                    continue;
                }
                reach = b;
                let at = line.clear_at(id, span(from, b), Claim::Proof, now);
                if at == now {
                    longest_clear = Some(b);
                } else if soonest.is_none_or(|(_, t)| at.wrapping_sub(now) <= t.wrapping_sub(now)) {
                    soonest = Some((b, at));
                }
            }
        }
        let end = u32::from(self.cfg.last) + 1;
        let short = reach < end && reach - from < limit;
        let read_ahead = |rb: &mut Self| match unread {
            Some(at) => Some(at),
            None if rb.push_next() => Some(rb.queue.len() - 1),
            None => None,
        };
        if short || longest_clear.is_none() {
            if let Some(at) = read_ahead(self) {
                self.begin(line, Ask::First { at }, Claim::Tentative, now);
                return;
            }
        }
        let hi = match (longest_clear, soonest) {
            (Some(b), _) | (None, Some((b, _))) => b,
            (None, None) => {
                // Nothing read and nothing to read: the queue is full of
                // windows read; start over from the first not delivered.
                self.restart_from(from, limit);
                return;
            }
        };
        self.begin(line, Ask::Deliver { lo: from, hi }, Claim::Proof, now);
    }

    /// Drops the queue and reads again from `from`, in windows of at most
    /// `asked` positions.
    fn restart_from(&mut self, from: u32, asked: u32) {
        self.queue.clear();
        self.next = from;
        let last = u32::from(self.cfg.last);
        if from > last {
            self.state = State::Complete;
            return;
        }
        let asked = asked.min(last + 1 - from).max(1) as u16;
        let _ = self.queue.push_back(Window {
            head: from,
            asked,
            prints: None,
        });
        self.next = from + u32::from(asked);
        self.state = State::Plan;
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
            prints: None,
        };
        self.next += u32::from(asked);
        self.queue.push_back(w).is_ok()
    }

    /// The positions `ask` reads, as `lo..hi`.
    fn range(&self, ask: Ask) -> Option<(u32, u32)> {
        match ask {
            Ask::First { at } => self.queue.iter().nth(at).map(|w| (w.head, w.end())),
            Ask::Deliver { lo, hi } => Some((lo, hi)),
        }
    }

    /// Starts the query `ask`.
    fn begin(&mut self, line: &mut Line, ask: Ask, claim: Claim, now: u32) {
        let Some((lo, hi)) = self.range(ask) else {
            self.state = State::Plan;
            return;
        };
        if let Err(e) = self.write_query(line, lo, hi) {
            self.state = State::Failed(Failure::Protocol(e));
            return;
        }
        let cmd = Command::of(
            self.cfg.stream.id,
            span(lo, hi),
            claim,
            line.config().max_sends,
        );
        line.begin(cmd, now);
        self.state = State::Query(ask);
    }

    fn write_query(&mut self, line: &Line, lo: u32, hi: u32) -> Result<(), Error> {
        let (station, checksum) = (line.config().station, line.config().checksum);
        let head = u16::try_from(lo).map_err(|_| Error::ValueOutOfRange { offset: 6 })?;
        let asked = u16::try_from(hi.saturating_sub(lo))
            .map_err(|_| Error::ValueOutOfRange { offset: 10 })?;
        self.query_len = write_query(
            self.cfg.stream,
            station,
            checksum,
            head,
            asked,
            &mut self.query,
        )?;
        Ok(())
    }

    /// The query `ask` timed out: ask fewer positions (a long reply is more
    /// likely hit by noise). A first read asks its window's first half and
    /// queues the rest right after it; a delivering query becomes the first
    /// read of a smaller window from the first position not delivered. A
    /// reply of the larger query still answers the smaller one exactly.
    fn split(&mut self, line: &mut Line, ask: Ask) {
        let at = match ask {
            Ask::First { at } => at,
            Ask::Deliver { lo, hi } if self.cfg.confirm => {
                let asked = hi.saturating_sub(lo) as u16;
                if asked <= 1 {
                    return;
                }
                let half = self.windows.shrink(asked);
                self.restart_from(lo, u32::from(half));
                if self.write_query(line, lo, lo + u32::from(half)).is_ok() {
                    line.accept(span(lo, lo + u32::from(half)));
                }
                self.state = State::Query(Ask::First { at: 0 });
                return;
            }
            Ask::Deliver { .. } => 0,
        };
        let Some(w) = self.queue.iter().nth(at).copied() else {
            return;
        };
        if w.asked <= 1 || self.queue.is_full() {
            return;
        }
        let half = self.windows.shrink(w.asked);
        let first = Window {
            asked: half,
            prints: None,
            ..w
        };
        let rest = Window {
            head: w.head + u32::from(half),
            asked: w.asked - half,
            prints: None,
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
        if self.write_query(line, first.head, first.end()).is_ok() {
            line.accept(span(first.head, first.end()));
        }
        if let Ask::Deliver { .. } = ask {
            self.state = State::Query(Ask::Deliver {
                lo: first.head,
                hi: first.end(),
            });
        }
    }

    /// The query `ask` was answered.
    fn answered(&mut self, ask: Ask) {
        let Some(prints) = self.answer else {
            self.state = State::Plan;
            return;
        };
        self.stats.queries += 1;
        let (lo, hi) = match ask {
            Ask::First { at } => {
                if let Some(w) = self.queue.iter_mut().nth(at) {
                    w.prints = Some(prints);
                }
                self.windows.grow();
                self.state = State::Plan;
                return;
            }
            Ask::Deliver { lo, hi } => (lo, hi),
        };
        if !self.cfg.confirm {
            self.state = State::Prove {
                started: false,
                lo,
                hi,
            };
            return;
        }
        // Every half the reply covers must agree with what was read of it.
        let stream = self.cfg.stream;
        let mut agree = true;
        if let Some(frame) = self.replies.reply() {
            for w in self.queue.iter_mut() {
                let halves = w.halves();
                let Some(known) = w.prints.as_mut() else {
                    continue;
                };
                for (print, (a, b)) in known.iter_mut().zip(halves) {
                    if a < b && lo <= a && b <= hi {
                        let seen = records_print(stream, &frame, a, b);
                        if seen != *print {
                            // This reply is provable: the next must agree.
                            agree = false;
                            *print = seen;
                        }
                    }
                }
            }
        }
        if agree {
            self.stats.windows_confirmed += 1;
            self.state = State::Prove {
                started: false,
                lo,
                hi,
            };
        } else {
            self.stats.disagreements += 1;
            self.state = State::Plan;
        }
    }

    /// The proof's echo is back: deliver the reply if nothing unplaced came
    /// since the last proof; else read everything not delivered again from
    /// its first read (the line now expects copies).
    fn proved(&mut self, line: &Line) {
        let State::Prove { lo, hi, .. } = self.state else {
            return;
        };
        let unplaced = line.stats().unplaced;
        if self.proven.is_none_or(|p| p == unplaced) {
            self.proven = Some(unplaced);
            self.state = State::Deliver { lo, hi };
            return;
        }
        self.proven = Some(unplaced);
        self.reconfirms = self.reconfirms.saturating_add(1);
        self.stats.reconfirmed += 1;
        // Nothing read since the last proof is trusted, after a resume too.
        let limit = u32::from(self.windows.span(u32::MAX));
        self.restart_from(self.delivered, limit);
        if self.reconfirms > MAX_RECONFIRMS {
            self.state = State::Failed(Failure::Unconfirmed { unplaced });
        }
    }

    /// Whether the reply to the query on the line is the one to deliver (a
    /// confirmation, or any query of an unconfirmed read-back): it is kept
    /// until delivered.
    pub fn delivers(&self) -> bool {
        matches!(self.state, State::Query(Ask::Deliver { .. }))
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
        if self.replies.reply().is_some() {
            return self.overhear(line, bytes, now);
        }
        let (asked, first) = match self.state {
            State::Query(ask) => (
                self.range(ask),
                match ask {
                    Ask::First { at } => self.queue.iter().nth(at).copied(),
                    Ask::Deliver { .. } => None,
                },
            ),
            _ => (None, None),
        };
        let mut judge = WindowCheck {
            cfg: &self.cfg,
            asked,
            first,
            judged: None,
            held: false,
        };
        let r = self.replies.receive(line, &mut judge, bytes, now);
        let judged = judge.judged;
        if let Status::Complete(Heard::Answer) = r.status {
            self.answer = judged;
        }
        self.count(r.status);
        r
    }

    /// Bytes received while a reply is kept for delivery: a reply to a
    /// query (a copy, a late one) is read as it passes, so that the line
    /// learns the positions it carries; the line's own decoder hears the
    /// rest (a fence's echo).
    fn overhear(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        let kind = self.cfg.stream;
        for (i, b) in bytes.iter().enumerate() {
            let b = core::slice::from_ref(b);
            // Both decoders see every byte (neither is left mid-frame); a
            // reply of the query's kind is the passing decoder's.
            let passing = self.passing.push(line, kind, b, now);
            let mut judge = WindowCheck {
                cfg: &self.cfg,
                asked: None,
                first: None,
                judged: None,
                held: true,
            };
            let other = self.replies.receive(line, &mut judge, b, now).status;
            let heard = if passing.is_partial() { other } else { passing };
            if !heard.is_partial() {
                self.count(heard);
                return Received {
                    consumed: i + 1,
                    status: heard,
                };
            }
        }
        Received {
            consumed: bytes.len(),
            status: Status::Partial,
        }
    }

    fn count(&mut self, heard: Status<Heard>) {
        match heard {
            Status::Complete(Heard::Mismatch | Heard::Stale | Heard::Unplaced) => {
                self.stats.stale_replies += 1
            }
            Status::Complete(Heard::Foreign | Heard::Broken(_)) => self.stats.ignored += 1,
            _ => {}
        }
    }
}

/// A query's reply heard while the engine keeps another (a copy, a late
/// reply), decoded as it streams by without a buffer: its station, the
/// positions it carries and the fingerprint of its bytes, which the line
/// hears at its end (as it would from the engine's own receiver).
#[derive(Debug, Clone)]
struct Passing {
    decoder: PositionStreamDecoder,
    /// Between frames: waiting for a header byte.
    hunting: bool,
    /// A reply of the query's kind is under way.
    started: bool,
    station: Station,
    carried: Span,
    print: u32,
}

impl Passing {
    const fn new() -> Self {
        Passing {
            decoder: PositionStreamDecoder::new(BypassPolicy::Reject),
            hunting: true,
            started: false,
            station: Station(0),
            carried: Span::UNKNOWN,
            print: FINGERPRINT_START,
        }
    }

    /// Byte `b` of the input at `now`; a reply of `kind` that ends is
    /// offered to the line (whole, or broken by its envelope).
    fn push(&mut self, line: &mut Line, kind: PositionStream, b: &[u8], now: u32) -> Status<Heard> {
        let Some(&byte) = b.first() else {
            return Status::Partial;
        };
        if self.hunting {
            if Header::from_byte(byte).is_none() {
                return Status::Partial;
            }
            self.decoder.reset();
            self.hunting = false;
            self.started = false;
            self.carried = Span::UNKNOWN;
            self.print = FINGERPRINT_START;
        }
        self.print = fingerprint_more(self.print, b);
        let Status::Complete(event) = self.decoder.push(byte) else {
            return Status::Partial;
        };
        match event {
            StreamEvent::Start {
                kind: k, station, ..
            } => {
                // Another message is the line's decoder's to hear.
                self.started = k == kind;
                self.hunting = !self.started;
                self.station = station;
                Status::Partial
            }
            StreamEvent::Record(rec) => {
                self.carried = self.carried.holding(rec.number);
                Status::Partial
            }
            StreamEvent::End { .. } => {
                self.hunting = true;
                self.started = false;
                let verdict = Verdict {
                    fits: false,
                    values: self.carried,
                    keep: false,
                };
                let print = self.print;
                Status::Complete(line.hear(
                    kind.header,
                    self.station,
                    kind.id,
                    None,
                    verdict,
                    print,
                    now,
                ))
            }
            StreamEvent::Error { error, .. } => {
                self.hunting = true;
                let started = core::mem::take(&mut self.started);
                if Header::from_byte(byte).is_some() {
                    // The byte that broke the frame starts the next.
                    self.decoder.reset();
                    self.hunting = false;
                    self.carried = Span::UNKNOWN;
                    self.print = fingerprint_more(FINGERPRINT_START, b);
                    let _ = self.decoder.push(byte);
                }
                if started {
                    line.broken(Some((kind.header, self.station, kind.id)), now);
                    return Status::Complete(Heard::Broken(error));
                }
                Status::Partial
            }
        }
    }

    /// The kept reply is released at `now` (a query goes out): a reply half
    /// heard is dropped, and a copy of it may still come.
    fn stop(&mut self, line: &mut Line, kind: PositionStream, now: u32) {
        self.hunting = true;
        if core::mem::take(&mut self.started) {
            line.broken(Some((kind.header, self.station, kind.id)), now);
        }
    }
}

/// The fingerprint of the records `frame` carries with numbers in
/// `lo..hi`, in the order it carries them (two replies that agree on those
/// records give the same, whatever else they carry).
fn records_print(stream: PositionStream, frame: &Frame<'_>, lo: u32, hi: u32) -> u32 {
    let mut r = frame.reader();
    let mut print = FINGERPRINT_START;
    let Ok((_, count)) = stream.read_prefix(&mut r) else {
        return print;
    };
    for _ in 0..count {
        let before = r.rest();
        let Ok(rec) = stream.layout.read_record(&mut r) else {
            break;
        };
        if (lo..hi).contains(&u32::from(rec.number)) {
            let used = before.len().saturating_sub(r.rest().len());
            print = fingerprint_more(print, before.get(..used).unwrap_or(&[]));
        }
    }
    print
}

/// A read-back's check of a reply: the records it carries lie in the
/// positions asked, no more than asked.
struct WindowCheck<'c> {
    cfg: &'c ReadBackConfig,
    /// The positions asked, `lo..hi`.
    asked: Option<(u32, u32)>,
    /// The window a first read asks: its halves' fingerprints are taken.
    first: Option<Window>,
    /// For the last reply judged to fit: its halves' fingerprints (first
    /// reads), or nothing to tell.
    judged: Option<[u32; 2]>,
    /// A reply is kept: replies to queries stream by ([`Passing`]).
    held: bool,
}

impl Judge for WindowCheck<'_> {
    fn judge(&mut self, f: &Frame<'_>) -> Verdict {
        let (fits, values) = check_reply(self.cfg, self.asked, f);
        self.judged = fits.then(|| match self.first {
            Some(w) => w
                .halves()
                .map(|(lo, hi)| records_print(self.cfg.stream, f, lo, hi)),
            None => [0; 2],
        });
        Verdict {
            fits,
            values,
            keep: self.first.is_none(),
        }
    }

    fn streams(&self, header: Header, code: u16) -> bool {
        self.held && header == self.cfg.stream.header && code == self.cfg.stream.id
    }
}

/// Checks a frame as the reply to a query of positions `asked` (`lo..hi`):
/// whether it is one, and the positions it carries (for the ledger).
fn check_reply(cfg: &ReadBackConfig, asked: Option<(u32, u32)>, f: &Frame<'_>) -> (bool, Span) {
    if f.header() != Header::Response || f.code() != cfg.stream.id {
        return (false, Span::UNKNOWN);
    }
    let mut r = f.reader();
    let Ok((_, count)) = cfg.stream.read_prefix(&mut r) else {
        return (false, Span::UNKNOWN);
    };
    let mut carried = Span::UNKNOWN;
    for _ in 0..count {
        let Ok(rec) = cfg.stream.layout.read_record(&mut r) else {
            return (false, Span::UNKNOWN);
        };
        carried = carried.holding(rec.number);
    }
    if r.finish().is_err() {
        return (false, Span::UNKNOWN);
    }
    let fits = asked.is_some_and(|(lo, hi)| {
        lo < hi && u32::from(count) <= hi - lo && carried.within(span(lo, hi))
    });
    (fits, carried)
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
