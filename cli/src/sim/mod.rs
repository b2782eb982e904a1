//! A controller simulator: the controller's side of protocol B, built on
//! the core, with a position table, a model of each axis and faults
//! injected on demand.
//!
//! Two parts:
//! - [`Controller`]: what a controller remembers (position table, axes,
//!   counters). It persists across connections, as a real controller's
//!   memory does.
//! - [`Session`]: what belongs to one connection (the frame decoder, replies
//!   not yet sent, the fault generator).
//!
//! [`Simulator`] is one of each, for tests that drive a single link. It is
//! sans-IO: bytes from the host go in with [`Simulator::receive`], reply
//! bytes come out of [`Simulator::take_output`] once their time has come.
//! Time is a millisecond tick supplied by the caller, so tests can run a
//! 1.6 MB transfer with 3-second timeouts in a fraction of a second of real
//! time, and watch a move take the time its distance and speed imply.
//! [`serve_tcp`] puts a simulator on a socket; [`crate::simulate`] serves
//! many connections on one shared controller.
//!
//! Like the controller (manual p. 9), it does not answer a command it could
//! not receive: bad checksum, broken frame, or one longer than the
//! profile's receive buffer.
//!
//! # Axis model
//! Eight axes, all connected, servo off and not homed at start, at 0.
//! - 232H switches the servo; switching it off stops a move.
//! - 233H homes: the axis travels to 0 at the end-search speed, then creeps
//!   for [`HOME_CREEP_MS`]; bits 1-2 of the 212H status read 1 meanwhile,
//!   2 after.
//! - 234H / 235H / 237H / 26BH move to a coordinate, 236H jogs (to the soft
//!   limit [`SOFT_LIMIT`]) or inches. A move follows a trapezoidal speed
//!   profile from its acceleration, speed and deceleration (0 G = 9,806.65
//!   mm/s² × the value / 100); zero values take the record's values (237H),
//!   then the simulator's parameters [`DEFAULT_SPEED`], [`DEFAULT_ACC`].
//! - 238H stops the axes at their current position.
//! - 212H reports bit 0 (in use) while an axis moves or homes, bits 1-2
//!   (homing), bit 3 (servo), bit 4 (last operation completed normally),
//!   and the position at the time of the query. 215H reports AUTO mode,
//!   no system error, "operating in AUTO" and "system ready"; it has no
//!   field for motion.
//!
//! # Refusals
//! Only when [`Controller::refuse`] is on (`iai simulate` turns it on;
//! `--accept-all` turns it off); otherwise every well-formed command gets
//! its normal response and a move runs whatever the servo and homing
//! state. The manuals state when a real controller refuses a command only in
//! general terms (an `&` reply when a received command cannot be executed,
//! TTA p. 15, 2003 p. 13) and publish no code list. The simulator refuses
//! the cases below with codes of its own, chosen for it and documented
//! here; a real controller's codes will differ:
//!
//! | code | refusal |
//! |---|---|
//! | [`INJECTED_ERROR_CODE`] `0E1` | fault injection (`error=P`) |
//! | [`UNSUPPORTED_ERROR_CODE`] `0E2` | body does not fit the layout, an ID a 2003 X-SEL does not know (the TTA simulator answers every catalogue message), position number past FFFFH |
//! | [`SERVO_OFF_CODE`] `0E4` | move, jog or home on an axis whose servo is off |
//! | [`NOT_HOMED_CODE`] `0E5` | 234H/235H/237H/26BH before the axis was homed (jog and inching are allowed) |
//! | [`AXIS_BUSY_CODE`] `0E6` | a new operation on an axis that is still moving or homing |
//! | [`NO_POSITION_CODE`] `0E7` | 237H/26BH to a position that is not defined or shares no axis with the pattern |

use std::collections::BTreeMap;

use iai_protocol_b::axis::{PerAxis, MAX_AXES};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::field::{FieldSpec, Reader, Writer};
use iai_protocol_b::frame::{emit_envelope, emit_trailer, Frame, Header, Station};
use iai_protocol_b::message::{
    AbsoluteMove, AxisStatus, AxisStatusQuery, AxisStatusResponse, Command, ErrorDetailQuery,
    ErrorDetailResponse, HomeReturn, JogInch, Message, OperationStop, PositionNumberMove,
    PositionNumberMove2, RelativeMove, Response, ServoOnOff, SystemStatusQuery,
    SystemStatusResponse,
};
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::profile::Profile;
use iai_protocol_b::stream::PositionStream;

