//! What the gateway last heard from the controller, and when: every read
//! of the map is answered from here, at once, whatever the controller is
//! doing. Ages are published in the health block.

use iai_protocol_b::message::{
    AxisStatus, AxisStatusResponse, ErrorDetailResponse, Homing, MoveOutcome,
    ProgramStatusResponse, SystemStatusResponse, VersionResponse,
};

use super::map::{ALMH, BITS, HEND, INTEGERS, MOVE, PEND, PWR, SV};

/// A group of polled data and when it was last answered.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stamp(Option<u32>);

impl Stamp {
    /// Answered at `now`.
    pub fn set(&mut self, now: u32) {
        self.0 = Some(now);
    }

    /// Milliseconds since the last answer, saturated at 65,535 (also when
    /// never answered).
    pub fn age(&self, now: u32) -> u16 {
        self.0.map_or(u16::MAX, |t| {
            u16::try_from(now.wrapping_sub(t)).unwrap_or(u16::MAX)
        })
    }
}

/// The polled data.
#[derive(Debug, Clone, Default)]
pub struct Cache {
    /// The axes as 212H last reported them.
    pub axes: [AxisStatus; 8],
    /// Axes whose cached status predates a motion command the controller
    /// confirmed: PEND and HEND read 0 until a 212H sent after it answers.
    pub stale: u8,
    /// When 212H last answered.
    pub axes_at: Stamp,
    /// 213H: status, executing step, error code, error step.
    pub program: [u16; 4],
    /// 215H: mode, most serious error, latest error, status bytes 1 to 4.
    pub system: [u16; 7],
    /// 216H: error number and details 1 to 4.
    pub error: (u16, [u32; 4]),
    /// When 213H, 215H or 216H last answered.
    pub system_at: Stamp,
    /// Input ports, output ports and flags (bit `i`: the `i`-th mapped).
    pub inputs: u32,
    /// Output ports.
    pub outputs: u32,
    /// Flags.
    pub flags: u32,
    /// When 20BH, 20CH or 20DH last answered.
    pub io_at: Stamp,
    /// Integer variables.
    pub integers: [i32; INTEGERS],
    /// When 20EH last answered.
    pub integers_at: Stamp,
    /// The last poll was answered.
    pub link_up: bool,
    /// Polls answered (wrapping).
    pub polls_ok: u16,
    /// Polls that got no reply (wrapping).
    pub polls_failed: u16,
    /// The last `&` code the controller sent the gateway.
    pub last_error: u16,
    /// Writes the command policy refused (wrapping).
    pub refused: u16,
    /// The controller's 201H reply (main CPU application), asked each time
    /// the line comes up; `None` until it answers, while the line is down,
    /// or when the controller refused it.
    pub version: Option<VersionResponse>,
}

impl Cache {
    /// Takes a 212H reply for the axes it names; `fresh` if the query went
    /// out after the last confirmed motion command.
    pub fn axes(&mut self, r: &AxisStatusResponse, fresh: bool, now: u32) {
        for (n, a) in r.axis_pattern.iter().zip(r.axes.iter()) {
            if let Some(slot) = self.axes.get_mut(usize::from(n).wrapping_sub(1)) {
                slot.clone_from(a);
            }
        }
        if fresh {
            self.stale = 0;
        }
        self.axes_at.set(now);
    }

    /// Whether the controller answered (`up`): `true` when the line came
    /// up now (it was down, or never up), and its version is to be asked
    /// (again: it may be another controller). The version is forgotten
    /// while the line is down.
    pub fn set_link(&mut self, up: bool) -> bool {
        let came_up = up && !self.link_up;
        if !up {
            self.version = None;
        }
        self.link_up = up;
        came_up
    }

    /// Takes a 213H reply.
    pub fn program(&mut self, r: &ProgramStatusResponse, now: u32) {
        self.program = [
            u16::from(r.status),
            r.executing_step_number,
            r.program_error_code,
            r.error_step_number,
        ];
        self.system_at.set(now);
    }

    /// Takes a 215H reply.
    pub fn system(&mut self, r: &SystemStatusResponse, now: u32) {
        self.system = [
            u16::from(r.system_mode),
            r.critical_system_error,
            r.latest_system_error,
            u16::from(r.status_byte_1),
            u16::from(r.status_byte_2),
            u16::from(r.status_byte_3),
            u16::from(r.status_byte_4),
        ];
        self.system_at.set(now);
    }

    /// Takes a 216H reply.
    pub fn error_detail(&mut self, r: &ErrorDetailResponse<'_>, now: u32) {
        self.error = (
            r.error_number,
            [r.detail_1, r.detail_2, r.detail_3, r.detail_4 as u32],
        );
        self.system_at.set(now);
    }

    /// DSS1 of axis `i` (0-based).
    pub fn dss1(&self, i: usize) -> u16 {
        let Some(a) = self.axes.get(i) else {
            return 0;
        };
        let fresh = self.stale & (1 << i) == 0;
        let mut w = 0;
        if !fresh || a.in_use() {
            w |= MOVE;
        }
        if self.link_up {
            w |= PWR;
        }
        if a.servo_on() {
            w |= SV;
        }
        if a.error_code != 0 {
            w |= ALMH;
        }
        if fresh && a.homing() == Homing::Done {
            w |= HEND;
        }
        // PEND: the manual's completion check says the last operation
        // completed (not a push error, not cancelled) and the axis is free.
        if fresh && a.outcome() == Some(MoveOutcome::Completed) {
            w |= PEND;
        }
        w
    }

    /// Sets bit `i` of the mapped ports from port bytes (8 a byte, lowest
    /// port in bit 0) starting at the first mapped one.
    pub fn port_bits(bytes: impl Iterator<Item = u8>) -> u32 {
        bytes
            .take(usize::from(BITS / 8))
            .enumerate()
            .fold(0, |acc, (i, b)| acc | u32::from(b) << (8 * i))
    }
}

/// The high and low words of a 32-bit value (high first, as the map
/// sends them).
pub const fn words(v: u32) -> [u16; 2] {
    [(v >> 16) as u16, v as u16]
}
