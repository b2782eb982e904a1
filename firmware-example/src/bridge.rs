//! Board-independent protocol bridging between the upstream (host) and
//! downstream (controller) serial ports.
//!
//! Only `embedded-io` traits, a millisecond clock and a sleep function are
//! used, so this module knows nothing about registers.
//!
//! # What the bridge does
//!
//! The bridge reads the upstream byte by byte. A header byte (`!`, `#`,
//! `&`, `%`) starts a frame; the first six bytes (header, station, ID) say
//! what it is:
//!
//! * **`!` with ID 26DH** (Change Position Data Continuous Write 2, up to
//!   20,000 records, 1.6 MB): the bytes go one by one into a
//!   [`PositionStreamDecoder`]; each record it hands out is pushed into the
//!   bounded [`RecordQueue`] of a [`Transfer`], which writes the records to
//!   the controller in controller-sized 26DH commands (at most 2,051
//!   bytes), each confirmed, with the spec's timeout and retries. No buffer
//!   holds the upstream message: only the decoder's 88-byte stage and
//!   [`QUEUE_LEN`] records. While the queue is full the bridge stops
//!   reading the upstream (see *Flow control*). When the upstream frame has
//!   ended with a valid checksum and the transfer is complete, the bridge
//!   sends **one** normal response upstream:
//!   `#` station `26D` count(4 hex) SC CR LF, the count being the number of
//!   records written (the whole table).
//! * **any other `!` command**: it goes through a [`FrameDecoder`] (checked:
//!   format, checksum or `@@`, CR LF, at most 2,051 bytes). A malformed one
//!   is dropped and never forwarded. A valid one is forwarded downstream
//!   unchanged; the controller's reply is checked the same way (valid
//!   frame, same station, and the same ID for a `#` response) and relayed
//!   upstream unchanged. Anything else from the controller is ignored. If
//!   no valid reply arrives within [`REPLY_TIMEOUT_MS`] (3 s) the bridge
//!   returns to idle without answering: the host times out and re-sends,
//!   as protocol B prescribes (2003 p. 62, timeout and retry).
//! * frames the host should never send (`#`, `&`) and noise are dropped.
//!
//! # Error responses of the bridge (26DH only)
//!
//! | code  | meaning |
//! |-------|---------|
//! | [`ERR_UPSTREAM_FRAME`] `B01` | the upstream 26DH was malformed: wrong checksum (found at its end), bad hex digit, bad axis pattern, missing CR LF, count mismatch |
//! | [`ERR_CONTROLLER_TIMEOUT`] `B02` | the controller did not confirm a chunk: no valid reply after 3 sends (3 s each) |
//! | [`ERR_CONTROLLER_ERROR`] `B03` | the controller kept answering a chunk with an `&` error response (3 sends) |
//! | [`ERR_UPSTREAM_STALLED`] `B04` | the upstream 26DH stopped for [`UPSTREAM_STALL_MS`] in the middle |
//! | [`ERR_INTERNAL`] `B05` | the transfer could not be set up (never seen in practice) |
//!
//! Position writes are idempotent (each record names its own position
//! number), so after any `&` response the host simply sends the whole
//! command again. Records before the failure may already be written;
//! writing them again is harmless. The codes are outside anything the
//! controllers are known to use, but the controllers' own code list is not
//! published (TTA p. 15, 2003 p. 13), so treat `B01`..`B05` as the bridge's.
//!
//! # Flow control
//!
//! When the record queue is full the bridge stops reading the upstream; the
//! UART driver's receive ring fills up and then leaves bytes in the UART.
//! QEMU then holds them back in its socket, so nothing is lost under QEMU.
//! Real hardware has no such back-pressure: a real link needs RTS/CTS
//! hardware flow control (the UART deasserting RTS when its FIFO fills),
//! or a host that sends no faster than the controller side drains
//! (26DH chunks to a TTA are confirmed one by one, so the downstream is the
//! bottleneck).
//!
//! # Quitting
//!
//! Outside a transfer the upstream may send [`QUIT`] (ESC 'Q' '!') after at
//! least [`QUIT_GUARD_MS`] of silence; [`run`] then returns.

