//! What the edge node publishes and takes: one table per kind of metric
//! (the node's, each axis's, the controller's), their aliases, their
//! values read from the bridge and the Modbus gateway's cache, and the
//! DCMD metrics turned into the gateway's commands. Aliases are fixed by
//! a metric's place in its table, so a rebirth gives every metric the
//! alias it had.

use iai_protocol_b::message::{AxisStatus, Homing};
use rmodbus::ErrorKind;

use super::mqtt::Writer;
use super::payload::{DataType, Received, Value};
use crate::bridge::Bridge;
use crate::codes;
use crate::modbus::command::Job;
use crate::modbus::map::{self, Item, CMD_BUSY, CMD_DONE, CMD_ERROR, RECORD_WORDS};
use crate::modbus::registers::{Registers, WINDOW_WORDS};

/// One metric: its name (after `Axis N/` for an axis's), its type, and
/// whether a DCMD or NCMD may write it.
#[derive(Debug, Clone, Copy)]
pub struct Def {
    /// Name.
    pub name: &'static str,
    /// Sparkplug data type.
    pub datatype: DataType,
    /// A command may write it.
    pub writable: bool,
}

const fn def(name: &'static str, datatype: DataType, writable: bool) -> Def {
    Def {
        name,
        datatype,
        writable,
    }
}

use DataType::{Boolean, Bytes, Int32, String as Str, UInt16, UInt32, UInt64, UInt8};

/// The node's metrics after `bdSeq` (NBIRTH, NDATA), alias `1 + index`.
pub const NODE: [Def; 17] = [
    def("Node Control/Rebirth", Boolean, true),
    def("Node Info/Firmware", Str, false),
    def("Node Info/Uptime ms", UInt64, false),
    def("Host Line/Host Connected", Boolean, false),
    def("Host Line/Hosts", UInt32, false),
    def("Controller Line/Up", Boolean, false),
    def("Controller Line/Polls OK", UInt32, false),
    def("Controller Line/Polls Failed", UInt32, false),
    def("Bridge/Forwarded", UInt32, false),
    def("Bridge/Reply Timeouts", UInt32, false),
    def("Bridge/Refused", UInt32, false),
    def("Modbus/Answered", UInt32, false),
    def("Config/Controller Station", UInt8, false),
    def("Config/Policy", UInt8, false),
    def("Config/Poll Period ms", UInt16, false),
    def("Config/Axes", UInt8, false),
    def("Config/Deadband", UInt32, false),
];

/// Index of `Node Control/Rebirth` in [`NODE`].
pub const REBIRTH: usize = 0;

/// An axis's metrics (named `Axis N/...`).
pub const AXIS: [Def; 7] = [
    def("Position", Int32, false),
    def("Status", UInt8, false),
    def("Status Bits", UInt16, false),
    def("Alarm", UInt16, false),
    def("Servo", Boolean, true),
    def("Home", Boolean, true),
    def("Move To", Int32, true),
];

/// Index of `Position` in [`AXIS`] (the one with a deadband).
pub const POSITION: usize = 0;

/// The controller's metrics, after every axis's.
pub const CONTROLLER: [Def; 27] = [
    def("Error/Number", UInt16, false),
    def("Error/Detail 1", UInt32, false),
    def("Error/Detail 2", UInt32, false),
    def("Error/Detail 3", UInt32, false),
    def("Error/Detail 4", UInt32, false),
    def("Program/Status", UInt16, false),
    def("Program/Step", UInt16, false),
    def("Program/Error", UInt16, false),
    def("Program/Error Step", UInt16, false),
    def("System/Mode", UInt16, false),
    def("System/Critical Error", UInt16, false),
    def("System/Latest Error", UInt16, false),
    def("System/Status 1", UInt16, false),
    def("System/Status 2", UInt16, false),
    def("System/Status 3", UInt16, false),
    def("System/Status 4", UInt16, false),
    def("Alarm Reset", Boolean, true),
    def("Move/Speed", UInt16, true),
    def("Move/Acceleration", UInt16, true),
    def("Table/Window Head", UInt16, true),
    def("Table/Window", Bytes, true),
    def("Table/Records Written", UInt32, false),
    def("Table/Writes", UInt32, false),
    def("Command/State", Str, false),
    def("Command/Code", UInt16, false),
    def("Command/Message", UInt16, false),
    def("Command/Seq", UInt8, false),
];

