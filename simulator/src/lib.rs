//! A controller simulator: the controller's side of protocol B, built on
//! the core, with a position table, a model of each axis and faults
//! injected on demand. It answers what it models (see
//! [`Controller::execute`]) and refuses every other message. It needs
//! only the core, so a test can put a controller on a port without the
//! `iai` tool (which runs it as `iai simulate`).
//!
//! - [`Controller`]: what a controller remembers (position table, axes,
//!   counters) and how it answers a command; it persists across
//!   connections, as a real controller's memory does.
//! - [`Session`]: what belongs to one connection (the frame decoder,
//!   replies not yet sent, the fault draws) and when its replies are due.
//! - [`Simulator`]: one of each, sans-IO, for tests that drive one link.
//! - [`server`]: many connections on one shared controller (TCP, a
//!   pseudo-terminal, or one connection it makes itself).
//!
//! Like the controller (manual p. 9), it does not answer a command it could
//! not receive: bad checksum, broken frame, or longer than its buffer.
//!
//! ```no_run
//! use std::net::TcpListener;
//! use iai_protocol_b::frame::Station;
//! use iai_simulator::server::{parse_faults, serve_tcp, ServeOptions, Shared};
//! use iai_simulator::Controller;
//!
//! let listener = TcpListener::bind("127.0.0.1:0")?;
//! println!("controller at {}", listener.local_addr()?);
//! let shared = Shared::new(Controller::tta(Station(0x99)));
//! let opts = ServeOptions {
//!     faults: parse_faults("drop=0.01")?,
//!     seed: 1,
//!     log_frames: false,
//! };
//! serve_tcp(listener, shared, opts)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod axis;
mod controller;
mod io;
pub mod server;

pub use axis::{Axis, Home};
pub use controller::Controller;
pub use io::Io;

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::position::PositionStream;

/// Error code the simulator sends when it injects an error response.
pub const INJECTED_ERROR_CODE: u16 = 0x0E1;
/// Error code for a command whose body does not fit its layout, whose ID
/// is not in the catalogue, or that the profile does not know.
pub const UNSUPPORTED_ERROR_CODE: u16 = 0x0E2;
/// Refusal: a catalogue message the simulator does not model (simulator's
/// own code; see the module docs).
pub const NOT_MODELLED_CODE: u16 = 0x0E3;
/// Refusal: the servo of an axis concerned is off (simulator's own code).
pub const SERVO_OFF_CODE: u16 = 0x0E4;
/// Refusal: a coordinate move before homing (simulator's own code).
pub const NOT_HOMED_CODE: u16 = 0x0E5;
/// Refusal: the axis is still moving or homing (simulator's own code).
pub const AXIS_BUSY_CODE: u16 = 0x0E6;
/// Refusal: 237H/26BH to an undefined position (simulator's own code).
pub const NO_POSITION_CODE: u16 = 0x0E7;

/// The simulated controller's delay before each reply (its α), ms.
pub const REPLY_DELAY_MS: u32 = 2;

/// Speed used when a command and its record give 0, mm/s.
pub const DEFAULT_SPEED: u16 = 100;
/// Acceleration and deceleration used when a command gives 0, 0.01 G.
pub const DEFAULT_ACC: u16 = 30;
/// Homing: time spent creeping onto the home position after the travel, ms.
pub const HOME_CREEP_MS: u32 = 100;
/// Jogging stops at ± this coordinate, 0.001 mm.
pub const SOFT_LIMIT: i32 = 9_999_999;

/// Faults to inject. Probabilities are per byte, per command or per reply.
#[derive(Debug, Clone, Default)]
pub struct Faults {
    /// Chance that a received byte has one bit flipped.
    pub flip_bit_in: f64,
    /// Chance that a received byte is lost.
    pub drop_byte_in: f64,
    /// Chance that a sent byte has one bit flipped.
    pub flip_bit_out: f64,
    /// Every n-th reply is not sent at all.
    pub drop_every_nth_reply: Option<u32>,
    /// Every n-th reply is sent late, after this many ms; the replies after
    /// it wait for it.
    pub late_every_nth_reply: Option<(u32, u32)>,
    /// Chance that a command gets an `&` error response instead of its reply.
    pub error_reply: f64,
    /// Chance that noise bytes precede a reply.
    pub garbage_before_reply: f64,
    /// Chance that a reply is not sent at all.
    pub drop_reply: f64,
    /// Chance that a reply is sent this many ms after its command (past
    /// the host's timeout, so that it meets the resend); the replies after
    /// it wait for it.
    pub late_reply: Option<(f64, u32)>,
    /// Chance that a reply is sent a second time, this many ms after the
    /// first (an echoing converter, a late copy); replies to later commands
    /// may come before the copy.
    pub dup_reply: Option<(f64, u32)>,
    /// The controller stops answering anything once this many position
    /// records were written (it hangs in the middle of a table).
    pub stop_after_records: Option<u64>,
    /// The controller stops answering anything after this many commands.
    pub stop_after_commands: Option<u32>,
    /// Chance, per position-write command, that one stored record differs
    /// from the one sent: two adjacent digits of one of its coordinates
    /// swapped, as a line fault that keeps the checksum valid would. The
    /// reply confirms the write; only reading back finds it.
    pub swap_record: f64,
}