/// Error code the simulator sends when it injects an error response.
pub const INJECTED_ERROR_CODE: u16 = 0x0E1;
/// Error code for a command whose body does not fit its layout (or whose ID
/// is not in the catalogue).
pub const UNSUPPORTED_ERROR_CODE: u16 = 0x0E2;
/// Refusal: the servo of an axis concerned is off (simulator's own code).
pub const SERVO_OFF_CODE: u16 = 0x0E4;
/// Refusal: a coordinate move before homing (simulator's own code).
pub const NOT_HOMED_CODE: u16 = 0x0E5;
/// Refusal: the axis is still moving or homing (simulator's own code).
pub const AXIS_BUSY_CODE: u16 = 0x0E6;
/// Refusal: 237H/26BH to an undefined position (simulator's own code).
pub const NO_POSITION_CODE: u16 = 0x0E7;

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
    /// Every n-th reply is sent late, after this many ms.
    pub late_every_nth_reply: Option<(u32, u32)>,
    /// Chance that a command gets an `&` error response instead of its reply.
    pub error_reply: f64,
    /// Chance that noise bytes precede a reply.
    pub garbage_before_reply: f64,
    /// Chance that a reply is not sent at all.
    pub drop_reply: f64,
    /// Chance that a reply is sent this many ms after its command (past
    /// the host's timeout, so that it meets the resend).
    pub late_reply: Option<(f64, u32)>,
    /// Chance that a reply is sent a second time, this many ms after the
    /// first (an echoing converter, a late copy).
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

/// Homing state (212H status bits 1-2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Home {
    /// Not homed since power-on.
    #[default]
    NotDone,
    /// Homing now.
    Returning,
    /// Homed.
    Done,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Move,
    Home,
}

/// A trapezoidal (or triangular) move, in 0.001 mm and ms: 1 mm/s is
/// 1 unit/ms, 0.01 G is 0.0980665 units/ms².
#[derive(Debug, Clone, Copy, PartialEq)]
struct Motion {
    kind: Kind,
    from: f64,
    to: f64,
    start: u32,
    acc: f64,
    dec: f64,
    peak: f64,
    t_acc: f64,
    t_cruise: f64,
    t_dec: f64,
}

fn units_per_ms2(centi_g: u16) -> f64 {
    f64::from(centi_g.max(1)) * 0.098_066_5
}

impl Motion {
    fn new(kind: Kind, from: i32, to: i32, start: u32, acc: u16, dec: u16, speed: u16) -> Self {
        let (a, d, v) = (
            units_per_ms2(acc),
            units_per_ms2(dec),
            f64::from(speed.max(1)),
        );
        let dist = (f64::from(to) - f64::from(from)).abs();
        let (d_a, d_d) = (v * v / (2.0 * a), v * v / (2.0 * d));
        let (peak, t_cruise) = if d_a + d_d <= dist {
            (v, (dist - d_a - d_d) / v)
        } else {
            ((2.0 * dist * a * d / (a + d)).sqrt(), 0.0)
        };
        Motion {
            kind,
            from: f64::from(from),
            to: f64::from(to),
            start,
            acc: a,
            dec: d,
            peak,
            t_acc: peak / a,
            t_cruise,
            t_dec: peak / d,
        }
    }

    /// Milliseconds the travel takes.
    fn duration(&self) -> f64 {
        self.t_acc + self.t_cruise + self.t_dec
    }

    /// Whole ms after which the axis is at rest (a homing adds its creep).
    fn end_ms(&self) -> u32 {
        let creep = if self.kind == Kind::Home {
            HOME_CREEP_MS
        } else {
            0
        };
        self.duration().ceil() as u32 + creep
    }

    /// Position at tick `now`.
    fn position(&self, now: u32) -> i32 {
        let t = f64::from(now.wrapping_sub(self.start));
        let s = if t >= self.duration() {
            (self.to - self.from).abs()
        } else if t < self.t_acc {
            0.5 * self.acc * t * t
        } else if t < self.t_acc + self.t_cruise {
            0.5 * self.peak * self.t_acc + self.peak * (t - self.t_acc)
        } else {
            let u = t - self.t_acc - self.t_cruise;
            0.5 * self.peak * self.t_acc + self.peak * self.t_cruise + self.peak * u
                - 0.5 * self.dec * u * u
        };
        let dir = if self.to >= self.from { 1.0 } else { -1.0 };
        (self.from + dir * s).round() as i32
    }
}

