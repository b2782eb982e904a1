//! The register map: one table ([`MAP`]), from which the server reads and
//! writes and from which the README's table is checked.
//!
//! Where the ROBO Cylinder (RC) Modbus map has a meaning that applies, its
//! address and bit are used (DRG1 0D00H, POSR 0D03H, PNOW 9000H, ALMC 9002H,
//! DSS1 9005H, the numeric move 9900H), one block per axis, axis `n` at
//! `+10H·(n−1)`, in the SEL's units: positions in 0.001 mm as signed 32-bit
//! values, high word first. Read-only registers answer function 03 and 04
//! alike; settings and command registers answer 03 and take 06 and 16.
//! Bits: discrete input `n` is input port `n`, coil `n` output port or
//! flag `n` (the controller's numbers, decimal).
//!
//! Each entry's registers and bits are described field by field
//! ([`Item::fields`]: type, unit, meaning, what a write starts and what
//! completes it): what `iai modbus map` prints and the README shows. The
//! firmware never calls it, so the descriptions take no flash.

use iai_protocol_b::catalogue::{self, MessageInfo};

/// The Modbus data space of an entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Space {
    /// Coils (functions 01, 05, 15).
    Coils,
    /// Discrete inputs (function 02).
    Discretes,
    /// Registers (functions 03, 04, 06, 16).
    Registers,
}

/// What a write to an entry does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Read only (a write is exception 02).
    Read,
    /// A setting kept in the gateway (no command).
    Setting,
    /// A write starts a command through the handshake ([`Item::Handshake`]).
    Command,
}

/// What an entry holds (the server's dispatch key).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    /// DRG1: control bits of an axis.
    Drg1,
    /// POSR: the position number CSTR moves to.
    Posr,
    /// PNOW: current position.
    Pnow,
    /// ALMC: the axis error code.
    Almc,
    /// The 212H status byte of an axis.
    AxisStatus,
    /// Encoder status (high byte) and sensor inputs (low byte).
    AxisIo,
    /// DSS1: status bits of an axis.
    Dss1,
    /// The numeric move of an axis.
    NumericMove,
    /// The program number polled with 213H.
    ProgramNumber,
    /// 213H: status, step, error code, error step.
    Program,
    /// 215H: mode, errors, status bytes.
    System,
    /// 216H: the latest system error and its details.
    ErrorDetail,
    /// Global integer variables.
    Integers,
    /// The first position of the table window.
    WindowHead,
    /// The records of the table window.
    WindowRecords,
    /// The gateway's health.
    Health,
    /// The command handshake.
    Handshake,
    /// Input ports.
    Inputs,
    /// Output ports.
    Outputs,
    /// Global flags.
    Flags,
}

/// One entry of the register map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Entry {
    /// Short name (the RC name where it has one).
    pub name: &'static str,
    /// What it holds.
    pub item: Item,
    /// Data space.
    pub space: Space,
    /// First address (PDU address, from 0).
    pub start: u16,
    /// Registers or bits per block.
    pub size: u16,
    /// Blocks: 8 for the per-axis entries (axis `n` at `start + 10H·(n−1)`).
    pub blocks: u8,
    /// What a write does.
    pub access: Access,
    /// The protocol-B message it is read from or written with.
    pub message: Option<&'static MessageInfo>,
    /// What the words or bits mean.
    pub meaning: &'static str,
}

/// Distance between two axis blocks.
pub const AXIS_STRIDE: u16 = 0x10;
/// Records in the table window.
pub const WINDOW_RECORDS: usize = 5;
/// Registers per window record: number, axis pattern, acceleration,
/// deceleration, speed, 8 positions of 2 registers.
pub const RECORD_WORDS: usize = 21;
/// Input ports, output ports and flags mapped (from the first of each).
pub const BITS: u16 = 32;
/// First input port, output port, flag and integer variable mapped (the
/// X-SEL's usual numbering: inputs from 000, outputs from 300, global
/// flags from 600, global integer variables from 200).
pub const FIRST_INPUT: u16 = 0;
/// First output port mapped.
pub const FIRST_OUTPUT: u16 = 300;
/// First global flag mapped.
pub const FIRST_FLAG: u16 = 600;
/// First global integer variable mapped.
pub const FIRST_INTEGER: u16 = 200;
/// Integer variables mapped.
pub const INTEGERS: usize = 8;