/// What the simulator counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Valid commands received.
    pub commands: u32,
    /// Replies sent (normal and error).
    pub replies: u32,
    /// Replies withheld by fault injection.
    pub dropped_replies: u32,
    /// Replies delayed by fault injection.
    pub late_replies: u32,
    /// Replies sent twice by fault injection.
    pub duplicated_replies: u32,
    /// Error responses injected.
    pub injected_errors: u32,
    /// Records stored with swapped digits.
    pub swapped_records: u32,
    /// Broken frames received (not answered).
    pub broken_frames: u32,
    /// Frames over the receive limit (not answered).
    pub oversize_frames: u32,
    /// Bytes received / sent.
    pub bytes_in: u64,
    /// Bytes sent.
    pub bytes_out: u64,
    /// Position records written.
    pub records_written: u64,
}

/// Deterministic xorshift generator (tests must be reproducible).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }
    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }
    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

/// One connection's state: decoder, replies waiting to go out, faults.
///
/// # Reply timing and order
/// A reply is due [`Controller::response_delay_ms`] after its command. A
/// real controller answers its commands one at a time, in the order it
/// received them, so late replies keep their order: a reply made late by
/// [`Faults::late_reply`] or [`Faults::late_every_nth_reply`] delays every
/// reply scheduled after it (no reply is due before one scheduled
/// earlier). Copies may come after later replies: a [`Faults::dup_reply`]
/// copy stands for an echoing converter on the line repeating a frame, and
/// arrives its delay after the original whatever was answered meanwhile.
/// A caller whose clock goes back (a command at a tick before the last
/// one's) starts a new time base: replies pending from before hold no new
/// one back.
pub struct Session {
    decoder: Box<FrameDecoder<4096>>,
    /// Replies (and copies) with the tick each is due at.
    outbox: Vec<(u32, Vec<u8>)>,
    rng: Rng,
    reply_no: u32,
    /// Tick the last reply (not copy) was scheduled for: no later reply is
    /// due before it.
    last_due: u32,
    /// Tick of the last command answered (to see the caller's clock
    /// restart).
    last_command_at: u32,
    stats: SimStats,
}

impl Session {
    /// A fresh connection with this fault seed.
    pub fn new(seed: u64) -> Self {
        Session {
            decoder: Box::new(FrameDecoder::with_policy(BypassPolicy::CommandsOnly)),
            outbox: Vec::new(),
            rng: Rng::new(seed),
            reply_no: 0,
            last_due: 0,
            last_command_at: 0,
            stats: SimStats::default(),
        }
    }

    /// Counters of this connection.
    pub fn stats(&self) -> SimStats {
        self.stats
    }

    /// Tick at which the next reply byte is due, if any.
    pub fn next_output_at(&self) -> Option<u32> {
        self.outbox.iter().map(|(t, _)| *t).min()
    }

    /// Reply bytes due by `now`, in order (replies due at the same tick
    /// in the order they were scheduled).
    pub fn take_output(&mut self, now: u32) -> Vec<u8> {
        // A stable sort: equal ticks keep their scheduling order.
        self.outbox.sort_by_key(|(t, _)| *t);
        let due = self.outbox.iter().take_while(|(t, _)| *t <= now).count();
        let out: Vec<u8> = self.outbox.drain(..due).flat_map(|(_, b)| b).collect();
        self.stats.bytes_out += out.len() as u64;
        out
    }

