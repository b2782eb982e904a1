//! The transfer engine: a position table of any size written in
//! controller-sized commands (26DH on a TTA), each confirmed, and read back
//! and compared as the [`Verify`] policy asks.
//!
//! [`Transfer`] pulls records from a [`RecordSource`], packs as many as
//! the controller takes into one command, and runs it over a [`Line`]
//! (timeouts, resends, what may still arrive: [`crate::line`]). A reply
//! confirms a frame only if it reports exactly the records sent (and, for
//! a range write, its start).
//!
//! - A reply carries only a count, so where the count is the proof
//!   ([`Verify::Off`], [`Verify::AfterFault`]) a frame never gets a count
//!   that a copy of an earlier reply could carry: the line's ledger says
//!   which counts are still possible, and the frame takes fewer records
//!   instead. Under [`Verify::Full`] the read-back is the proof.
//! - A frame whose reply times out is sent again with half its records
//!   (a long frame is more likely hit by noise); frames grow back by a
//!   quarter per confirmation.
//! - An `&` stops the transfer with the code ([`Failure::Controller`]);
//!   [`Transfer::resume`] sends the frame again when the caller decides
//!   to (2003 p. 66 asks for "appropriate action", not a blind resend).
//!   Nothing is lost, skipped or reordered.
//!
//! Verification: a confirmed frame means the controller
//! *said* it wrote that many records. The 8-bit SC lets some corruptions
//! through, and a count cannot say which records. With [`Verify::Full`]
//! every frame is read back (21FH for 26DH, 22DH for 290H/291H, 209H for
//! 244H/245H) and compared record by record with the frame still held for
//! retries; a frame that differs is rewritten (up to `rewrites` times,
//! then [`Failure::Mismatch`]). That the controller stores the values
//! unchanged is an **assumption** (no manual gives a clamping or rounding
//! rule, TTA pp. 35, 60).
//!
//! RAM: the frame buffer `N` (default 2,051 bytes, the TTA's receive
//! limit) with its decoder state, a 32-byte reply decoder, the read-back's
//! 88-byte stage, one held-back record and counters, whatever the table
//! size. Flavours: [`Transfer::run_blocking`], [`Transfer::poll_nb`] and,
//! with the `async` feature, `Transfer::run_async`.

mod build;
mod source;
mod verify;

pub use source::{packed_len, Pull, RecordBuffer, RecordSource};

use verify::Verifier;

use crate::checksum::BypassPolicy;
use crate::clock::Clock;
use crate::decoder::{FrameDecoder, Received, Status};
use crate::engine::{self, Engine, Step};
use crate::error::Failure;
use crate::frame::{Frame, Header, TRAILER_LEN};
use crate::limits;
use crate::line::{Claim, Command, Due, Heard, Judge, Line, Receiver, Span, Verdict};
use crate::position::{PositionRecord, PositionStream};
use crate::profile::Profile;

/// Most records one frame carries (the read-back keeps one bit per record).
/// A 2,051-byte 26DH holds at most 113 (records without axes).
pub const MAX_FRAME_RECORDS: u16 = 128;

