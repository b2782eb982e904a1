//! The transfer engine: a position table of any size written to a
//! controller as a sequence of controller-sized commands, each confirmed,
//! and read back and compared as the [`Verify`] policy asks.
//!
//! [`Transfer`] is a sans-IO state machine. It pulls records from a source,
//! packs as many as the controller's receive limit allows into one command
//! of the chosen [`PositionStream`] (26DH by default), hands the frame to
//! the caller to transmit, and checks the reply through the crate's one
//! reply matcher ([`crate::exchange`]): a `#` response from the station
//! with the stream's ID that reports exactly the records sent (and, for a
//! range write, echoes the start number). Time is a millisecond tick from
//! the caller (`u32`, wrapping).
//!
//! # Faults
//! - No valid reply within 3 s after the frame was *completely sent*: the
//!   same frame is sent again, up to `max_sends` sends (position writes
//!   are idempotent: each record names its position).
//! - An `&` error response: the transfer stops with the code
//!   ([`TransferError::Controller`]); the spec asks for "appropriate
//!   action", not a blind resend (2003 p. 66). [`Transfer::resume`] sends
//!   the frame again when the caller decides to.
//! - A reply with another count never confirms the frame and never makes
//!   a record be skipped: it may be a late answer to an earlier frame or a
//!   partial write. It is reported ([`TransferEvent::CountMismatch`]) and
//!   the frame stays unconfirmed (a resend after the timeout rewrites it).
//!
//! # Late and duplicated replies
//! The protocol has no sequence numbers: a 26DH reply says only how many
//! records were written. A reply can come late (after the timeout and the
//! resend) or twice (an echoing converter). So that no such reply confirms
//! a frame it does not belong to, the engine never gives a frame a record
//! count that a reply still in flight could carry; it sends fewer records
//! instead and carries the rest to the next frame:
//!
//! - never the count of the frame answered last, for `duplicate_window_ms`
//!   after its reply (when the records left allow no other count, as with
//!   one last record after a frame of one, the frame waits that long);
//! - never the count of a frame sent within `timeout_ms + late_window_ms`
//!   (3 + 3 s) whose reply did not come, or that was sent more than once;
//! - once the line has shown a late or duplicated reply (a reply while
//!   none was awaited, or one with the wrong count), never the count of a
//!   frame answered within `duplicate_window_ms` (3 s).
//!
//! The last rule waits for evidence because it is costly: at 115,200
//! baud more frames fit in 3 s than an 8-axis frame has counts (24), so
//! frames get shorter and the transfer takes about 40 % longer. On a clean
//! line the guard costs about 2 % (every other frame one record shorter).
//! A reply later than those windows is outside what the engine can tell
//! apart, and so is the first duplicate on a line that arrives while a
//! frame with its count was lost: [`Verify::Full`] catches what they would
//! do.
//!
//! # Verification
//! A confirmed frame means the controller *said* it wrote that many
//! records. The 8-bit SC lets some corruptions through (two bit flips that
//! cancel), and a count cannot say which records. [`Verify`] reads the
//! written positions back (21FH for 26DH, 22DH for 290H/291H, 209H for
//! 244H/245H), in windows sized so that every reply fits the controller's
//! transmit buffer, compares them record by record with the frame still
//! held for retries, and rewrites the frame when one differs (up to
//! `rewrites` times, then [`TransferError::Mismatch`] naming the first
//! differing position). A read-back reply carries nothing that ties it
//! to its query, so after a rewrite the frame's next read-back waits until
//! no reply to its earlier queries can still come (`duplicate_window_ms`
//! after the last one, longer while a late reply to a resent query is
//! possible): otherwise a copy of the reply from before the rewrite could
//! pass for the new state (about 3 s per rewrite). The reply is compared as it streams in through a
//! [`PositionStreamDecoder`](crate::stream::PositionStreamDecoder) (no
//! second frame buffer); a comparison counts
//! only when the reply's SC, station and ID check out.
//!
//! What is compared: every field the write sends (position number, axis
//! pattern, acceleration, deceleration, speed, one coordinate per axis,
//! and the extended byte for 290H/291H). The manuals do not say the
//! controller changes a stored value (no clamping, rounding or "0 means
//! keep" rule for position data is given, TTA pp. 35, 60), so the values
//! are compared exactly; that the controller stores them unchanged is an
//! **assumption**. A record sent twice in one frame is compared against
//! its last copy.
//!
//! | policy | what it proves | wire time added |
//! |---|---|---|
//! | [`Verify::Off`] | nothing beyond the count ([`Guarantee::Unverified`]) | none |
//! | [`Verify::AfterFault`] | every frame confirmed after a timeout, a resend, a count mismatch or an unexpected reply is read back; a frame confirmed at its first send is trusted ([`Guarantee::FaultsVerified`]): a corruption that passes the SC goes unseen | none on a clean line; about one frame's length per faulty frame |
//! | [`Verify::Full`] | every record ([`Guarantee::Verified`]) | about as much again as the write (a 21FH reply carries the same 82 bytes per 8-axis record as the 26DH), plus an 18-byte query per window |
//!
//! A frame whose reply times out (or arrives broken) is sent again with
//! half its records (the rest go to the next frame), and frames stay that
//! short until they get through again, growing by a quarter per confirmed
//! frame: on a noisy line a long frame rarely arrives whole (at one
//! flipped bit in 1,000 bytes, 2 KB frames fail seven times in eight).
//! Read-back windows shrink and grow the same way. Each command is still
//! sent at most `max_sends` times; after [`Step::Failed`], resuming keeps
//! the smaller sizes.
//!
//! After a failure, [`Transfer::resume`] sends the unconfirmed frame (or
//! the interrupted read-back) again: no record is lost, skipped or
//! reordered.
//!
//! RAM: the frame buffer `N` (default 2,051 bytes, the TTA's receive
//! limit), a 32-byte reply decoder, the read-back decoder's 88-byte stage,
//! one held-back record and counters, whatever the table size. Flavours:
//! [`Transfer::run_blocking`] over `embedded-io`, [`Transfer::poll_nb`] for
//! a non-blocking main loop, `Transfer::run_async` with the `async`
//! feature.

mod guard;
mod source;
mod verify;

pub use source::{Pull, RecordQueue, RecordSource};

use guard::Guard;
use verify::{bit, Verifier, Walk};

use crate::catalogue;
use crate::checksum::{BypassPolicy, ChecksumMode};
use crate::client::Received;
use crate::clock::{later, passed, Clock};
use crate::decoder::{Event, FrameDecoder};
use crate::drive::{self, Engine, Stop, Want};
use crate::error::{Error, BRIDGE_CODES};
use crate::exchange::{Due, Exchange, ExchangeConfig, Finish, Offer, Quarantine};
use crate::field::{move_within, Writer};
use crate::frame::{emit_envelope, emit_trailer, Header, Station, ENVELOPE_LEN, TRAILER_LEN};
use crate::limits;
use crate::position::{PositionRecord, PositionStream};

/// Most records one frame carries (the read-back keeps one bit per record).
/// A 2,051-byte 26DH holds at most 113 (records without axes).
pub const MAX_FRAME_RECORDS: u16 = 128;