    /// Bytes from the host at `now`, executed on `ctl`.
    pub fn receive(&mut self, ctl: &mut Controller, faults: &Faults, bytes: &[u8], now: u32) {
        for &b in bytes {
            self.stats.bytes_in += 1;
            if self.rng.chance(faults.drop_byte_in) {
                continue;
            }
            let b = if self.rng.chance(faults.flip_bit_in) {
                b ^ (1 << self.rng.below(8))
            } else {
                b
            };
            let cmd = match self.decoder.push(b) {
                Status::Partial => None,
                Status::Complete(Event::Error(e)) => {
                    if matches!(e, iai_protocol_b::error::Error::FrameTooLong { .. }) {
                        self.stats.oversize_frames += 1;
                    } else {
                        self.stats.broken_frames += 1;
                    }
                    None
                }
                Status::Complete(Event::Frame(f)) => {
                    let f: Frame<'_> = f;
                    if f.len() > ctl.max_receive {
                        self.stats.oversize_frames += 1;
                        None
                    } else if f.header() != Header::Command || f.station() != ctl.station {
                        None
                    } else {
                        // Copy out: the frame borrows the decoder.
                        Some(f.as_bytes().to_vec())
                    }
                }
            };
            let Some(cmd) = cmd else { continue };
            if faults
                .stop_after_records
                .is_some_and(|n| ctl.records_written >= n)
                || faults
                    .stop_after_commands
                    .is_some_and(|n| self.stats.commands >= n)
            {
                // Hung: nothing is executed or answered any more.
                continue;
            }
            self.stats.commands += 1;
            let Ok(frame) = Frame::new_checked(&cmd, BypassPolicy::CommandsOnly) else {
                continue;
            };
            let is_write = PositionStream::find(Header::Command, frame.code()).is_some();
            let swap = if is_write && self.rng.chance(faults.swap_record) {
                self.stats.swapped_records += 1;
                Some(&mut self.rng)
            } else {
                None
            };
            let before = ctl.records_written;
            let out = ctl.execute(&frame, now, swap);
            self.stats.records_written += ctl.records_written - before;
            self.schedule(ctl, faults, out, now);
        }
    }

    /// Queues `reply` to the command received at `now`, with the faults
    /// drawn for it. Replies keep their order; copies need not (see "Reply
    /// timing and order" above).
    fn schedule(&mut self, ctl: &Controller, faults: &Faults, reply: Option<Vec<u8>>, now: u32) {
        let Some(mut reply) = reply else { return };
        self.reply_no += 1;
        let n = self.reply_no;
        if faults
            .drop_every_nth_reply
            .is_some_and(|k| n.is_multiple_of(k))
            || self.rng.chance(faults.drop_reply)
        {
            self.stats.dropped_replies += 1;
            return;
        }
        if self.rng.chance(faults.error_reply) {
            self.stats.injected_errors += 1;
            reply = ctl.error_frame(INJECTED_ERROR_CODE);
        }
        for b in reply.iter_mut() {
            if self.rng.chance(faults.flip_bit_out) {
                *b ^= 1 << self.rng.below(8);
            }
        }
        if self.rng.chance(faults.garbage_before_reply) {
            let noise: Vec<u8> = (0..1 + self.rng.below(12))
                .map(|_| b"xyz\r\n0123?"[self.rng.below(10) as usize])
                .collect();
            reply.splice(0..0, noise);
        }
        let mut at = now.wrapping_add(ctl.response_delay_ms);
        if let Some((k, late)) = faults.late_every_nth_reply {
            if n.is_multiple_of(k) {
                self.stats.late_replies += 1;
                at = now.wrapping_add(late);
            }
        }
        if let Some((p, late)) = faults.late_reply {
            if self.rng.chance(p) {
                self.stats.late_replies += 1;
                at = now.wrapping_add(late);
            }
        }
        // In order: not before a reply scheduled earlier, late or not. A
        // caller whose clock went back started a new time base: what was
        // scheduled on the old one holds nothing back.
        if now < self.last_command_at {
            self.last_due = 0;
        }
        self.last_command_at = now;
        at = at.max(self.last_due);
        self.last_due = at;
        let copy = match faults.dup_reply {
            Some((p, later)) if self.rng.chance(p) => {
                self.stats.duplicated_replies += 1;
                Some((at.wrapping_add(later), reply.clone()))
            }
            _ => None,
        };
        self.stats.replies += 1;
        self.outbox.push((at, reply));
        // A copy keeps its own time: later replies may come before it.
        self.outbox.extend(copy);
    }
}