/// Alias of the first device metric.
pub const DEVICE_ALIAS: u16 = 100;

/// Device metrics with `axes` axes.
pub fn device_count(axes: u8) -> usize {
    usize::from(axes.clamp(1, 8)) * AXIS.len() + CONTROLLER.len()
}

/// Most device metrics (8 axes).
pub const MAX_DEVICE: usize = 8 * AXIS.len() + CONTROLLER.len();

/// A device metric by its index: an axis's (axis 1..=8, index in
/// [`AXIS`]) or the controller's (index in [`CONTROLLER`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceMetric {
    /// An axis's.
    Axis(u8, usize),
    /// The controller's.
    Controller(usize),
}

impl DeviceMetric {
    /// The metric at `index` with `axes` axes.
    pub fn at(index: usize, axes: u8) -> Option<DeviceMetric> {
        let per_axes = usize::from(axes.clamp(1, 8)) * AXIS.len();
        if index < per_axes {
            Some(DeviceMetric::Axis(
                (index / AXIS.len()) as u8 + 1,
                index % AXIS.len(),
            ))
        } else {
            let k = index - per_axes;
            (k < CONTROLLER.len()).then_some(DeviceMetric::Controller(k))
        }
    }

    /// Its definition.
    pub fn def(self) -> Def {
        let d = match self {
            DeviceMetric::Axis(_, k) => AXIS.get(k),
            DeviceMetric::Controller(k) => CONTROLLER.get(k),
        };
        d.copied().unwrap_or(def("", Boolean, false))
    }

    /// Writes its name.
    pub fn name(self, w: &mut Writer<'_>) {
        if let DeviceMetric::Axis(axis, _) = self {
            w.put(b"Axis ");
            w.byte(b'0' + axis % 10);
            w.byte(b'/');
        }
        w.put(self.def().name.as_bytes());
    }

    /// Whether `name` is its name.
    pub fn is_named(self, name: &str) -> bool {
        match self {
            DeviceMetric::Axis(axis, _) => name
                .strip_prefix("Axis ")
                .and_then(|r| r.strip_prefix(char::from(b'0' + axis % 10)))
                .and_then(|r| r.strip_prefix('/'))
                .is_some_and(|r| r == self.def().name),
            DeviceMetric::Controller(_) => name == self.def().name,
        }
    }
}

/// What the node has to say about the last command (the gateway's
/// handshake, and a refusal of its own since the handshake's last
/// command).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Refusal {
    /// The `&` code: [`codes::REFUSED`] (commands off, or the policy),
    /// [`codes::HOST_BUSY`] (a command is busy), [`codes::UPSTREAM_FRAME`]
    /// (a value the command cannot take).
    pub code: u16,
    /// The message the command would have been sent as (0: none).
    pub message: u16,
    /// The handshake's sequence number when it was refused: the refusal
    /// stands until the handshake takes another command.
    pub seq: u8,
}

/// What the values are read from.
pub struct View<'v> {
    /// The bridge.
    pub bridge: &'v Bridge,
    /// The Modbus gateway's registers (cache, handshake, window).
    pub regs: &'v Registers,
    /// Modbus requests answered.
    pub modbus_answered: u32,
    /// A protocol-B host is connected.
    pub host_connected: bool,
    /// Protocol-B hosts so far.
    pub hosts: u32,
    /// Milliseconds since start.
    pub uptime_ms: u64,
    /// The position deadband, 0.001 mm.
    pub deadband: u32,
    /// The speed and acceleration of `Move To` commands.
    pub motion: (u16, u16),
    /// The node's last refusal, if it stands.
    pub refusal: Option<Refusal>,
    /// `Move To` targets as last written, per axis.
    pub targets: [i32; 8],
}

