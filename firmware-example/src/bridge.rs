//! The bridge: protocol B between a host (upstream) and one controller
//! (downstream), board-independent and never blocking.
//!
//! [`Bridge::poll`] makes what progress the ports allow and answers
//! [`Poll::Busy`] (call again), [`Poll::Wait`] (nothing can move before
//! one of the listed events or the deadline) or [`Poll::Quit`]. Time is a
//! wrapping millisecond tick passed in by the caller, so the same code runs
//! on a board ([`run`]) and in the host model of `host-tests`, in virtual
//! time.
//!
//! # What the bridge does
//!
//! It reads the upstream byte by byte. A header byte (`!`, `#`, `&`, `%`)
//! starts a frame; the first six bytes (header, station, ID) decide:
//!
//! * **to the bridge's own station** ([`Config::bridge_station`]): the
//!   command is checked and answered by the bridge itself: the status
//!   query [`codes::STATUS_QUERY`] (see [`crate::status`]), `&`
//!   [`codes::UNKNOWN_QUERY`] for any other ID.
//! * **to another station than the controller's**: skipped, unanswered
//!   (counted in `other_station`).
//! * **refused by the policy** ([`crate::config::Policy`]): skipped without
//!   a buffer (a refused 26DH may be 1.6 MB long) while its checksum is
//!   summed; if the checksum (or `@@`) is right, the bridge answers `&`
//!   [`codes::REFUSED`]. Nothing reaches the controller.
//! * **26DH** (Change Position Data Continuous Write 2, up to 20,000
//!   records, 1.6 MB): see [`Bridge`]'s 26DH path below.
//! * **any other command**: checked (format, checksum or `@@`, CR LF, at most
//!   2,051 bytes), forwarded unchanged, and the controller's checked reply
//!   (valid frame, same station, same ID for `#`) relayed unchanged. With
//!   no valid reply within [`REPLY_TIMEOUT_MS`] the bridge answers
//!   nothing: the host times out and sends again (2003 p. 62).
//!   With XON/XOFF on, a reply whose text holds 0x11 or 0x13 is replaced by
//!   `&` [`codes::XON_XOFF_IN_TEXT`].
//! * `#`/`&` frames from the host, malformed commands and noise are dropped.
//!
//! # The 26DH path
//!
//! The bytes go one by one into a [`PositionStreamDecoder`]; each record
//! goes into the bounded [`RecordQueue`] of a [`Transfer`], which writes the
//! records to the controller in 26DH commands of at most 2,051 bytes, each
//! confirmed with the spec's timeout and retries, and **reads each one back
//! (21FH) and compares it record by record before it takes more records
//! from the host** ([`Verify::Full`](iai_protocol_b::transfer::Verify)): a
//! chunk that reads back different is rewritten, twice at most. While the
//! queue is full the bridge stops reading the upstream; the receive ring
//! then fills and the line's flow control stops the host
//! ([`crate::serial`]). The host's last record is held back until the
//! upstream checksum is known, so a 26DH whose checksum fails never
//! completes a write. When the upstream frame has ended with a valid
//! checksum and every chunk is confirmed and read back equal, the bridge
//! answers once: `#` station `26D` count(4 hex).
//!
//! The host times out 3 s after its last byte (2003 p. 62). What the
//! bridge still has to do then is bounded by [`pipeline`]: chunk and queue
//! sizes for the downstream rate such that the rest fits
//! [`FINAL_BUDGET_MS`].
//!
//! # What `#` and `&` mean to the host
//!
//! * `#` with the count: the controller holds every record of the message,
//!   read back and compared, and the message's checksum was right.
//! * `&` with the controller's own code: the controller refused a chunk;
//!   the bridge stops at once (an `&` is not resent blindly, 2003 p. 66) so
//!   that the host can ask 216H for its detail.
//! * `&` with a bridge code ([`codes`]): B01 (malformed, found at the broken
//!   byte or at the checksum), B02 (a chunk unconfirmed after 3 sends),
//!   B04 (the host stalled), B05 (no transfer could start), B07 (bytes
//!   lost on the way in), B0A (a chunk still read back different after two
//!   rewrites).
//!
//! An `&` carries a code and nothing else, so it cannot say how far the
//! write went. The host should assume that any prefix of the message's
//! records may have been written, and, after B01, B04 or B07, that records
//! decoded from bytes corrupted before the error showed may have been
//! written too: a flipped bit in a position number writes a position the
//! host never named (in the bridge fault suite, 47 of 2,400 corrupted
//! messages wrote 181 such positions, about 4 each). Position writes are
//! idempotent: sending the whole message again makes every one of its
//! records right; positions outside it that matter must be read back.
//!
//! Why the bridge cannot simply hold the message until its checksum is
//! known: a 26DH may be 1,640,014 bytes, and the bridge's whole RAM is
//! 8 KiB. Only the last record is held back.
//!
//! # Buffers
//!
//! One 2,051-byte area serves both paths: in pass-through it is the frame
//! decoder (the command, then the reply); in a 26DH it is the transfer's
//! chunk buffer. The two never run at once.

use embedded_io::{Read, ReadReady, Write, WriteReady};
use iai_protocol_b::catalogue::{self, Reply, Resend};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::clock::reached;
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::exchange::{Due, Exchange, ExchangeConfig, Finish, Offer, Quarantine};
use iai_protocol_b::field::{decode_unsigned, FieldSpec};
use iai_protocol_b::frame::{emit_frame, Header, Station, ENVELOPE_LEN};
use iai_protocol_b::limits;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::stream::{PositionStream, PositionStreamDecoder, StreamEvent};
use iai_protocol_b::transfer::{
    RecordQueue, Step, Transfer, TransferConfig, TransferError, MAX_FRAME_RECORDS,
};

use crate::codes;
use crate::config::{Config, Source};
use crate::log;
use crate::serial::{self, FlowControl, UPSTREAM_MARKS, XOFF, XON};
use crate::status;

/// Upstream silence required before the quit sequence.
pub const QUIT_GUARD_MS: u32 = 20;

/// Records buffered between the upstream decoder and the transfer. The
/// transfer packs records into its chunk as they come, so a few suffice;
/// more only lets the host run further ahead while a chunk is confirmed.
pub const QUEUE_LEN: usize = 8;

/// How long the bridge waits for the controller's reply to a forwarded
/// command before it gives up silently (2003 p. 62: 3 s).
pub const REPLY_TIMEOUT_MS: u32 = 3_000;

/// Of the host's 3 s for a 26DH reply (counted from the end of its
/// transmission), what the bridge may spend writing and reading back what
/// is left when the host's last byte arrives; the rest is the margin for
/// the controller's processing and the reply's way up.
pub const FINAL_BUDGET_MS: u32 = 2_000;

/// How long a 26DH may pause upstream in its middle (while the bridge is
/// ready to read) before it is abandoned with [`codes::UPSTREAM_STALLED`].
pub const UPSTREAM_STALL_MS: u32 = 5_000;

/// Largest frame handled in pass-through (a TTA receives at most 2,051
/// bytes and sends at most 2,048, TTA p. 15).
pub const FRAME_CAP: usize = limits::TTA.command;