/// How much the engine reads back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Verify {
    /// Trust the count in each reply.
    Off,
    /// Read back the frames whose confirmation came after a fault.
    AfterFault,
    /// Read back every frame.
    Full,
}

/// What a completed transfer proves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Guarantee {
    /// Every record was read back and compared equal.
    Verified,
    /// Every frame confirmed after a fault was read back and compared
    /// equal; the others are trusted on their reply's count.
    FaultsVerified,
    /// Only the replies' counts: nothing was read back.
    Unverified,
}

/// Settings of a transfer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransferConfig {
    /// Station, timeout, sends, turnaround, late and duplicate windows.
    pub exchange: ExchangeConfig,
    /// The write message used (26DH unless told otherwise).
    pub stream: PositionStream,
    /// Start number of a range write (244H, 290H); ignored by the others.
    pub start: u16,
    /// Largest command frame the controller accepts, header through LF.
    pub max_frame: usize,
    /// Largest response frame the controller sends (sizes the read-back
    /// windows).
    pub max_response: usize,
    /// Checksum or `@@`.
    pub checksum: ChecksumMode,
    /// How much is read back.
    pub verify: Verify,
    /// Rewrites of a frame that read back different before giving up.
    pub rewrites: u8,
    /// Most records per frame (at most [`MAX_FRAME_RECORDS`]): fewer make
    /// each frame's write and read-back shorter, e.g. so that a bridge's
    /// last frames fit its host's reply timeout on a slow line.
    pub max_records: u16,
}

impl TransferConfig {
    /// 26DH to a TTA at `station`: 2,051-byte frames, 3 s timeout, 3 sends,
    /// replies guarded against for 3 s after they came (duplicates) and 3 s
    /// after their timeout (late ones), full verification.
    pub const fn tta(station: Station) -> Self {
        let mut exchange = ExchangeConfig::new(station);
        exchange.duplicate_window_ms = exchange.timeout_ms;
        TransferConfig {
            exchange,
            stream: PositionStream::CHANGE_2,
            start: 0,
            max_frame: limits::TTA.command,
            max_response: limits::TTA.response,
            checksum: ChecksumMode::Compute,
            verify: Verify::Full,
            rewrites: 2,
            max_records: MAX_FRAME_RECORDS,
        }
    }

    /// This configuration with another verification policy.
    pub const fn with_verify(mut self, verify: Verify) -> Self {
        self.verify = verify;
        self
    }
}

/// Counters of a transfer.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransferStats {
    /// Records written, confirmed, and verified as the policy asks.
    pub records_confirmed: u32,
    /// Write replies accepted (rewrites included).
    pub frames_confirmed: u32,
    /// Write frames sent, resends and rewrites included.
    pub frames_sent: u32,
    /// Bytes of write frames sent.
    pub bytes_sent: u64,
    /// Frames (writes or read-back queries) sent again after a timeout.
    pub retries: u32,
    /// Timeouts.
    pub timeouts: u32,
    /// `&` error responses received.
    pub error_replies: u32,
    /// Write replies whose count was not the frame's.
    pub count_mismatches: u32,
    /// Replies that came when none was awaited (late or duplicated).
    pub stale_replies: u32,
    /// Frames from the line that were no reply to the awaited command.
    pub ignored_frames: u32,
    /// Broken frames and noise seen on the reply line.
    pub line_errors: u32,
    /// Frames sent with fewer records than fitted, so that no reply still
    /// in flight could confirm them.
    pub guarded_frames: u32,
    /// Frames cut to half their records after a timeout.
    pub shrunk_frames: u32,
    /// Frames read back and compared equal.
    pub frames_verified: u32,
    /// Records read back and compared equal.
    pub records_verified: u32,
    /// Read-back queries sent (resends included).
    pub verify_queries: u32,
    /// Bytes of read-back queries sent.
    pub verify_bytes_sent: u64,
    /// Frames written again because their read-back differed.
    pub rewrites: u32,
    /// Read-back queries held after a rewrite until no reply to the
    /// frame's earlier queries could still arrive.
    pub held_queries: u32,
    /// Bytes received from the controller.
    pub bytes_received: u64,
}

/// How a transfer ended well.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TransferReport {
    /// What the controller is known to hold.
    pub guarantee: Guarantee,
    /// The counters.
    pub stats: TransferStats,
}

/// Why a transfer stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TransferError<E = core::convert::Infallible> {
    /// No valid reply (to a write or a read-back query) after `max_sends`
    /// sends.
    Timeout,
    /// The controller answered with this error code.
    Controller {
        /// The code.
        code: u16,
    },
    /// A bridge on the way answered with one of its own codes
    /// ([`BRIDGE_CODES`]).
    Bridge {
        /// The code.
        code: u16,
    },
    /// A frame still read back different after `rewrites` rewrites.
    Mismatch {
        /// The first differing position.
        first_position: u16,
        /// How many of the frame's records differ.
        records: u16,
    },
    /// Record number `index` (0-based, in source order) cannot be encoded.
    InvalidRecord {
        /// Index of the record.
        index: u32,
        /// Why.
        error: Error,
    },
    /// The configuration cannot work (a frame buffer or limit too small for
    /// one record, a start number out of its field).
    Config(Error),
    /// The driver failed.
    Io(E),
}

impl TransferError {
    fn widen<E>(self) -> TransferError<E> {
        match self {
            TransferError::Timeout => TransferError::Timeout,
            TransferError::Controller { code } => TransferError::Controller { code },
            TransferError::Bridge { code } => TransferError::Bridge { code },
            TransferError::Mismatch {
                first_position,
                records,
            } => TransferError::Mismatch {
                first_position,
                records,
            },
            TransferError::InvalidRecord { index, error } => {
                TransferError::InvalidRecord { index, error }
            }
            TransferError::Config(e) => TransferError::Config(e),
            TransferError::Io(never) => match never {},
        }
    }

    fn rejected(code: u16) -> Self {
        if BRIDGE_CODES.contains(&code) {
            TransferError::Bridge { code }
        } else {
            TransferError::Controller { code }
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
    /// Every record was written (and verified as the policy asks).
    Complete(TransferReport),
    /// The transfer stopped; [`Transfer::resume`] continues it.
    Failed(TransferError),
}

/// What one call of [`Transfer::received`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TransferEvent {
    /// All bytes used; nothing complete.
    NeedMore,
    /// The frame's reply came with its count.
    Confirmed {
        /// Records in the frame.
        records: u16,
    },
    /// A write reply from the station reported another count (or start):
    /// not a confirmation (see the module docs).
    CountMismatch {
        /// Records in the frame awaiting its reply.
        sent: u16,
        /// The count the reply carried.
        reported: u16,
    },
    /// An error response to the awaited command.
    Rejected {
        /// Its code.
        code: u16,
    },
    /// A read-back window was answered and compared.
    Compared {
        /// First position of the window.
        head: u16,
        /// Records of the frame that compared equal in it.
        equal: u16,
        /// Records of the frame missing or different in it.
        differ: u16,
    },
    /// A reply that came when none was awaited: late or duplicated.
    Stale,
    /// A valid frame that is no reply to the awaited command.
    Foreign,
    /// A broken frame or noise was dropped.
    Broken(Error),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Packing the next frame (from this tick on).
    Build {
        not_before: Option<u32>,
    },
    /// The frame is being sent and confirmed.
    Write,
    /// The confirmed frame is being read back.
    Verify,
    Complete,
    Failed(TransferError, Resume),
}

/// Where [`Transfer::resume`] picks up after a failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Resume {
    Nothing,
    Write,
    Verify,
}

