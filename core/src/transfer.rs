//! The transfer engine: a position table of any size written to a
//! controller as a sequence of controller-sized commands, each confirmed.
//!
//! [`Transfer`] is a sans-IO state machine. It pulls records from a source,
//! packs as many as the controller's receive limit allows into one command
//! of the chosen [`PositionStream`] (26DH by default), hands the frame to
//! the caller to transmit, and checks the reply: a `#` response from the
//! same station with the same ID must echo the number of records sent.
//! Time comes from the caller as a millisecond tick (`u32`, wrapping).
//!
//! Faults, per the timeout-and-retry rules (X-SEL spec 2003 p. 62; assumed
//! for the TTA, whose chapter is lost):
//! - no valid reply within `timeout_ms` (3 s) after the frame was sent: the
//!   same frame is sent again, up to `max_tries` sends in all (3);
//! - an `&` error response: also sent again (position writes are
//!   idempotent), then the transfer fails with the error code;
//! - anything else (another ID, station or count, noise, broken frames) is
//!   not a reply to this frame and is ignored.
//!
//! The protocol has no sequence numbers: a reply says only how many records
//! were written. So that a late reply to an earlier frame cannot confirm
//! the current one, the engine never gives a frame the record count of the
//! frame before it, nor that of a frame that timed out within the last
//! `late_guard_ms` (it holds records back for the next frame instead).
//! A reply arriving later than that is outside anything the spec allows
//! (the controller answers within α ms) and is not guarded against.
//!
//! After a failure, [`Transfer::resume`] sends the unconfirmed frame again:
//! no record is lost, skipped or reordered.
//!
//! RAM: the frame buffer `N` (default 2,051 bytes, the TTA's receive limit),
//! a 32-byte reply decoder, one held-back record and counters — independent
//! of the table size. Flavours: [`Transfer::run_blocking`] over
//! `embedded-io`, [`Transfer::poll_nb`] for a non-blocking main loop.

use crate::checksum::{BypassPolicy, ChecksumMode};
use crate::decoder::{Event, FrameDecoder};
use crate::error::Error;
use crate::exchange::{reached, Due, Exchange};
use crate::field::{FieldSpec, Writer};
use crate::frame::{emit_envelope, emit_trailer, Frame, Header, Station};
use crate::position::PositionRecord;
use crate::stream::PositionStream;

/// Default frame buffer: the largest command a TTA accepts.
pub const TTA_MAX_COMMAND: usize = 2051;

/// Settings of a transfer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransferConfig {
    /// Station addressed.
    pub station: Station,
    /// The write message used (26DH unless told otherwise).
    pub stream: PositionStream,
    /// Start number of a range write (244H, 290H); ignored by the others.
    pub start: u16,
    /// Largest command frame the controller accepts, header through LF
    /// (TTA 2,051; X-SEL J/K and TT 1,023).
    pub max_frame: usize,
    /// Reply timeout after the frame was sent, ms (3,000 per the spec).
    pub timeout_ms: u32,
    /// Sends per frame before giving up (3).
    pub max_tries: u8,
    /// Pause after a reply before the next command, ms (at least 1).
    pub turnaround_ms: u32,
    /// Checksum or `@@`.
    pub checksum: ChecksumMode,
    /// How long after a timeout a late reply to that frame is still
    /// guarded against, ms.
    pub late_guard_ms: u32,
}

impl TransferConfig {
    /// 26DH to a TTA at `station`: 2,051-byte frames, 3 s timeout, 3 tries.
    pub const fn tta(station: Station) -> Self {
        TransferConfig {
            station,
            stream: PositionStream::CHANGE_2,
            start: 0,
            max_frame: TTA_MAX_COMMAND,
            timeout_ms: 3000,
            max_tries: 3,
            turnaround_ms: 1,
            checksum: ChecksumMode::Compute,
            late_guard_ms: 30_000,
        }
    }
}

/// Counters of a transfer.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransferStats {
    /// Records confirmed by the controller.
    pub records_confirmed: u32,
    /// Frames confirmed.
    pub frames_confirmed: u32,
    /// Frames sent, retries included.
    pub frames_sent: u32,
    /// Bytes sent, retries included.
    pub bytes_sent: u64,
    /// Frames sent again (after a timeout or an error response).
    pub retries: u32,
    /// Timeouts.
    pub timeouts: u32,
    /// `&` error responses received.
    pub error_replies: u32,
    /// Frames received that were not a reply to the outstanding command.
    pub ignored_frames: u32,
    /// Broken frames and noise bytes seen on the reply line.
    pub line_errors: u32,
}

