//! The command handshake, like the command area of IAI's RCM-GW
//! gateways: a write that starts a command is answered at once and the
//! command is queued; the status word (CMDST, [`super::map::Item::Handshake`])
//! says busy until the controller answered, then done, or error with the
//! code in the next register (bit 15 set). One command at a time: a
//! command write while one is busy is answered with exception 06. Done
//! means the controller confirmed the command (its `#` reply; for a table
//! write, every record read back equal), never less.

use iai_protocol_b::catalogue::{self, MessageInfo};
use iai_protocol_b::position::PositionRecord;

use super::map::{CMD_BUSY, CMD_DONE, CMD_ERROR, INTEGERS};

/// A command the gateway runs on the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Job {
    /// 232H on one axis (1..=8).
    Servo {
        /// Axis.
        axis: u8,
        /// On or off.
        on: bool,
    },
    /// 233H.
    Home {
        /// Axis.
        axis: u8,
    },
    /// 26BH to the position in POSR.
    MoveToPosition {
        /// Axis.
        axis: u8,
        /// Position number.
        number: u16,
    },
    /// 234H.
    Move {
        /// Axis.
        axis: u8,
        /// Target, 0.001 mm.
        position: i32,
        /// mm/s (0: the parameter).
        speed: u16,
        /// 0.01 G (0: the parameter).
        acceleration: u16,
    },
    /// 238H.
    Stop {
        /// Axis.
        axis: u8,
    },
    /// 252H.
    AlarmReset,
    /// 24AH.
    Output {
        /// Port number.
        port: u16,
        /// On or off.
        on: bool,
    },
    /// 24BH, a global flag.
    Flag {
        /// Flag number.
        flag: u16,
        /// On or off.
        on: bool,
    },
    /// 24CH of global integer variables.
    Integers {
        /// First variable.
        first: u16,
        /// How many (1..=8).
        count: u8,
        /// Their values.
        values: [i32; INTEGERS],
    },
    /// 21FH of the table window from this position.
    ReadWindow {
        /// First position.
        head: u16,
    },
    /// 26DH of the staged window records, read back.
    WriteWindow {
        /// First staged record.
        first: u8,
        /// How many.
        count: u8,
    },
}

impl Job {
    /// The protocol-B message the command is sent as (what the command
    /// policy decides on, and what CMDST reports).
    pub const fn message(&self) -> &'static MessageInfo {
        match self {
            Job::Servo { .. } => &catalogue::SERVO_ON_OFF,
            Job::Home { .. } => &catalogue::HOME_RETURN,
            Job::MoveToPosition { .. } => &catalogue::POSITION_NUMBER_MOVE_2,
            Job::Move { .. } => &catalogue::ABSOLUTE_MOVE,
            Job::Stop { .. } => &catalogue::OPERATION_STOP,
            Job::AlarmReset => &catalogue::ALARM_RESET,
            Job::Output { .. } => &catalogue::OUTPUT_PORT_CHANGE,
            Job::Flag { .. } => &catalogue::FLAG_CHANGE,
            Job::Integers { .. } => &catalogue::INTEGER_VARIABLE_CHANGE,
            Job::ReadWindow { .. } => &catalogue::EFFECTIVE_POSITION_QUERY_2,
            Job::WriteWindow { .. } => &catalogue::CHANGE_POSITION_DATA_2,
        }
    }

    /// The axes (bit `n − 1`: axis `n`) whose state the command changes:
    /// once it is confirmed, their cached status reads MOVE 1, PEND and
    /// HEND 0 until a later 212H. An alarm reset changes them all.
    pub const fn moves(&self) -> u8 {
        match *self {
            Job::Servo { axis, .. }
            | Job::Home { axis }
            | Job::MoveToPosition { axis, .. }
            | Job::Move { axis, .. }
            | Job::Stop { axis } => 1 << (axis.wrapping_sub(1) & 7),
            Job::AlarmReset => u8::MAX,
            _ => 0,
        }
    }
}

/// Where the handshake is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// No command since start.
    Idle,
    /// Accepted, waiting for the line.
    Queued(Job),
    /// On the line.
    Running(Job),
    /// Confirmed.
    Done,
    /// Failed with this code.
    Failed(u16),
}

/// The command area.
#[derive(Debug, Clone, Copy)]
pub struct Handshake {
    state: State,
    /// Commands accepted (wrapping): the low byte of the status word.
    seq: u8,
    /// The message of the last command accepted.
    id: u16,
}

impl Default for Handshake {
    fn default() -> Self {
        Self::new()
    }
}

impl Handshake {
    /// No command yet.
    pub const fn new() -> Self {
        Handshake {
            state: State::Idle,
            seq: 0,
            id: 0,
        }
    }