/// How much the engine reads back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Verify {
    /// Trust the count in each reply.
    Off,
    /// Read back the frames confirmed after a fault (a timeout, a resend,
    /// a wrong count, a stale or foreign reply while they were written).
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
    /// The write message used.
    pub stream: PositionStream,
    /// Start number of a range write (244H, 290H); ignored by the others.
    pub start: u16,
    /// Largest command frame the controller accepts, header through LF.
    pub max_frame: usize,
    /// Largest response frame the controller sends (sizes the read-back
    /// windows).
    pub max_response: usize,
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
    /// Tables for a controller of `profile`: its table write (26DH on a
    /// TTA, 245H on a 2003 X-SEL) in frames as large as it receives, full
    /// verification, two rewrites.
    pub const fn new(profile: Profile) -> Self {
        TransferConfig {
            stream: profile.table_write(),
            start: 0,
            max_frame: profile.max_command_frame(),
            max_response: profile.max_response_frame(),
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

    /// How much a write's reply has to prove. Under [`Verify::Full`] the
    /// read-back that follows is the proof (a write a copy seemed to
    /// confirm reads back different and is rewritten), so the reply need
    /// only not be an error's copy; otherwise the count it carries is the
    /// proof, and no reply that may still arrive may carry it.
    const fn write_claim(&self) -> Claim {
        match self.verify {
            Verify::Full => Claim::Tentative,
            _ => Claim::Proof,
        }
    }

    /// What a success proves under this policy.
    pub const fn guarantee(&self) -> Guarantee {
        match self.verify {
            Verify::Off => Guarantee::Unverified,
            Verify::AfterFault => Guarantee::FaultsVerified,
            Verify::Full => Guarantee::Verified,
        }
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
    /// Writes or read-back queries sent again after a timeout.
    pub retries: u32,
    /// Timeouts (each resend, and each time the sends ran out).
    pub timeouts: u32,
    /// `&` error responses received.
    pub error_replies: u32,
    /// Write replies whose count was not the frame's.
    pub count_mismatches: u32,
    /// Replies that came when none was awaited (late or copied), and
    /// read-back replies for another window.
    pub stale_replies: u32,
    /// Frames from the line that were no reply to the awaited command.
    pub ignored_frames: u32,
    /// Broken frames and noise seen on the reply line.
    pub line_errors: u32,
    /// Frames sent with fewer records than fitted, so that no reply that
    /// may still arrive could confirm them.
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
    /// Records a read-back did not find at all (stored elsewhere:
    /// [`Failure::Misplaced`]).
    pub misplaced: u32,
    /// Bytes received from the controller.
    pub bytes_received: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Packing the next frame.
    Build,
    /// The frame is being sent and confirmed.
    Write,
    /// The confirmed frame is being read back.
    Verify,
    Complete,
    Failed(Failure, Resume),
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
    /// When it was last sent, no reply that may still arrive could pass for
    /// its reply: the reply taken is the controller's to this frame, which
    /// it took whole (a record its read-back lacks went elsewhere).
    provable: bool,
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
    /// The frame buffer: envelope, prefix, packed records (and the chunk's
    /// trailer). Between transfers it is lent out as a frame decoder.
    frame: FrameDecoder<N>,
    /// End of the packed records (0: nothing packed).
    fill: usize,
    /// Records packed, the chunk's first.
    packed: u16,
    chunk: Option<Chunk>,
    /// An unexpected frame came between two frames: the next is faulted.
    pending_fault: bool,
    /// Records per frame now: halved after a timeout, grown back after
    /// each confirmation.
    frame_limit: u16,
    replies: Receiver<32>,
    verifier: Verifier,
    state: State,
    stats: TransferStats,
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
            frame: FrameDecoder::with_policy(BypassPolicy::CommandsOnly),
            fill: 0,
            packed: 0,
            chunk: None,
            pending_fault: false,
            frame_limit: cfg.max_records.clamp(1, MAX_FRAME_RECORDS),
            replies: Receiver::new(),
            verifier: Verifier::new(&cfg),
            state: State::Build,
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
                misplaced: 0,
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
    /// second transfer (about 3 KB) on the stack. Counters start from
    /// zero. What the old transfer left in flight is the line's to
    /// remember.
    pub fn restart(&mut self, cfg: TransferConfig) {
        let total = self.source.total();
        // Every field, so that a new one cannot be forgotten here.
        let Transfer {
            cfg: c,
            source: _,
            held,
            source_done,
            total: t,
            frame,
            fill,
            packed,
            chunk,
            pending_fault,
            frame_limit,
            replies,
            verifier,
            state,
            stats,
        } = self;
        *c = cfg;
        *held = None;
        *source_done = false;
        *t = total;
        frame.take_buffer();
        *fill = 0;
        *packed = 0;
        *chunk = None;
        *pending_fault = false;
        *frame_limit = cfg.max_records.clamp(1, MAX_FRAME_RECORDS);
        *replies = Receiver::new();
        *verifier = Verifier::new(&cfg);
        *state = State::Build;
        *stats = TransferStats::default();
    }

    /// The frame buffer as a frame decoder, lent out between transfers (a
    /// bridge decodes single commands and replies in it while no 26DH
    /// runs). Its bytes are the transfer's from the first
    /// [`Transfer::poll`] after [`Transfer::new`] or [`Transfer::restart`]
    /// until the transfer ends (and through a [`Transfer::resume`]): decode
    /// only outside that span, and restart before polling again.
    pub fn idle_decoder(&mut self) -> &mut FrameDecoder<N> {
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

    /// The record source (e.g. to push records into a [`RecordBuffer`]).
    pub fn source_mut(&mut self) -> &mut I {
        &mut self.source
    }

    /// Gives back the record source (e.g. to recover it after a failure).
    pub fn into_source(self) -> I {
        self.source
    }

    /// Positions of the frame in flight that read back different or
    /// missing (after a [`Failure::Mismatch`], or during a read-back).
    pub fn mismatched_positions(&self) -> impl Iterator<Item = u16> + '_ {
        self.differing()
    }

    /// After a failure: try again where it stopped (the unconfirmed frame,
    /// or its read-back), with a fresh count of sends and rewrites.
    /// Nothing is lost or repeated out of order; the sends before the
    /// resume are the line's to settle.
    pub fn resume(&mut self, line: &mut Line, now: u32) {
        if let State::Failed(_, resume) = self.state {
            self.verifier.rewrites = 0;
            if let Some(c) = self.chunk.as_mut() {
                // Its earlier sends timed out or were refused: a fault.
                c.faulted = true;
            }
            match resume {
                Resume::Nothing => {}
                Resume::Write => self.start_write(line, now),
                Resume::Verify => self.start_verify(line, now),
            }
        }
    }

    /// Decides the next step at tick `now`.
    pub fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, Guarantee> {
        loop {
            match self.state {
                State::Build => match self.build(line, now) {
                    Ok(build::Built::Ready) => self.start_write(line, now),
                    Ok(build::Built::Pending) => return Step::Idle,
                    Ok(build::Built::Exhausted) => self.state = State::Complete,
                    Ok(build::Built::Wait(t)) => return Step::WaitUntil(t),
                    Err(e) => self.state = State::Failed(e, Resume::Nothing),
                },
                State::Write | State::Verify => {
                    let writing = self.state == State::Write;
                    match line.poll(now) {
                        Due::Fence => return Step::Transmit(line.fence_bytes()),
                        Due::Send { fresh } => {
                            if fresh {
                                if line.sends() > 1 {
                                    self.stats.retries += 1;
                                    self.stats.timeouts += 1;
                                    if writing {
                                        self.shrink_chunk(line, now);
                                    } else {
                                        self.shrink_window(line);
                                    }
                                }
                                self.replies.clear(line, now);
                                self.drop_read_back(line, now);
                            }
                            if !matches!(self.state, State::Write | State::Verify) {
                                continue;
                            }
                            let bytes = if writing {
                                let end = self.chunk.map_or(0, |c| c.cut + TRAILER_LEN);
                                if fresh {
                                    let id = self.cfg.stream.id;
                                    if let Some(c) = self.chunk.as_mut() {
                                        let accepts = Span::one(c.records);
                                        c.provable =
                                            line.clear_at(id, accepts, Claim::Proof, now) == now;
                                    }
                                    self.stats.frames_sent += 1;
                                    self.stats.bytes_sent += end as u64;
                                }
                                self.frame.buffer().get(..end)
                            } else {
                                let q = self.verifier.query();
                                if fresh {
                                    self.stats.verify_queries += 1;
                                    self.stats.verify_bytes_sent += q.len() as u64;
                                }
                                Some(q)
                            };
                            return Step::Transmit(bytes.unwrap_or(&[]));
                        }
                        Due::WaitUntil(t) => return Step::WaitUntil(t),
                        Due::Done(Ok(())) if writing => self.confirmed(line, now),
                        Due::Done(Ok(())) => self.window_answered(line, now),
                        Due::Done(Err(e)) => self.failed(e, writing),
                        // Another engine took the line meanwhile.
                        Due::Idle => self.failed(
                            Failure::Timeout {
                                sends: line.sends(),
                            },
                            writing,
                        ),
                    }
                }
                State::Complete => {
                    // Verified frame by frame, but a record went elsewhere:
                    // what it overwrote is not known.
                    return Step::Done(match self.verifier.misplaced {
                        Some(position) => Err(Failure::Misplaced { position }),
                        None => Ok(self.cfg.guarantee()),
                    });
                }
                State::Failed(e, _) => return Step::Done(Err(e)),
            }
        }
    }

    fn failed(&mut self, e: Failure, writing: bool) {
        if !matches!(e, Failure::Controller { .. }) {
            self.stats.timeouts += 1;
        }
        let resume = if writing {
            Resume::Write
        } else {
            Resume::Verify
        };
        self.state = State::Failed(e, resume);
    }

    /// Begins (or begins again) the write of the chunk.
    fn start_write(&mut self, line: &mut Line, now: u32) {
        let records = self.chunk.map_or(0, |c| c.records);
        let max_sends = line.config().max_sends;
        let cmd = Command::of(
            self.cfg.stream.id,
            Span::one(records),
            self.cfg.write_claim(),
            max_sends,
        );
        line.begin(cmd, now);
        self.state = State::Write;
    }

    /// The caller finished transmitting at tick `now`: the reply timeout
    /// starts.
    pub fn sent(&mut self, line: &mut Line, now: u32) {
        line.sent(now);
    }

    /// Bytes received from the controller at tick `now`. Returns at the
    /// first frame (or broken one): call again with the rest of the input
    /// until it answers [`Status::Partial`].
    pub fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        // A read-back reply streams by the verifier byte by byte, whatever
        // the transfer awaits: it is compared while a read-back runs, and
        // otherwise (a copy, a late reply) still tells the line which
        // positions it carried, which a 32-byte buffer could not. The
        // receiver takes the other frames.
        for (i, &b) in bytes.iter().enumerate() {
            self.stats.bytes_received += 1;
            let mut heard = self.verify_byte(line, b, now);
            if heard.is_partial() {
                heard = self.receive(line, core::slice::from_ref(&b), now).status;
            }
            if let Status::Complete(h) = heard {
                return Received {
                    consumed: i + 1,
                    status: Status::Complete(h),
                };
            }
        }
        Received {
            consumed: bytes.len(),
            status: Status::Partial,
        }
    }

    /// The receiver's part: write replies, errors, fences, anything else.
    fn receive(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        let mut judge = CountCheck {
            cfg: &self.cfg,
            chunk: match self.state {
                State::Write => self.chunk,
                _ => None,
            },
        };
        let r = self.replies.receive(line, &mut judge, bytes, now);
        if let Status::Complete(heard) = r.status {
            if let Heard::Broken(_) = heard {
                self.stats.line_errors += 1;
            }
            self.judged(heard);
        }
        r
    }

    /// Counts what a frame meant; anything but the reply faults the chunk.
    fn judged(&mut self, heard: Heard) {
        if !matches!(heard, Heard::Answer | Heard::Fence) {
            match self.chunk.as_mut() {
                Some(c) => c.faulted = true,
                None => self.pending_fault = true,
            }
        }
        match heard {
            Heard::Answer => self.stats.frames_confirmed += 1,
            Heard::Rejected(_) => self.stats.error_replies += 1,
            Heard::Mismatch => self.stats.count_mismatches += 1,
            Heard::Stale | Heard::Unplaced => self.stats.stale_replies += 1,
            Heard::Foreign => self.stats.ignored_frames += 1,
            Heard::Fence | Heard::Broken(_) => {}
        }
    }

    /// The write reply came: read back, or finish the frame.
    fn confirmed(&mut self, line: &mut Line, now: u32) {
        let Some(c) = self.chunk.as_mut() else {
            self.state = State::Build;
            return;
        };
        c.faulted |= line.faulted();
        let faulted = c.faulted;
        self.frame_limit = crate::window::grown(
            self.frame_limit,
            self.cfg.max_records.clamp(1, MAX_FRAME_RECORDS),
        );
        let verify = match self.cfg.verify {
            Verify::Off => false,
            Verify::AfterFault => faulted,
            Verify::Full => true,
        };
        if verify {
            self.begin_verify();
            self.start_verify(line, now);
        } else {
            self.finish_chunk();
        }
    }

    /// Runs the transfer to the end over a UART, blocking.
    ///
    /// `uart` must report readiness ([`embedded_io::ReadReady`]) so that the
    /// engine can watch its deadline while no byte arrives.
    pub fn run_blocking<U, C>(
        &mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
    ) -> Result<Guarantee, Failure<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        engine::run_blocking(self, line, uart, clock)
    }

    /// Makes what progress is possible without waiting (see
    /// [`engine::poll_nb`]). `WouldBlock` means "call again later".
    pub fn poll_nb<U, C>(
        &mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
    ) -> nb::Result<Guarantee, Failure<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        engine::poll_nb(self, line, uart, clock)
    }

    /// Runs the transfer to the end over an `embedded-io-async` UART,
    /// sleeping at most `poll_ms` between checks while it waits (a
    /// [`RecordBuffer`] source is filled by its owner between calls; a
    /// pending source just sleeps).
    #[cfg(feature = "async")]
    pub async fn run_async<U, C>(
        &mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
        poll_ms: u32,
    ) -> Result<Guarantee, Failure<U::Error>>
    where
        U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
        C: crate::clock::AsyncClock,
    {
        engine::run_async(self, line, uart, clock, poll_ms).await
    }
}