/// A controller with one connection: the simulator for single-link tests.
/// Derefs to its [`Controller`] (`sim.table`, `sim.station`, …).
///
/// It is sans-IO: bytes from the host go in with [`Simulator::receive`],
/// reply bytes come out of [`Simulator::take_output`] once their time has
/// come. Time is a millisecond tick supplied by the caller, so a test runs
/// a 1.6 MB transfer with 3-second timeouts in a fraction of a second, and
/// watches a move take the time its distance and speed imply.
pub struct Simulator {
    /// Faults to inject.
    pub faults: Faults,
    ctl: Controller,
    session: Session,
}

impl std::ops::Deref for Simulator {
    type Target = Controller;
    fn deref(&self) -> &Controller {
        &self.ctl
    }
}

impl std::ops::DerefMut for Simulator {
    fn deref_mut(&mut self) -> &mut Controller {
        &mut self.ctl
    }
}

impl Simulator {
    /// A simulator around `ctl`, no faults.
    pub fn new(ctl: Controller) -> Self {
        Simulator {
            faults: Faults::default(),
            ctl,
            session: Session::new(1),
        }
    }

    /// A TTA at `station`, no faults.
    pub fn tta(station: Station) -> Self {
        Self::new(Controller::tta(station))
    }

    /// A 2003-generation X-SEL, no faults.
    pub fn xsel_2003(station: Station) -> Self {
        Self::new(Controller::xsel_2003(station))
    }

    /// With these faults and this random seed.
    pub fn with_faults(mut self, faults: Faults, seed: u64) -> Self {
        self.faults = faults;
        self.session.rng = Rng::new(seed);
        self
    }

    /// The controller.
    pub fn controller(&self) -> &Controller {
        &self.ctl
    }

    /// Counters so far.
    pub fn stats(&self) -> SimStats {
        self.session.stats
    }

    /// Tick at which the next reply byte is due, if any.
    pub fn next_output_at(&self) -> Option<u32> {
        self.session.next_output_at()
    }

    /// Reply bytes due by `now`, in order.
    pub fn take_output(&mut self, now: u32) -> Vec<u8> {
        self.session.take_output(now)
    }

    /// Bytes from the host at `now`.
    pub fn receive(&mut self, bytes: &[u8], now: u32) {
        self.session
            .receive(&mut self.ctl, &self.faults, bytes, now);
    }

    /// Whether the controller has stopped (see [`Faults::stop_after_records`]).
    pub fn stopped(&self) -> bool {
        self.faults
            .stop_after_records
            .is_some_and(|n| self.ctl.records_written >= n)
            || self
                .faults
                .stop_after_commands
                .is_some_and(|n| self.session.stats.commands >= n)
    }

    /// A new connection: partial frames and pending replies are dropped,
    /// the controller's memory stays.
    pub fn reconnect(&mut self) {
        let seed = self.session.rng.next_u64();
        self.session = Session::new(seed);
    }
}

