//! The bridge: protocol B between a host (upstream) and one controller
//! (downstream), board-independent and never blocking.
//!
//! [`Bridge::poll`] makes what progress the ports allow and answers
//! [`Poll::Busy`] (call again), [`Poll::Wait`] (nothing can move before one
//! of the listed events or the deadline) or [`Poll::Quit`]. Time is a
//! wrapping millisecond tick passed in by the caller, so the same code runs
//! on a board ([`run`]) and in the host model of `host-tests`, in virtual
//! time. Its jobs, one file each:
//!
//! - `upstream`: frames from the host, by their envelope: commands to the
//!   bridge's own station are answered by the bridge ([`crate::status`]),
//!   other stations' commands are skipped, refused ones ([`crate::config`])
//!   are read to their end and answered `&` [`crate::codes::REFUSED`];
//! - `passthrough`: any other command is checked, forwarded, and the
//!   controller's checked reply relayed (the core's relay engine); without
//!   one in time the bridge answers nothing and the host resends (2003
//!   p. 62);
//! - `table_write`: a 26DH of any size is decoded record by record and written
//!   in controller-sized chunks, each confirmed and read back equal before
//!   more is taken from the host; one `#` with the count at the end;
//! - [`pipeline`]: chunk and queue sizes for the downstream rate, so that
//!   the final reply fits the host's timeout.
//!
//! The downstream line is one [`Line`] for both paths, moved by one
//! [`Driver`]: what the 26DH path left in flight (a read-back's late reply)
//! the pass-through knows, and the reverse; a line just booted fences its
//! first command. The line expects copied replies only as long after a
//! reply as [`Config::duplicate_window_ms`] says, or as it learns.
//!
//! Buffers: one 2,051-byte area serves both paths. It is the frame buffer
//! of the 26DH transfer, built once and restarted in place for each 26DH;
//! between 26DHs it is lent out as the pass-through's frame decoder
//! ([`Transfer::idle_decoder`]), which holds the command, then the reply.

pub mod history;
mod passthrough;
pub mod pipeline;
mod session;
mod table_write;
mod upstream;

use embedded_io::{Write, WriteReady};
use iai_protocol_b::axis::MAX_AXES;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::engine::Driver;
use iai_protocol_b::frame::Station;
use iai_protocol_b::line::Line;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::relay::Relay;
use iai_protocol_b::transfer::{packed_len, RecordBuffer, Transfer};
use iai_protocol_b::{line::LineConfig, profile::Profile, transfer::TransferConfig};

use crate::config::editor::Editor;
use crate::config::{Config, Source};
use crate::log;
use crate::serial::{Counted, Port};
use crate::status::{self, LastError, Stats};

use table_write::StreamWork;
use upstream::Upstream;

/// Upstream silence required before the quit sequence.
pub const QUIT_GUARD_MS: u32 = 20;

/// Bytes of the buffer between the upstream decoder and the transfer:
/// room for a whole chunk of 8-axis records (24 in a 2,051-byte frame, 43
/// bytes each packed), so that the host sends the next chunk while the
/// controller writes and reads back this one.
pub const QUEUE_BYTES: usize = FRAME_RECORDS_8_AXES * packed_len(MAX_AXES);

/// 8-axis records in one controller-sized 26DH chunk.
const FRAME_RECORDS_8_AXES: usize =
    (FRAME_CAP - STREAM.overhead()) / STREAM.layout.record_len(MAX_AXES);

/// How long a 26DH may pause upstream in its middle (while the bridge is
/// ready to read) before it is abandoned with
/// [`crate::codes::UPSTREAM_STALLED`].
pub const UPSTREAM_STALL_MS: u32 = 5_000;

/// Largest frame handled in pass-through (a TTA receives at most 2,051
/// bytes and sends at most 2,048, TTA p. 15).
pub const FRAME_CAP: usize = Profile::TTA.max_command_frame();

/// Bytes of the bridge's own replies (the status reply is the longest).
pub const RESPONSE_CAP: usize = status::REPLY_LEN;

/// The 26DH stream the bridge splits: the TTA's table write.
const STREAM: PositionStream = Profile::TTA.table_write();

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
    /// The controller's reply (or a timer of the line).
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