/// Bytes of the bridge's own replies (the status reply is the longest).
pub const RESPONSE_CAP: usize = status::REPLY_LEN;

/// Upstream bytes read per call (a staging chunk, not a message buffer).
const IN_CHUNK: usize = 16;

/// The 26DH stream the bridge splits.
const STREAM: PositionStream = PositionStream::CHANGE_2;

/// A serial port as the bridge sees it: non-blocking `embedded-io` plus an
/// overrun count.
pub trait Port: Read + ReadReady + Write + WriteReady {
    /// Received bytes lost since the last call (receive ring full, or the
    /// UART's overrun flag). Ports that cannot lose bytes return 0.
    fn take_overruns(&mut self) -> u32 {
        0
    }
}

/// Why [`Bridge::poll`] failed: a port reported an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error<U, D> {
    /// The upstream port failed.
    Upstream(U),
    /// The downstream port failed.
    Downstream(D),
}

/// What [`Bridge::poll`] achieved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Poll {
    /// Something moved: call again.
    Busy,
    /// Nothing can move until one of the events in the [`Wait`] happens.
    Wait(Wait),
    /// The quit sequence arrived (only with [`Config::quit_sequence`]).
    Quit,
}

/// What the bridge waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wait {
    /// Call [`Bridge::poll`] again at this tick at the latest (a reply
    /// timeout, a turnaround, a stall limit), if any.
    pub deadline: Option<u32>,
    /// Why it is waiting.
    pub reason: Reason,
    /// Which port events would let it move.
    pub interest: Interest,
}

/// Why the bridge is waiting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    /// Bytes from the host (idle, or inside a command).
    Host,
    /// The controller's reply (or a timer of the 26DH transfer).
    Controller,
    /// Room in the upstream transmit ring.
    HostRoom,
    /// Room in the downstream transmit ring.
    ControllerRoom,
}

/// Port events that would let the bridge move.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Interest {
    /// Upstream bytes to read.
    pub up_read: bool,
    /// Room to write upstream.
    pub up_write: bool,
    /// Downstream bytes to read.
    pub down_read: bool,
    /// Room to write downstream.
    pub down_write: bool,
}

/// What the bridge counted since start.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stats {
    /// Commands forwarded downstream as they were.
    pub forwarded: u32,
    /// Replies relayed upstream.
    pub relayed: u32,
    /// Forwarded commands that got no valid reply in time.
    pub reply_timeouts: u32,
    /// Upstream frames dropped as malformed (never forwarded).
    pub rejected: u32,
    /// Commands refused by the policy (answered `&` B06).
    pub refused: u32,
    /// Commands for a station other than the controller's and the bridge's.
    pub other_station: u32,
    /// Commands the bridge answered itself (its own station).
    pub own_queries: u32,
    /// 26DH commands completed (`#` sent).
    pub streams_ok: u32,
    /// 26DH commands answered with `&`.
    pub streams_failed: u32,
    /// Records confirmed by the controller in 26DH chunks.
    pub records: u32,
    /// 26DH chunks sent downstream, retries included.
    pub chunks_sent: u32,
    /// Chunks sent again.
    pub retries: u32,
    /// Chunk replies that timed out.
    pub chunk_timeouts: u32,
    /// `&` replies to chunks.
    pub chunk_error_replies: u32,
    /// Upstream bytes lost (receive overruns).
    pub upstream_overruns: u32,
    /// Downstream bytes lost (receive overruns).
    pub downstream_overruns: u32,
    /// Bytes read from the upstream.
    pub upstream_in: u64,
    /// Bytes written to the upstream.
    pub upstream_out: u64,
    /// Bytes read from the downstream.
    pub downstream_in: u64,
    /// Bytes written to the downstream.
    pub downstream_out: u64,
}

/// The last `&` code the bridge sent of its own, and when.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LastError {
    /// The code ([`codes`]).
    pub code: u16,
    /// The tick (ms) it was sent.
    pub at_ms: u32,
}

/// The 26DH transfer: records from the upstream decoder through a bounded
/// queue to controller-sized commands.
type Job = Transfer<RecordQueue<QUEUE_LEN>>;

/// The 26DH state: the upstream decoder and, once the count is known, the
/// transfer.
struct StreamWork {
    decoder: PositionStreamDecoder,
    job: Option<Job>,
    /// The host's last record, held back until its checksum is known: a
    /// 26DH whose checksum fails never completes a write.
    last: Option<PositionRecord>,
    /// Chunk and queue sizes for the downstream rate.
    pipeline: Pipeline,
}

/// The shared 2,051-byte area (see the module docs). The variants differ
/// in size by the transfer's record queue; sharing is the point.
#[allow(clippy::large_enum_variant)]
enum Work {
    /// Pass-through and the bridge's own queries: the command, then the
    /// reply (the command is sent once, so it need not be kept).
    Frame(FrameDecoder<FRAME_CAP>),
    /// A 26DH.
    Stream(StreamWork),
}

/// The chapter-5 settings of a forwarded command: one send (the host
/// resends, after its own timeout), 3 s for the reply.
const fn passthrough(station: Station) -> ExchangeConfig {
    let mut cfg = ExchangeConfig::new(station);
    cfg.max_sends = 1;
    cfg.timeout_ms = REPLY_TIMEOUT_MS;
    cfg
}

/// Where the bridge is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Hunting for a header byte upstream.
    Idle,
    /// Collecting the first [`ENVELOPE_LEN`] bytes of an upstream frame.
    Head,
    /// Feeding an upstream command (not 26DH) to the frame decoder.
    Command,
    /// Skipping a command to its end; at a valid end answer `answer`.
    Skip { answer: Option<u16>, cr: bool },
    /// Writing the decoded command downstream.
    SendCommand,
    /// Waiting for the controller's reply (the exchange says until when).
    AwaitReply,
    /// Writing the reply upstream.
    RelayReply,
    /// A 26DH stream is being decoded and transferred.
    Stream {
        station: Station,
        /// The upstream frame ended well (`End`).
        upstream_done: bool,
        /// Stop as soon as the downstream line is clean, answering this code.
        abort: Option<u16>,
        /// Since when the bridge has been ready for upstream bytes.
        waiting_since: u32,
    },
    /// Writing the bridge's own response upstream.
    Respond,
}

/// One step of reading the upstream.
enum Up {
    Byte(u8),
    /// Bytes were lost before the next one.
    Lost,
    Empty,
}

/// The bridge's state: about 3 KiB; keep it in a static. It holds no port
/// and no clock.
pub struct Bridge {
    cfg: Config,
    source: Source,
    mode: Mode,
    head: [u8; ENVELOPE_LEN],
    head_len: usize,
    work: Work,
    /// Running checksum of a skipped command and its last two bytes.
    skip_sum: u8,
    skip_tail: [u8; 2],
    /// Bytes of the current outgoing frame already written.
    out_off: usize,
    /// The forwarded command's exchange: timeout and the reply matcher.
    exchange: Exchange,
    /// The 26DH transfer's next deadline and whether a chunk waits for
    /// room downstream.
    stream_deadline: Option<u32>,
    tx_blocked: bool,
    resp: [u8; RESPONSE_CAP],
    resp_len: usize,
    inbuf: [u8; IN_CHUNK],
    in_pos: usize,
    in_len: usize,
    quit: QuitDetector,
    stats: Stats,
    last_error: Option<LastError>,
}