/// Why a transfer stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TransferError<E = core::convert::Infallible> {
    /// No valid reply after `max_tries` sends.
    Timeout,
    /// The controller kept answering with this error code.
    ErrorResponse {
        /// The error code.
        code: u16,
    },
    /// Record number `index` (0-based, in source order) cannot be encoded.
    InvalidRecord {
        /// Index of the record.
        index: u32,
        /// Why.
        error: Error,
    },
    /// The configuration cannot work (a frame buffer or limit too small for
    /// one record, or a record count above the format's maximum).
    Config(Error),
    /// The driver failed.
    Io(E),
}

impl<E> TransferError<E> {
    fn widen(e: TransferError) -> Self {
        match e {
            TransferError::Timeout => TransferError::Timeout,
            TransferError::ErrorResponse { code } => TransferError::ErrorResponse { code },
            TransferError::InvalidRecord { index, error } => {
                TransferError::InvalidRecord { index, error }
            }
            TransferError::Config(e) => TransferError::Config(e),
            TransferError::Io(never) => match never {},
        }
    }
}

/// What the caller should do next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step<'a> {
    /// Send these bytes, then call [`Transfer::sent`].
    Transmit(&'a [u8]),
    /// Feed received bytes to [`Transfer::received`]; call `poll` again by
    /// this tick at the latest.
    WaitUntil(u32),
    /// The source has no record ready: call `poll` again when it has.
    NeedRecords,
    /// Every record was confirmed.
    Complete(TransferStats),
    /// The transfer stopped; [`Transfer::resume`] continues it.
    Failed(TransferError),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Packing the next frame (from this tick on).
    Build {
        not_before: u32,
    },
    /// The frame is being sent and confirmed.
    Exchange,
    Complete,
    Failed(TransferError),
}

/// Timed-out counts remembered at once (older ones are forgotten first).
const SUSPECTS: usize = 4;
/// Records that can be held back: one that did not fit, plus one for the
/// previous count and one per suspect count.
const HELD: usize = 2 + SUSPECTS;

/// Writes a position table to a controller in confirmed chunks.
pub struct Transfer<I, const N: usize = TTA_MAX_COMMAND> {
    cfg: TransferConfig,
    source: I,
    /// Records taken from the source but not yet in a frame, in order.
    held: heapless::Deque<PositionRecord, HELD>,
    /// Record counts of frames that timed out, and until when to avoid them.
    suspects: heapless::Vec<(u16, u32), SUSPECTS>,
    /// Start offsets of the last records in the frame being built.
    marks: heapless::Deque<usize, HELD>,
    source_done: bool,
    taken: u32,
    frame: [u8; N],
    frame_len: usize,
    frame_records: u16,
    prev_records: u16,
    exchange: Exchange,
    total: Option<u32>,
    state: State,
    replies: FrameDecoder<32>,
    stats: TransferStats,
}

impl<I: RecordSource, const N: usize> Transfer<I, N> {
    /// A transfer of the records of `source`.
    pub fn new(cfg: TransferConfig, source: I) -> Self {
        let total = source.total();
        Transfer {
            cfg,
            source,
            held: heapless::Deque::new(),
            suspects: heapless::Vec::new(),
            marks: heapless::Deque::new(),
            source_done: false,
            taken: 0,
            frame: [0; N],
            frame_len: 0,
            frame_records: 0,
            prev_records: 0,
            exchange: Exchange::new(),
            total,
            state: State::Build { not_before: 0 },
            replies: FrameDecoder::with_policy(BypassPolicy::Reject),
            stats: TransferStats::default(),
        }
    }

    /// Sets the number of records expected (for progress), when the source
    /// cannot tell.
    pub fn with_total(mut self, total: u32) -> Self {
        self.total = Some(total);
        self
    }

    /// Counters so far.
    pub fn stats(&self) -> TransferStats {
        self.stats
    }

    /// `(records confirmed, records in all if known)`.
    pub fn progress(&self) -> (u32, Option<u32>) {
        (self.stats.records_confirmed, self.total)
    }