/// DRG1 bit 12: servo on (a level).
pub const SON: u16 = 1 << 12;
/// DRG1 bit 8: alarm reset (rising edge).
pub const ALRS: u16 = 1 << 8;
/// DRG1 bit 5: stop (rising edge).
pub const STP: u16 = 1 << 5;
/// DRG1 bit 4: home return (rising edge).
pub const HOME: u16 = 1 << 4;
/// DRG1 bit 3: start the move to POSR (rising edge).
pub const CSTR: u16 = 1 << 3;

/// DSS1 bit 13: the controller answers the gateway's polls.
pub const PWR: u16 = 1 << 13;
/// DSS1 bit 12: servo on.
pub const SV: u16 = 1 << 12;
/// DSS1 bit 10: the axis reports an error code.
pub const ALMH: u16 = 1 << 10;
/// DSS1 bit 5: the axis is moving, or its status is not yet from a 212H
/// sent after the gateway's last confirmed command on it (this map's own
/// bit, not the RC's): what a PLC waits to see clear after a command.
pub const MOVE: u16 = 1 << 5;
/// DSS1 bit 4: homed.
pub const HEND: u16 = 1 << 4;
/// DSS1 bit 3: the last operation ended normally and the axis is at rest.
pub const PEND: u16 = 1 << 3;

/// Handshake status word, bit 15: the command failed (code in the next
/// register).
pub const CMD_ERROR: u16 = 1 << 15;
/// Handshake status word, bit 14: a command is queued or on the line.
pub const CMD_BUSY: u16 = 1 << 14;
/// Handshake status word, bit 13: the controller confirmed the command.
pub const CMD_DONE: u16 = 1 << 13;

/// One row of [`MAP`], in the order its columns are read.
#[allow(clippy::too_many_arguments)]
const fn entry(
    name: &'static str,
    item: Item,
    space: Space,
    start: u16,
    size: u16,
    blocks: u8,
    access: Access,
    message: Option<&'static MessageInfo>,
    meaning: &'static str,
) -> Entry {
    Entry {
        name,
        item,
        space,
        start,
        size,
        blocks,
        access,
        message,
        meaning,
    }
}

use Access::{Command, Read, Setting};
use Space::{Coils, Discretes, Registers};