impl Bridge {
    /// An idle bridge with this configuration (`source` says where it came
    /// from, for the status query).
    pub const fn new(cfg: Config, source: Source) -> Self {
        Self {
            cfg,
            source,
            mode: Mode::Idle,
            head: [0; ENVELOPE_LEN],
            head_len: 0,
            work: Work::Frame(FrameDecoder::with_policy(BypassPolicy::CommandsOnly)),
            skip_sum: 0,
            skip_tail: [0; 2],
            out_off: 0,
            exchange: Exchange::new(passthrough(cfg.controller_station), Quarantine::ByContent),
            stream_deadline: None,
            tx_blocked: false,
            resp: [0; RESPONSE_CAP],
            resp_len: 0,
            inbuf: [0; IN_CHUNK],
            in_pos: 0,
            in_len: 0,
            quit: QuitDetector::new(),
            stats: Stats {
                forwarded: 0,
                relayed: 0,
                reply_timeouts: 0,
                rejected: 0,
                refused: 0,
                other_station: 0,
                own_queries: 0,
                streams_ok: 0,
                streams_failed: 0,
                records: 0,
                chunks_sent: 0,
                retries: 0,
                chunk_timeouts: 0,
                chunk_error_replies: 0,
                upstream_overruns: 0,
                upstream_out: 0,
                upstream_in: 0,
                downstream_overruns: 0,
                downstream_in: 0,
                downstream_out: 0,
            },
            last_error: None,
        }
    }

    /// Sets the configuration (at start, before the first [`Bridge::poll`]);
    /// lets a board keep the bridge in a `static` built by the `const`
    /// [`Bridge::new`].
    pub fn configure(&mut self, cfg: Config, source: Source) {
        self.cfg = cfg;
        self.source = source;
        self.exchange
            .set_config(passthrough(cfg.controller_station));
    }

    /// The configuration in force.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Where the configuration came from.
    pub fn config_source(&self) -> Source {
        self.source
    }

    /// Counters so far.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// The last `&` code the bridge sent of its own.
    pub fn last_error(&self) -> Option<LastError> {
        self.last_error
    }

    /// Whether the bridge is between commands (nothing half done).
    pub fn is_idle(&self) -> bool {
        self.mode == Mode::Idle
    }

    /// Makes what progress is possible at tick `now` without waiting.
    pub fn poll<U: Port, D: Port>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<Poll, Error<U::Error, D::Error>> {
        let lost = down.take_overruns();
        if lost > 0 {
            self.stats.downstream_overruns = self.stats.downstream_overruns.wrapping_add(lost);
            if let (Mode::AwaitReply, Work::Frame(f)) = (self.mode, &mut self.work) {
                // The reply being decoded lost bytes: start again.
                f.reset();
            }
        }
        let moved = match self.mode {
            Mode::Idle | Mode::Head | Mode::Command | Mode::Skip { .. } => {
                let mut moved = self.drain_downstream(down).map_err(Error::Downstream)?;
                while matches!(
                    self.mode,
                    Mode::Idle | Mode::Head | Mode::Command | Mode::Skip { .. }
                ) {
                    let b = match self.next_up(up).map_err(Error::Upstream)? {
                        Up::Empty => break,
                        Up::Lost => {
                            moved = true;
                            if self.mode != Mode::Idle {
                                self.stats.rejected += 1;
                            }
                            self.go_idle();
                            continue;
                        }
                        Up::Byte(b) => b,
                    };
                    moved = true;
                    if self.cfg.quit_sequence && self.quit.feed(b, now) && self.mode == Mode::Idle {
                        return Ok(Poll::Quit);
                    }
                    self.on_upstream_byte(b, now);
                }
                moved
            }
            Mode::SendCommand | Mode::AwaitReply | Mode::RelayReply => {
                self.poll_passthrough(up, down, now)?
            }
            Mode::Stream { .. } => self.poll_stream(up, down, now)?,
            Mode::Respond => {
                let resp = self.resp.get(..self.resp_len).unwrap_or(&[]);
                let out = &mut self.stats.upstream_out;
                let n = write_some(up, resp, &mut self.out_off, out).map_err(Error::Upstream)?;
                if self.out_off >= self.resp_len {
                    self.go_idle();
                }
                n > 0
            }
        };
        Ok(if moved {
            Poll::Busy
        } else {
            Poll::Wait(self.wait(now))
        })
    }

    /// What the bridge waits for in its current mode.
    fn wait(&mut self, now: u32) -> Wait {
        let host = Interest {
            up_read: true,
            down_read: true,
            ..Interest::default()
        };
        let (deadline, reason, interest) = match self.mode {
            Mode::Idle | Mode::Head | Mode::Command | Mode::Skip { .. } => {
                (None, Reason::Host, host)
            }
            Mode::SendCommand => (
                None,
                Reason::ControllerRoom,
                Interest {
                    down_write: true,
                    ..Interest::default()
                },
            ),
            Mode::AwaitReply => (
                match self.exchange.poll(now) {
                    Due::WaitUntil(t) => Some(t),
                    _ => Some(now),
                },
                Reason::Controller,
                Interest {
                    down_read: true,
                    ..Interest::default()
                },
            ),
            Mode::RelayReply | Mode::Respond => (
                None,
                Reason::HostRoom,
                Interest {
                    up_write: true,
                    ..Interest::default()
                },
            ),
            Mode::Stream {
                upstream_done,
                abort,
                waiting_since,
                ..
            } => {
                let reading = !upstream_done && abort.is_none() && !self.queue_full();
                let stall = reading.then(|| waiting_since.wrapping_add(UPSTREAM_STALL_MS));
                let deadline = earliest(now, stall, self.stream_deadline);
                let reason = if self.tx_blocked {
                    Reason::ControllerRoom
                } else if reading {
                    Reason::Host
                } else {
                    Reason::Controller
                };
                (
                    deadline,
                    reason,
                    Interest {
                        up_read: reading,
                        down_read: true,
                        down_write: self.tx_blocked,
                        up_write: false,
                    },
                )
            }
        };
        Wait {
            deadline,
            reason,
            interest,
        }
    }

    /// The next upstream byte. Checks the overrun count each time it reads
    /// a new chunk from the port, so every byte handed out before
    /// [`Up::Lost`] was received before the loss.
    fn next_up<U: Port>(&mut self, up: &mut U) -> Result<Up, U::Error> {
        if self.in_pos >= self.in_len {
            let lost = up.take_overruns();
            if lost > 0 {
                self.stats.upstream_overruns = self.stats.upstream_overruns.wrapping_add(lost);
                return Ok(Up::Lost);
            }
            if !up.read_ready()? {
                return Ok(Up::Empty);
            }
            let n = up.read(&mut self.inbuf)?;
            self.stats.upstream_in += n as u64;
            self.in_pos = 0;
            self.in_len = n.min(IN_CHUNK);
        }
        match self.inbuf.get(self.in_pos).copied() {
            Some(b) if self.in_pos < self.in_len => {
                self.in_pos += 1;
                Ok(Up::Byte(b))
            }
            _ => Ok(Up::Empty),
        }
    }