/// A second user of the controller line (the Modbus gateway): it runs its
/// own exchanges, one at a time, when the bridge grants it the line. The
/// protocol-B host goes first: while the host has a command waiting, the
/// bridge asks the guest to give up an exchange it may abandon (a poll),
/// and otherwise waits for it to end before it starts the host's command;
/// the guest starts nothing while a host command or a 26DH runs.
pub trait Guest {
    /// Whether an exchange of the guest's is under way.
    fn holds_line(&self) -> bool;
    /// Whether it has an exchange to start at `now`.
    fn wants_line(&self, now: u32) -> bool;
    /// Whether its exchange may be abandoned now.
    fn may_yield(&self) -> bool;
    /// Abandons its exchange (the line owes the reply and fences).
    fn yield_line(&mut self, line: &mut Line, now: u32);
    /// Starts or drives its exchange: reads from and writes to `down`;
    /// `Ok(moved)`.
    fn run<D: Port>(&mut self, line: &mut Line, down: &mut D, now: u32) -> Result<bool, D::Error>;
    /// What it waits for.
    fn wait(&self, now: u32) -> GuestWait;
}

/// What a [`Guest`] waits for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GuestWait {
    /// Poll again by this tick.
    pub deadline: Option<u32>,
    /// Its transmission waits for room downstream.
    pub down_write: bool,
}

/// No guest: the bridge alone.
pub struct NoGuest;

impl Guest for NoGuest {
    fn holds_line(&self) -> bool {
        false
    }
    fn wants_line(&self, _now: u32) -> bool {
        false
    }
    fn may_yield(&self) -> bool {
        true
    }
    fn yield_line(&mut self, _line: &mut Line, _now: u32) {}
    fn run<D: Port>(&mut self, _l: &mut Line, _d: &mut D, _now: u32) -> Result<bool, D::Error> {
        Ok(false)
    }
    fn wait(&self, _now: u32) -> GuestWait {
        GuestWait::default()
    }
}

/// A port with nothing attached: reads nothing, takes every byte (the
/// protocol-B upstream of a two-UART board whose one upstream port speaks
/// Modbus).
pub struct NoPort;

impl embedded_io::ErrorType for NoPort {
    type Error = core::convert::Infallible;
}
impl embedded_io::ReadReady for NoPort {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(false)
    }
}
impl embedded_io::Read for NoPort {
    fn read(&mut self, _buf: &mut [u8]) -> Result<usize, Self::Error> {
        Ok(0)
    }
}
impl embedded_io::WriteReady for NoPort {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(true)
    }
}
impl embedded_io::Write for NoPort {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
impl Port for NoPort {}

/// The 26DH transfer: records from the upstream decoder through a bounded
/// queue to controller-sized commands.
type Job = Transfer<RecordBuffer<QUEUE_BYTES>>;

/// Where the bridge is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Hunting for a header byte upstream.
    Idle,
    /// Collecting the envelope (header, station, ID) of an upstream frame.
    Head,
    /// Feeding an upstream command (not 26DH) to the frame decoder.
    Command,
    /// Skipping a command to its end; at a valid end answer `answer`.
    Skip { answer: Option<u16> },
    /// The decoded command is relayed downstream (after a fence, if the
    /// line asks for one) and its reply awaited.
    Forward,
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

/// The bridge's state: about 5 KiB; keep it in a static. It holds no port
/// and no clock.
pub struct Bridge {
    cfg: Config,
    source: Source,
    mode: Mode,
    up: Upstream,
    /// The downstream line: the command on it and what may still arrive.
    line: Line,
    /// The 26DH transfer, built once and restarted in place for each 26DH.
    /// Between 26DHs its frame buffer is the pass-through's decoder.
    job: Job,
    /// The pass-through's exchange, run in the job's frame buffer.
    relay: Relay,
    /// Where the transmission downstream stands.
    driver: Driver,
    /// A 26DH's upstream side.
    stream: StreamWork,
    /// Bytes of the current outgoing frame already written.
    out_off: usize,
    /// The 26DH transfer's next deadline and whether a frame waits for
    /// room downstream.
    stream_deadline: Option<u32>,
    tx_blocked: bool,
    resp: [u8; RESPONSE_CAP],
    resp_len: usize,
    stats: Stats,
    last_error: Option<LastError>,
    /// A host command decoded and waiting for the line (the guest still
    /// holds it): its ID.
    forward_pending: Option<u16>,
    /// The guest holds the line in this poll: the bridge's own paths
    /// leave the downstream alone.
    guest_holds: bool,
    /// Since when the host's XOFF holds the upstream transmitter.
    xoff_since: Option<u32>,
    /// The configuration page's writes, if the board keeps a page it can
    /// write (the configuration messages, see `upstream`).
    editor: Option<&'static mut Editor<'static>>,
    /// The last frames through the bridge.
    history: history::History,
}

/// The line to the controller for `cfg`.
const fn line_config(cfg: &Config) -> LineConfig {
    LineConfig::new(cfg.controller_station).with_duplicate_window(cfg.duplicate_window_ms)
}

impl Bridge {
    /// An idle bridge with this configuration (`source` says where it came
    /// from, for the status query). `seed` makes the downstream line's
    /// fence texts its own: give a different one at each boot.
    #[inline(always)]
    pub fn new(cfg: Config, source: Source, seed: u32) -> Self {
        Self {
            cfg,
            source,
            mode: Mode::Idle,
            up: Upstream::new(),
            line: Line::new(line_config(&cfg), seed),
            job: Transfer::new(TransferConfig::new(Profile::TTA), RecordBuffer::new()),
            relay: Relay::new(),
            driver: Driver::new(),
            stream: StreamWork::new(cfg.downstream_baud),
            out_off: 0,
            stream_deadline: None,
            tx_blocked: false,
            resp: [0; RESPONSE_CAP],
            resp_len: 0,
            stats: Stats::default(),
            last_error: None,
            forward_pending: None,
            guest_holds: false,
            xoff_since: None,
            editor: None,
            history: history::History::new(),
        }
    }