/// The frame in flight: its records are the first `records` of the packed
/// ones; the bytes its trailer covers are saved to be restored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Chunk {
    records: u16,
    /// Where the records end and the trailer starts.
    cut: usize,
    saved: [u8; TRAILER_LEN],
    /// Start number (range writes).
    start: u16,
    /// Something abnormal happened while it was written.
    faulted: bool,
    /// Whether a reply to it was accepted.
    confirmed: bool,
    /// Times it went out, across resumes (a reply to any of them may
    /// still come).
    sends: u8,
}

/// A frame or window limit after a success: a quarter more, at least one,
/// at most `max`.
fn grow(limit: u16, max: u16) -> u16 {
    limit.saturating_add((limit / 4).max(1)).min(max)
}

/// Writes a position table to a controller in confirmed (and verified)
/// chunks.
pub struct Transfer<I, const N: usize = { limits::TTA.command }> {
    cfg: TransferConfig,
    source: I,
    /// A record taken from the source that did not fit the last frame.
    held: Option<PositionRecord>,
    source_done: bool,
    total: Option<u32>,
    /// Envelope, prefix, packed records (and the trailer of the chunk).
    frame: [u8; N],
    /// End of the packed records (0: nothing packed).
    fill: usize,
    /// Records packed, the chunk's first.
    packed: u16,
    chunk: Option<Chunk>,
    /// Record counts a reply still in flight could carry.
    guard: Guard,
    /// An unexpected frame came between two frames: the next is faulted.
    pending_fault: bool,
    /// Records per frame now: halved after a timeout, grown back after
    /// each confirmation.
    frame_limit: u16,
    /// Positions per read-back query now, likewise.
    window_limit: u16,
    exchange: Exchange,
    replies: FrameDecoder<32>,
    verifier: Verifier,
    state: State,
    stats: TransferStats,
}

/// The transfer's exchange: copies of the replies it takes are the
/// engine's own guard's business (see the module docs); a stale reply
/// still starts the duplicate window, and the horizon covers it.
const fn engine_exchange(cfg: &ExchangeConfig) -> Exchange {
    Exchange::new(*cfg, Quarantine::ByContent).owner_guards_reply_copies()
}

impl<I: RecordSource, const N: usize> Transfer<I, N> {
    /// A transfer of the records of `source`.
    ///
    /// Always inlined, so that a caller building it into its final place
    /// (a `static`, through `MaybeUninit::write`) writes it there: out of
    /// line, the 2 KB value was built on the stack and copied.
    #[inline(always)]
    pub fn new(cfg: TransferConfig, source: I) -> Self {
        let total = source.total();
        Transfer {
            cfg,
            source,
            held: None,
            source_done: false,
            total,
            frame: [0; N],
            fill: 0,
            packed: 0,
            chunk: None,
            guard: Guard::new(cfg.exchange.horizon()),
            pending_fault: false,
            frame_limit: cfg.max_records.clamp(1, MAX_FRAME_RECORDS),
            window_limit: cfg.stream.read_back().window(cfg.max_response),
            exchange: engine_exchange(&cfg.exchange),
            replies: FrameDecoder::with_policy(BypassPolicy::Reject),
            verifier: Verifier::new(cfg.stream.read_back()),
            state: State::Build { not_before: None },
            stats: TransferStats {
                records_confirmed: 0,
                frames_confirmed: 0,
                frames_sent: 0,
                bytes_sent: 0,
                retries: 0,
                timeouts: 0,
                error_replies: 0,
                count_mismatches: 0,
                stale_replies: 0,
                ignored_frames: 0,
                line_errors: 0,
                guarded_frames: 0,
                shrunk_frames: 0,
                frames_verified: 0,
                records_verified: 0,
                verify_queries: 0,
                verify_bytes_sent: 0,
                rewrites: 0,
                held_queries: 0,
                bytes_received: 0,
            },
        }
    }

    /// Sets the number of records expected (for progress), when the source
    /// cannot tell.
    pub fn with_total(mut self, total: u32) -> Self {
        self.total = Some(total);
        self
    }

    /// [`Transfer::with_total`] in place.
    pub fn set_total(&mut self, total: u32) {
        self.total = Some(total);
    }

    /// Starts over with `cfg` and the source as it is now, in place: the
    /// same as `*self = Transfer::new(cfg, source)` without building a
    /// second transfer (about 3 KB, most of it the frame buffer) on the
    /// stack. Counters start from zero; the frame buffer's bytes are left
    /// as they are (a frame is written before it is read).
    pub fn restart(&mut self, cfg: TransferConfig) {
        let total = self.source.total();
        // Every field, so that a new one cannot be forgotten here.
        let Transfer {
            cfg: c,
            source: _,
            held,
            source_done,
            total: t,
            frame: _,
            fill,
            packed,
            chunk,
            guard,
            pending_fault,
            frame_limit,
            window_limit,
            exchange,
            replies,
            verifier,
            state,
            stats,
        } = self;
        *c = cfg;
        *held = None;
        *source_done = false;
        *t = total;
        *fill = 0;
        *packed = 0;
        *chunk = None;
        *guard = Guard::new(cfg.exchange.horizon());
        *pending_fault = false;
        *frame_limit = cfg.max_records.clamp(1, MAX_FRAME_RECORDS);
        *window_limit = cfg.stream.read_back().window(cfg.max_response);
        *exchange = engine_exchange(&cfg.exchange);
        *replies = FrameDecoder::with_policy(BypassPolicy::Reject);
        *verifier = Verifier::new(cfg.stream.read_back());
        *state = State::Build { not_before: None };
        *stats = TransferStats::default();
    }

    /// The frame buffer, lent out between transfers (a bridge decodes
    /// single frames in it while no 26DH runs). Its bytes are the
    /// transfer's from the first [`Transfer::poll`] after
    /// [`Transfer::new`] or [`Transfer::restart`] until the transfer ends
    /// (and through a [`Transfer::resume`]): write it only outside that
    /// span, and restart before polling again. Bytes written inside it go
    /// out as they are (never a panic: every access is checked).
    pub fn frame_buffer(&mut self) -> &mut [u8; N] {
        &mut self.frame
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

    /// What a success would prove under the configured policy.
    pub const fn guarantee(&self) -> Guarantee {
        match self.cfg.verify {
            Verify::Off => Guarantee::Unverified,
            Verify::AfterFault => Guarantee::FaultsVerified,
            Verify::Full => Guarantee::Verified,
        }
    }

    /// Positions of the frame in flight that read back different or
    /// missing (after a [`TransferError::Mismatch`], or during a read-back).
    pub fn mismatched_positions(&self) -> impl Iterator<Item = u16> + '_ {
        let differ = self.verifier.differ;
        self.chunk_numbers()
            .enumerate()
            .filter(move |(i, _)| differ & bit(*i) != 0)
            .map(|(_, n)| n)
    }