    /// Back to hunting for a frame upstream.
    fn go_idle(&mut self) {
        self.mode = Mode::Idle;
        self.out_off = 0;
        self.head_len = 0;
        self.stream_deadline = None;
        self.tx_blocked = false;
        match &mut self.work {
            Work::Frame(f) => {
                f.reset();
                f.set_policy(BypassPolicy::CommandsOnly);
            }
            Work::Stream(_) => {
                self.work = Work::Frame(FrameDecoder::with_policy(BypassPolicy::CommandsOnly));
            }
        }
    }

    /// Reads and drops whatever the controller sends unasked (late replies,
    /// noise) while no reply is expected.
    fn drain_downstream<D: Port>(&mut self, down: &mut D) -> Result<bool, D::Error> {
        let mut buf = [0u8; 16];
        let mut moved = false;
        while down.read_ready()? {
            let n = down.read(&mut buf)?;
            if n == 0 {
                break;
            }
            self.stats.downstream_in += n as u64;
            moved = true;
        }
        Ok(moved)
    }

    /// One upstream byte in the Idle, Head, Command or Skip mode.
    fn on_upstream_byte(&mut self, b: u8, now: u32) {
        let is_header = Header::from_byte(b).is_some();
        match self.mode {
            Mode::Idle | Mode::Head if is_header => {
                self.head[0] = b;
                self.head_len = 1;
                self.mode = Mode::Head;
            }
            Mode::Idle => {}
            Mode::Head => {
                if let Some(slot) = self.head.get_mut(self.head_len) {
                    *slot = b;
                    self.head_len += 1;
                }
                if self.head_len == ENVELOPE_LEN {
                    self.classify(now);
                }
            }
            Mode::Command => self.command_byte(b, now),
            Mode::Skip { answer, cr } => self.skip_byte(b, answer, cr, now),
            _ => {}
        }
    }

    /// The envelope is complete: decide what to do with the frame.
    fn classify(&mut self, now: u32) {
        let head = self.head;
        let station = decode_unsigned(FieldSpec::hex(2), &head[1..3], 1).ok();
        let id = decode_unsigned(FieldSpec::hex(3), &head[3..6], 3).ok();
        if let (b'!', Some(station), Some(id)) = (head[0], station, id) {
            let station = Station(station as u8);
            let id = id as u16;
            if station == self.cfg.bridge_station {
                self.start_command(now);
                return;
            }
            if station != self.cfg.controller_station {
                self.stats.other_station += 1;
                self.start_skip(None);
                return;
            }
            if !self.cfg.policy.allows(id) {
                log::warning!("command {=u16:X}H refused by the policy", id);
                self.start_skip(Some(codes::REFUSED));
                return;
            }
            if id == STREAM.id {
                self.start_stream(station, now);
                return;
            }
        }
        self.start_command(now);
    }

    /// Pass-through (or own query): the envelope goes to the frame decoder.
    fn start_command(&mut self, now: u32) {
        if let Work::Frame(f) = &mut self.work {
            f.reset();
            f.set_policy(BypassPolicy::CommandsOnly);
        }
        self.mode = Mode::Command;
        let head = self.head;
        for &b in &head {
            self.command_byte(b, now);
            if self.mode != Mode::Command {
                break;
            }
        }
    }

    /// Skip the rest of the frame, summing its checksum.
    fn start_skip(&mut self, answer: Option<u16>) {
        let head = self.head;
        self.skip_sum = head.iter().fold(0u8, |s, &b| s.wrapping_add(b));
        self.skip_tail = [head[4], head[5]];
        self.mode = Mode::Skip { answer, cr: false };
    }

    /// One byte of a skipped command.
    fn skip_byte(&mut self, b: u8, answer: Option<u16>, cr: bool, now: u32) {
        if cr {
            // CR must be followed by LF; the two bytes before CR are SC.
            let [h, l] = self.skip_tail;
            let covered = self.skip_sum.wrapping_sub(h).wrapping_sub(l);
            let sc_ok = (h == b'@' && l == b'@')
                || decode_unsigned(FieldSpec::hex(2), &[h, l], 0).ok() == Some(u64::from(covered));
            let station =
                Station(decode_unsigned(FieldSpec::hex(2), &self.head[1..3], 1).unwrap_or(0) as u8);
            match (b == b'\n' && sc_ok, answer) {
                (true, Some(code)) => {
                    self.stats.refused += 1;
                    self.respond_error(station, code, now);
                }
                (true, None) => self.go_idle(),
                (false, _) => {
                    self.stats.rejected += 1;
                    self.go_idle();
                    self.on_upstream_byte(b, now);
                }
            }
            return;
        }
        if Header::from_byte(b).is_some() {
            // The frame was cut: this header starts the next one.
            self.stats.rejected += 1;
            self.go_idle();
            self.on_upstream_byte(b, now);
            return;
        }
        if b == b'\r' {
            self.mode = Mode::Skip { answer, cr: true };
            return;
        }
        self.skip_sum = self.skip_sum.wrapping_add(b);
        self.skip_tail = [self.skip_tail[1], b];
    }

    /// One byte of a pass-through command (or an own query).
    fn command_byte(&mut self, b: u8, now: u32) {
        let Work::Frame(frames) = &mut self.work else {
            return;
        };
        match frames.push(b) {
            Event::NeedMore => {}
            Event::Frame(f) if f.header() == Header::Command => {
                let (station, id) = (f.station(), f.code());
                if station == self.cfg.bridge_station {
                    self.stats.own_queries += 1;
                    let body_empty = f.body().is_empty();
                    self.own_query(station, id, body_empty, now);
                } else {
                    // Its catalogue entry says what to expect; one outside
                    // the catalogue is sent once and any `#` with its ID
                    // taken.
                    match catalogue::lookup(id) {
                        Some(info) => self.exchange.start(info, now),
                        None => self
                            .exchange
                            .start_raw(id, Resend::Unsafe, Reply::Normal, now),
                    }
                    self.mode = Mode::SendCommand;
                    self.out_off = 0;
                }
            }
            Event::Frame(_) => {
                // Only commands go downstream.
                self.stats.rejected += 1;
                self.go_idle();
            }
            Event::Error(_e) => {
                log::warning!("malformed upstream command dropped: {}", _e);
                self.stats.rejected += 1;
                self.go_idle();
                if Header::from_byte(b).is_some() {
                    // The header byte that cut the frame starts the next one.
                    self.on_upstream_byte(b, now);
                }
            }
        }
    }