/// The register map, by ascending start address within each space.
pub const MAP: &[Entry] = &[
    entry("DRG1", Item::Drg1, Registers, 0x0D00, 1, 8, Command, None,
        "bit 12 SON servo on (level, 232H); rising edges: bit 4 HOME (233H), bit 3 CSTR move to POSR (26BH), bit 5 STP stop (238H), bit 8 ALRS alarm reset (252H); one command per write"),
    entry("POSR", Item::Posr, Registers, 0x0D03, 1, 8, Setting, None,
        "position number CSTR moves to"),
    entry("PRGNO", Item::ProgramNumber, Registers, 0x2130, 1, 1, Setting, None,
        "program number polled with 213H (1..=255, default 1)"),
    entry("PRGST", Item::Program, Registers, 0x2131, 4, 1, Read, Some(&catalogue::PROGRAM_STATUS_QUERY),
        "program status, executing step, program error code, error step"),
    entry("SYSST", Item::System, Registers, 0x2150, 7, 1, Read, Some(&catalogue::SYSTEM_STATUS_QUERY),
        "system mode, most serious error, latest error, status bytes 1 to 4"),
    entry("ERRDT", Item::ErrorDetail, Registers, 0x2160, 9, 1, Read, Some(&catalogue::ERROR_DETAIL_QUERY),
        "latest system error: number, details 1 to 4 (2 registers each, high word first)"),
    entry("INTV", Item::Integers, Registers, 0x20E0, 16, 1, Command, Some(&catalogue::INTEGER_VARIABLE_CHANGE),
        "global integer variables 200 to 207, 2 registers each (signed, high word first); read from 20EH, a write of whole variables is one 24CH"),
    entry("PWHEAD", Item::WindowHead, Registers, 0x21F0, 1, 1, Command, Some(&catalogue::EFFECTIVE_POSITION_QUERY_2),
        "first position of the table window: a write reads positions N..N+4 (21FH, two replies that agree)"),
    entry("PWREC", Item::WindowRecords, Registers, 0x2200, 105, 1, Command, Some(&catalogue::CHANGE_POSITION_DATA_2),
        "5 records of 21 registers: number, axis pattern, acceleration, deceleration, speed, axes 1 to 8 (2 registers each); a write of whole records is written with 26DH, read back with 21FH and compared"),
    entry("PNOW", Item::Pnow, Registers, 0x9000, 2, 8, Read, Some(&catalogue::AXIS_STATUS_QUERY),
        "current position, 0.001 mm, signed, high word first"),
    entry("ALMC", Item::Almc, Registers, 0x9002, 1, 8, Read, Some(&catalogue::AXIS_STATUS_QUERY),
        "axis error code (0: none)"),
    entry("AXST", Item::AxisStatus, Registers, 0x9003, 1, 8, Read, Some(&catalogue::AXIS_STATUS_QUERY),
        "212H status byte: bit 0 in use, bits 1-2 homing (2 done), bit 3 servo on, bit 4 completed"),
    entry("AXIO", Item::AxisIo, Registers, 0x9004, 1, 8, Read, Some(&catalogue::AXIS_STATUS_QUERY),
        "encoder status (high byte), sensor inputs (low byte)"),
    entry("DSS1", Item::Dss1, Registers, 0x9005, 1, 8, Read, Some(&catalogue::AXIS_STATUS_QUERY),
        "bit 13 PWR controller answering, bit 12 SV servo on, bit 10 ALMH error, bit 5 MOVE moving or not yet polled since a command, bit 4 HEND homed, bit 3 PEND completed and at rest"),
    entry("MOVN", Item::NumericMove, Registers, 0x9900, 9, 8, Command, Some(&catalogue::ABSOLUTE_MOVE),
        "numeric move, 9 registers in one write: position (2, 0.001 mm), band (2, ignored), speed (2, mm/s), acceleration (0.01 G), push (must be 0), control (ignored)"),
    entry("HEALTH", Item::Health, Registers, 0xB000, 10, 1, Read, None,
        "link up, ages (ms) of axis, system, I/O and variable data, polls answered, polls unanswered, last & code, writes refused, polling period (ms)"),
    entry("CMDST", Item::Handshake, Registers, 0xB100, 3, 1, Read, None,
        "handshake: status word (bit 15 error, bit 14 busy, bit 13 done, low byte the command's sequence number), error code, protocol-B message ID"),
    entry("IN", Item::Inputs, Discretes, FIRST_INPUT, BITS, 1, Read, Some(&catalogue::INPUT_PORT_QUERY),
        "input ports 000 to 031"),
    entry("OUT", Item::Outputs, Coils, FIRST_OUTPUT, BITS, 1, Command, Some(&catalogue::OUTPUT_PORT_CHANGE),
        "output ports 300 to 331: read from 20CH, one coil per write (24AH)"),
    entry("FLAG", Item::Flags, Coils, FIRST_FLAG, BITS, 1, Command, Some(&catalogue::FLAG_CHANGE),
        "global flags 600 to 631: read from 20DH, one coil per write (24BH)"),
];

/// How a field's registers are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Type {
    /// One register, unsigned.
    U16,
    /// Two registers, signed (two's complement), high word first.
    I32,
    /// Two registers, unsigned, high word first.
    U32,
    /// One register of bits (its bits follow as [`Type::Bit`] fields).
    Bits,
    /// One bit of the register at the field's offset.
    Bit(u8),
    /// The low byte of the register at the field's offset.
    Low8,
    /// One coil or discrete input.
    Bool,
}

impl Type {
    /// Registers (or bits, in the bit spaces) the field takes; 0 for the
    /// parts of a register.
    pub const fn width(self) -> u16 {
        match self {
            Type::I32 | Type::U32 => 2,
            Type::U16 | Type::Bits | Type::Bool => 1,
            Type::Bit(_) | Type::Low8 => 0,
        }
    }
}

