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
        "bit 13 PWR controller answering, bit 12 SV servo on, bit 10 ALMH error, bit 4 HEND homed, bit 3 PEND completed and at rest"),
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
}