    /// A command to the bridge's own station.
    fn own_query(&mut self, station: Station, id: u16, body_empty: bool, now: u32) {
        if id == codes::STATUS_QUERY && body_empty {
            let report = status::Report {
                now_ms: now,
                config: &self.cfg,
                source: self.source,
                stats: &self.stats,
                last_error: self.last_error,
            };
            self.resp_len = report.emit(station, &mut self.resp).unwrap_or(0);
            self.out_off = 0;
            self.mode = Mode::Respond;
        } else {
            self.respond_error(station, codes::UNKNOWN_QUERY, now);
        }
    }

    // ---------------------------------------------------------------
    // Pass-through: forward one command, relay its reply, through the
    // core's exchange (chapter 5 timing and the one reply matcher).
    // ---------------------------------------------------------------

    /// The pass-through modes: send the command when the exchange says so,
    /// offer what the controller sends to the exchange, relay the reply.
    fn poll_passthrough<U: Port, D: Port>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<bool, Error<U::Error, D::Error>> {
        let Work::Frame(frames) = &mut self.work else {
            self.go_idle();
            return Ok(true);
        };
        let mut moved = false;
        match self.mode {
            Mode::SendCommand => {
                if let Due::WaitUntil(_) = self.exchange.poll(now) {
                    // The turnaround after the last reply has not passed.
                    return Ok(false);
                }
                let bytes = frames.last_frame().map_or(&[][..], |f| f.as_bytes());
                let out = &mut self.stats.downstream_out;
                let n =
                    write_some(down, bytes, &mut self.out_off, out).map_err(Error::Downstream)?;
                moved |= n > 0;
                if self.out_off >= bytes.len() {
                    // All in the transmit ring: the reply clock starts.
                    self.out_off = 0;
                    self.stats.forwarded += 1;
                    frames.reset();
                    frames.set_policy(BypassPolicy::Reject);
                    self.exchange.sent(now);
                    self.mode = Mode::AwaitReply;
                    moved = true;
                }
            }
            Mode::AwaitReply => {
                let mut buf = [0u8; 1];
                let mut xchar = false;
                while down.read_ready().map_err(Error::Downstream)? {
                    if down.read(&mut buf).map_err(Error::Downstream)? == 0 {
                        break;
                    }
                    self.stats.downstream_in += 1;
                    moved = true;
                    match frames.push(buf[0]) {
                        Event::Frame(f) => {
                            let offer = self.exchange.offer(&f, true, now);
                            if matches!(offer, Offer::Accepted | Offer::Rejected(_)) {
                                xchar = f.as_bytes().iter().any(|&b| b == XON || b == XOFF);
                                break;
                            }
                        }
                        Event::Error(_) => {
                            let envelope = frames.failed_envelope();
                            self.exchange.broken_frame(envelope, now);
                        }
                        Event::NeedMore => {}
                    }
                }
                let station = self.cfg.controller_station;
                match self.exchange.poll(now) {
                    Due::Done(Finish::Replied | Finish::ErrorReply(_)) => {
                        if xchar && self.cfg.flow == FlowControl::XonXoff {
                            self.respond_error(station, codes::XON_XOFF_IN_TEXT, now);
                        } else {
                            self.mode = Mode::RelayReply;
                            self.out_off = 0;
                        }
                        moved = true;
                    }
                    Due::Done(_) => {
                        // No valid reply (or none expected, 25BH): the host
                        // times out and decides, as without a bridge.
                        log::warning!("no reply from the controller within 3 s");
                        self.stats.reply_timeouts += 1;
                        self.go_idle();
                        moved = true;
                    }
                    Due::Transmit { .. } | Due::WaitUntil(_) | Due::Idle => {}
                }
            }
            Mode::RelayReply => {
                let bytes = frames.last_frame().map_or(&[][..], |f| f.as_bytes());
                let out = &mut self.stats.upstream_out;
                let n = write_some(up, bytes, &mut self.out_off, out).map_err(Error::Upstream)?;
                moved |= n > 0;
                if self.out_off >= bytes.len() {
                    self.stats.relayed += 1;
                    self.go_idle();
                    moved = true;
                }
            }
            _ => {}
        }
        Ok(moved)
    }

    // ---------------------------------------------------------------
    // 26DH: decode the host's stream, write it in confirmed chunks. The
    // lead's transfer engine replaces `start_stream` and `poll_stream`.
    // ---------------------------------------------------------------

    /// A 26DH begins: the envelope goes to the stream decoder.
    fn start_stream(&mut self, station: Station, now: u32) {
        let mut decoder = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
        for &b in &self.head {
            // The envelope alone never completes an event.
            let _ = decoder.push(b);
        }
        self.work = Work::Stream(StreamWork {
            decoder,
            job: None,
            last: None,
            pipeline: pipeline(self.cfg.downstream_baud),
        });
        self.stream_deadline = None;
        self.tx_blocked = false;
        self.mode = Mode::Stream {
            station,
            upstream_done: false,
            abort: None,
            waiting_since: now,
        };
        log::info!("26DH stream for station {=u8:02X}", station.0);
    }

    /// Whether the 26DH queue holds all the records the pipeline allows
    /// (see [`pipeline`]): the bridge then stops reading the host.
    fn queue_full(&mut self) -> bool {
        match &mut self.work {
            Work::Stream(StreamWork {
                job: Some(j),
                pipeline,
                ..
            }) => {
                let limit = pipeline.queued_records;
                let q = j.source_mut();
                q.is_full() || q.len() >= limit
            }
            _ => false,
        }
    }

