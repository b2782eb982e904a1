//! The server's context: reads answered from the cache and the settings,
//! writes checked against the map and turned into settings or queued
//! commands. What is refused, and how (Modbus application protocol, 7):
//! an address outside the map or not writable, 02; a value the entry
//! cannot take, 03; a command while one is busy, 06; a command the
//! command policy refuses, 01 (counted in the health block).

use rmodbus::ErrorKind;

use super::cache::{words, Cache};
use super::command::{words_record, Handshake, Job};
use super::map::{
    self, Access, At, Item, Space, ALRS, CSTR, FIRST_FLAG, FIRST_INTEGER, FIRST_OUTPUT, HOME,
    INTEGERS, RECORD_WORDS, SON, STP, WINDOW_RECORDS,
};
use super::poll::Schedule;
use crate::config::{ModbusConfig, Policy};
use iai_protocol_b::message::AxisStatus;

/// Registers of the table window.
pub const WINDOW_WORDS: usize = WINDOW_RECORDS * RECORD_WORDS;

/// The gateway's registers: settings, the cache, the handshake, the
/// table window.
pub struct Registers {
    /// The gateway's settings.
    pub cfg: ModbusConfig,
    /// The command policy (config.rs).
    pub policy: Policy,
    /// DRG1 as last written, per axis.
    pub drg1: [u16; 8],
    /// POSR per axis.
    pub posr: [u16; 8],
    /// The numeric move as last written, per axis.
    pub movn: [[u16; 9]; 8],
    /// The program polled with 213H.
    pub program: u8,
    /// The polled data.
    pub cache: Cache,
    /// The command handshake.
    pub hs: Handshake,
    /// The polling schedule.
    pub schedule: Schedule,
    /// The table window's first position.
    pub head: u16,
    /// The table window as read back, or as written: a write's records
    /// wait here until the transfer takes them (no other command starts
    /// meanwhile), so they read as written while the write is busy and
    /// after it failed.
    pub window: [u16; WINDOW_WORDS],
    /// A master has addressed the gateway: it polls from then on (a
    /// bridge with no PLC on its Modbus port leaves the line alone).
    pub active: bool,
}

/// Most registers a write outside the table window carries (INTV: 16).
const SHORT_WRITE: usize = 16;

/// Big-endian register pairs of `data` into `words` (as many as both have).
fn be_words(words: &mut [u16], data: &[u8]) {
    for (w, pair) in words.iter_mut().zip(data.chunks_exact(2)) {
        if let [hi, lo] = *pair {
            *w = u16::from_be_bytes([hi, lo]);
        }
    }
}

impl Registers {
    /// Fresh registers.
    #[inline(always)]
    pub fn new(cfg: ModbusConfig, policy: Policy) -> Self {
        Registers {
            cfg,
            policy,
            drg1: [0; 8],
            posr: [0; 8],
            movn: [[0; 9]; 8],
            program: 1,
            cache: Cache::default(),
            hs: Handshake::new(),
            schedule: Schedule::new(cfg.poll_period_ms),
            head: 0,
            window: [0; WINDOW_WORDS],
            active: false,
        }
    }

    fn find(&self, space: Space, addr: u16) -> Option<At> {
        map::find(space, addr, self.cfg.axes)
    }

    /// Reads `count` registers from `start` as big-endian bytes into `out`;
    /// `inputs`: function 04 (read-only entries only).
    pub fn read_words(
        &self,
        start: u16,
        count: u16,
        inputs: bool,
        out: &mut [u8],
        now: u32,
    ) -> Result<(), ErrorKind> {
        if count == 0 {
            return Err(ErrorKind::IllegalDataValue);
        }
        for (i, pair) in out.chunks_exact_mut(2).take(usize::from(count)).enumerate() {
            let addr = start
                .checked_add(i as u16)
                .ok_or(ErrorKind::IllegalDataAddress)?;
            let at = self
                .find(Space::Registers, addr)
                .filter(|at| !inputs || at.entry.access == Access::Read)
                .ok_or(ErrorKind::IllegalDataAddress)?;
            pair.copy_from_slice(&self.word(at, now).to_be_bytes());
        }
        Ok(())
    }