/// A transfer's check of a write reply: exactly the chunk's records (and,
/// for a range write, its start). Read-back replies stream to the
/// verifier while a read-back runs.
struct CountCheck<'c> {
    cfg: &'c TransferConfig,
    /// The chunk being written, if a write reply is awaited.
    chunk: Option<Chunk>,
}

impl Judge for CountCheck<'_> {
    fn judge(&mut self, f: &Frame<'_>) -> Verdict {
        let reply = if f.code() == self.cfg.stream.id {
            self.cfg.stream.parse_reply(f).ok()
        } else {
            None
        };
        let values = reply.map_or(Span::UNKNOWN, |(_, n)| Span::one(n));
        let fits = match (self.chunk, reply) {
            (Some(c), Some((start, count))) => {
                (self.cfg.stream.start_width == 0 || start == c.start) && count == c.records
            }
            _ => false,
        };
        Verdict {
            fits,
            values,
            keep: false,
        }
    }

    fn streams(&self, header: Header, code: u16) -> bool {
        let read_back = self.cfg.stream.read_back();
        header == read_back.header && code == read_back.id
    }
}

impl<I: RecordSource, const N: usize> Engine for Transfer<I, N> {
    type Output = Guarantee;
    fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, Guarantee> {
        Transfer::poll(self, line, now)
    }
    fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        Transfer::received(self, line, bytes, now)
    }
    fn sent(&mut self, line: &mut Line, now: u32) {
        Transfer::sent(self, line, now);
    }
}

#[cfg(test)]
mod tests;