    /// The 26DH mode: decode upstream bytes into the queue, drive the
    /// transfer, answer once at the end.
    fn poll_stream<U: Port, D: Port>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<bool, Error<U::Error, D::Error>> {
        let Mode::Stream {
            station,
            mut upstream_done,
            mut abort,
            mut waiting_since,
        } = self.mode
        else {
            return Ok(false);
        };
        let mut moved = false;

        // Upstream: decode while the queue has room.
        while !upstream_done && abort.is_none() {
            if self.queue_full() {
                waiting_since = now;
                break;
            }
            let b = match self.next_up(up).map_err(Error::Upstream)? {
                Up::Byte(b) => b,
                Up::Lost => {
                    log::warning!("26DH: upstream bytes lost");
                    abort = Some(codes::UPSTREAM_OVERRUN);
                    moved = true;
                    break;
                }
                Up::Empty => {
                    if reached(now, waiting_since.wrapping_add(UPSTREAM_STALL_MS)) {
                        log::warning!("26DH stalled upstream");
                        abort = Some(codes::UPSTREAM_STALLED);
                    }
                    break;
                }
            };
            moved = true;
            waiting_since = now;
            let Work::Stream(work) = &mut self.work else {
                abort = Some(codes::INTERNAL);
                break;
            };
            match work.decoder.push(b) {
                StreamEvent::NeedMore => {}
                StreamEvent::Start {
                    station: s, count, ..
                } => {
                    log::info!("26DH: {=u16} records", count);
                    let cfg = TransferConfig {
                        max_records: work.pipeline.chunk_records,
                        ..TransferConfig::tta(s)
                    };
                    let job = Transfer::new(cfg, RecordQueue::new()).with_total(u32::from(count));
                    work.job = Some(job);
                }
                StreamEvent::Record(rec) => {
                    if work.decoder.records_done() == work.decoder.records_announced() {
                        // The last record waits for the checksum.
                        work.last = Some(rec);
                    } else {
                        let pushed = work
                            .job
                            .as_mut()
                            .is_some_and(|job| job.source_mut().push(rec).is_ok());
                        if !pushed {
                            // Cannot happen: the queue had room.
                            abort = Some(codes::INTERNAL);
                        }
                    }
                }
                StreamEvent::End { records: _records } => {
                    log::info!("26DH upstream ended well: {=u16} records", _records);
                    upstream_done = true;
                }
                StreamEvent::Error {
                    error: _error,
                    records_ok: _ok,
                } => {
                    log::warning!("26DH upstream broken after {=u16} records: {}", _ok, _error);
                    abort = Some(codes::UPSTREAM_FRAME);
                }
            }
        }

        // The checksum was right: the held-back record may go, and the
        // transfer learns that no more come.
        if upstream_done {
            if let Work::Stream(StreamWork {
                job: Some(job),
                last,
                ..
            }) = &mut self.work
            {
                if let Some(rec) = last.take() {
                    if let Err(rec) = job.source_mut().push(rec) {
                        *last = Some(rec);
                    }
                }
                if last.is_none() {
                    job.source_mut().finish();
                }
            }
        }

        // Downstream: the transfer.
        let mut answer: Option<Result<u16, u16>> = None;
        self.tx_blocked = false;
        self.stream_deadline = None;
        let was_full = self.queue_full();
        let job = match &mut self.work {
            Work::Stream(StreamWork { job: Some(job), .. }) => Some(job),
            _ => None,
        };
        if let Some(job) = job {
            let mut buf = [0u8; 16];
            while down.read_ready().map_err(Error::Downstream)? {
                let n = down.read(&mut buf).map_err(Error::Downstream)?;
                if n == 0 {
                    break;
                }
                self.stats.downstream_in += n as u64;
                job.received_all(buf.get(..n).unwrap_or(&[]), now);
                moved = true;
            }
            loop {
                match job.poll(now) {
                    Step::Transmit(bytes) => {
                        if abort.is_some() && self.out_off == 0 {
                            answer = abort.map(Err);
                            break;
                        }
                        let out = &mut self.stats.downstream_out;
                        let n = write_some(down, bytes, &mut self.out_off, out)
                            .map_err(Error::Downstream)?;
                        moved |= n > 0;
                        if self.out_off < bytes.len() {
                            self.tx_blocked = true;
                            break;
                        }
                        // All in the transmit ring: the reply clock starts.
                        self.out_off = 0;
                        job.sent(now);
                    }
                    Step::WaitUntil(t) => {
                        self.stream_deadline = Some(t);
                        if abort.is_some() {
                            answer = abort.map(Err);
                        }
                        break;
                    }
                    Step::NeedRecords => {
                        if abort.is_some() {
                            answer = abort.map(Err);
                        }
                        break;
                    }
                    Step::Complete(report) => {
                        // Every chunk was read back and compared equal.
                        answer = Some(Ok(report.stats.records_confirmed as u16));
                        break;
                    }
                    Step::Failed(e) => {
                        log::warning!("26DH transfer failed: {}", e);
                        answer = Some(Err(match e {
                            TransferError::Timeout => codes::CONTROLLER_TIMEOUT,
                            // The controller's own code goes up as it is:
                            // the host can ask it for the 216H detail.
                            TransferError::Controller { code } | TransferError::Bridge { code } => {
                                code
                            }
                            TransferError::Mismatch { .. } => codes::VERIFY_MISMATCH,
                            _ => codes::INTERNAL,
                        }));
                        break;
                    }
                }
            }
            if answer.is_some() {
                let s = job.stats();
                self.stats.records += s.records_confirmed;
                self.stats.chunks_sent += s.frames_sent;
                self.stats.retries += s.retries;
                self.stats.chunk_timeouts += s.timeouts;
                self.stats.chunk_error_replies += s.error_replies;
            }
        } else {
            moved |= self.drain_downstream(down).map_err(Error::Downstream)?;
            if abort.is_some() {
                answer = abort.map(Err);
            }
        }

        if was_full && !self.queue_full() {
            // The transfer took records: the upstream may be read again.
            moved = true;
        }
        self.mode = Mode::Stream {
            station,
            upstream_done,
            abort,
            waiting_since,
        };
        match answer {
            Some(Ok(count)) => {
                self.stats.streams_ok += 1;
                self.respond_count(station, count);
                moved = true;
            }
            Some(Err(code)) => {
                self.stats.streams_failed += 1;
                self.respond_error(station, code, now);
                moved = true;
            }
            None => {}
        }
        Ok(moved)
    }

    /// Queue the 26DH's `#` reply with the count.
    fn respond_count(&mut self, station: Station, count: u16) {
        self.go_idle();
        self.resp_len = emit_frame(
            &mut self.resp,
            Header::Response,
            station,
            STREAM.id,
            Default::default(),
            |w| STREAM.write_prefix(w, 0, count),
        )
        .unwrap_or(0);
        self.mode = Mode::Respond;
    }

    /// Queue an `&` reply with one of the bridge's codes.
    fn respond_error(&mut self, station: Station, code: u16, now: u32) {
        self.go_idle();
        self.last_error = Some(LastError { code, at_ms: now });
        self.resp_len = emit_frame(
            &mut self.resp,
            Header::Error,
            station,
            code,
            Default::default(),
            |_| Ok(()),
        )
        .unwrap_or(0);
        self.mode = Mode::Respond;
    }
}

/// Controller time allowed per command when the 26DH pipeline is sized:
/// its response delay (α, I/O parameter 97, 2003 p. 8) plus the time it
/// takes to store a chunk. Neither manual gives a figure, so this is an
/// **assumption** (the processing time of the host model's tests); a
/// slower controller makes the final reply later by the difference per
/// command.
pub const PROCESSING_ALLOWANCE_MS: u32 = 50;

/// A 26DH command's envelope, count and trailer.
const CHUNK_ENVELOPE_BYTES: u64 = 14;

/// Bytes on the downstream line per chunk besides its records: the 26DH
/// command's envelope, count and trailer, its reply (14), the 21FH query
/// (18) and its reply's envelope, count, start and trailer (18).
const CHUNK_OVERHEAD_BYTES: u64 = CHUNK_ENVELOPE_BYTES + 14 + 18 + 18;

/// Bytes of an 8-axis 26DH record, the longest (TTA p. 60).
const LONGEST_RECORD_BYTES: u64 = 82;

/// Fewest records per chunk. The transfer never gives a frame the count of
/// the frame before (a late reply could confirm it); with chunks of at
/// least 3 the counts alternate without ever leaving a frame of one after
/// a frame of one, which would wait out the duplicate window.
const MIN_CHUNK_RECORDS: u16 = 3;