    /// The value of one register.
    fn word(&self, at: At, now: u32) -> u16 {
        let b = usize::from(at.block);
        let o = usize::from(at.offset);
        let c = &self.cache;
        let none = AxisStatus::default();
        let axis = c.axes.get(b).unwrap_or(&none);
        let pick = |ws: &[u16]| ws.get(o).copied().unwrap_or(0);
        match at.entry.item {
            Item::Drg1 => pick(self.drg1.get(b..).unwrap_or(&[])),
            Item::Posr => pick(self.posr.get(b..).unwrap_or(&[])),
            Item::Pnow => pick(&words(axis.current_position as u32)),
            Item::Almc => axis.error_code,
            Item::AxisStatus => u16::from(axis.axis_status),
            Item::AxisIo => {
                u16::from(axis.encoder_status) << 8 | u16::from(axis.sensor_input_status)
            }
            Item::Dss1 => c.dss1(b),
            Item::NumericMove => self.movn.get(b).map_or(0, |m| pick(m)),
            Item::ProgramNumber => u16::from(self.program),
            Item::Program => pick(&c.program),
            Item::System => pick(&c.system),
            Item::ErrorDetail => match o.checked_sub(1) {
                None => c.error.0,
                Some(k) => {
                    let d = c.error.1.get(k / 2).copied().unwrap_or(0);
                    words(d).get(k % 2).copied().unwrap_or(0)
                }
            },
            Item::Integers => {
                let v = c.integers.get(o / 2).copied().unwrap_or(0);
                words(v as u32).get(o % 2).copied().unwrap_or(0)
            }
            Item::WindowHead => self.head,
            Item::WindowRecords => pick(&self.window),
            Item::Health => pick(&[
                u16::from(c.link_up),
                c.axes_at.age(now),
                c.system_at.age(now),
                c.io_at.age(now),
                c.integers_at.age(now),
                c.polls_ok,
                c.polls_failed,
                c.last_error,
                c.refused,
                self.cfg.poll_period_ms,
            ]),
            Item::Handshake => pick(&self.hs.words()),
            Item::Inputs | Item::Outputs | Item::Flags => 0,
        }
    }

    /// Reads `count` bits from `start` of `space`, packed (bit 0 first)
    /// into `out`.
    pub fn read_bits(
        &self,
        space: Space,
        start: u16,
        count: u16,
        out: &mut [u8],
    ) -> Result<(), ErrorKind> {
        if count == 0 {
            return Err(ErrorKind::IllegalDataValue);
        }
        for i in 0..count {
            let addr = start.checked_add(i).ok_or(ErrorKind::IllegalDataAddress)?;
            let at = self
                .find(space, addr)
                .ok_or(ErrorKind::IllegalDataAddress)?;
            let bits = match at.entry.item {
                Item::Inputs => self.cache.inputs,
                Item::Outputs => self.cache.outputs,
                Item::Flags => self.cache.flags,
                _ => return Err(ErrorKind::IllegalDataAddress),
            };
            if bits >> at.offset & 1 != 0 {
                if let Some(byte) = out.get_mut(usize::from(i / 8)) {
                    *byte |= 1 << (i % 8);
                }
            }
        }
        Ok(())
    }

    /// Queues `job` if the policy allows its message and no command is
    /// busy (exception 01 or 06 otherwise): the one way in to the
    /// handshake for every front (Modbus, Sparkplug's DCMD).
    pub fn command(&mut self, job: Job) -> Result<(), ErrorKind> {
        if !self.policy.allows(job.message().id) {
            self.cache.refused = self.cache.refused.wrapping_add(1);
            return Err(ErrorKind::IllegalFunction);
        }
        if !self.hs.accept(job) {
            return Err(ErrorKind::SlaveDeviceBusy);
        }
        Ok(())
    }

    /// Writes `count` registers from `start` (`data`: big-endian bytes).
    pub fn write_words(&mut self, start: u16, count: u16, data: &[u8]) -> Result<(), ErrorKind> {
        if count == 0 || data.len() != 2 * usize::from(count) {
            return Err(ErrorKind::IllegalDataValue);
        }
        let at = self
            .find(Space::Registers, start)
            .filter(|at| at.offset + count <= at.entry.size)
            .ok_or(ErrorKind::IllegalDataAddress)?;
        if at.entry.access == Access::Read {
            return Err(ErrorKind::IllegalDataAddress);
        }
        if at.entry.item == Item::WindowRecords {
            // Up to 105 registers: read from the frame as they are copied,
            // not gathered on the stack first.
            return self.write_records(at.offset, data);
        }
        // The other writable entries are at most 16 registers (INTV).
        let mut values = [0u16; SHORT_WRITE];
        be_words(&mut values, data);
        let values = values
            .get(..usize::from(count))
            .ok_or(ErrorKind::IllegalDataAddress)?;
        let first = values.first().copied().unwrap_or(0);
        let b = usize::from(at.block);
        let axis = at.block + 1;
        match at.entry.item {
            Item::Drg1 => self.write_drg1(b, axis, first),
            Item::Posr => {
                if let Some(p) = self.posr.get_mut(b) {
                    *p = first;
                }
                Ok(())
            }
            Item::ProgramNumber => {
                self.program = u8::try_from(first)
                    .ok()
                    .filter(|p| *p > 0)
                    .ok_or(ErrorKind::IllegalDataValue)?;
                Ok(())
            }
            Item::NumericMove => self.write_numeric_move(b, axis, at.offset, values),
            Item::Integers => self.write_integers(at.offset, values),
            Item::WindowHead => {
                // The window's last position must exist: N + 4 ≤ 65535.
                if first > u16::MAX - (WINDOW_RECORDS as u16 - 1) {
                    return Err(ErrorKind::IllegalDataValue);
                }
                self.command(Job::ReadWindow { head: first })?;
                self.head = first;
                Ok(())
            }
            _ => Err(ErrorKind::IllegalDataAddress),
        }
    }