/// The firmware's name and version (`Node Info/Firmware`).
pub const FIRMWARE: &str = concat!("iai-protocol-b gateway ", env!("CARGO_PKG_VERSION"));

impl View<'_> {
    /// The node metric at `index` of [`NODE`].
    pub fn node(&self, index: usize) -> Value<'static> {
        let s = self.bridge.stats();
        let c = &self.regs.cache;
        let cfg = self.bridge.config();
        let int = |v: u32| Value::Int(v);
        match index {
            0 => Value::Bool(false),
            1 => Value::Str(FIRMWARE),
            2 => Value::Long(self.uptime_ms),
            3 => Value::Bool(self.host_connected),
            4 => int(self.hosts),
            5 => Value::Bool(c.link_up),
            6 => int(c.polls_ok.into()),
            7 => int(c.polls_failed.into()),
            8 => int(s.forwarded),
            9 => int(s.reply_timeouts),
            10 => int(s.refused),
            11 => int(self.modbus_answered),
            12 => int(cfg.controller_station.0.into()),
            13 => int(cfg.policy.code().into()),
            14 => int(self.regs.schedule.period_ms()),
            15 => int(self.regs.cfg.axes.into()),
            _ => int(self.deadband),
        }
    }

    /// The device metric `m`; `words` receives the table window.
    pub fn device<'w>(&self, m: DeviceMetric, words: &'w mut [u16; WINDOW_WORDS]) -> Value<'w> {
        let c = &self.regs.cache;
        let int = |v: u32| Value::Int(v);
        match m {
            DeviceMetric::Axis(axis, k) => {
                let i = usize::from(axis.wrapping_sub(1));
                let none = AxisStatus::default();
                let a = c.axes.get(i).unwrap_or(&none);
                match k {
                    0 => int(a.current_position as u32),
                    1 => int(a.axis_status.into()),
                    2 => int(c.dss1(i).into()),
                    3 => int(a.error_code.into()),
                    4 => Value::Bool(a.servo_on()),
                    5 => Value::Bool(a.homing() == Homing::Done),
                    _ => int(self.targets.get(i).copied().unwrap_or(0) as u32),
                }
            }
            DeviceMetric::Controller(k) => {
                let pick = |ws: &[u16], i: usize| int(ws.get(i).copied().unwrap_or(0).into());
                let [flags, code, message] = self.regs.hs.words();
                let seq = (flags & 0xFF) as u8;
                let refusal = self.refusal.filter(|r| r.seq == seq);
                match k {
                    0 => int(c.error.0.into()),
                    1..=4 => int(c.error.1.get(k - 1).copied().unwrap_or(0)),
                    5..=8 => pick(&c.program, k - 5),
                    9..=15 => pick(&c.system, k - 9),
                    16 => Value::Bool(false),
                    17 => int(self.motion.0.into()),
                    18 => int(self.motion.1.into()),
                    19 => int(self.regs.head.into()),
                    20 => {
                        words.copy_from_slice(&self.regs.window);
                        Value::Words(words.as_slice())
                    }
                    21 => int(self.bridge.stats().records),
                    22 => int(self.bridge.stats().streams_ok),
                    23 => Value::Str(match refusal {
                        Some(_) => "refused",
                        None if flags & CMD_ERROR != 0 => "error",
                        None if flags & CMD_BUSY != 0 => "busy",
                        None if flags & CMD_DONE != 0 => "done",
                        None => "idle",
                    }),
                    24 => int(refusal.map_or(code, |r| r.code).into()),
                    25 => int(refusal.map_or(message, |r| r.message).into()),
                    _ => int(seq.into()),
                }
            }
        }
    }
}

/// A number that stands for a value, to see whether it changed: the
/// value itself for numbers, a CRC-32 of texts and bytes.
pub fn fingerprint(v: Value<'_>) -> u32 {
    match v {
        Value::Int(v) => v,
        Value::Long(v) => (v ^ v >> 32) as u32,
        Value::Bool(b) => b.into(),
        Value::Str(s) => crate::config::crc32(s.as_bytes()),
        Value::Words(ws) => {
            let mut crc = 0u32;
            for w in ws {
                crc = crc.rotate_left(5) ^ crate::config::crc32(&w.to_be_bytes()) ^ u32::from(*w);
            }
            crc
        }
    }
}