    /// After [`Step::Failed`]: try again where it stopped (the unconfirmed
    /// frame, or its read-back), with a fresh count of sends and rewrites.
    /// Nothing is lost or repeated out of order.
    pub fn resume(&mut self, now: u32) {
        if let State::Failed(_, resume) = self.state {
            self.verifier.rewrites = 0;
            if let Some(c) = self.chunk.as_mut() {
                // Its earlier sends timed out or were refused: a fault,
                // whatever the exchange (which starts afresh) sees next.
                c.faulted = true;
            }
            match resume {
                Resume::Nothing => {}
                Resume::Write => self.start_write(now),
                Resume::Verify => self.start_verify(now),
            }
        }
    }

    /// Decides the next step at tick `now`.
    pub fn poll(&mut self, now: u32) -> Step<'_> {
        loop {
            match self.state {
                State::Build { not_before } => {
                    if let Some(t) =
                        not_before.filter(|&t| !passed(now, t, self.exchange.horizon()))
                    {
                        return Step::WaitUntil(t);
                    }
                    match self.build(now) {
                        Ok(Built::Ready) => self.start_write(now),
                        Ok(Built::Pending) => return Step::NeedRecords,
                        Ok(Built::Exhausted) => self.state = State::Complete,
                        Ok(Built::Wait(t)) => return Step::WaitUntil(t),
                        Err(e) => self.state = State::Failed(e, Resume::Nothing),
                    }
                }
                State::Write | State::Verify => {
                    let writing = self.state == State::Write;
                    match self.exchange.poll(now) {
                        Due::Transmit { fresh } => {
                            if fresh && self.exchange.sends() > 1 {
                                if writing {
                                    self.shrink_chunk(now);
                                } else {
                                    self.shrink_window();
                                }
                            }
                            let end = if writing {
                                self.chunk.map_or(0, |c| c.cut + TRAILER_LEN)
                            } else {
                                self.verifier.query_len
                            };
                            if fresh {
                                self.count_send(writing, end);
                            }
                            let bytes = if writing {
                                self.frame.get(..end)
                            } else {
                                self.verifier.query.get(..end)
                            };
                            return Step::Transmit(bytes.unwrap_or(&[]));
                        }
                        Due::WaitUntil(t) => return Step::WaitUntil(t),
                        Due::Done(Finish::Replied) if writing => self.confirmed(now),
                        Due::Done(Finish::Replied) => self.window_answered(now),
                        Due::Done(Finish::ErrorReply(code)) => {
                            let resume = if writing {
                                Resume::Write
                            } else {
                                Resume::Verify
                            };
                            self.state = State::Failed(TransferError::rejected(code), resume);
                        }
                        Due::Done(_) | Due::Idle => {
                            self.stats.timeouts += 1;
                            let resume = if writing {
                                Resume::Write
                            } else {
                                Resume::Verify
                            };
                            self.state = State::Failed(TransferError::Timeout, resume);
                        }
                    }
                }
                State::Complete => {
                    return Step::Complete(TransferReport {
                        guarantee: self.guarantee(),
                        stats: self.stats,
                    })
                }
                State::Failed(e, _) => return Step::Failed(e),
            }
        }
    }

    fn count_send(&mut self, writing: bool, len: usize) {
        if self.exchange.sends() > 1 {
            self.stats.retries += 1;
            self.stats.timeouts += 1;
        }
        if writing {
            self.stats.frames_sent += 1;
            self.stats.bytes_sent += len as u64;
            if let Some(c) = self.chunk.as_mut() {
                c.sends = c.sends.saturating_add(1);
            }
        } else {
            self.stats.verify_queries += 1;
            self.stats.verify_bytes_sent += len as u64;
        }
        self.replies.reset();
        self.verifier.hunting = true;
    }

    fn start_write(&mut self, now: u32) {
        if let Some(c) = self.chunk.as_mut() {
            c.confirmed = false;
        }
        if core::mem::take(&mut self.verifier.queried) {
            // Written again after a read-back: the next read-back waits
            // until no reply to the earlier queries can come (their
            // duplicates, late replies to their other sends).
            let dup = now.wrapping_add(self.cfg.exchange.duplicate_window_ms);
            self.verifier.hold = Some(later(self.exchange.quiet_from(now), dup));
        }
        // The resend rules, not the entry: `lookup` would link every
        // entry and its name into a program.
        match catalogue::request_rules(self.cfg.stream.id) {
            Some((resend, reply)) => {
                self.exchange
                    .start_raw(self.cfg.stream.id, resend, reply, now);
                self.state = State::Write;
            }
            None => {
                self.state = State::Failed(
                    TransferError::Config(Error::UnknownMessageId {
                        id: self.cfg.stream.id,
                    }),
                    Resume::Nothing,
                )
            }
        }
    }

    /// The caller finished transmitting the frame at tick `now`: its reply
    /// timeout starts.
    pub fn sent(&mut self, now: u32) {
        if self.state == State::Write && self.exchange.busy() && !self.exchange.awaiting() {
            if let Some(c) = self.chunk {
                let until = now
                    .wrapping_add(self.cfg.exchange.timeout_ms)
                    .wrapping_add(self.cfg.exchange.late_window_ms);
                self.guard.sent(c.records, until, now);
            }
        }
        self.exchange.sent(now);
    }

    /// Bytes received from the controller at tick `now`. Returns at the
    /// first event (the same shape as the frame decoder's `decode`): call
    /// again with the rest of the input until it answers
    /// [`TransferEvent::NeedMore`].
    pub fn received(&mut self, bytes: &[u8], now: u32) -> Received<TransferEvent> {
        for (i, &b) in bytes.iter().enumerate() {
            self.stats.bytes_received += 1;
            let event = self.byte(b, now);
            if event != TransferEvent::NeedMore {
                return Received {
                    consumed: i + 1,
                    event,
                };
            }
        }
        Received {
            consumed: bytes.len(),
            event: TransferEvent::NeedMore,
        }
    }

    /// Feeds all of `bytes` ([`Transfer::received`] in a loop); the events
    /// are counted in [`Transfer::stats`].
    pub fn received_all(&mut self, mut bytes: &[u8], now: u32) {
        loop {
            let r = self.received(bytes, now);
            bytes = bytes.get(r.consumed..).unwrap_or(&[]);
            if r.event == TransferEvent::NeedMore {
                return;
            }
        }
    }

    fn byte(&mut self, b: u8, now: u32) -> TransferEvent {
        if self.state == State::Verify {
            let e = self.verify_byte(b, now);
            if e != TransferEvent::NeedMore {
                return e;
            }
        }
        match self.replies.push(b) {
            Event::NeedMore => TransferEvent::NeedMore,
            Event::Error(e) => {
                // A long read-back reply overflows this small decoder: the
                // read-back path decodes it.
                if self.state == State::Verify && matches!(e, Error::FrameTooLong { .. }) {
                    return TransferEvent::NeedMore;
                }
                self.stats.line_errors += 1;
                let envelope = self.replies.failed_envelope();
                let read_back = self.verifier.stream;
                // Outside a read-back, a read-back reply overflows this
                // decoder (its envelope is then unknown) or arrives broken:
                // treat either as a stale read-back reply, whose copy may
                // still come (what it costs is time, never a claim).
                let read_back_reply = matches!(e, Error::FrameTooLong { .. })
                    || envelope.is_some_and(|(h, s, id)| {
                        h == read_back.header
                            && s == self.cfg.exchange.station
                            && id == read_back.id
                    });
                if read_back_reply && self.state != State::Verify {
                    self.stale_read_back(now);
                }
                if matches!(self.state, State::Write | State::Verify) {
                    self.exchange.broken_frame(envelope, now);
                }
                TransferEvent::Broken(e)
            }
            Event::Frame(f) => {
                let read_back = self.verifier.stream;
                if f.header() == read_back.header && f.code() == read_back.id {
                    // Decoded by the read-back path (or, outside a read-back,
                    // a late reply to one).
                    if self.state != State::Verify {
                        self.stats.stale_replies += 1;
                        self.pending_fault = true;
                        self.stale_read_back(now);
                        return TransferEvent::Stale;
                    }
                    return TransferEvent::NeedMore;
                }
                if f.header() == Header::Response
                    && f.code() == self.cfg.stream.id
                    && self.state != State::Write
                {
                    // A late or duplicated write reply between frames.
                    self.stats.stale_replies += 1;
                    self.pending_fault = true;
                    self.guard.duplicates_seen = true;
                    return TransferEvent::Stale;
                }
                let (content_ok, reported) = match (self.state, self.chunk) {
                    (State::Write, Some(c)) => match self.cfg.stream.parse_reply(&f) {
                        Ok((start, count)) => {
                            let start_ok = self.cfg.stream.start_width == 0 || start == c.start;
                            (start_ok && count == c.records, count)
                        }
                        Err(_) => (false, 0),
                    },
                    _ => (false, 0),
                };
                let offer = self.exchange.offer(&f, content_ok, now);
                self.judged(offer, reported)
            }
        }
    }

    /// Counts and reports what a complete frame meant.
    fn judged(&mut self, offer: Offer, reported: u16) -> TransferEvent {
        if !matches!(offer, Offer::Accepted) {
            if let Some(c) = self.chunk.as_mut() {
                c.faulted = true;
            } else {
                self.pending_fault = true;
            }
        }
        match offer {
            Offer::Accepted => {
                self.stats.frames_confirmed += 1;
                let records = self.chunk.map_or(0, |c| c.records);
                TransferEvent::Confirmed { records }
            }
            Offer::Rejected(code) => {
                self.stats.error_replies += 1;
                TransferEvent::Rejected { code }
            }
            Offer::Mismatch => {
                self.stats.count_mismatches += 1;
                self.guard.duplicates_seen = true;
                TransferEvent::CountMismatch {
                    sent: self.chunk.map_or(0, |c| c.records),
                    reported,
                }
            }
            Offer::Stale => {
                self.stats.stale_replies += 1;
                self.guard.duplicates_seen = true;
                TransferEvent::Stale
            }
            Offer::Foreign => {
                self.stats.ignored_frames += 1;
                TransferEvent::Foreign
            }
        }
    }

    /// The write reply came: read back, or finish the frame.
    fn confirmed(&mut self, now: u32) {
        let Some(mut c) = self.chunk else {
            self.state = State::Build {
                not_before: Some(now),
            };
            return;
        };
        c.faulted |= self.exchange.faulted();
        c.confirmed = true;
        // The sends before a resume count too: their replies may still come.
        let sends = c.sends.max(self.exchange.sends());
        self.frame_limit = grow(
            self.frame_limit,
            self.cfg.max_records.clamp(1, MAX_FRAME_RECORDS),
        );
        self.chunk = Some(c);
        // Duplicates of this reply may come for a while; replies to its
        // other sends until their own late window closes.
        let dup = now.wrapping_add(self.cfg.exchange.duplicate_window_ms);
        self.guard.answered(c.records, sends, dup, now);
        let verify = match self.cfg.verify {
            Verify::Off => false,
            Verify::AfterFault => c.faulted,
            Verify::Full => true,
        };
        if verify {
            self.verifier.checked = self.superseded();
            self.verifier.differ = 0;
            self.start_verify(now);
        } else {
            self.finish_chunk(now);
        }
    }

    /// The frame is done: restore what its trailer covered, carry the
    /// records it did not take to the front.
    fn finish_chunk(&mut self, now: u32) {
        self.verifier.hold = None;
        self.verifier.queried = false;
        if let Some(c) = self.chunk.take() {
            self.stats.records_confirmed += u32::from(c.records);
            let records_start = ENVELOPE_LEN + self.cfg.stream.prefix_len();
            if let Some(dst) = self.frame.get_mut(c.cut..c.cut + TRAILER_LEN) {
                dst.copy_from_slice(&c.saved);
            }
            let carried = self.fill.saturating_sub(c.cut);
            // Both ranges lie inside the frame buffer: the chunk was built there.
            let _ = move_within(&mut self.frame, c.cut, carried, records_start);
            self.packed = self.packed.saturating_sub(c.records);
            self.fill = if self.packed > 0 {
                records_start + carried
            } else {
                0
            };
        }
        let turnaround = now
            .wrapping_add(self.cfg.exchange.turnaround_ms)
            .wrapping_add(1);
        self.state = State::Build {
            not_before: Some(turnaround),
        };
    }

    /// Takes the next record: the held-back one first, then the source.
    fn pull(&mut self) -> Pull {
        if let Some(r) = self.held.take() {
            return Pull::Record(r);
        }
        if self.source_done {
            return Pull::End;
        }
        let p = self.source.pull();
        if p == Pull::End {
            self.source_done = true;
        }
        p
    }

    /// Packs records until the frame is full or the source ends, then
    /// chooses how many go in this frame (see the module docs on late
    /// replies) and closes it.
    fn build(&mut self, now: u32) -> Result<Built, TransferError> {
        let cfg = self.cfg;
        let stream = cfg.stream;
        let limit = cfg.max_frame.min(N);
        let records_start = ENVELOPE_LEN + stream.prefix_len();
        let first_index = self.stats.records_confirmed;
        let start = u32::from(cfg.start) + first_index;
        let max_records = stream.max_records.min(self.frame_limit);
        if self.fill < records_start {
            // Begin a frame only when a record is there for it: a table that
            // ends at the top of a range write's start field must complete.
            match self.pull() {
                Pull::Record(r) => self.held = Some(r),
                Pull::Pending => return Ok(Built::Pending),
                Pull::End => return Ok(Built::Exhausted),
            }
            self.fill = records_start;
            self.packed = 0;
        }
        let full = loop {
            if self.packed >= max_records {
                break true;
            }
            let rec = match self.pull() {
                Pull::Record(r) => r,
                Pull::Pending => return Ok(Built::Pending),
                Pull::End => break false,
            };
            let index = first_index + u32::from(self.packed);
            // In a range write record i is position start + i: a number the
            // start field must be able to express.
            if stream.start_width > 0
                && u64::from(cfg.start) + u64::from(index) > stream.start_field().max_unsigned()
            {
                self.held = Some(rec);
                if self.packed == 0 {
                    self.fill = 0;
                    return Err(TransferError::Config(Error::ValueOutOfRange {
                        offset: ENVELOPE_LEN,
                    }));
                }
                break true;
            }
            let len = stream.layout.record_len(rec.axes.count());
            if self.fill + len + TRAILER_LEN > limit {
                self.held = Some(rec);
                if self.packed == 0 {
                    self.fill = 0;
                    return Err(TransferError::Config(Error::BufferTooSmall));
                }
                break true;
            }
            let mut w = Writer::resume(&mut self.frame, self.fill);
            if let Err(error) = stream.layout.write_record(&rec, &mut w) {
                return Err(TransferError::InvalidRecord { index, error });
            }
            self.fill = w.len();
            self.packed += 1;
        };
        let _ = full;
        if self.packed == 0 {
            self.fill = 0;
            return Ok(Built::Exhausted);
        }
        // The most records that no reply still in flight could confirm.
        self.guard.prune(now);
        let Some(n) = (1..=self.packed)
            .rev()
            .find(|&n| !self.guard.blocks(n, now))
        else {
            return Ok(Built::Wait(self.guard.wake(now)));
        };
        if n < self.packed {
            self.stats.guarded_frames += 1;
        }
        let start = u16::try_from(start).map_err(|_| {
            TransferError::Config(Error::ValueOutOfRange {
                offset: ENVELOPE_LEN,
            })
        })?;
        let (cut, saved) = self.close_frame(n, start)?;
        self.chunk = Some(Chunk {
            records: n,
            cut,
            saved,
            start,
            faulted: core::mem::take(&mut self.pending_fault),
            confirmed: false,
            sends: 0,
        });
        Ok(Built::Ready)
    }

    /// Closes the frame after its first `n` packed records: envelope and
    /// prefix with that count, the trailer after the `n`-th record. Returns
    /// where the trailer starts and the bytes it covers.
    fn close_frame(
        &mut self,
        n: u16,
        start: u16,
    ) -> Result<(usize, [u8; TRAILER_LEN]), TransferError> {
        let cfg = self.cfg;
        let stream = cfg.stream;
        let cut = {
            let mut walk = Walk {
                bytes: self.frame.get(..self.fill).unwrap_or(&[]),
                at: ENVELOPE_LEN + stream.prefix_len(),
                stream,
            };
            for _ in 0..n {
                walk.next();
            }
            walk.at
        };
        let mut saved = [0u8; TRAILER_LEN];
        if let Some(src) = self.frame.get(cut..cut + TRAILER_LEN) {
            saved.copy_from_slice(src);
        }
        let mut w = Writer::new(&mut self.frame);
        emit_envelope(&mut w, Header::Command, cfg.exchange.station, stream.id)
            .and_then(|()| stream.write_prefix(&mut w, start, n))
            .map_err(TransferError::Config)?;
        let mut w = Writer::resume(&mut self.frame, cut);
        emit_trailer(&mut w, cfg.checksum).map_err(TransferError::Config)?;
        Ok((cut, saved))
    }

    /// The frame in flight timed out: send its first half instead (a long
    /// frame is more likely hit by noise) and keep frames that small until
    /// they get through again. The rest is carried to the next frame; the
    /// count still avoids those a late reply could carry.
    fn shrink_chunk(&mut self, now: u32) {
        let Some(c) = self.chunk else { return };
        self.guard.prune(now);
        let Some(n) = (1..=c.records / 2)
            .rev()
            .find(|&n| !self.guard.blocks(n, now))
        else {
            return;
        };
        if let Some(dst) = self.frame.get_mut(c.cut..c.cut + TRAILER_LEN) {
            dst.copy_from_slice(&c.saved);
        }
        match self.close_frame(n, c.start) {
            Ok((cut, saved)) => {
                self.chunk = Some(Chunk {
                    records: n,
                    cut,
                    saved,
                    ..c
                });
                self.frame_limit = n;
                self.stats.shrunk_frames += 1;
            }
            Err(e) => self.state = State::Failed(e, Resume::Nothing),
        }
    }
}