/// What passed over a served connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Traffic<'a> {
    /// Bytes from the host.
    Received(&'a [u8]),
    /// Bytes the simulator sent.
    Sent(&'a [u8]),
    /// The host closed the connection.
    Closed,
}

/// Serves the simulator on a TCP stream with real time until the peer
/// closes the connection.
pub fn serve_tcp(sim: &mut Simulator, stream: std::net::TcpStream) -> std::io::Result<()> {
    serve_tcp_observed(sim, stream, |_| Ok(()))
}

/// Like [`serve_tcp`], showing every read and write to `observe`.
pub fn serve_tcp_observed(
    sim: &mut Simulator,
    mut stream: std::net::TcpStream,
    mut observe: impl FnMut(Traffic<'_>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    use std::io::{Read, Write};
    let t0 = std::time::Instant::now();
    let now = || u32::try_from(t0.elapsed().as_millis()).unwrap_or(u32::MAX);
    stream.set_read_timeout(Some(std::time::Duration::from_millis(1)))?;
    stream.set_nodelay(true)?;
    let mut buf = [0u8; 4096];
    loop {
        match stream.read(&mut buf) {
            Ok(0) => return observe(Traffic::Closed),
            Ok(n) => {
                sim.receive(&buf[..n], now());
                observe(Traffic::Received(&buf[..n]))?;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => return Err(e),
        }
        let out = sim.take_output(now());
        if !out.is_empty() {
            stream.write_all(&out)?;
            observe(Traffic::Sent(&out))?;
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use iai_protocol_b::axis::AxisPattern;
    use iai_protocol_b::field::Writer;
    use iai_protocol_b::frame::{emit_envelope, emit_trailer};
    use iai_protocol_b::message::{
        AbsoluteMove, AxisStatusQuery, AxisStatusResponse, HomeReturn, Message, OperationStop,
        ServoOnOff,
    };
    use iai_protocol_b::position::PositionRecord;

    const ST: Station = Station(0x99);

    fn send<'a, M: Message<'a>>(sim: &mut Simulator, msg: &M, now: u32) -> Vec<u8> {
        let mut buf = [0u8; 128];
        let n = msg.emit(ST, &mut buf).unwrap();
        sim.receive(&buf[..n], now);
        sim.take_output(now + 1000)
    }

    fn status(sim: &mut Simulator, now: u32) -> (u8, i32) {
        let q = AxisStatusQuery {
            query_axis_pattern: AxisPattern::first(1),
        };
        let reply = send(sim, &q, now);
        let f = Frame::new_checked(&reply, BypassPolicy::Reject).unwrap();
        let r = AxisStatusResponse::parse(&f).unwrap();
        let a = r.axes.first().unwrap();
        (a.axis_status, a.current_position)
    }

    fn error_code(reply: &[u8]) -> Option<u16> {
        let f = Frame::new_checked(reply, BypassPolicy::Reject).ok()?;
        (f.header() == Header::Error).then(|| f.code())
    }

    fn move_to(to: i32, speed: u16) -> AbsoluteMove {
        let mut c = AbsoluteMove {
            axis_pattern: AxisPattern::first(1),
            acceleration: 30,
            deceleration: 30,
            speed,
            ..AbsoluteMove::default()
        };
        c.absolute_coordinate.push(to).unwrap();
        c
    }

    #[test]
    fn a_move_takes_the_time_its_profile_implies() {
        let mut sim = Simulator::tta(ST);
        sim.refuse = true;
        let one = AxisPattern::first(1);
        // Refused before servo on and before homing.
        let r = send(&mut sim, &move_to(50_000, 100), 0);
        assert_eq!(error_code(&r), Some(SERVO_OFF_CODE));
        let servo = ServoOnOff {
            axis_pattern: one,
            operation_type: 1,
        };
        assert_eq!(error_code(&send(&mut sim, &servo, 0)), None);
        let r = send(&mut sim, &move_to(50_000, 100), 0);
        assert_eq!(error_code(&r), Some(NOT_HOMED_CODE));
        let home = HomeReturn {
            axis_pattern: one,
            ..HomeReturn::default()
        };
        send(&mut sim, &home, 10);
        assert_eq!(status(&mut sim, 20).0 & 0b111, 0b011, "in use, homing");
        // Completed, servo on, homed (bits 4, 3, 1-2 = 2).
        assert_eq!(status(&mut sim, 10 + HOME_CREEP_MS + 1).0, 0x1C);
        // 50 mm at 100 mm/s, 0.3 G: 0.034 s ramps, about 534 ms in all.
        let t0 = 1_000;
        assert_eq!(error_code(&send(&mut sim, &move_to(50_000, 100), t0)), None);
        let (st, mid) = status(&mut sim, t0 + 250);
        assert_eq!(st & 1, 1, "in use while moving");
        assert!((20_000..30_000).contains(&mid), "{mid}");
        let r = send(&mut sim, &move_to(0, 100), t0 + 260);
        assert_eq!(error_code(&r), Some(AXIS_BUSY_CODE));
        assert_eq!(
            status(&mut sim, t0 + 520).0 & 1,
            1,
            "still moving at 520 ms"
        );
        let (st, end) = status(&mut sim, t0 + 540);
        assert_eq!((st & 1, st & 0x10, end), (0, 0x10, 50_000));
        // Stop half-way: no completion bit, position kept.
        let t1 = 2_000;
        send(&mut sim, &move_to(0, 100), t1);
        let stop = OperationStop {
            stop_axis_pattern: one,
            appended_command_byte: 0,
        };
        send(&mut sim, &stop, t1 + 200);
        let (st, at) = status(&mut sim, t1 + 5_000);
        assert_eq!(st & 0x11, 0);
        assert!((20_000..35_000).contains(&at), "{at}");
    }

    #[test]
    fn a_range_write_past_ffff_is_refused_not_wrapped() {
        let mut sim = Simulator::tta(ST);
        // 290H: start FFFF, two records.
        let rec = PositionRecord::new(0, 1, 1, 1, &[(1, 5)]).unwrap();
        let kind = PositionStream::RANGE_3;
        let mut buf = vec![0u8; 256];
        let mut w = Writer::new(&mut buf);
        emit_envelope(&mut w, Header::Command, ST, kind.id).unwrap();
        kind.write_prefix(&mut w, 0xFFFF, 2).unwrap();
        kind.layout.write_record(&rec, &mut w).unwrap();
        kind.layout.write_record(&rec, &mut w).unwrap();
        emit_trailer(&mut w, Default::default()).unwrap();
        let frame = w.written().to_vec();
        sim.receive(&frame, 0);
        let out = sim.take_output(100);
        assert_eq!(error_code(&out), Some(UNSUPPORTED_ERROR_CODE));
        assert!(sim.table.is_empty());
    }

    #[test]
    fn a_new_connection_starts_clean_and_keeps_memory() {
        let mut sim = Simulator::tta(ST);
        sim.table
            .insert(3, PositionRecord::new(3, 1, 1, 1, &[(1, 5)]).unwrap());
        // Half a frame, then the connection goes.
        sim.receive(b"!99212", 0);
        sim.reconnect();
        let q = AxisStatusQuery {
            query_axis_pattern: AxisPattern::first(1),
        };
        let reply = send(&mut sim, &q, 10);
        assert!(reply.starts_with(b"#99212"), "{reply:?}");
        assert_eq!(sim.table.len(), 1);
    }

    const FIRST: &[u8] = b"!99200first-late20\r\n";
    const FIRST_REPLY: &[u8] = b"#99200first-late22\r\n";
    const NEXT: &[u8] = b"!99200then-next!E1\r\n";
    const NEXT_REPLY: &[u8] = b"#99200then-next!E3\r\n";

    #[test]
    fn a_late_reply_holds_back_the_replies_after_it() {
        let mut sim = Simulator::tta(ST);
        sim.faults.late_reply = Some((1.0, 500));
        sim.receive(FIRST, 0);
        sim.faults = Faults::default();
        sim.receive(NEXT, 10);
        // The second reply would be due at 12; it waits for the first.
        assert_eq!(sim.next_output_at(), Some(500));
        assert!(sim.take_output(499).is_empty());
        assert_eq!(sim.take_output(500), [FIRST_REPLY, NEXT_REPLY].concat());
        assert_eq!(sim.stats().late_replies, 1);
    }

    #[test]
    fn a_copy_may_come_after_later_replies() {
        let mut sim = Simulator::tta(ST);
        // The first reply late and copied 300 ms after it.
        sim.faults.late_reply = Some((1.0, 500));
        sim.faults.dup_reply = Some((1.0, 300));
        sim.receive(FIRST, 0);
        sim.faults = Faults::default();
        sim.receive(NEXT, 10);
        assert_eq!(sim.take_output(500), [FIRST_REPLY, NEXT_REPLY].concat());
        assert_eq!(sim.next_output_at(), Some(800));
        assert_eq!(sim.take_output(800), FIRST_REPLY);
        // Without lateness the copy still comes after the next reply.
        let mut sim = Simulator::tta(ST);
        sim.faults.dup_reply = Some((1.0, 300));
        sim.receive(FIRST, 0);
        sim.faults = Faults::default();
        sim.receive(NEXT, 10);
        assert_eq!(
            sim.take_output(1_000),
            [FIRST_REPLY, NEXT_REPLY, FIRST_REPLY].concat()
        );
        assert_eq!(sim.stats().duplicated_replies, 1);
    }

    #[test]
    fn a_clock_that_restarts_starts_a_new_order() {
        // One run ends at 20 s with a late reply still pending; the next
        // run's clock starts again at 0.
        let mut sim = Simulator::tta(ST);
        sim.receive(NEXT, 19_000);
        sim.faults.late_reply = Some((1.0, 5_000));
        sim.receive(FIRST, 20_000);
        assert_eq!(sim.take_output(20_000), NEXT_REPLY);
        sim.faults = Faults::default();
        sim.receive(NEXT, 10);
        assert_eq!(sim.take_output(12), NEXT_REPLY);
        assert_eq!(sim.take_output(25_000), FIRST_REPLY);
    }
}