/// One field of an entry: a register, a register pair, a bit or a byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    /// Offset in the entry's block (in its record, for [`Fields::repeat`]
    /// over 1).
    pub offset: u16,
    /// Short name (the entry's own for an entry of one field).
    pub name: &'static str,
    /// Its type.
    pub ty: Type,
    /// Unit and scale ("" for none).
    pub unit: &'static str,
    /// What it means; for a writable field, what a write starts and what
    /// completes it.
    pub meaning: &'static str,
}

/// The fields of an entry: `list`, repeated `repeat` times `stride`
/// registers (or bits) apart, the `k`-th numbered `first + k`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fields {
    /// Repetitions (records, variables, ports).
    pub repeat: u16,
    /// Distance between two repetitions.
    pub stride: u16,
    /// Number of the first repetition (position record 1, port 300, ...).
    pub first: u16,
    /// What the repetitions are ("records", "ports"; "" for one).
    pub counts: &'static str,
    /// The fields of one repetition.
    pub list: &'static [Field],
}

/// A [`Field`] (a struct expression, so that the lists are promoted to
/// statics).
macro_rules! f {
    ($offset:expr, $name:expr, $ty:expr, $unit:expr, $meaning:expr) => {
        Field {
            offset: $offset,
            name: $name,
            ty: $ty,
            unit: $unit,
            meaning: $meaning,
        }
    };
}

const fn once(list: &'static [Field]) -> Fields {
    Fields {
        repeat: 1,
        stride: 0,
        first: 0,
        counts: "",
        list,
    }
}

use Type::{Bit, Bits, Bool, Low8, I32, U16, U32};

/// What completes a write of a [`Access::Command`] entry ("Done" in the
/// fields' meanings): the handshake, read after the write's answer.
pub const DONE: &str = "Done: CMDST's SEQ is the write's (one more than before it) and BUSY is 0: DONE 1 confirmed, ERR 1 failed with CODE";