/// One simulated axis.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Axis {
    /// Servo on.
    pub servo: bool,
    /// Homing state.
    pub home: Home,
    /// The last operation ended normally (212H bit 4).
    pub completed: bool,
    pos: i32,
    motion: Option<Motion>,
}

impl Axis {
    /// Brings the state up to tick `now`: a move whose time has passed ends.
    fn settle(&mut self, now: u32) {
        if let Some(m) = self.motion {
            if now.wrapping_sub(m.start) >= m.end_ms() {
                self.pos = m.to as i32;
                self.motion = None;
                self.completed = true;
                if m.kind == Kind::Home {
                    self.home = Home::Done;
                }
            }
        }
    }

    /// Position at tick `now` (0.001 mm).
    pub fn position(&self, now: u32) -> i32 {
        self.motion.map_or(self.pos, |m| m.position(now))
    }

    /// Moving or homing at the last settle.
    pub fn in_use(&self) -> bool {
        self.motion.is_some()
    }

    /// The 212H status byte.
    pub fn status_byte(&self) -> u8 {
        let home = match self.home {
            Home::NotDone => 0,
            Home::Returning => 1,
            Home::Done => 2,
        };
        u8::from(self.in_use())
            | home << 1
            | u8::from(self.servo) << 3
            | u8::from(self.completed) << 4
    }

    /// Stops at the current position; the operation did not complete.
    fn stop(&mut self, now: u32) {
        if let Some(m) = self.motion.take() {
            self.pos = m.position(now);
            self.completed = false;
            if m.kind == Kind::Home {
                self.home = Home::NotDone;
            }
        }
    }
}

/// The controller's memory: position table, axes, limits.
#[derive(Debug, Clone)]
pub struct Controller {
    /// The kind of controller: which messages it knows.
    pub profile: Profile,
    /// Station code.
    pub station: Station,
    /// Largest command frame accepted (TTA 2,051; X-SEL J/K 1,023).
    pub max_receive: usize,
    /// Largest response frame sent (TTA 2,048; X-SEL J/K 1,024).
    pub max_transmit: usize,
    /// Delay before replying (the controller's α), ms.
    pub response_delay_ms: u32,
    /// The position table.
    pub table: BTreeMap<u16, PositionRecord>,
    /// The eight axes.
    pub axes: [Axis; MAX_AXES],
    /// Position records written, over all connections.
    pub records_written: u64,
    /// Refuse moves as described in the module docs (servo off, not
    /// homed, busy, undefined position). Off in the constructors, so that
    /// protocol tests get a normal response to every well-formed command;
    /// `iai simulate` turns it on.
    pub refuse: bool,
}

/// A command's outcome: a reply frame, or nothing.
type Reply = Option<Vec<u8>>;

impl Controller {
    /// A TTA at `station`: 2,051 / 2,048-byte buffers, α = 2 ms.
    pub fn tta(station: Station) -> Self {
        Controller {
            profile: Profile::TTA,
            station,
            max_receive: 2051,
            max_transmit: 2048,
            response_delay_ms: 2,
            table: BTreeMap::new(),
            axes: [Axis::default(); MAX_AXES],
            records_written: 0,
            refuse: false,
        }
    }

    /// A 2003-generation X-SEL (1,023 / 1,024-byte buffers).
    pub fn xsel_2003(station: Station) -> Self {
        Controller {
            profile: Profile::XSEL_2003,
            max_receive: 1023,
            max_transmit: 1024,
            ..Self::tta(station)
        }
    }

    /// Brings every axis up to tick `now`.
    pub fn settle(&mut self, now: u32) {
        for a in self.axes.iter_mut() {
            a.settle(now);
        }
    }

    fn error_frame(&self, code: u16) -> Vec<u8> {
        let mut buf = [0u8; 16];
        let mut w = Writer::new(&mut buf);
        // 10 bytes always fit.
        let _ = emit_envelope(&mut w, Header::Error, self.station, code);
        let _ = emit_trailer(&mut w, Default::default());
        w.written().to_vec()
    }