    /// The settings.
    pub fn config(&self) -> &TransferConfig {
        &self.cfg
    }

    /// The record source (e.g. to push records into a [`RecordQueue`]).
    pub fn source_mut(&mut self) -> &mut I {
        &mut self.source
    }

    /// Gives back the record source (e.g. to recover it after a failure).
    pub fn into_source(self) -> I {
        self.source
    }

    /// After [`Step::Failed`]: try the unconfirmed frame again, with a
    /// fresh count of tries. Nothing is lost or repeated out of order.
    pub fn resume(&mut self, now: u32) {
        if let State::Failed(e) = self.state {
            match e {
                TransferError::InvalidRecord { .. } | TransferError::Config(_) => {}
                _ if self.frame_records > 0 => {
                    self.exchange.start(now);
                    self.state = State::Exchange;
                }
                _ => self.state = State::Build { not_before: now },
            }
        }
    }

    /// Decides the next step at tick `now`.
    pub fn poll(&mut self, now: u32) -> Step<'_> {
        loop {
            match self.state {
                State::Build { not_before } => {
                    if !reached(now, not_before) {
                        return Step::WaitUntil(not_before);
                    }
                    match self.build(now) {
                        Ok(Built::Ready) => {
                            self.exchange.start(now);
                            self.state = State::Exchange;
                        }
                        Ok(Built::Pending) => return Step::NeedRecords,
                        Ok(Built::Exhausted) => self.state = State::Complete,
                        Err(e) => self.state = State::Failed(e),
                    }
                }
                State::Exchange => match self.exchange.poll(now) {
                    Due::Transmit { fresh } => {
                        if fresh {
                            self.stats.frames_sent += 1;
                            self.stats.bytes_sent += self.frame_len as u64;
                            self.replies.reset();
                        }
                        return Step::Transmit(self.frame.get(..self.frame_len).unwrap_or(&[]));
                    }
                    Due::WaitUntil(t) => return Step::WaitUntil(t),
                    Due::TimedOut => {
                        self.stats.timeouts += 1;
                        if self.suspects.is_full() {
                            self.suspects.remove(0);
                        }
                        let until = now.wrapping_add(self.cfg.late_guard_ms);
                        let _ = self.suspects.push((self.frame_records, until));
                        self.retry_or_fail(now, TransferError::Timeout);
                    }
                    Due::Idle => self.state = State::Failed(TransferError::Timeout),
                },
                State::Complete => return Step::Complete(self.stats),
                State::Failed(e) => return Step::Failed(e),
            }
        }
    }

    /// The caller finished transmitting the frame at tick `now`.
    pub fn sent(&mut self, now: u32) {
        self.exchange.sent(now, self.cfg.timeout_ms);
    }

    /// Bytes received from the controller at tick `now`.
    pub fn received(&mut self, mut bytes: &[u8], now: u32) {
        while !bytes.is_empty() {
            let d = self.replies.decode(bytes);
            bytes = bytes.get(d.consumed..).unwrap_or(&[]);
            let verdict = match d.event {
                Event::NeedMore => break,
                Event::Error(_) => {
                    self.stats.line_errors += 1;
                    continue;
                }
                Event::Frame(f) => judge(&self.cfg, self.frame_records, &f),
            };
            if !(self.state == State::Exchange && self.exchange.awaiting()) {
                self.stats.ignored_frames += 1;
                continue;
            }
            match verdict {
                Verdict::Confirmed => {
                    self.stats.records_confirmed += u32::from(self.frame_records);
                    self.stats.frames_confirmed += 1;
                    self.prev_records = self.frame_records;
                    self.frame_len = 0;
                    self.frame_records = 0;
                    self.exchange.finish();
                    self.state = State::Build {
                        not_before: now.wrapping_add(self.cfg.turnaround_ms),
                    };
                }
                Verdict::ErrorReply(code) => {
                    self.stats.error_replies += 1;
                    self.retry_or_fail(
                        now.wrapping_add(self.cfg.turnaround_ms),
                        TransferError::ErrorResponse { code },
                    );
                }
                Verdict::NotOurs => self.stats.ignored_frames += 1,
            }
        }
    }

    fn retry_or_fail(&mut self, at: u32, why: TransferError) {
        if self.exchange.retry(at, self.cfg.max_tries) {
            self.stats.retries += 1;
        } else {
            self.state = State::Failed(why);
        }
    }

    /// Takes the next record: a held-back one first, then the source.
    fn pull(&mut self) -> Pull {
        if let Some(r) = self.held.pop_front() {
            return Pull::Record(r);
        }
        if self.source_done {
            return Pull::End;
        }
        let p = self.source.pull();
        match p {
            Pull::Record(_) => self.taken += 1,
            Pull::End => self.source_done = true,
            Pull::Pending => {}
        }
        p
    }

    /// Packs records into the next frame until it is full or the source
    /// ends; a source that is not ready leaves the frame half-built for the
    /// next call.
    fn build(&mut self, now: u32) -> core::result::Result<Built, TransferError> {
        let cfg = self.cfg;
        let limit = cfg.max_frame.min(N);
        let first_index = self.stats.records_confirmed;
        if self.frame_len == 0 {
            // Only start a frame when there is a record for it: a table that
            // ends exactly at the top of a range write's start field must
            // complete, not fail on a start number it never needs.
            match self.pull() {
                Pull::Record(r) => {
                    let _ = self.held.push_front(r);
                }
                Pull::Pending => return Ok(Built::Pending),
                Pull::End => return Ok(Built::Exhausted),
            }
            let start = u16::try_from(u32::from(cfg.start) + first_index)
                .map_err(|_| TransferError::Config(Error::ValueOutOfRange { offset: 6 }))?;
            let mut w = Writer::new(&mut self.frame);
            emit_envelope(&mut w, Header::Command, cfg.station, cfg.stream.id)
                .and_then(|()| cfg.stream.write_prefix(&mut w, start, 0))
                .map_err(TransferError::Config)?;
            self.frame_len = w.len();
            self.frame_records = 0;
            self.marks.clear();
        }
        let full = loop {
            let rec = match self.pull() {
                Pull::Record(r) => r,
                Pull::Pending => return Ok(Built::Pending),
                Pull::End => break false,
            };
            let len = cfg.stream.layout.record_len(rec.axes.count());
            let n = self.frame_records;
            // In a range write, record i is position start + i: it must be
            // a number the start field can express.
            let index = first_index + u32::from(n);
            if cfg.stream.start_width > 0
                && u64::from(cfg.start) + u64::from(index)
                    > FieldSpec::hex(cfg.stream.start_width).max_unsigned()
            {
                let _ = self.held.push_front(rec);
                if n == 0 {
                    self.frame_len = 0;
                    return Err(TransferError::Config(Error::ValueOutOfRange { offset: 6 }));
                }
                break true;
            }
            if n >= cfg.stream.max_records || self.frame_len + len + 4 > limit {
                let _ = self.held.push_front(rec);
                if n == 0 {
                    return Err(TransferError::Config(Error::BufferTooSmall));
                }
                break true;
            }
            let mut w = Writer::resume(&mut self.frame, self.frame_len);
            if let Err(error) = cfg.stream.layout.write_record(&rec, &mut w) {
                let _ = self.held.push_front(rec);
                self.frame_len = 0;
                return Err(TransferError::InvalidRecord {
                    index: first_index + u32::from(n),
                    error,
                });
            }
            if self.marks.is_full() {
                self.marks.pop_front();
            }
            let _ = self.marks.push_back(self.frame_len);
            self.frame_len = w.len();
            self.frame_records += 1;
        };
        let _ = full;
        if self.frame_records == 0 {
            self.frame_len = 0;
            return Ok(Built::Exhausted);
        }
        // Avoid the counts a late reply could carry (see module docs).
        self.suspects.retain(|&(_, until)| !reached(now, until));
        let prev = self.prev_records;
        let mut w = Writer::resume(&mut self.frame, self.frame_len);
        let mut n = self.frame_records;
        while n > 1
            && (n == prev || self.suspects.iter().any(|&(c, _)| c == n))
            && !self.held.is_full()
        {
            let Some(mark) = self.marks.pop_back() else {
                break;
            };
            let mut r = crate::field::Reader::new(w.written().get(mark..).unwrap_or(&[]), mark);
            let Ok(rec) = cfg.stream.layout.read_record(&mut r) else {
                break;
            };
            if self.held.push_front(rec).is_err() {
                break;
            }
            w.truncate(mark);
            n -= 1;
        }
        let count_at = crate::frame::ENVELOPE_LEN + cfg.stream.prefix_len()
            - usize::from(cfg.stream.count_width);
        w.patch_unsigned(
            count_at,
            FieldSpec::hex(cfg.stream.count_width),
            u64::from(n),
        )
        .and_then(|()| emit_trailer(&mut w, cfg.checksum))
        .map_err(TransferError::Config)?;
        self.frame_len = w.len();
        self.frame_records = n;
        Ok(Built::Ready)
    }
}