    /// DRG1: SON is a level, HOME, CSTR, STP and ALRS rising edges; one
    /// command per write. The value is kept only when its command was
    /// accepted, so that a refused edge can be written again.
    fn write_drg1(&mut self, b: usize, axis: u8, v: u16) -> Result<(), ErrorKind> {
        let old = self.drg1.get(b).copied().unwrap_or(0);
        let rising = v & !old;
        let mut jobs = [None; 5];
        if (v ^ old) & SON != 0 {
            jobs[0] = Some(Job::Servo {
                axis,
                on: v & SON != 0,
            });
        }
        if rising & HOME != 0 {
            jobs[1] = Some(Job::Home { axis });
        }
        if rising & CSTR != 0 {
            let number = self.posr.get(b).copied().unwrap_or(0);
            jobs[2] = Some(Job::MoveToPosition { axis, number });
        }
        if rising & STP != 0 {
            jobs[3] = Some(Job::Stop { axis });
        }
        if rising & ALRS != 0 {
            jobs[4] = Some(Job::AlarmReset);
        }
        let mut it = jobs.iter().flatten();
        match (it.next(), it.next()) {
            (Some(_), Some(_)) => return Err(ErrorKind::IllegalDataValue),
            (Some(&job), None) => self.command(job)?,
            (None, _) => {}
        }
        if let Some(slot) = self.drg1.get_mut(b) {
            *slot = v;
        }
        Ok(())
    }

    /// The numeric move: all 9 registers in one write.
    fn write_numeric_move(
        &mut self,
        b: usize,
        axis: u8,
        offset: u16,
        v: &[u16],
    ) -> Result<(), ErrorKind> {
        let [p_hi, p_lo, _band_hi, _band_lo, s_hi, s_lo, acc, push, _control] = v else {
            return Err(ErrorKind::IllegalDataValue);
        };
        if offset != 0 || *push != 0 || *s_hi != 0 {
            return Err(ErrorKind::IllegalDataValue);
        }
        let position = (u32::from(*p_hi) << 16 | u32::from(*p_lo)) as i32;
        self.command(Job::Move {
            axis,
            position,
            speed: *s_lo,
            acceleration: *acc,
        })?;
        if let Some(m) = self.movn.get_mut(b) {
            m.copy_from_slice(v);
        }
        Ok(())
    }

    /// Whole integer variables: one 24CH.
    fn write_integers(&mut self, offset: u16, v: &[u16]) -> Result<(), ErrorKind> {
        if !offset.is_multiple_of(2) || !v.len().is_multiple_of(2) {
            return Err(ErrorKind::IllegalDataValue);
        }
        let mut values = [0i32; INTEGERS];
        for (slot, pair) in values.iter_mut().zip(v.chunks_exact(2)) {
            if let [hi, lo] = *pair {
                *slot = (u32::from(hi) << 16 | u32::from(lo)) as i32;
            }
        }
        self.command(Job::Integers {
            first: FIRST_INTEGER + offset / 2,
            count: (v.len() / 2) as u8,
            values,
        })
    }

    /// Whole window records (`data`: big-endian registers): staged in the
    /// window, then written by the transfer.
    fn write_records(&mut self, offset: u16, data: &[u8]) -> Result<(), ErrorKind> {
        let (o, n) = (usize::from(offset), data.len() / 2);
        if !o.is_multiple_of(RECORD_WORDS) || !n.is_multiple_of(RECORD_WORDS) {
            return Err(ErrorKind::IllegalDataValue);
        }
        let mut rec = [0u16; RECORD_WORDS];
        for bytes in data.chunks_exact(2 * RECORD_WORDS) {
            be_words(&mut rec, bytes);
            if words_record(&rec).is_none() {
                return Err(ErrorKind::IllegalDataValue);
            }
        }
        let job = Job::WriteWindow {
            first: (o / RECORD_WORDS) as u8,
            count: (n / RECORD_WORDS) as u8,
        };
        if !self.policy.allows(job.message().id) || self.hs.busy() {
            // The staged records of a busy write must stay as they are.
            return self.command(job);
        }
        if let Some(dst) = self.window.get_mut(o..o + n) {
            be_words(dst, data);
        }
        self.command(job)
    }

    /// Writes `count` coils from `start`: one output port or flag per
    /// write (`data`: packed bits).
    pub fn write_bits(&mut self, start: u16, count: u16, data: &[u8]) -> Result<(), ErrorKind> {
        let at = self
            .find(Space::Coils, start)
            .ok_or(ErrorKind::IllegalDataAddress)?;
        if count != 1 {
            return Err(ErrorKind::IllegalDataValue);
        }
        let on = data.first().is_some_and(|b| b & 1 != 0);
        let job = match at.entry.item {
            Item::Outputs => Job::Output {
                port: FIRST_OUTPUT + at.offset,
                on,
            },
            Item::Flags => Job::Flag {
                flag: FIRST_FLAG + at.offset,
                on,
            },
            _ => return Err(ErrorKind::IllegalDataAddress),
        };
        self.command(job)
    }
}