    fn emit<'a, M: Message<'a>>(&self, msg: &M) -> Vec<u8> {
        let mut buf = vec![0u8; self.max_transmit];
        match msg.emit(self.station, &mut buf) {
            Ok(n) => {
                buf.truncate(n);
                buf
            }
            Err(_) => self.error_frame(UNSUPPORTED_ERROR_CODE),
        }
    }

    /// The normal response of `id` with default (zero) fields.
    fn ack(&self, id: u16) -> Reply {
        let r = Response::default_for(id)?;
        let mut buf = vec![0u8; self.max_transmit];
        let n = r.emit(self.station, &mut buf).ok()?;
        buf.truncate(n);
        Some(buf)
    }

    /// Executes one checked command at tick `now`; the reply frame, or
    /// `None` for no reply. `swap` alters one record of a position write.
    pub fn execute(&mut self, f: &Frame<'_>, now: u32, swap: Option<&mut Rng>) -> Reply {
        self.settle(now);
        if self.profile != Profile::TTA && !self.profile.supports(f.code()) {
            // A message this kind of controller does not know (the TTA
            // simulator answers every catalogue message, whatever family).
            return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
        }
        if let Some(kind) = PositionStream::find(Header::Command, f.code()) {
            return Some(self.write_positions(kind, f, swap));
        }
        if let Some(kind) = PositionStream::find(Header::Response, f.code()) {
            return Some(self.query_positions(kind, f));
        }
        match f.code() {
            0x212 => {
                let q = AxisStatusQuery::parse(f).ok()?;
                let mut axes = PerAxis::new();
                for n in q.query_axis_pattern.iter() {
                    let a = self
                        .axes
                        .get(usize::from(n) - 1)
                        .copied()
                        .unwrap_or_default();
                    let _ = axes.push(AxisStatus {
                        axis_status: a.status_byte(),
                        sensor_input_status: 0,
                        error_code: 0,
                        encoder_status: 0,
                        current_position: a.position(now),
                    });
                }
                Some(self.emit(&AxisStatusResponse {
                    axis_pattern: q.query_axis_pattern,
                    axes,
                }))
            }
            0x215 => {
                SystemStatusQuery::parse(f).ok()?;
                // AUTO mode, no system error; byte 3: operating in AUTO,
                // system ready. 215H has no motion field: moves show in
                // 212H only.
                Some(self.emit(&SystemStatusResponse {
                    system_mode: 1,
                    status_byte_3: 0b110,
                    ..SystemStatusResponse::default()
                }))
            }
            0x216 => {
                let q = ErrorDetailQuery::parse(f).ok()?;
                // Illustrative details (error C74H, program 1, step 5, axis 2, point -3).
                Some(self.emit(&ErrorDetailResponse {
                    error_number: 0xC74,
                    detail_1: u32::from(q.type_2),
                    detail_2: 5,
                    detail_3: 2,
                    detail_4: -3,
                    ..ErrorDetailResponse::default()
                }))
            }
            0x232 => {
                let Ok(c) = ServoOnOff::parse(f) else {
                    return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
                };
                let on = c.operation_type & 1 == 1;
                for n in c.axis_pattern.iter() {
                    if let Some(a) = self.axes.get_mut(usize::from(n) - 1) {
                        if !on {
                            a.stop(now);
                        }
                        a.servo = on;
                    }
                }
                self.ack(0x232)
            }
            0x233 => {
                let Ok(c) = HomeReturn::parse(f) else {
                    return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
                };
                let speed = if c.end_search_speed == 0 {
                    DEFAULT_SPEED
                } else {
                    c.end_search_speed
                };
                let targets: Vec<(u8, i32)> = c.axis_pattern.iter().map(|n| (n, 0)).collect();
                if let Err(code) = self.start(&targets, Kind::Home, now, (0, 0, speed), false) {
                    return Some(self.error_frame(code));
                }
                self.ack(0x233)
            }
            0x234 => {
                let Ok(c) = AbsoluteMove::parse(f) else {
                    return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
                };
                let targets: Vec<(u8, i32)> = c
                    .axis_pattern
                    .iter()
                    .zip(c.absolute_coordinate.iter().copied())
                    .collect();
                let p = (c.acceleration, c.deceleration, c.speed);
                self.motion_reply(0x234, &targets, now, p, true)
            }
            0x235 => {
                let Ok(c) = RelativeMove::parse(f) else {
                    return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
                };
                let targets: Vec<(u8, i32)> = c
                    .axis_pattern
                    .iter()
                    .zip(c.relative_distance.iter().copied())
                    .map(|(n, d)| (n, self.axis_pos(n, now).saturating_add(d)))
                    .collect();
                let p = (c.acceleration, c.deceleration, c.speed);
                self.motion_reply(0x235, &targets, now, p, true)
            }
            0x236 => {
                let Ok(c) = JogInch::parse(f) else {
                    return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
                };
                let positive = c.operation_type & 1 == 1;
                let targets: Vec<(u8, i32)> = c
                    .axis_pattern
                    .iter()
                    .map(|n| {
                        let here = self.axis_pos(n, now);
                        let to = match (c.inching_distance, positive) {
                            (0, true) => SOFT_LIMIT,
                            (0, false) => -SOFT_LIMIT,
                            (d, true) => here.saturating_add_unsigned(d),
                            (d, false) => here.saturating_sub_unsigned(d),
                        };
                        (n, to.clamp(-SOFT_LIMIT, SOFT_LIMIT))
                    })
                    .collect();
                let p = (c.acceleration, c.deceleration, c.speed);
                self.motion_reply(0x236, &targets, now, p, false)
            }
            0x237 | 0x26B => {
                let parsed = if f.code() == 0x237 {
                    PositionNumberMove::parse(f).map(|c| {
                        (
                            c.axis_pattern,
                            c.acceleration,
                            c.deceleration,
                            c.speed,
                            c.position_number,
                        )
                    })
                } else {
                    PositionNumberMove2::parse(f).map(|c| {
                        (
                            c.axis_pattern,
                            c.acceleration,
                            c.deceleration,
                            c.speed,
                            c.position_number,
                        )
                    })
                };
                let Ok((pattern, acc, dec, speed, number)) = parsed else {
                    return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
                };
                if pattern.is_empty() {
                    // No axis concerned: nothing to move, nothing to refuse.
                    return self.ack(f.code());
                }
                let Some(rec) = self.table.get(&number).cloned() else {
                    return if self.refuse {
                        Some(self.error_frame(NO_POSITION_CODE))
                    } else {
                        self.ack(f.code())
                    };
                };
                let targets: Vec<(u8, i32)> = pattern
                    .iter()
                    .filter_map(|n| rec.position(n).map(|p| (n, p)))
                    .collect();
                if targets.is_empty() {
                    return if self.refuse {
                        Some(self.error_frame(NO_POSITION_CODE))
                    } else {
                        self.ack(f.code())
                    };
                }
                let pick = |given: u16, stored: u16, default: u16| {
                    [given, stored]
                        .into_iter()
                        .find(|v| *v != 0)
                        .unwrap_or(default)
                };
                let p = (
                    pick(acc, rec.acceleration, DEFAULT_ACC),
                    pick(dec, rec.deceleration, DEFAULT_ACC),
                    pick(speed, rec.speed, DEFAULT_SPEED),
                );
                self.motion_reply(f.code(), &targets, now, p, true)
            }
            0x238 => {
                let Ok(c) = OperationStop::parse(f) else {
                    return Some(self.error_frame(UNSUPPORTED_ERROR_CODE));
                };
                for n in c.stop_axis_pattern.iter() {
                    if let Some(a) = self.axes.get_mut(usize::from(n) - 1) {
                        a.stop(now);
                    }
                }
                self.ack(0x238)
            }
            // Every other message of the catalogue: a well-formed command gets
            // its response with default (zero) fields; 25BH gets none.
            id => match Command::parse(f) {
                Err(_) => Some(self.error_frame(UNSUPPORTED_ERROR_CODE)),
                Ok(_) => self.ack(id),
            },
        }
    }