/// What [`Transfer::build`] achieved.
enum Built {
    Ready,
    Pending,
    Exhausted,
}

/// What a [`RecordSource`] has to offer.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pull {
    /// The next record.
    Record(PositionRecord),
    /// No record yet; ask again later.
    Pending,
    /// No more records.
    End,
}

/// Where a transfer takes its records from. Every
/// `Iterator<Item = PositionRecord>` is one (never pending); a
/// [`RecordQueue`] is one that fills as records arrive.
pub trait RecordSource {
    /// The next record, if ready.
    fn pull(&mut self) -> Pull;
    /// Records in all, if known.
    fn total(&self) -> Option<u32> {
        None
    }
}

impl<I: Iterator<Item = PositionRecord>> RecordSource for I {
    fn pull(&mut self) -> Pull {
        self.next().map_or(Pull::End, Pull::Record)
    }
    fn total(&self) -> Option<u32> {
        let (lo, hi) = self.size_hint();
        if Some(lo) == hi {
            u32::try_from(lo).ok()
        } else {
            None
        }
    }
}

/// A bounded FIFO of records that a producer fills as they arrive (for
/// example from a [`PositionStreamDecoder`](crate::stream::PositionStreamDecoder))
/// and a [`Transfer`] drains. It is pending while empty, until
/// [`RecordQueue::finish`].
#[derive(Debug, Clone, Default)]
pub struct RecordQueue<const Q: usize> {
    items: heapless::Deque<PositionRecord, Q>,
    finished: bool,
}