/// How much of a 26DH the bridge holds between the host and the
/// controller (see [`pipeline`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pipeline {
    /// Most records per 26DH chunk.
    pub chunk_records: u16,
    /// Most records decoded from the host and waiting for a chunk.
    pub queued_records: usize,
}

/// Microseconds `bytes` take at `baud` (8N1).
const fn line_us(bytes: u64, baud: u64) -> u64 {
    bytes * 10_000_000 / baud
}

/// Worst-case time (µs) from the host's last byte to the end of the last
/// chunk's read-back with chunks of `chunk` records and a queue of `queued`
/// at `baud`. Still to be written and read back (each byte crossing the
/// line twice): what the receive ring may hold (up to its pause mark plus
/// the host's latency), the queued records, the held-back last record and
/// a chunk just sent, all of 8-axis records (the longest; a chunk is at
/// most a 2,051-byte frame whatever its records), each chunk with its
/// commands' overhead and [`PROCESSING_ALLOWANCE_MS`] per command.
const fn finish_us(chunk: u64, queued: u64, baud: u64) -> u64 {
    let ring = (UPSTREAM_MARKS.pause_at + serial::HOST_LATENCY) as u64;
    let frame_records = (FRAME_CAP as u64 - CHUNK_ENVELOPE_BYTES) / LONGEST_RECORD_BYTES;
    let chunk_bytes = if chunk < frame_records {
        chunk
    } else {
        frame_records
    } * LONGEST_RECORD_BYTES;
    let bytes = ring + (queued + 1) * LONGEST_RECORD_BYTES + chunk_bytes;
    let chunks = bytes.div_ceil(chunk_bytes);
    let per_chunk =
        line_us(CHUNK_OVERHEAD_BYTES, baud) + 2 * 1_000 * PROCESSING_ALLOWANCE_MS as u64;
    2 * line_us(bytes, baud) + chunks * per_chunk
}

/// The largest chunks (then the longest queue) such that, when the host's
/// last byte arrives, what is left can be written and read back within
/// [`FINAL_BUDGET_MS`] at `baud`, in a worst-case model: the receive ring
/// full to its pause mark plus the host's latency, the queue, the held-back
/// record and a chunk just sent, all of 8-axis records, written and read
/// back, with [`PROCESSING_ALLOWANCE_MS`] per command. Chunks of at least
/// three records and a queue of at least one whatever the rate. At 9,600
/// baud: chunks of 5 records and a queue of 1 (1.93 s left at
/// the end, worst case); 19,200: 15 and 1 (1.92 s); from 38,400: chunks
/// as long as a 2,051-byte frame allows (24 8-axis records, more of fewer
/// axes) and the full queue of [`QUEUE_LEN`] (1.74 s at 38,400, 0.71 s at
/// 115,200).
pub const fn pipeline(baud: u32) -> Pipeline {
    let baud = if baud == 0 { 1 } else { baud as u64 };
    let budget = FINAL_BUDGET_MS as u64 * 1_000;
    let mut chunk = MAX_FRAME_RECORDS as u64;
    while chunk > MIN_CHUNK_RECORDS as u64 {
        if finish_us(chunk, 1, baud) <= budget {
            break;
        }
        chunk -= 1;
    }
    let mut queued = QUEUE_LEN as u64;
    while queued > 1 && finish_us(chunk, queued, baud) > budget {
        queued -= 1;
    }
    Pipeline {
        chunk_records: chunk as u16,
        queued_records: queued as usize,
    }
}

/// The earlier of two optional deadlines, seen from `now`.
fn earliest(now: u32, a: Option<u32>, b: Option<u32>) -> Option<u32> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if a.wrapping_sub(now) <= b.wrapping_sub(now) {
            a
        } else {
            b
        }),
        (a, b) => a.or(b),
    }
}

/// Writes what `port` takes right now of `bytes[*off..]`, never waiting;
/// advances `*off` and `*counter` by the bytes written and returns them.
fn write_some<W: Write + WriteReady>(
    port: &mut W,
    bytes: &[u8],
    off: &mut usize,
    counter: &mut u64,
) -> Result<usize, W::Error> {
    let rest = bytes.get(*off..).unwrap_or(&[]);
    if rest.is_empty() || !port.write_ready()? {
        return Ok(0);
    }
    let n = port.write(rest)?;
    *off += n;
    *counter += n as u64;
    Ok(n)
}

/// Recognises [`codes::QUIT`] after [`QUIT_GUARD_MS`] of silence.
struct QuitDetector {
    matched: usize,
    last_byte_ms: Option<u32>,
}

impl QuitDetector {
    const fn new() -> Self {
        Self {
            matched: 0,
            last_byte_ms: None,
        }
    }

    /// Feed one byte read at `now_ms`; `true` once the sequence is complete.
    fn feed(&mut self, byte: u8, now_ms: u32) -> bool {
        let quiet_before = self
            .last_byte_ms
            .is_none_or(|last| now_ms.wrapping_sub(last) >= QUIT_GUARD_MS);
        self.last_byte_ms = Some(now_ms);
        if self.matched > 0 && codes::QUIT.get(self.matched) == Some(&byte) {
            self.matched += 1;
            if self.matched == codes::QUIT.len() {
                self.matched = 0;
                return true;
            }
        } else if byte == codes::QUIT[0] && quiet_before {
            self.matched = 1;
        } else {
            self.matched = 0;
        }
        false
    }
}