use embedded_io::{Read, ReadReady, Write, WriteReady};
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::field::{decode_unsigned, FieldSpec};
use iai_protocol_b::frame::{emit_frame, Header, Station, ENVELOPE_LEN};
use iai_protocol_b::limits;
use iai_protocol_b::stream::{PositionStream, PositionStreamDecoder, StreamEvent};
use iai_protocol_b::transfer::{RecordQueue, Step, Transfer, TransferConfig, TransferError};

use crate::log;

/// Upstream byte sequence that ends the run.
pub const QUIT: [u8; 3] = [0x1B, b'Q', b'!'];

/// Upstream silence required before the quit sequence.
pub const QUIT_GUARD_MS: u32 = 20;

/// Records buffered between the upstream decoder and the transfer
/// (a little over two 8-axis chunks of 24 records).
pub const QUEUE_LEN: usize = 64;

/// How long the bridge waits for the controller's reply to a forwarded
/// command before it gives up silently.
pub const REPLY_TIMEOUT_MS: u32 = 3_000;

/// How long a 26DH command may pause upstream in its middle (while the
/// bridge is ready to read) before it is abandoned with
/// [`ERR_UPSTREAM_STALLED`].
pub const UPSTREAM_STALL_MS: u32 = 5_000;

/// `&` code: the upstream 26DH was malformed (checksum, format).
pub const ERR_UPSTREAM_FRAME: u16 = 0xB01;
/// `&` code: the controller did not confirm a chunk (timeouts).
pub const ERR_CONTROLLER_TIMEOUT: u16 = 0xB02;
/// `&` code: the controller kept answering a chunk with `&`.
pub const ERR_CONTROLLER_ERROR: u16 = 0xB03;
/// `&` code: the upstream 26DH stopped in its middle.
pub const ERR_UPSTREAM_STALLED: u16 = 0xB04;
/// `&` code: the transfer could not be set up.
pub const ERR_INTERNAL: u16 = 0xB05;

/// Largest frame handled in pass-through (a TTA receives at most 2,051
/// bytes and sends at most 2,048).
const FRAME_CAP: usize = limits::TTA.command;

/// Upstream bytes read per call (a staging chunk, not a message buffer).
const IN_CHUNK: usize = 32;

/// The 26DH stream the bridge splits.
const STREAM: PositionStream = PositionStream::CHANGE_2;

/// Why [`run`] stopped with an error.
#[derive(Debug)]
pub enum Error<U, D> {
    /// The upstream port failed.
    Upstream(U),
    /// The downstream port failed.
    Downstream(D),
}

/// What the bridge counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BridgeStats {
    /// Commands forwarded downstream as they were.
    pub forwarded: u32,
    /// Replies relayed upstream.
    pub relayed: u32,
    /// Forwarded commands that got no valid reply in time.
    pub reply_timeouts: u32,
    /// Upstream frames dropped as malformed (never forwarded).
    pub rejected: u32,
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
    /// Bytes read from the upstream.
    pub upstream_in: u64,
    /// Bytes written to the upstream.
    pub upstream_out: u64,
    /// Bytes read from the downstream.
    pub downstream_in: u64,
    /// Bytes written to the downstream.
    pub downstream_out: u64,
}

/// The 26DH transfer: records from the upstream decoder through a bounded
/// queue to controller-sized commands.
type Job = Transfer<RecordQueue<QUEUE_LEN>>;

/// Where the bridge is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Hunting for a header byte upstream.
    Idle,
    /// Collecting the first [`ENVELOPE_LEN`] bytes of an upstream frame.
    Head,
    /// Feeding an upstream command (not 26DH) to the frame decoder.
    Command,
    /// Writing the decoded command downstream.
    SendCommand { station: Station, id: u16 },
    /// Waiting for the controller's reply.
    AwaitReply {
        station: Station,
        id: u16,
        deadline: u32,
    },
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