    /// Answers the configuration messages with `editor` (see
    /// [`crate::config::wire`]); without one they are refused
    /// [`crate::codes::STORE_FAILED`].
    pub fn attach_editor(&mut self, editor: &'static mut Editor<'static>) {
        self.editor = Some(editor);
    }

    /// The configuration page's writes, if attached.
    pub fn editor(&mut self) -> Option<&mut Editor<'static>> {
        self.editor.as_deref_mut()
    }

    /// The last frames through the bridge.
    pub fn history(&self) -> &history::History {
        &self.history
    }

    /// Records `frame` in the history, as the bridge does (the web page's
    /// tests only).
    #[cfg(all(test, feature = "ethernet"))]
    pub(crate) fn history_for_tests(&mut self, frame: &[u8], now: u32) {
        self.history
            .record(history::Dir::FromHost, frame, frame.len(), now);
    }

    /// Sets the configuration (at start, before the first [`Bridge::poll`]):
    /// lets a board build the bridge before its configuration is read.
    pub fn configure(&mut self, cfg: Config, source: Source) {
        self.cfg = cfg;
        self.source = source;
        self.line.set_config(line_config(&cfg));
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

    /// The downstream line's counters (fences, timeouts, stale replies).
    pub fn line_stats(&self) -> iai_protocol_b::line::LineStats {
        self.line.stats()
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
        self.poll_with(up, down, &mut NoGuest, now)
    }

    /// [`Bridge::poll`] with a second user of the controller line, granted
    /// the line as [`Guest`] says.
    pub fn poll_with<U: Port, D: Port, G: Guest>(
        &mut self,
        up: &mut U,
        down: &mut D,
        guest: &mut G,
        now: u32,
    ) -> Result<Poll, Error<U::Error, D::Error>> {
        let xoff_until = self.watch_xoff(up, now);
        let mut guest_moved = false;
        let host_waits = self.forward_pending.is_some() || matches!(self.mode, Mode::Stream { .. });
        if host_waits && guest.holds_line() && guest.may_yield() {
            guest.yield_line(&mut self.line, now);
            guest_moved = true;
        }
        let host_busy = matches!(self.mode, Mode::Forward | Mode::Stream { .. });
        if guest.holds_line() || (!host_busy && guest.wants_line(now)) {
            guest_moved |= guest
                .run(&mut self.line, down, now)
                .map_err(Error::Downstream)?;
        }
        self.guest_holds = guest.holds_line();
        let lost = down.take_overruns();
        if lost > 0 {
            self.stats.downstream_overruns = self.stats.downstream_overruns.wrapping_add(lost);
            if self.mode == Mode::Forward && self.line.awaiting() {
                // The reply being decoded lost bytes: start again.
                self.job.idle_decoder().reset();
            }
        }
        let moved = match self.mode {
            Mode::Idle | Mode::Head | Mode::Command | Mode::Skip { .. } => {
                match self.poll_upstream(up, down, now)? {
                    upstream::Read::Quit => return Ok(Poll::Quit),
                    upstream::Read::Moved(moved) => moved,
                }
            }
            Mode::Forward | Mode::RelayReply => self.poll_passthrough(up, down, now)?,
            Mode::Stream { .. } => self.poll_stream(up, down, now)?,
            Mode::Respond => self.poll_respond(up, now).map_err(Error::Upstream)?,
        };
        Ok(if moved || guest_moved {
            Poll::Busy
        } else {
            let mut w = self.wait(now);
            w.deadline = earliest(now, w.deadline, xoff_until);
            let g = guest.wait(now);
            if self.guest_holds {
                w.interest.down_read = true;
                w.interest.down_write |= g.down_write;
                w.deadline = earliest(now, w.deadline, g.deadline);
            } else if !host_busy {
                w.deadline = earliest(now, w.deadline, g.deadline);
            }
            Poll::Wait(w)
        })
    }

    /// Lets the host's XOFF hold the upstream transmitter at most
    /// [`Config::xoff_hold_ms`]: an XOFF that line noise made, or a host
    /// that never sends XON, must not silence the bridge for good. The
    /// tick by which to look again while it holds.
    fn watch_xoff<U: Port>(&mut self, up: &mut U, now: u32) -> Option<u32> {
        if !up.peer_stopped() {
            self.xoff_since = None;
            return None;
        }
        let since = *self.xoff_since.get_or_insert(now);
        let until = since.wrapping_add(self.cfg.xoff_hold_ms);
        if iai_protocol_b::clock::reached(now, until) {
            log::warning!("XOFF from the host held the transmitter too long: let go");
            up.release_peer_stop();
            self.stats.xoff_released = self.stats.xoff_released.wrapping_add(1);
            self.xoff_since = None;
            return None;
        }
        Some(until)
    }

    /// What the bridge waits for in its current mode.
    fn wait(&mut self, now: u32) -> Wait {
        let only = |i: Interest| i;
        let (deadline, reason, interest) = match self.mode {
            Mode::Idle | Mode::Head | Mode::Command | Mode::Skip { .. } => (
                None,
                Reason::Host,
                Interest {
                    up_read: true,
                    down_read: true,
                    ..Interest::default()
                },
            ),
            Mode::Forward if self.forward_pending.is_some() || self.guest_holds => (
                None,
                Reason::Controller,
                Interest {
                    down_read: true,
                    ..Interest::default()
                },
            ),
            Mode::Forward => (
                self.stream_deadline,
                if self.tx_blocked {
                    Reason::ControllerRoom
                } else {
                    Reason::Controller
                },
                only(Interest {
                    down_read: true,
                    down_write: self.tx_blocked,
                    ..Interest::default()
                }),
            ),
            Mode::RelayReply | Mode::Respond => (
                None,
                Reason::HostRoom,
                only(Interest {
                    up_write: true,
                    ..Interest::default()
                }),
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

    /// Back to hunting for a frame upstream.
    fn go_idle(&mut self) {
        self.mode = Mode::Idle;
        self.forward_pending = None;
        self.out_off = 0;
        self.up.head_len = 0;
        self.stream_deadline = None;
        self.tx_blocked = false;
        // The job's frame buffer is the decoder's again (a 26DH restarts
        // the job before it polls it).
        self.stream.started = false;
        let frames = self.job.idle_decoder();
        frames.reset();
        frames.set_policy(BypassPolicy::CommandsOnly);
    }

    /// Lets the line hear whatever the controller sends while no command
    /// is on it (late replies, copies, noise): placed or noticed by the
    /// line, never dropped unread.
    fn drain_downstream<D: Port>(&mut self, down: &mut D, now: u32) -> Result<bool, D::Error> {
        if self.guest_holds {
            // The bytes are the guest's.
            return Ok(false);
        }
        let (din, dout) = (
            &mut self.stats.downstream_in,
            &mut self.stats.downstream_out,
        );
        let mut port = Counted::new(down, din, dout);
        let mut clock = || now;
        self.driver.listen(&mut self.line, &mut port, &mut clock)
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
pub(crate) fn write_some<W: Write + WriteReady>(
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
mod tests;