impl Item {
    /// Its registers or bits, field by field.
    #[rustfmt::skip]
    pub const fn fields(self) -> Fields {
        match self {
            Item::Drg1 => once(&[
                f!(0, "DRG1", Bits, "", "control word of the axis; a write changes at most one of SON, HOME, CSTR, STP, ALRS (two: exception 03); reads back as last accepted"),
                f!(0, "SON", Bit(12), "", "servo on while 1, off when 0 (a level: a write that changes it sends 232H for this axis). Done, then DSS1 SV follows"),
                f!(0, "ALRS", Bit(8), "", "alarm reset on 0 to 1 (252H, the whole controller). Done, then wait for MOVE 0 on the axes; ALMH then says whether the alarm cleared"),
                f!(0, "STP", Bit(5), "", "stop on 0 to 1 (238H, this axis). Done, then wait for MOVE 0; PEND stays 0 (the operation did not complete)"),
                f!(0, "HOME", Bit(4), "", "home return on 0 to 1 (233H, this axis). Done, then wait for MOVE 0 and HEND 1"),
                f!(0, "CSTR", Bit(3), "", "move to position POSR on 0 to 1 (26BH, this axis only, whatever axes the record holds). Done, then wait for MOVE 0 and PEND 1; an undefined position: failed, code 0E7"),
            ]),
            Item::Posr => once(&[
                f!(0, "POSR", U16, "position number", "the position CSTR moves to (kept in the gateway, any value)"),
            ]),
            Item::ProgramNumber => once(&[
                f!(0, "PRGNO", U16, "program number", "the program 213H is polled for, 1..=255 (0 or above: exception 03); default 1"),
            ]),
            Item::Program => once(&[
                f!(0, "STATUS", U16, "", "213H program status code"),
                f!(1, "STEP", U16, "step number", "step being executed"),
                f!(2, "ERROR", U16, "error code", "program error code (0: none)"),
                f!(3, "ERRSTEP", U16, "step number", "step where the error occurred"),
            ]),
            Item::System => once(&[
                f!(0, "MODE", U16, "", "215H system mode"),
                f!(1, "CRITICAL", U16, "error code", "most serious system error (0: none)"),
                f!(2, "LATEST", U16, "error code", "latest system error (0: none)"),
                f!(3, "STATUS1", U16, "", "system status byte 1 (low byte)"),
                f!(4, "STATUS2", U16, "", "system status byte 2 (low byte)"),
                f!(5, "STATUS3", U16, "", "system status byte 3 (low byte)"),
                f!(6, "STATUS4", U16, "", "system status byte 4 (low byte)"),
            ]),
            Item::ErrorDetail => once(&[
                f!(0, "NUMBER", U16, "error code", "216H latest system error number"),
                f!(1, "DETAIL1", U32, "", "detail 1"),
                f!(3, "DETAIL2", U32, "", "detail 2"),
                f!(5, "DETAIL3", U32, "", "detail 3"),
                f!(7, "DETAIL4", U32, "", "detail 4"),
            ]),
            Item::Integers => Fields { repeat: INTEGERS as u16, stride: 2, first: FIRST_INTEGER,
                counts: "variables", list: &[
                f!(0, "INTV", I32, "", "global integer variable (read from 20EH); a write of whole variables (even offset, even count) is one 24CH. Done, then the value reads back after the next poll"),
            ]},
            Item::WindowHead => once(&[
                f!(0, "PWHEAD", U16, "position number", "first position N of the table window, 0..=65531 (above: exception 03): a write reads positions N..N+4 (21FH, two replies that agree). Done, then PWREC holds them"),
            ]),
            Item::WindowRecords => Fields { repeat: WINDOW_RECORDS as u16, stride: RECORD_WORDS as u16, first: 1, counts: "records", list: &[
                f!(0, "NUM", U16, "position number", "the record's position number (a write may name any, in any order)"),
                f!(1, "PAT", U16, "axis pattern", "bit n-1: axis n has a coordinate; 0 on read: the position is not defined; a write with 0 or above FFH: exception 03"),
                f!(2, "ACC", U16, "0.01 G", "acceleration"),
                f!(3, "DEC", U16, "0.01 G", "deceleration"),
                f!(4, "SPD", U16, "mm/s", "speed"),
                f!(5, "POS1", I32, "0.001 mm", "axis 1's coordinate; 0 when the pattern has no axis 1"),
                f!(7, "POS2", I32, "0.001 mm", "axis 2's coordinate; 0 when not in the pattern"),
                f!(9, "POS3", I32, "0.001 mm", "axis 3's coordinate; 0 when not in the pattern"),
                f!(11, "POS4", I32, "0.001 mm", "axis 4's coordinate; 0 when not in the pattern"),
                f!(13, "POS5", I32, "0.001 mm", "axis 5's coordinate; 0 when not in the pattern"),
                f!(15, "POS6", I32, "0.001 mm", "axis 6's coordinate; 0 when not in the pattern"),
                f!(17, "POS7", I32, "0.001 mm", "axis 7's coordinate; 0 when not in the pattern"),
                f!(19, "POS8", I32, "0.001 mm", "axis 8's coordinate; 0 when not in the pattern"),
            ]},
            Item::Pnow => once(&[
                f!(0, "PNOW", I32, "0.001 mm", "current position (212H)"),
            ]),
            Item::Almc => once(&[
                f!(0, "ALMC", U16, "error code", "axis error code (212H; 0: none)"),
            ]),
            Item::AxisStatus => once(&[
                f!(0, "AXST", U16, "", "212H status byte: bit 0 in use, bits 1-2 homing (2: done), bit 3 servo on, bit 4 completed, bit 5 push error"),
            ]),
            Item::AxisIo => once(&[
                f!(0, "AXIO", U16, "", "encoder status (high byte), sensor inputs (low byte: bit 0 creep, 1 overrun, 2 origin)"),
            ]),
            Item::Dss1 => once(&[
                f!(0, "DSS1", Bits, "", "status of the axis from the latest 212H (all 0 before the first)"),
                f!(0, "PWR", Bit(13), "", "the controller answers the gateway's polls"),
                f!(0, "SV", Bit(12), "", "servo on"),
                f!(0, "ALMH", Bit(10), "", "the axis reports an error code (ALMC)"),
                f!(0, "MOVE", Bit(5), "", "moving (212H in use), or not yet polled since the gateway's last confirmed command on this axis or alarm reset: wait for 0 after each command"),
                f!(0, "HEND", Bit(4), "", "homed (0 while MOVE is 1 after a command)"),
                f!(0, "PEND", Bit(3), "", "the last operation completed and the axis is at rest (0 while MOVE is 1 after a command, and after a stop)"),
            ]),
            Item::NumericMove => once(&[
                f!(0, "POS", I32, "0.001 mm", "target of the numeric move; the 9 registers are written in one write (fewer, or from another offset: exception 03), which sends 234H for this axis. Done, then wait for MOVE 0 and PEND 1"),
                f!(2, "BAND", U32, "", "ignored (234H has no positioning band)"),
                f!(4, "SPD", U32, "mm/s", "speed, 0: the controller's parameter; high word above 0: exception 03"),
                f!(6, "ACC", U16, "0.01 G", "acceleration and deceleration, 0: the controller's parameter"),
                f!(7, "PUSH", U16, "", "must be 0 (234H cannot push: exception 03)"),
                f!(8, "CTRL", U16, "", "ignored"),
            ]),
            Item::Health => once(&[
                f!(0, "LINK", U16, "", "1: the last poll or command was answered"),
                f!(1, "AGE_AXES", U16, "ms", "age of PNOW..DSS1 (65535: never polled, or older)"),
                f!(2, "AGE_SYSTEM", U16, "ms", "age of PRGST, SYSST, ERRDT"),
                f!(3, "AGE_IO", U16, "ms", "age of IN, OUT, FLAG"),
                f!(4, "AGE_VARS", U16, "ms", "age of INTV"),
                f!(5, "POLLS_OK", U16, "", "polls answered (wrapping)"),
                f!(6, "POLLS_FAILED", U16, "", "polls unanswered (wrapping)"),
                f!(7, "LAST_ERROR", U16, "error code", "the last & code the controller sent the gateway"),
                f!(8, "REFUSED", U16, "", "writes the command policy refused (wrapping)"),
                f!(9, "PERIOD", U16, "ms", "polling period"),
            ]),
            Item::Handshake => once(&[
                f!(0, "CMDST", Bits, "", "command status"),
                f!(0, "ERR", Bit(15), "", "the last command failed (code in CMDST+1)"),
                f!(0, "BUSY", Bit(14), "", "a command is queued or on the line (another command write: exception 06)"),
                f!(0, "DONE", Bit(13), "", "the controller confirmed the last command"),
                f!(0, "SEQ", Low8, "", "commands accepted, wrapping: +1 per accepted command write, unchanged by a refused write"),
                f!(1, "CODE", U16, "error code", "why the last command failed: the controller's & code, B02 no answer, B0A read back different, B05 not started"),
                f!(2, "MSG", U16, "message ID", "the protocol-B message of the last accepted command (232H, 233H, ...)"),
            ]),
            Item::Inputs => Fields { repeat: BITS, stride: 1, first: FIRST_INPUT,
                counts: "input ports", list: &[
                f!(0, "IN", Bool, "", "input port (20BH)"),
            ]},
            Item::Outputs => Fields { repeat: BITS, stride: 1, first: FIRST_OUTPUT,
                counts: "output ports", list: &[
                f!(0, "OUT", Bool, "", "output port (read from 20CH); a write of one coil sends 24AH. Done, then it reads back after the next poll"),
            ]},
            Item::Flags => Fields { repeat: BITS, stride: 1, first: FIRST_FLAG,
                counts: "flags", list: &[
                f!(0, "FLAG", Bool, "", "global flag (read from 20DH); a write of one coil sends 24BH. Done, then it reads back after the next poll"),
            ]},
        }
    }
}