impl<const Q: usize> RecordQueue<Q> {
    /// An empty queue.
    pub const fn new() -> Self {
        RecordQueue {
            items: heapless::Deque::new(),
            finished: false,
        }
    }
    /// Appends a record; gives it back if the queue is full.
    pub fn push(&mut self, rec: PositionRecord) -> core::result::Result<(), PositionRecord> {
        self.items.push_back(rec)
    }
    /// No more records will come.
    pub fn finish(&mut self) {
        self.finished = true;
    }
    /// Whether [`RecordQueue::finish`] was called.
    pub fn is_finished(&self) -> bool {
        self.finished
    }
    /// Records waiting.
    pub fn len(&self) -> usize {
        self.items.len()
    }
    /// Whether no record is waiting.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
    /// Whether another record would not fit.
    pub fn is_full(&self) -> bool {
        self.items.is_full()
    }
}

impl<const Q: usize> RecordSource for RecordQueue<Q> {
    fn pull(&mut self) -> Pull {
        match self.items.pop_front() {
            Some(r) => Pull::Record(r),
            None if self.finished => Pull::End,
            None => Pull::Pending,
        }
    }
}

enum Verdict {
    Confirmed,
    ErrorReply(u16),
    NotOurs,
}

/// Is `f` the reply to the outstanding frame of `records` records?
fn judge(cfg: &TransferConfig, records: u16, f: &Frame<'_>) -> Verdict {
    if f.station() != cfg.station {
        return Verdict::NotOurs;
    }
    match f.header() {
        Header::Error => Verdict::ErrorReply(f.code()),
        Header::Response => match cfg.stream.parse_reply(f) {
            Ok((_, count)) if count == records => Verdict::Confirmed,
            _ => Verdict::NotOurs,
        },
        Header::Command => Verdict::NotOurs,
    }
}

/// A millisecond clock for the blocking and `nb` flavours.
pub trait Clock {
    /// The current tick, ms, wrapping.
    fn now_ms(&mut self) -> u32;
    /// Called while waiting for bytes (e.g. `cortex_m::asm::wfi`).
    fn idle(&mut self) {}
}