    fn axis_pos(&self, n: u8, now: u32) -> i32 {
        self.axes
            .get(usize::from(n) - 1)
            .map_or(0, |a| a.position(now))
    }

    fn motion_reply(
        &mut self,
        id: u16,
        targets: &[(u8, i32)],
        now: u32,
        p: (u16, u16, u16),
        needs_home: bool,
    ) -> Reply {
        match self.start(targets, Kind::Move, now, p, needs_home) {
            Ok(()) => self.ack(id),
            Err(code) => Some(self.error_frame(code)),
        }
    }

    /// Starts a move (or homing) of each `(axis, target)`: all or none.
    fn start(
        &mut self,
        targets: &[(u8, i32)],
        kind: Kind,
        now: u32,
        (acc, dec, speed): (u16, u16, u16),
        needs_home: bool,
    ) -> Result<(), u16> {
        let or = |v: u16, d: u16| if v == 0 { d } else { v };
        let (acc, dec, speed) = (
            or(acc, DEFAULT_ACC),
            or(dec, DEFAULT_ACC),
            or(speed, DEFAULT_SPEED),
        );
        for &(n, _) in targets {
            let a = self
                .axes
                .get(usize::from(n) - 1)
                .ok_or(UNSUPPORTED_ERROR_CODE)?;
            if !self.refuse {
                continue;
            }
            if !a.servo {
                return Err(SERVO_OFF_CODE);
            }
            if a.in_use() {
                return Err(AXIS_BUSY_CODE);
            }
            if needs_home && a.home != Home::Done {
                return Err(NOT_HOMED_CODE);
            }
        }
        for &(n, to) in targets {
            if let Some(a) = self.axes.get_mut(usize::from(n) - 1) {
                // Without refusals a new move takes over from where the
                // axis is.
                a.pos = a.position(now);
                a.motion = None;
                a.completed = false;
                if kind == Kind::Home {
                    a.home = Home::Returning;
                }
                a.motion = Some(Motion::new(kind, a.pos, to, now, acc, dec, speed));
            }
        }
        Ok(())
    }