/// Where a DCMD metric leads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// A job for the gateway's handshake.
    Job(Job),
    /// The table window's head (a 21FH read through the handshake).
    WindowHead(u16),
    /// Whole window records to write (26DH through the handshake).
    Window,
    /// The speed of the next `Move To`.
    Speed(u16),
    /// Its acceleration.
    Acceleration(u16),
}

/// What a DCMD metric asks, or `None` if it is no writable metric or its
/// value does not fit.
pub fn command(
    m: DeviceMetric,
    value: Received<'_>,
    motion: (u16, u16),
) -> Option<Result<Command, ()>> {
    if !m.def().writable {
        return None;
    }
    let int = |v: Received<'_>| match v {
        Received::Int(v) => Ok(v),
        _ => Err(()),
    };
    let u16_of = |v: Received<'_>| int(v).and_then(|v| u16::try_from(v).map_err(|_| ()));
    Some(match (m, value) {
        (DeviceMetric::Axis(axis, 4), Received::Bool(on)) => {
            Ok(Command::Job(Job::Servo { axis, on }))
        }
        (DeviceMetric::Axis(axis, 5), Received::Bool(true)) => Ok(Command::Job(Job::Home { axis })),
        (DeviceMetric::Axis(axis, 6), v) => int(v).map(|p| {
            Command::Job(Job::Move {
                axis,
                position: p as u32 as i32,
                speed: motion.0,
                acceleration: motion.1,
            })
        }),
        (DeviceMetric::Controller(16), Received::Bool(true)) => Ok(Command::Job(Job::AlarmReset)),
        (DeviceMetric::Controller(17), v) => u16_of(v).map(Command::Speed),
        (DeviceMetric::Controller(18), v) => u16_of(v).map(Command::Acceleration),
        (DeviceMetric::Controller(19), v) => u16_of(v).map(Command::WindowHead),
        (DeviceMetric::Controller(20), Received::Bytes(_)) => Ok(Command::Window),
        _ => Err(()),
    })
}

/// Submits `cmd` (with `bytes`, the window records of [`Command::Window`])
/// to the gateway's command policy and handshake, as a Modbus write of
/// the same command would be; `Err` with the refusal's `&` code and
/// message.
pub fn submit(
    regs: &mut Registers,
    cmd: Command,
    bytes: &[u8],
    allowed: bool,
) -> Result<(), (u16, u16)> {
    let message = match cmd {
        Command::Job(job) => job.message().id,
        Command::WindowHead(_) => Job::ReadWindow { head: 0 }.message().id,
        Command::Window => Job::WriteWindow { first: 0, count: 0 }.message().id,
        Command::Speed(_) | Command::Acceleration(_) => 0,
    };
    if !allowed {
        return Err((codes::REFUSED, message));
    }
    let start = |item: Item| {
        map::MAP
            .iter()
            .find(|e| e.item == item)
            .map_or(0, |e| e.start)
    };
    let result = match cmd {
        Command::Job(job) => regs.command(job),
        Command::WindowHead(head) => {
            regs.write_words(start(Item::WindowHead), 1, &head.to_be_bytes())
        }
        Command::Window => {
            let words = bytes.len() / 2;
            if words == 0 || !words.is_multiple_of(RECORD_WORDS) || !bytes.len().is_multiple_of(2) {
                Err(ErrorKind::IllegalDataValue)
            } else {
                regs.write_words(start(Item::WindowRecords), words as u16, bytes)
            }
        }
        Command::Speed(_) | Command::Acceleration(_) => Ok(()),
    };
    result.map_err(|e| {
        let code = match e {
            ErrorKind::IllegalFunction => codes::REFUSED,
            ErrorKind::SlaveDeviceBusy => codes::HOST_BUSY,
            _ => codes::UPSTREAM_FRAME,
        };
        (code, message)
    })
}