impl<I: RecordSource, const N: usize> Transfer<I, N> {
    /// Runs the transfer to the end over a UART, blocking.
    ///
    /// `uart` must report readiness ([`embedded_io::ReadReady`]) so that the
    /// engine can watch its deadline while no byte arrives.
    pub fn run_blocking<U>(
        &mut self,
        uart: &mut U,
        clock: &mut impl Clock,
    ) -> core::result::Result<TransferStats, TransferError<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
    {
        loop {
            match self.poll_nb(uart, clock.now_ms()) {
                Ok(stats) => return Ok(stats),
                Err(nb::Error::Other(e)) => return Err(e),
                Err(nb::Error::WouldBlock) => clock.idle(),
            }
        }
    }

    /// Makes what progress is possible without waiting: sends a frame that
    /// is due, reads the bytes already received, checks the deadline.
    /// `WouldBlock` means "call again later".
    pub fn poll_nb<U>(
        &mut self,
        uart: &mut U,
        now: u32,
    ) -> nb::Result<TransferStats, TransferError<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
    {
        let mut buf = [0u8; 32];
        while uart
            .read_ready()
            .map_err(|e| nb::Error::Other(TransferError::Io(e)))?
        {
            let n = uart
                .read(&mut buf)
                .map_err(|e| nb::Error::Other(TransferError::Io(e)))?;
            if n == 0 {
                break;
            }
            self.received(buf.get(..n).unwrap_or(&[]), now);
        }
        match self.poll(now) {
            Step::Transmit(bytes) => {
                uart.write_all(bytes)
                    .map_err(|e| nb::Error::Other(TransferError::Io(e)))?;
                uart.flush()
                    .map_err(|e| nb::Error::Other(TransferError::Io(e)))?;
                self.sent(now);
                Err(nb::Error::WouldBlock)
            }
            Step::WaitUntil(_) | Step::NeedRecords => Err(nb::Error::WouldBlock),
            Step::Complete(stats) => Ok(stats),
            Step::Failed(e) => Err(nb::Error::Other(TransferError::widen(e))),
        }
    }
}

/// A millisecond clock that can sleep, for the async flavour.
#[cfg(feature = "async")]
pub trait AsyncClock {
    /// The current tick, ms, wrapping.
    fn now_ms(&mut self) -> u32;
    /// Sleeps about `ms` milliseconds (or until woken earlier).
    fn sleep_ms(&mut self, ms: u32) -> impl core::future::Future<Output = ()>;
}

#[cfg(feature = "async")]
impl<I: RecordSource, const N: usize> Transfer<I, N> {
    /// Runs the transfer to the end over an `embedded-io-async` UART.
    ///
    /// While waiting for a reply it polls [`embedded_io_async::ReadReady`]
    /// and sleeps `poll_ms` between checks, so the deadline is always seen
    /// even if no byte ever arrives. A [`RecordQueue`] source is filled
    /// by whoever owns the transfer between calls; here a pending source
    /// just sleeps.
    pub async fn run_async<U, C>(
        &mut self,
        uart: &mut U,
        clock: &mut C,
        poll_ms: u32,
    ) -> core::result::Result<TransferStats, TransferError<U::Error>>
    where
        U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
        C: AsyncClock,
    {
        let mut buf = [0u8; 32];
        loop {
            while uart.read_ready().map_err(TransferError::Io)? {
                let n = uart.read(&mut buf).await.map_err(TransferError::Io)?;
                if n == 0 {
                    break;
                }
                let now = clock.now_ms();
                self.received(buf.get(..n).unwrap_or(&[]), now);
            }
            let now = clock.now_ms();
            match self.poll(now) {
                Step::Transmit(bytes) => {
                    uart.write_all(bytes).await.map_err(TransferError::Io)?;
                    uart.flush().await.map_err(TransferError::Io)?;
                    let now = clock.now_ms();
                    self.sent(now);
                }
                Step::WaitUntil(t) => {
                    clock
                        .sleep_ms(t.wrapping_sub(now).clamp(1, poll_ms.max(1)))
                        .await
                }
                Step::NeedRecords => clock.sleep_ms(poll_ms.max(1)).await,
                Step::Complete(stats) => return Ok(stats),
                Step::Failed(e) => return Err(TransferError::widen(e)),
            }
        }
    }
}