    fn write_positions(
        &mut self,
        kind: PositionStream,
        f: &Frame<'_>,
        swap: Option<&mut Rng>,
    ) -> Vec<u8> {
        let mut r = f.reader();
        let parsed = (|| {
            let (start, count) = kind.read_prefix(&mut r)?;
            let mut recs = Vec::with_capacity(usize::from(count));
            for i in 0..count {
                let mut rec = kind.layout.read_record(&mut r)?;
                if kind.layout.number_width == 0 {
                    // A range write past position FFFFH has nowhere to go.
                    rec.number = start
                        .checked_add(i)
                        .ok_or(iai_protocol_b::Error::ValueOutOfRange { offset: 6 })?;
                }
                recs.push(rec);
            }
            r.finish()?;
            Ok::<_, iai_protocol_b::Error>((start, recs))
        })();
        let Ok((start, mut recs)) = parsed else {
            return self.error_frame(UNSUPPORTED_ERROR_CODE);
        };
        if let Some(rng) = swap {
            swap_digits(&mut recs, rng);
        }
        let n = recs.len() as u16;
        for rec in recs {
            self.table.insert(rec.number, rec);
        }
        self.records_written += u64::from(n);
        let mut buf = [0u8; 32];
        let mut w = Writer::new(&mut buf);
        let ok = emit_envelope(&mut w, Header::Response, self.station, kind.id)
            .and_then(|_| kind.write_prefix(&mut w, start, n))
            .and_then(|_| emit_trailer(&mut w, Default::default()));
        match ok {
            Ok(()) => w.written().to_vec(),
            Err(_) => self.error_frame(UNSUPPORTED_ERROR_CODE),
        }
    }

    /// 209H / 21FH / 22DH: the defined records in the window of position
    /// numbers `head..head + asked`, as many as fit the transmit buffer.
    fn query_positions(&mut self, kind: PositionStream, f: &Frame<'_>) -> Vec<u8> {
        let body = f.body();
        let w_num = kind.count_width;
        let mut r = Reader::new(body, 6);
        let q = (|| {
            if kind.reserved {
                r.take(2)?;
            }
            let head = r.unsigned(FieldSpec::hex(w_num))? as u16;
            let n = r.unsigned(FieldSpec::hex(w_num))? as u16;
            r.finish()?;
            Ok::<_, iai_protocol_b::Error>((head, n))
        })();
        let Ok((head, asked)) = q else {
            return self.error_frame(UNSUPPORTED_ERROR_CODE);
        };
        let mut buf = vec![0u8; self.max_transmit];
        let mut w = Writer::new(&mut buf);
        let written = (|| {
            emit_envelope(&mut w, Header::Response, self.station, kind.id)?;
            kind.write_prefix(&mut w, 0, 0)?;
            let count_at = w.len() - usize::from(kind.count_width);
            let mut n = 0u16;
            // The window head..head+asked; only defined records are returned.
            let end = u32::from(head) + u32::from(asked);
            for rec in self
                .table
                .range(head..)
                .map(|(_, r)| r)
                .take_while(|r| u32::from(r.number) < end)
            {
                if w.len() + kind.layout.record_len(rec.axes.count()) + 4 > self.max_transmit {
                    break;
                }
                kind.layout.write_record(rec, &mut w)?;
                n += 1;
            }
            w.patch_unsigned(count_at, FieldSpec::hex(kind.count_width), u64::from(n))?;
            emit_trailer(&mut w, Default::default())
        })();
        match written {
            Ok(()) => w.written().to_vec(),
            Err(_) => self.error_frame(UNSUPPORTED_ERROR_CODE),
        }
    }
}