/// Which port operations would let the bridge make progress.
#[derive(Debug, Clone, Copy, Default)]
struct Interest {
    up_read: bool,
    up_write: bool,
    down_read: bool,
    down_write: bool,
}

/// The bridge's state. Keep it in a static (about 8 KiB); it holds no
/// port and no clock.
pub struct Bridge {
    mode: Mode,
    head: [u8; ENVELOPE_LEN],
    head_len: usize,
    /// Upstream commands, then the controller's reply (one at a time).
    frames: FrameDecoder<FRAME_CAP>,
    stream: PositionStreamDecoder,
    job: Option<Job>,
    /// Bytes of the current outgoing frame already written.
    out_off: usize,
    /// A 26DH chunk waits for room in the downstream transmit ring.
    tx_blocked: bool,
    resp: [u8; 16],
    resp_len: usize,
    inbuf: [u8; IN_CHUNK],
    in_pos: usize,
    in_len: usize,
    quit: QuitDetector,
    stats: BridgeStats,
}

impl Default for Bridge {
    fn default() -> Self {
        Self::new()
    }
}

impl Bridge {
    /// An idle bridge.
    pub const fn new() -> Self {
        Self {
            mode: Mode::Idle,
            head: [0; ENVELOPE_LEN],
            head_len: 0,
            frames: FrameDecoder::with_policy(BypassPolicy::CommandsOnly),
            stream: PositionStreamDecoder::new(BypassPolicy::CommandsOnly),
            job: None,
            out_off: 0,
            tx_blocked: false,
            resp: [0; 16],
            resp_len: 0,
            inbuf: [0; IN_CHUNK],
            in_pos: 0,
            in_len: 0,
            quit: QuitDetector::new(),
            stats: BridgeStats {
                forwarded: 0,
                relayed: 0,
                reply_timeouts: 0,
                rejected: 0,
                streams_ok: 0,
                streams_failed: 0,
                records: 0,
                chunks_sent: 0,
                retries: 0,
                chunk_timeouts: 0,
                chunk_error_replies: 0,
                upstream_in: 0,
                upstream_out: 0,
                downstream_in: 0,
                downstream_out: 0,
            },
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> BridgeStats {
        self.stats
    }

    /// Whether upstream bytes are wanted in the current mode.
    fn wants_upstream(&mut self) -> bool {
        match self.mode {
            Mode::Idle | Mode::Head | Mode::Command => true,
            Mode::Stream {
                upstream_done,
                abort,
                ..
            } => !upstream_done && abort.is_none() && !queue_full(&mut self.job),
            _ => false,
        }
    }

    fn interest(&mut self) -> Interest {
        let up_read = self.wants_upstream() && self.in_pos == self.in_len;
        match self.mode {
            Mode::Idle | Mode::Head | Mode::Command => Interest {
                up_read,
                down_read: true,
                ..Interest::default()
            },
            Mode::SendCommand { .. } => Interest {
                down_write: true,
                ..Interest::default()
            },
            Mode::AwaitReply { .. } => Interest {
                down_read: true,
                ..Interest::default()
            },
            Mode::RelayReply | Mode::Respond => Interest {
                up_write: true,
                ..Interest::default()
            },
            Mode::Stream { .. } => Interest {
                up_read,
                down_read: true,
                down_write: self.tx_blocked,
                up_write: false,
            },
        }
    }

    /// The next upstream byte, if one is there (reads a chunk when the
    /// staging chunk is used up).
    fn up_byte<U: Read + ReadReady>(&mut self, up: &mut U) -> Result<Option<u8>, U::Error> {
        if self.in_pos == self.in_len {
            if !up.read_ready()? {
                return Ok(None);
            }
            let n = up.read(&mut self.inbuf)?;
            self.stats.upstream_in += n as u64;
            self.in_pos = 0;
            self.in_len = n;
        }
        let b = self.inbuf.get(self.in_pos).copied();
        if b.is_some() {
            self.in_pos += 1;
        }
        Ok(b)
    }

    /// Makes what progress is possible without waiting. `Ok(None)`: nothing
    /// moved; `Ok(Some(true))`: the quit sequence came; `Ok(Some(false))`:
    /// something moved.
    fn poll<U, D>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<Option<bool>, Error<U::Error, D::Error>>
    where
        U: Read + ReadReady + Write + WriteReady,
        D: Read + ReadReady + Write + WriteReady,
    {
        let mut moved = false;
        match self.mode {
            Mode::Idle | Mode::Head | Mode::Command => {
                moved |= self.drain_downstream(down).map_err(Error::Downstream)?;
                while matches!(self.mode, Mode::Idle | Mode::Head | Mode::Command) {
                    let Some(b) = self.up_byte(up).map_err(Error::Upstream)? else {
                        break;
                    };
                    moved = true;
                    let quit = self.quit.feed(b, now);
                    if quit && self.mode == Mode::Idle {
                        return Ok(Some(true));
                    }
                    self.on_upstream_byte(b, now);
                }
            }
            Mode::SendCommand { station, id } => {
                let done = {
                    let bytes = self.frames.last_frame().map_or(&[][..], |f| f.as_bytes());
                    let out = &mut self.stats.downstream_out;
                    let n = write_some(down, bytes, &mut self.out_off, out)
                        .map_err(Error::Downstream)?;
                    moved |= n > 0;
                    self.out_off >= bytes.len()
                };
                if done {
                    self.out_off = 0;
                    self.stats.forwarded += 1;
                    self.frames.reset();
                    self.frames.set_policy(BypassPolicy::Reject);
                    self.mode = Mode::AwaitReply {
                        station,
                        id,
                        deadline: now.wrapping_add(REPLY_TIMEOUT_MS),
                    };
                    moved = true;
                }
            }
            Mode::AwaitReply {
                station,
                id,
                deadline,
            } => {
                let mut buf = [0u8; 1];
                while down.read_ready().map_err(Error::Downstream)? {
                    if down.read(&mut buf).map_err(Error::Downstream)? == 0 {
                        break;
                    }
                    self.stats.downstream_in += 1;
                    moved = true;
                    let valid = match self.frames.push(buf[0]) {
                        Event::Frame(f) => {
                            f.station() == station
                                && match f.header() {
                                    Header::Response => f.code() == id,
                                    Header::Error => true,
                                    Header::Command => false,
                                }
                        }
                        Event::NeedMore | Event::Error(_) => false,
                    };
                    if valid {
                        self.mode = Mode::RelayReply;
                        self.out_off = 0;
                        break;
                    }
                }
                if self.mode != Mode::RelayReply && now.wrapping_sub(deadline) < 0x8000_0000 {
                    log::warning!("no reply from the controller within 3 s");
                    self.stats.reply_timeouts += 1;
                    self.go_idle();
                    moved = true;
                }
            }
            Mode::RelayReply => {
                let done = {
                    let bytes = self.frames.last_frame().map_or(&[][..], |f| f.as_bytes());
                    let out = &mut self.stats.upstream_out;
                    let n =
                        write_some(up, bytes, &mut self.out_off, out).map_err(Error::Upstream)?;
                    moved |= n > 0;
                    self.out_off >= bytes.len()
                };
                if done {
                    self.stats.relayed += 1;
                    self.go_idle();
                    moved = true;
                }
            }
            Mode::Stream { .. } => moved |= self.poll_stream(up, down, now)?,
            Mode::Respond => {
                let resp = self.resp.get(..self.resp_len).unwrap_or(&[]);
                let out = &mut self.stats.upstream_out;
                let n = write_some(up, resp, &mut self.out_off, out).map_err(Error::Upstream)?;
                moved |= n > 0;
                if self.out_off >= self.resp_len {
                    self.go_idle();
                    moved = true;
                }
            }
        }
        Ok(moved.then_some(false))
    }

    /// Back to hunting for a frame upstream.
    fn go_idle(&mut self) {
        self.mode = Mode::Idle;
        self.out_off = 0;
        self.job = None;
        self.stream.reset();
        self.frames.reset();
        self.frames.set_policy(BypassPolicy::CommandsOnly);
    }

    /// Reads and drops whatever the controller sends unasked (late replies,
    /// noise) while no reply is expected.
    fn drain_downstream<D: Read + ReadReady>(&mut self, down: &mut D) -> Result<bool, D::Error> {
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

    /// One upstream byte in the Idle, Head or Command mode.
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
            _ => {}
        }
    }

    /// The envelope is complete: a 26DH stream or a pass-through command.
    fn classify(&mut self, now: u32) {
        let head = self.head;
        let station = decode_unsigned(FieldSpec::hex(2), &head[1..3], 1);
        let id = decode_unsigned(FieldSpec::hex(3), &head[3..6], 3);
        if let (b'!', Ok(station), Ok(id)) = (head[0], station, id) {
            if id == u64::from(STREAM.id) {
                self.stream.reset();
                for &b in &head {
                    // The envelope alone never completes an event.
                    let _ = self.stream.push(b);
                }
                self.mode = Mode::Stream {
                    station: Station(station as u8),
                    upstream_done: false,
                    abort: None,
                    waiting_since: now,
                };
                log::info!("26DH stream for station {=u8:02X}", station as u8);
                return;
            }
        }
        self.frames.reset();
        self.frames.set_policy(BypassPolicy::CommandsOnly);
        self.mode = Mode::Command;
        for &b in &head {
            self.command_byte(b, now);
            if self.mode != Mode::Command {
                break;
            }
        }
    }

    /// One byte of a pass-through command.
    fn command_byte(&mut self, b: u8, now: u32) {
        match self.frames.push(b) {
            Event::NeedMore => {}
            Event::Frame(f) => {
                if f.header() == Header::Command {
                    self.mode = Mode::SendCommand {
                        station: f.station(),
                        id: f.code(),
                    };
                    self.out_off = 0;
                } else {
                    // Only commands go downstream.
                    self.stats.rejected += 1;
                    self.go_idle();
                }
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

    /// The 26DH mode: decode upstream bytes into the queue, drive the
    /// transfer, answer once at the end.
    fn poll_stream<U, D>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<bool, Error<U::Error, D::Error>>
    where
        U: Read + ReadReady + Write + WriteReady,
        D: Read + ReadReady + Write + WriteReady,
    {
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
            if queue_full(&mut self.job) {
                waiting_since = now;
                break;
            }
            let Some(b) = self.up_byte(up).map_err(Error::Upstream)? else {
                if now.wrapping_sub(waiting_since) >= UPSTREAM_STALL_MS {
                    log::warning!("26DH stalled upstream");
                    abort = Some(ERR_UPSTREAM_STALLED);
                }
                break;
            };
            moved = true;
            waiting_since = now;
            match self.stream.push(b) {
                StreamEvent::NeedMore => {}
                StreamEvent::Start {
                    station: s, count, ..
                } => {
                    log::info!("26DH: {=u16} records", count);
                    let job = Transfer::new(TransferConfig::tta(s), RecordQueue::new())
                        .with_total(u32::from(count));
                    self.job = Some(job);
                }
                StreamEvent::Record(rec) => {
                    if let Some(job) = self.job.as_mut() {
                        if job.source_mut().push(rec).is_err() {
                            // Cannot happen: the queue had room.
                            abort = Some(ERR_INTERNAL);
                        }
                    }
                }
                StreamEvent::End { records: _records } => {
                    log::info!("26DH upstream ended well: {=u16} records", _records);
                    if let Some(job) = self.job.as_mut() {
                        job.source_mut().finish();
                    }
                    upstream_done = true;
                }
                StreamEvent::Error {
                    error: _error,
                    records_ok: _ok,
                } => {
                    log::warning!("26DH upstream broken after {=u16} records: {}", _ok, _error);
                    abort = Some(ERR_UPSTREAM_FRAME);
                }
            }
        }

        // Downstream: the transfer.
        let mut answer: Option<Result<u16, u16>> = None;
        self.tx_blocked = false;
        if let Some(job) = self.job.as_mut() {
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
                    Step::WaitUntil(_) | Step::NeedRecords => {
                        if abort.is_some() {
                            answer = abort.map(Err);
                        }
                        break;
                    }
                    Step::Complete(report) => {
                        answer = Some(Ok(report.stats.records_confirmed as u16));
                        break;
                    }
                    Step::Failed(e) => {
                        log::warning!("26DH transfer failed: {}", e);
                        answer = Some(Err(match e {
                            TransferError::Timeout => ERR_CONTROLLER_TIMEOUT,
                            TransferError::Controller { .. } | TransferError::Bridge { .. } => {
                                ERR_CONTROLLER_ERROR
                            }
                            _ => ERR_INTERNAL,
                        }));
                        break;
                    }
                }
            }
        } else if abort.is_some() {
            answer = abort.map(Err);
        }

        self.mode = Mode::Stream {
            station,
            upstream_done,
            abort,
            waiting_since,
        };
        if let Some(answer) = answer {
            if let Some(job) = self.job.as_ref() {
                let s = job.stats();
                self.stats.records += s.records_confirmed;
                self.stats.chunks_sent += s.frames_sent;
                self.stats.retries += s.retries;
                self.stats.chunk_timeouts += s.timeouts;
                self.stats.chunk_error_replies += s.error_replies;
            }
            self.respond(station, answer);
            moved = true;
        }
        Ok(moved)
    }

    /// Queue the bridge's own response: `#…26D count` or `&` code.
    fn respond(&mut self, station: Station, answer: Result<u16, u16>) {
        let n = match answer {
            Ok(count) => {
                self.stats.streams_ok += 1;
                emit_frame(
                    &mut self.resp,
                    Header::Response,
                    station,
                    STREAM.id,
                    ChecksumMode::Compute,
                    |w| STREAM.write_prefix(w, 0, count),
                )
            }
            Err(code) => {
                self.stats.streams_failed += 1;
                emit_frame(
                    &mut self.resp,
                    Header::Error,
                    station,
                    code,
                    ChecksumMode::Compute,
                    |_| Ok(()),
                )
            }
        };
        self.job = None;
        self.stream.reset();
        self.out_off = 0;
        // Both fit 16 bytes; an error would leave an empty response.
        self.resp_len = n.unwrap_or(0);
        self.mode = Mode::Respond;
    }
}

/// Whether the transfer's record queue has no room.
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

fn queue_full(job: &mut Option<Job>) -> bool {
    job.as_mut().is_some_and(|j| j.source_mut().is_full())
}

/// Recognises [`QUIT`] after [`QUIT_GUARD_MS`] of silence.
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
        if self.matched > 0 && QUIT.get(self.matched) == Some(&byte) {
            self.matched += 1;
            if self.matched == QUIT.len() {
                self.matched = 0;
                return true;
            }
        } else if byte == QUIT[0] && quiet_before {
            self.matched = 1;
        } else {
            self.matched = 0;
        }
        false
    }
}

/// Bridge until the upstream sends the quit sequence (`Ok` with the
/// counters) or a port fails.
///
/// Never waits inside a port call: it checks `read_ready` / `write_ready`
/// first, and when nothing can move calls `sleep` with a readiness check,
/// which should sleep (e.g. WFI) unless that check says there is work.
/// `now_ms` is a wrapping millisecond clock.
pub fn run<U, D>(
    bridge: &mut Bridge,
    upstream: &mut U,
    downstream: &mut D,
    now_ms: impl Fn() -> u32,
    mut sleep: impl FnMut(&mut dyn FnMut() -> bool),
) -> Result<BridgeStats, Error<U::Error, D::Error>>
where
    U: Read + ReadReady + Write + WriteReady,
    D: Read + ReadReady + Write + WriteReady,
{
    loop {
        match bridge.poll(upstream, downstream, now_ms())? {
            Some(true) => return Ok(bridge.stats()),
            Some(false) => {}
            None => {
                let i = bridge.interest();
                let start = now_ms();
                sleep(&mut || {
                    // Timers (reply timeout, turnaround, stall) count in
                    // ms: wake on every tick.
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