    /// Whether a command is queued or running (a new one is refused, 06).
    pub fn busy(&self) -> bool {
        matches!(self.state, State::Queued(_) | State::Running(_))
    }

    /// Accepts `job`; `false` (nothing changes) while busy.
    pub fn accept(&mut self, job: Job) -> bool {
        if self.busy() {
            return false;
        }
        self.seq = self.seq.wrapping_add(1);
        self.id = job.message().id;
        self.state = State::Queued(job);
        true
    }

    /// The queued command, now taken onto the line.
    pub fn take(&mut self) -> Option<Job> {
        match self.state {
            State::Queued(job) => {
                self.state = State::Running(job);
                Some(job)
            }
            _ => None,
        }
    }

    /// Whether a command waits for the line.
    pub fn queued(&self) -> bool {
        matches!(self.state, State::Queued(_))
    }

    /// The running command ended: `Ok` when the controller confirmed it,
    /// else the code reported.
    pub fn finish(&mut self, result: Result<(), u16>) {
        self.state = match result {
            Ok(()) => State::Done,
            Err(code) => State::Failed(code),
        };
    }

    /// CMDST: the status word, the error code, the message ID.
    pub fn words(&self) -> [u16; 3] {
        let (flags, code) = match self.state {
            State::Idle => (0, 0),
            State::Queued(_) | State::Running(_) => (CMD_BUSY, 0),
            State::Done => (CMD_DONE, 0),
            State::Failed(code) => (CMD_ERROR, code),
        };
        [flags | u16::from(self.seq), code, self.id]
    }
}

/// A window record as registers: number, axis pattern, acceleration,
/// deceleration, speed, then two registers (high word first) per axis
/// 1..=8, 0 for the axes the record does not have.
pub fn record_words(rec: &PositionRecord) -> [u16; super::map::RECORD_WORDS] {
    let mut w = [0u16; super::map::RECORD_WORDS];
    let head = [
        rec.number,
        u16::from(rec.axes.bits()),
        rec.acceleration,
        rec.deceleration,
        rec.speed,
    ];
    for (slot, v) in w.iter_mut().zip(head) {
        *slot = v;
    }
    for axis in 1..=8u8 {
        if let Some(p) = rec.position(axis) {
            let at = 5 + 2 * usize::from(axis - 1);
            let [hi, lo] = super::cache::words(p as u32);
            if let Some(s) = w.get_mut(at) {
                *s = hi;
            }
            if let Some(s) = w.get_mut(at + 1) {
                *s = lo;
            }
        }
    }
    w
}

/// The record that window registers describe; `None` if the axis
/// pattern is 0 (read back, it means a position that is not defined;
/// 26DH defines no meaning for it) or not a byte.
pub fn words_record(w: &[u16]) -> Option<PositionRecord> {
    let get = |i: usize| w.get(i).copied().unwrap_or(0);
    let pattern = u8::try_from(get(1)).ok().filter(|&p| p != 0)?;
    let mut pairs = [(0u8, 0i32); 8];
    let mut n = 0;
    for axis in 1..=8u8 {
        if pattern & (1 << (axis - 1)) != 0 {
            let at = 5 + 2 * usize::from(axis - 1);
            let v = (u32::from(get(at)) << 16 | u32::from(get(at + 1))) as i32;
            if let Some(slot) = pairs.get_mut(n) {
                *slot = (axis, v);
                n += 1;
            }
        }
    }
    PositionRecord::new(get(0), get(2), get(3), get(4), pairs.get(..n)?).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_status_word_follows_the_command() {
        let mut h = Handshake::new();
        assert_eq!(h.words(), [0, 0, 0]);
        assert!(h.accept(Job::Home { axis: 1 }));
        assert_eq!(h.words(), [CMD_BUSY | 1, 0, 0x233]);
        assert!(!h.accept(Job::Stop { axis: 1 }), "busy: refused");
        assert_eq!(h.take(), Some(Job::Home { axis: 1 }));
        assert_eq!(h.take(), None);
        h.finish(Err(0x0E4));
        assert_eq!(h.words(), [CMD_ERROR | 1, 0x0E4, 0x233]);
        assert!(h.accept(Job::Servo { axis: 1, on: true }));
        h.take();
        h.finish(Ok(()));
        assert_eq!(h.words(), [CMD_DONE | 2, 0, 0x232]);
    }

    #[test]
    fn a_record_round_trips_through_its_registers() {
        let rec = PositionRecord::new(7, 30, 30, 100, &[(1, 100_000), (3, -25_500)]).unwrap();
        let w = record_words(&rec);
        assert_eq!(w[..7], [7, 0b101, 30, 30, 100, 0x0001, 0x86A0]);
        assert_eq!(w[9..11], [0xFFFF, 0x9C64]);
        assert_eq!(words_record(&w), Some(rec));
    }
}