/// Swaps two adjacent, different hex digits of one coordinate of one
/// record: the sum of the frame's characters, hence its SC, is unchanged.
fn swap_digits(recs: &mut [PositionRecord], rng: &mut Rng) {
    let with_coords: Vec<usize> = (0..recs.len())
        .filter(|&i| recs.get(i).is_some_and(|r| !r.positions.is_empty()))
        .collect();
    let Some(&i) = with_coords.get(rng.below(with_coords.len() as u64) as usize) else {
        return;
    };
    let Some(rec) = recs.get_mut(i) else { return };
    let k = rng.below(rec.positions.len() as u64) as usize;
    let Some(p) = rec.positions.get_mut(k) else {
        return;
    };
    let digits = format!("{:08X}", *p as u32).into_bytes();
    let pairs: Vec<usize> = (0..7)
        .filter(|&j| digits.get(j) != digits.get(j + 1))
        .collect();
    let Some(&j) = pairs.get(rng.below(pairs.len() as u64) as usize) else {
        // All eight digits equal (0, -1): change the speed's digits instead.
        rec.speed = rec.speed.rotate_left(4);
        return;
    };
    let mut d = digits;
    d.swap(j, j + 1);
    let text = String::from_utf8_lossy(&d).into_owned();
    if let Ok(v) = u32::from_str_radix(&text, 16) {
        *p = v as i32;
    }
}

/// One connection's state: decoder, replies waiting to go out, faults.
pub struct Session {
    decoder: Box<FrameDecoder<4096>>,
    outbox: Vec<(u32, Vec<u8>)>,
    rng: Rng,
    reply_no: u32,
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

    /// Reply bytes due by `now`, in order.
    pub fn take_output(&mut self, now: u32) -> Vec<u8> {
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
                Event::NeedMore => None,
                Event::Error(e) => {
                    if matches!(e, iai_protocol_b::Error::FrameTooLong { .. }) {
                        self.stats.oversize_frames += 1;
                    } else {
                        self.stats.broken_frames += 1;
                    }
                    None
                }
                Event::Frame(f) => {
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

    fn schedule(&mut self, ctl: &Controller, faults: &Faults, reply: Reply, now: u32) {
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
        if let Some((p, later)) = faults.dup_reply {
            if self.rng.chance(p) {
                self.stats.duplicated_replies += 1;
                self.outbox.push((at.wrapping_add(later), reply.clone()));
            }
        }

        self.stats.replies += 1;
        self.outbox.push((at, reply));
    }
}

/// A controller with one connection: the simulator for single-link tests.
/// Derefs to its [`Controller`] (`sim.table`, `sim.station`, …).
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

    /// A 2003-generation X-SEL (1,023 / 1,024-byte buffers).
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

    #[test]
    fn a_swapped_record_keeps_the_checksum() {
        let mut rng = Rng::new(3);
        let orig = PositionRecord::new(1, 1, 1, 1, &[(1, 0x1234_5678)]).unwrap();
        let mut recs = vec![orig.clone()];
        swap_digits(&mut recs, &mut rng);
        let changed = recs.first().unwrap();
        assert_ne!(changed, &orig);
        let digit_sum = |r: &PositionRecord| -> u32 {
            format!("{:08X}", *r.positions.first().unwrap() as u32)
                .bytes()
                .map(u32::from)
                .sum()
        };
        assert_eq!(digit_sum(changed), digit_sum(&orig));
    }
}