/// Bridges until the quit sequence (`Ok` with the counters) or a port
/// error.
///
/// Never waits inside a port call. When nothing can move it calls `sleep`
/// with a readiness check, which should sleep (e.g. WFI) unless the check
/// says there is work; `feed` runs once per loop (a watchdog: if the loop
/// stalls, the watchdog resets the MCU). `now_ms` is a wrapping millisecond
/// clock; timers count in ms, so the board must wake at least once a
/// millisecond or by the deadline.
pub fn run<U: Port, D: Port>(
    bridge: &mut Bridge,
    upstream: &mut U,
    downstream: &mut D,
    now_ms: impl Fn() -> u32,
    mut sleep: impl FnMut(&mut dyn FnMut() -> bool),
    mut feed: impl FnMut(),
) -> Result<Stats, Error<U::Error, D::Error>> {
    loop {
        feed();
        match bridge.poll(upstream, downstream, now_ms())? {
            Poll::Quit => return Ok(bridge.stats()),
            Poll::Busy => {}
            Poll::Wait(w) => {
                let i = w.interest;
                let start = now_ms();
                sleep(&mut || {
                    now_ms() != start
                        || (i.up_read && upstream.read_ready().unwrap_or(true))
                        || (i.down_read && downstream.read_ready().unwrap_or(true))
                        || (i.up_write && upstream.write_ready().unwrap_or(true))
                        || (i.down_write && downstream.write_ready().unwrap_or(true))
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::config::{AllowList, Policy};
    use iai_protocol_b::checksum::ChecksumMode;
    use iai_protocol_b::frame::Frame;

    #[test]
    fn the_pipeline_fits_the_final_reply_budget() {
        let p = |chunk_records, queued_records| Pipeline {
            chunk_records,
            queued_records,
        };
        assert_eq!(pipeline(9_600), p(5, 1));
        assert_eq!(pipeline(19_200), p(15, 1));
        assert_eq!(pipeline(38_400), p(MAX_FRAME_RECORDS, QUEUE_LEN));
        assert_eq!(pipeline(u32::MAX), p(MAX_FRAME_RECORDS, QUEUE_LEN));
        // Too slow for the budget: the smallest pipeline that still runs.
        assert_eq!(pipeline(0), p(MIN_CHUNK_RECORDS, 1));
        assert_eq!(pipeline(1_200), p(MIN_CHUNK_RECORDS, 1));
        for baud in [9_600u32, 19_200, 38_400, 57_600, 115_200, 230_400] {
            let q = pipeline(baud);
            let t = finish_us(
                u64::from(q.chunk_records),
                q.queued_records as u64,
                baud.into(),
            );
            assert!(t <= u64::from(FINAL_BUDGET_MS) * 1_000, "{baud}: {t} us");
        }
    }

    /// A port over byte vectors: reads `input`, collects what is written.
    #[derive(Default)]
    struct Fake {
        input: Vec<u8>,
        output: Vec<u8>,
    }

    impl embedded_io::ErrorType for Fake {
        type Error = core::convert::Infallible;
    }
    impl ReadReady for Fake {
        fn read_ready(&mut self) -> Result<bool, Self::Error> {
            Ok(!self.input.is_empty())
        }
    }
    impl Read for Fake {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
            let n = buf.len().min(self.input.len());
            buf[..n].copy_from_slice(&self.input[..n]);
            self.input.drain(..n);
            Ok(n)
        }
    }
    impl WriteReady for Fake {
        fn write_ready(&mut self) -> Result<bool, Self::Error> {
            Ok(true)
        }
    }
    impl Write for Fake {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            self.output.extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }
    impl Port for Fake {}

    fn frame(header: Header, station: u8, code: u16, body: &[u8]) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let n = emit_frame(
            &mut buf,
            header,
            Station(station),
            code,
            ChecksumMode::Compute,
            |w| w.put(body),
        )
        .unwrap();
        buf[..n].to_vec()
    }

    /// Polls until the bridge waits, at tick `now`.
    fn settle(b: &mut Bridge, up: &mut Fake, down: &mut Fake, now: u32) {
        for _ in 0..10_000 {
            if let Poll::Wait(_) = b.poll(up, down, now).unwrap() {
                return;
            }
        }
        panic!("the bridge never waits");
    }

    fn bridge(policy: Policy) -> Bridge {
        Bridge::new(
            Config {
                policy,
                ..Config::DEFAULT
            },
            Source::Default,
        )
    }

    #[test]
    fn own_station_answers_status_and_b09() {
        let mut b = bridge(Policy::ForwardAll);
        let (mut up, mut down) = (Fake::default(), Fake::default());
        up.input = frame(Header::Command, 0xBB, codes::STATUS_QUERY, b"");
        up.input.extend(frame(Header::Command, 0xBB, 0x212, b"01"));
        settle(&mut b, &mut up, &mut down, 7);
        settle(&mut b, &mut up, &mut down, 8);
        assert!(down.output.is_empty());
        let status =
            Frame::new_checked(&up.output[..status::REPLY_LEN], BypassPolicy::Reject).unwrap();
        let fields = status::parse(status.body()).unwrap();
        assert_eq!(fields[1], ("uptime_ms", 7));
        assert_eq!(fields[16], ("own_queries", 1));
        assert_eq!(
            &up.output[status::REPLY_LEN..],
            &frame(Header::Error, 0xBB, codes::UNKNOWN_QUERY, b"")[..]
        );
        assert_eq!(b.last_error().map(|e| e.code), Some(codes::UNKNOWN_QUERY));
    }

    #[test]
    fn other_stations_are_ignored_and_refusals_answered_after_the_end() {
        let mut b = bridge(Policy::Allow(AllowList::of(&[0x212])));
        let (mut up, mut down) = (Fake::default(), Fake::default());
        up.input = frame(Header::Command, 0x42, 0x212, b"01");
        up.input.extend(frame(Header::Command, 0x99, 0x25B, b""));
        settle(&mut b, &mut up, &mut down, 0);
        settle(&mut b, &mut up, &mut down, 1);
        assert!(down.output.is_empty());
        assert_eq!(up.output, frame(Header::Error, 0x99, codes::REFUSED, b""));
        assert_eq!(b.stats().other_station, 1);
        assert_eq!(b.stats().refused, 1);
        // A refused command with a wrong checksum gets no answer.
        let mut bad = frame(Header::Command, 0x99, 0x25B, b"");
        bad[6] ^= 1;
        up.input = bad;
        up.output.clear();
        settle(&mut b, &mut up, &mut down, 2);
        assert!(up.output.is_empty());
        assert_eq!(b.stats().rejected, 1);
        // The allowed one goes through.
        up.input = frame(Header::Command, 0x99, 0x212, b"01");
        settle(&mut b, &mut up, &mut down, 3);
        assert_eq!(down.output, frame(Header::Command, 0x99, 0x212, b"01"));
    }

    #[test]
    fn a_reply_with_xoff_in_its_text_is_not_relayed_under_xon_xoff() {
        for flow in [FlowControl::XonXoff, FlowControl::None] {
            let mut b = Bridge::new(
                Config {
                    flow,
                    ..Config::DEFAULT
                },
                Source::Default,
            );
            let (mut up, mut down) = (Fake::default(), Fake::default());
            let cmd = frame(Header::Command, 0x99, 0x200, b"0123456789");
            up.input = cmd.clone();
            settle(&mut b, &mut up, &mut down, 0);
            assert_eq!(down.output, cmd);
            let reply = frame(Header::Response, 0x99, 0x200, b"01234\x1356789");
            down.input = reply.clone();
            settle(&mut b, &mut up, &mut down, 5);
            settle(&mut b, &mut up, &mut down, 6);
            let want = match flow {
                FlowControl::XonXoff => frame(Header::Error, 0x99, codes::XON_XOFF_IN_TEXT, b""),
                _ => reply,
            };
            assert_eq!(up.output, want, "{flow:?}");
        }
    }

    #[test]
    fn no_reply_within_3_s_gives_no_answer_and_the_deadline_says_when() {
        let mut b = bridge(Policy::ForwardAll);
        let (mut up, mut down) = (Fake::default(), Fake::default());
        up.input = frame(Header::Command, 0x99, 0x212, b"01");
        settle(&mut b, &mut up, &mut down, 100);
        let Poll::Wait(w) = b.poll(&mut up, &mut down, 100).unwrap() else {
            panic!("waits for the reply");
        };
        assert_eq!(w.reason, Reason::Controller);
        assert_eq!(w.deadline, Some(100 + REPLY_TIMEOUT_MS));
        settle(&mut b, &mut up, &mut down, 100 + REPLY_TIMEOUT_MS);
        assert!(b.is_idle());
        assert!(up.output.is_empty());
        assert_eq!(b.stats().reply_timeouts, 1);
    }
}