/// What [`Transfer::build`] achieved.
enum Built {
    Ready,
    Pending,
    Exhausted,
    /// Every count that fits is guarded until this tick.
    Wait(u32),
}

impl<I: RecordSource, const N: usize> Transfer<I, N> {
    /// Runs the transfer to the end over a UART, blocking.
    ///
    /// `uart` must report readiness ([`embedded_io::ReadReady`]) so that the
    /// engine can watch its deadline while no byte arrives.
    pub fn run_blocking<U, C>(
        &mut self,
        uart: &mut U,
        clock: &mut C,
    ) -> Result<TransferReport, TransferError<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        drive::run_blocking(self, uart, clock).map_err(TransferError::from_stop)
    }

    /// Makes what progress is possible without waiting: reads the bytes
    /// already received, sends a frame that is due (reading the clock
    /// *after* the write, so that the reply timeout starts at the end of
    /// the transmission), checks the deadline. `WouldBlock` means "call
    /// again later".
    pub fn poll_nb<U, C>(
        &mut self,
        uart: &mut U,
        clock: &mut C,
    ) -> nb::Result<TransferReport, TransferError<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        drive::poll_nb(self, uart, clock).map_err(|e| e.map(TransferError::from_stop))
    }

    /// Runs the transfer to the end over an `embedded-io-async` UART.
    ///
    /// While waiting it checks [`embedded_io_async::ReadReady`] and sleeps
    /// at most `poll_ms` between checks, so the deadline is always seen
    /// even if no byte arrives. The clock is read after each write, so the
    /// reply timeout starts at the end of the transmission. A
    /// [`RecordQueue`] source is filled by whoever owns the transfer
    /// between calls; here a pending source just sleeps.
    #[cfg(feature = "async")]
    pub async fn run_async<U, C>(
        &mut self,
        uart: &mut U,
        clock: &mut C,
        poll_ms: u32,
    ) -> Result<TransferReport, TransferError<U::Error>>
    where
        U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
        C: crate::clock::AsyncClock,
    {
        drive::run_async(self, uart, clock, poll_ms)
            .await
            .map_err(TransferError::from_stop)
    }
}