/// Where an address falls in the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct At {
    /// The entry.
    pub entry: &'static Entry,
    /// The block (axis − 1 for the per-axis entries).
    pub block: u8,
    /// Offset of the address in its block.
    pub offset: u16,
}

/// The entry, block and offset of `addr` in `space`; `None` outside the
/// map (or in a block beyond `blocks`, for the per-axis entries).
pub fn find(space: Space, addr: u16, blocks: u8) -> Option<At> {
    MAP.iter().filter(|e| e.space == space).find_map(|e| {
        let rel = addr.checked_sub(e.start)?;
        let (block, offset) = if e.blocks > 1 {
            (rel / AXIS_STRIDE, rel % AXIS_STRIDE)
        } else {
            (0, rel)
        };
        let block = u8::try_from(block).ok()?;
        (offset < e.size && block < e.blocks.min(blocks.max(1))).then_some(At {
            entry: e,
            block,
            offset,
        })
    })
}

/// Registers (or bits) the whole map holds, all blocks counted: the map's
/// size.
pub fn size() -> (u32, u32) {
    MAP.iter().fold((0, 0), |(regs, bits), e| {
        let n = u32::from(e.size) * u32::from(e.blocks);
        match e.space {
            Space::Registers => (regs + n, bits),
            _ => (regs, bits + n),
        }
    })
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn addresses_fall_in_one_entry_each() {
        let at = find(Space::Registers, 0x9015, 8).unwrap();
        assert_eq!((at.entry.name, at.block, at.offset), ("DSS1", 1, 0));
        let at = find(Space::Registers, 0x9001, 8).unwrap();
        assert_eq!((at.entry.name, at.block, at.offset), ("PNOW", 0, 1));
        // Axis 3's block when two axes are mapped: outside.
        assert_eq!(find(Space::Registers, 0x9020, 2), None);
        assert_eq!(find(Space::Registers, 0x9006, 8), None);
        assert_eq!(find(Space::Coils, 331, 8).unwrap().offset, 31);
        assert_eq!(find(Space::Coils, 332, 8), None);
        // No two entries share an address.
        for space in [Space::Coils, Space::Discretes, Space::Registers] {
            for addr in 0..=u16::MAX {
                let n = MAP
                    .iter()
                    .filter(|e| e.space == space)
                    .filter(|e| {
                        addr.checked_sub(e.start).is_some_and(|rel| {
                            let (b, o) = if e.blocks > 1 {
                                (rel / AXIS_STRIDE, rel % AXIS_STRIDE)
                            } else {
                                (0, rel)
                            };
                            o < e.size && b < u16::from(e.blocks)
                        })
                    })
                    .count();
                assert!(n <= 1, "{space:?} {addr:#06x}");
            }
        }
        assert_eq!(size(), (292, 96));
    }

    #[test]
    fn fields_cover_every_register_once() {
        for e in MAP {
            let fs = e.item.fields();
            let unit = if e.space == Space::Registers {
                "register"
            } else {
                "bit"
            };
            let mut covered = std::vec![0u8; usize::from(e.size)];
            let mut words = std::vec![false; usize::from(e.size)];
            for k in 0..fs.repeat {
                for fld in fs.list {
                    let at = k * fs.stride + fld.offset;
                    for i in at..at + fld.ty.width() {
                        covered[usize::from(i)] += 1;
                    }
                    if fld.ty == Type::Bits {
                        words[usize::from(at)] = true;
                    }
                }
            }
            assert!(
                covered.iter().all(|&n| n == 1),
                "{}: {unit}s covered {covered:?}",
                e.name
            );
            // Bits and bytes lie in a register of bits.
            for fld in fs.list {
                if let Type::Bit(_) | Type::Low8 = fld.ty {
                    assert!(words[usize::from(fld.offset)], "{}.{}", e.name, fld.name);
                }
            }
        }
        // The bit constants are the fields' bits.
        let bit = |item: Item, name: &str| {
            item.fields().list.iter().find_map(|f| match f.ty {
                Type::Bit(b) if f.name == name => Some(1u16 << b),
                _ => None,
            })
        };
        for (item, name, value) in [
            (Item::Drg1, "SON", SON),
            (Item::Drg1, "ALRS", ALRS),
            (Item::Drg1, "STP", STP),
            (Item::Drg1, "HOME", HOME),
            (Item::Drg1, "CSTR", CSTR),
            (Item::Dss1, "PWR", PWR),
            (Item::Dss1, "SV", SV),
            (Item::Dss1, "ALMH", ALMH),
            (Item::Dss1, "MOVE", MOVE),
            (Item::Dss1, "HEND", HEND),
            (Item::Dss1, "PEND", PEND),
            (Item::Handshake, "ERR", CMD_ERROR),
            (Item::Handshake, "BUSY", CMD_BUSY),
            (Item::Handshake, "DONE", CMD_DONE),
        ] {
            assert_eq!(bit(item, name), Some(value), "{name}");
        }
    }
}