impl<I: RecordSource, const N: usize> Engine for Transfer<I, N> {
    type Output = TransferReport;
    type Error = TransferError;
    fn feed(&mut self, bytes: &[u8], now: u32) {
        self.received_all(bytes, now);
    }
    fn want(&mut self, now: u32) -> Want<'_, Result<TransferReport, TransferError>> {
        match self.poll(now) {
            Step::Transmit(bytes) => Want::Transmit(bytes),
            Step::WaitUntil(t) => Want::WaitUntil(t),
            Step::NeedRecords => Want::Idle,
            Step::Complete(report) => Want::Done(Ok(report)),
            Step::Failed(e) => Want::Done(Err(e)),
        }
    }
    fn sent(&mut self, now: u32) {
        Transfer::sent(self, now);
    }
}

impl<E> TransferError<E> {
    pub(crate) fn from_stop(stop: Stop<TransferError, E>) -> Self {
        match stop {
            Stop::Engine(e) => e.widen(),
            Stop::Io(e) => TransferError::Io(e),
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::message::{
        ChangePositionData2Response, EffectivePositionResponse2, Message, Repeated,
    };

    const ST: Station = Station(0x99);

    fn records(n: u16, axes: u8) -> Vec<PositionRecord> {
        (1..=n)
            .map(|i| {
                let coords: Vec<(u8, i32)> = (1..=axes).map(|a| (a, i32::from(i) * 10)).collect();
                PositionRecord::new(i, 30, 30, 100, &coords).unwrap()
            })
            .collect()
    }

    fn reply_26dh(count: u16) -> Vec<u8> {
        let r = ChangePositionData2Response {
            number_of_changed_positions: count,
        };
        let mut buf = [0u8; 16];
        let n = r.emit(ST, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn events(
        t: &mut Transfer<std::vec::IntoIter<PositionRecord>>,
        mut bytes: &[u8],
    ) -> Vec<TransferEvent> {
        let mut out = Vec::new();
        loop {
            let r = t.received(bytes, 10);
            bytes = &bytes[r.consumed..];
            if r.event == TransferEvent::NeedMore {
                return out;
            }
            out.push(r.event);
        }
    }

    fn transmitted(t: &mut Transfer<std::vec::IntoIter<PositionRecord>>, now: u32) -> Vec<u8> {
        match t.poll(now) {
            Step::Transmit(b) => b.to_vec(),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_reply_with_another_count_never_confirms_and_a_reply_before_the_send_is_stale() {
        let cfg = TransferConfig::tta(ST).with_verify(Verify::Off);
        let mut t = Transfer::<_>::new(cfg, records(3, 2).into_iter());
        let frame = transmitted(&mut t, 0);
        assert_eq!(&frame[..10], b"!9926D0003");
        // Before `sent`: not a reply to this frame.
        assert_eq!(events(&mut t, &reply_26dh(3)), [TransferEvent::Stale]);
        t.sent(5);
        assert_eq!(
            events(&mut t, &reply_26dh(2)),
            [TransferEvent::CountMismatch {
                sent: 3,
                reported: 2
            }]
        );
        assert!(matches!(t.poll(10), Step::WaitUntil(3_005)));
        assert_eq!(
            events(&mut t, &reply_26dh(3)),
            [TransferEvent::Confirmed { records: 3 }]
        );
        // The turnaround (1 ms, two ticks), then nothing is left to send.
        assert_eq!(t.poll(20), Step::WaitUntil(22));
        match t.poll(22) {
            Step::Complete(r) => {
                assert_eq!(r.guarantee, Guarantee::Unverified);
                assert_eq!(r.stats.records_confirmed, 3);
                assert_eq!(r.stats.count_mismatches, 1);
            }
            other => panic!("{other:?}"),
        }
    }

    /// Runs a queue-fed transfer of `recs` (Verify::Off) to its end,
    /// answering every chunk: what it sent and its report.
    fn run_queued(
        t: &mut Transfer<RecordQueue<4>>,
        recs: &[PositionRecord],
        mut now: u32,
    ) -> (Vec<Vec<u8>>, TransferReport) {
        let mut rest = recs.iter();
        let mut sent = Vec::new();
        loop {
            while !t.source_mut().is_full() {
                match rest.next() {
                    Some(r) => t.source_mut().push(r.clone()).unwrap(),
                    None => {
                        t.source_mut().finish();
                        break;
                    }
                }
            }
            match t.poll(now) {
                Step::Transmit(b) => {
                    let n =
                        u16::from_str_radix(std::str::from_utf8(&b[6..10]).unwrap(), 16).unwrap();
                    sent.push(b.to_vec());
                    t.sent(now);
                    t.received_all(&reply_26dh(n), now + 1);
                }
                Step::WaitUntil(d) => now = d,
                Step::NeedRecords => now += 1,
                Step::Complete(r) => return (sent, r),
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn a_restarted_transfer_runs_as_a_new_one() {
        let first = TransferConfig::tta(ST).with_verify(Verify::Off);
        let second = TransferConfig {
            max_records: 5,
            ..TransferConfig::tta(ST).with_verify(Verify::Off)
        };
        let recs = records(17, 3);

        let mut fresh = Transfer::<_>::new(second, RecordQueue::<4>::new()).with_total(17);
        let expected = run_queued(&mut fresh, &recs, 1_000);

        // A transfer left half way (a chunk sent, never answered, records
        // queued), its buffer then used for something else.
        let mut t = Transfer::<_>::new(first, RecordQueue::<4>::new());
        for r in &recs[..4] {
            t.source_mut().push(r.clone()).unwrap();
        }
        t.source_mut().finish();
        assert!(matches!(t.poll(0), Step::Transmit(_)));
        t.sent(0);
        t.frame_buffer().fill(b'%');
        t.source_mut().clear();
        assert!(t.source_mut().is_empty() && !t.source_mut().is_finished());
        t.restart(second);
        t.set_total(17);
        assert_eq!(t.progress(), (0, Some(17)));
        assert_eq!(t.stats(), TransferStats::default());
        assert_eq!(run_queued(&mut t, &recs, 1_000), expected);
        assert_eq!(expected.1.stats.records_confirmed, 17);
    }

    #[test]
    fn consecutive_frames_never_share_a_count() {
        // 8-axis records: 24 fit a frame. 48 records go as 24, 23, 1.
        let cfg = TransferConfig::tta(ST).with_verify(Verify::Off);
        let mut t = Transfer::<_>::new(cfg, records(48, 8).into_iter());
        let mut counts = Vec::new();
        let mut now = 0;
        loop {
            match t.poll(now) {
                Step::Transmit(b) => {
                    let n =
                        u16::from_str_radix(std::str::from_utf8(&b[6..10]).unwrap(), 16).unwrap();
                    counts.push(n);
                    t.sent(now);
                    t.received_all(&reply_26dh(n), now + 1);
                }
                Step::WaitUntil(d) => now = d,
                Step::Complete(_) => break,
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(counts, [24, 23, 1]);
    }

    #[test]
    fn a_frame_that_reads_back_different_is_rewritten() {
        let recs = records(2, 1);
        let mut t = Transfer::<_>::new(TransferConfig::tta(ST), recs.clone().into_iter());
        let mut now = 0;
        let mut writes = 0;
        let mut stored = recs.clone();
        stored[1].positions[0] += 1; // the controller holds record 2 altered
        loop {
            match t.poll(now) {
                Step::Transmit(b) if b.starts_with(b"!9926D") => {
                    writes += 1;
                    t.sent(now);
                    if writes > 1 {
                        stored = recs.clone(); // the rewrite lands
                    }
                    t.received_all(&reply_26dh(2), now + 1);
                }
                Step::Transmit(b) => {
                    assert!(
                        b.starts_with(b"!9921F00010002"),
                        "the frame's two positions from 1, not a whole 24-record window"
                    );
                    t.sent(now);
                    let r = EffectivePositionResponse2 {
                        records: Repeated::from_slice(&stored),
                    };
                    let mut buf = [0u8; 128];
                    let n = r.emit(ST, &mut buf).unwrap();
                    t.received_all(&buf[..n], now + 1);
                }
                Step::WaitUntil(d) => now = d.max(now + 1),
                Step::Complete(r) => {
                    assert_eq!(r.guarantee, Guarantee::Verified);
                    assert_eq!(r.stats.rewrites, 1);
                    assert_eq!(r.stats.records_verified, 2);
                    break;
                }
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(writes, 2);
    }

    /// A frame resumed after a timeout was sent before the resume too: a
    /// late reply to that send may still come. The next frame of the same
    /// count waits for it, and (after a fault) the frame is read back
    /// (fuzz finding F12).
    #[test]
    fn sends_before_a_resume_still_count() {
        // Sent at 0, timed out, resumed and sent again at 3,005: confirmed.
        let resumed = |cfg: TransferConfig, count: u16| {
            let mut t = Transfer::<_>::new(cfg, records(2, 1).into_iter());
            assert!(matches!(t.poll(0), Step::Transmit(b) if b.starts_with(b"!9926D")));
            t.sent(0);
            assert!(matches!(
                t.poll(3_000),
                Step::Failed(TransferError::Timeout)
            ));
            t.resume(3_000);
            assert!(matches!(t.poll(3_000), Step::Transmit(b) if b.starts_with(b"!9926D")));
            t.sent(3_005);
            t.received_all(&reply_26dh(count), 3_006);
            t
        };
        let mut cfg = TransferConfig::tta(ST).with_verify(Verify::Off);
        cfg.max_records = 1;
        cfg.exchange.max_sends = 1;
        cfg.exchange.late_window_ms = 10_000;
        let mut t = resumed(cfg, 1);
        // Record 2 (count 1 too) waits until the first send's reply can no
        // longer come: 0 + 3,000 + 10,000 at the earliest.
        assert_eq!(t.poll(3_010), Step::WaitUntil(3_012)); // the turnaround
        let mut at = 3_012;
        while let Step::WaitUntil(w) = t.poll(at) {
            at = w;
        }
        assert!(at >= 13_000, "record 2 went out at {at}");

        let mut cfg = TransferConfig::tta(ST).with_verify(Verify::AfterFault);
        cfg.exchange.max_sends = 1;
        let mut t = resumed(cfg, 2);
        // Confirmed after a fault: read back.
        assert!(matches!(t.poll(3_012), Step::Transmit(b) if b.starts_with(b"!9921F")));
    }

    /// The hold after a rewrite lies a whole duplicate window ahead, here
    /// further than a timeout, a late window and a restart together: it
    /// must still read as a hold, not as one set long ago (fuzz F11).
    #[test]
    fn a_hold_longer_than_the_exchange_windows_is_kept() {
        let recs = records(2, 1);
        let mut cfg = TransferConfig::tta(ST);
        cfg.exchange.duplicate_window_ms = 60_000;
        let mut t = Transfer::<_>::new(cfg, recs.clone().into_iter());
        let mut altered = recs.clone();
        altered[1].positions[0] += 1;
        let old = {
            let r = EffectivePositionResponse2 {
                records: Repeated::from_slice(&altered),
            };
            let mut buf = [0u8; 128];
            let n = r.emit(ST, &mut buf).unwrap();
            buf[..n].to_vec()
        };
        assert!(matches!(t.poll(0), Step::Transmit(b) if b.starts_with(b"!9926D")));
        t.sent(5);
        t.received_all(&reply_26dh(2), 6);
        assert!(matches!(t.poll(8), Step::Transmit(b) if b.starts_with(b"!9921F")));
        t.sent(10);
        t.received_all(&old, 11);
        assert!(matches!(t.poll(13), Step::Transmit(b) if b.starts_with(b"!9926D")));
        t.sent(20);
        t.received_all(&reply_26dh(2), 21);
        assert_eq!(t.poll(23), Step::WaitUntil(60_013));
    }

    /// A read-back reply carries nothing that ties it to its query: after
    /// a rewrite, a copy of the reply from before it would read as the
    /// new state. The next query waits until no such copy can come.
    #[test]
    fn after_a_rewrite_an_old_read_back_reply_cannot_verify_the_frame() {
        let recs = records(2, 1);
        let mut t = Transfer::<_>::new(TransferConfig::tta(ST), recs.clone().into_iter());
        let mut altered = recs.clone();
        altered[1].positions[0] += 1;
        let read_back = |stored: &[PositionRecord]| {
            let r = EffectivePositionResponse2 {
                records: Repeated::from_slice(stored),
            };
            let mut buf = [0u8; 128];
            let n = r.emit(ST, &mut buf).unwrap();
            buf[..n].to_vec()
        };
        let old = read_back(&altered);
        // Written, confirmed, read back different at 11.
        assert!(matches!(t.poll(0), Step::Transmit(b) if b.starts_with(b"!9926D")));
        t.sent(5);
        t.received_all(&reply_26dh(2), 6);
        assert!(matches!(t.poll(6), Step::WaitUntil(8)));
        assert!(matches!(t.poll(8), Step::Transmit(b) if b.starts_with(b"!9921F")));
        t.sent(10);
        t.received_all(&old, 11);
        // The rewrite goes out and is confirmed.
        assert!(matches!(t.poll(11), Step::WaitUntil(13)));
        assert!(matches!(t.poll(13), Step::Transmit(b) if b.starts_with(b"!9926D")));
        t.sent(20);
        t.received_all(&reply_26dh(2), 21);
        // The read-back waits out the duplicate window of the old reply
        // (3 s from the verdict at 11).
        assert_eq!(t.poll(23), Step::WaitUntil(3_011));
        // A copy of the old reply meanwhile is stale, not a comparison; a
        // copy of it may come until 3,500, so the query waits for that.
        assert_eq!(t.received(&old, 500).event, TransferEvent::Stale,);
        assert_eq!(t.poll(3_011), Step::WaitUntil(3_500));
        assert!(matches!(t.poll(3_500), Step::Transmit(b) if b.starts_with(b"!9921F")));
        t.sent(3_505);
        t.received_all(&read_back(&recs), 3_506);
        assert_eq!(t.poll(3_506), Step::WaitUntil(3_508));
        match t.poll(3_508) {
            Step::Complete(r) => {
                assert_eq!(r.guarantee, Guarantee::Verified);
                assert_eq!(r.stats.rewrites, 1);
                assert_eq!(r.stats.held_queries, 1);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_frame_that_stays_different_fails_naming_its_records() {
        let recs = records(3, 1);
        let cfg = TransferConfig {
            rewrites: 1,
            ..TransferConfig::tta(ST)
        };
        let mut t = Transfer::<_>::new(cfg, recs.clone().into_iter());
        let mut stored = recs.clone();
        stored.remove(1); // position 2 never gets stored
        let mut now = 0;
        let err = loop {
            match t.poll(now) {
                Step::Transmit(b) if b.starts_with(b"!9926D") => {
                    t.sent(now);
                    t.received_all(&reply_26dh(3), now + 1);
                }
                Step::Transmit(_) => {
                    t.sent(now);
                    let r = EffectivePositionResponse2 {
                        records: Repeated::from_slice(&stored),
                    };
                    let mut buf = [0u8; 128];
                    let n = r.emit(ST, &mut buf).unwrap();
                    t.received_all(&buf[..n], now + 1);
                }
                Step::WaitUntil(d) => now = d.max(now + 1),
                Step::Failed(e) => break e,
                other => panic!("{other:?}"),
            }
        };
        assert_eq!(
            err,
            TransferError::Mismatch {
                first_position: 2,
                records: 1
            }
        );
        assert_eq!(t.mismatched_positions().collect::<Vec<_>>(), [2]);
    }
}
