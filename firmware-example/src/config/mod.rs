//! The bridge's run-time configuration and the command policy, and the
//! configuration page that holds it.
//!
//! A board reads a [`Config`] at start from the bridge's block at the
//! start of the configuration page ([`Config::from_block`]); a blank or
//! invalid block gives [`Config::DEFAULT`] and the status query says which
//! ([`Source`]). The page ([`page`]) holds independent blocks, each with
//! its own magic, version and CRC; it is kept in two flash slots by the
//! [`store`], so that a power cut leaves the old or the new page. Every
//! setting of the page is declared once, in [`settings`]; [`access`] holds
//! the web block and the password that guards every write, [`editor`] the
//! writes themselves and [`wire`] the bridge's messages that carry them.
//!
//! # Bridge block (128 bytes in version 3, multi-byte numbers little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `IAIB` |
//! | 4 | 1 | layout version, 3 (versions 1 and 2, 64 bytes, are still read: their missing fields take the defaults) |
//! | 5 | 1 | upstream flow control: 0 none, 1 XON/XOFF, 2 RTS/CTS |
//! | 6 | 1 | controller station (I/O parameter No. 91 of the controller) |
//! | 7 | 1 | the bridge's own station (must differ) |
//! | 8 | 4 | upstream baud rate |
//! | 12 | 4 | downstream baud rate |
//! | 16 | 1 | policy: 0 forward all, 1 read-only preset, 2 allow-list |
//! | 17 | 1 | flags: bit 0 = honour the quit sequence (QEMU test runs only) |
//! | 18 | 1 | Modbus unit ID, [`UNITS`] (version 2; 0 in version 1) |
//! | 19 | 1 | Modbus: bits 0-1 parity (0 none, 1 even, 2 odd); bit 2 = the upstream port speaks Modbus RTU instead of protocol B (two-UART boards) |
//! | 20 | 32 | allow-list: bit `id - 200H` (byte `(id - 200H) / 8`, bit `id % 8`) for IDs 200H..2FFH |
//! | 52 | 4 | Modbus baud rate (version 2) |
//! | 56 | 2 | Modbus: polling period, ms, [`POLL_PERIODS_MS`] (version 2) |
//! | 58 | 1 | Modbus: axes polled and mapped, [`AXES`] (version 2) |
//! | 59 | 1 | 0 |
//! | 60 | 4 | duplicate window, ms, [`DUPLICATE_WINDOWS_MS`] (version 3; versions 1 and 2 end here with their CRC) |
//! | 64 | 4 | XOFF hold, ms, [`XOFF_HOLDS_MS`] (version 3) |
//! | 68 | 56 | 0 |
//! | 124 | 4 | CRC-32 (IEEE 802.3, as zlib's `crc32`) of bytes 0..124 |
//!
//! The command policy applies to both upstreams: a Modbus write whose
//! protocol-B command the policy refuses is answered with exception 01.
//!
//! Baud rates must be one a TTA offers (9,600, 19,200, 38,400, 57,600,
//! 115,200; TTA p. 7). A board that cannot set a rate (QEMU ignores them)
//! still reports the configured one.

pub mod access;
pub mod editor;
pub mod page;
pub mod settings;
pub mod store;
pub mod wire;

use core::ops::RangeInclusive;

use iai_protocol_b::catalogue;
use iai_protocol_b::frame::Station;

use crate::serial::FlowControl;

/// Size of the bridge's block (version 3).
pub const BLOCK_LEN: usize = 128;
/// Size of a version 1 or 2 block.
pub const BLOCK_LEN_V2: usize = 64;
/// First bytes of a configuration block.
pub const MAGIC: [u8; 4] = *b"IAIB";
/// Layout version this firmware writes (it reads 1, 2 and 3).
pub const VERSION: u8 = 3;
/// The longest an XOFF holds the bridge's transmitter unless configured
/// otherwise, ms: longer than any host's pause to drain its buffer, short
/// enough that a bridge stopped by noise answers again within the host's
/// resends.
pub const DEFAULT_XOFF_HOLD_MS: u32 = 5_000;
/// Baud rates the TTA offers (TTA p. 7).
pub const BAUD_RATES: [u32; 5] = [9_600, 19_200, 38_400, 57_600, 115_200];
/// Modbus unit IDs a gateway may take (0 is the broadcast, 248..=255
/// are reserved by the Modbus specification).
pub const UNITS: RangeInclusive<u8> = 1..=247;
/// The Modbus gateway's polling periods, ms.
pub const POLL_PERIODS_MS: RangeInclusive<u16> = 10..=60_000;
/// Axes the Modbus gateway polls and maps.
pub const AXES: RangeInclusive<u8> = 1..=8;
/// Duplicate windows a line may declare, ms (0: a direct line).
pub const DUPLICATE_WINDOWS_MS: RangeInclusive<u32> = 0..=60_000;
/// How long an XOFF from the host may hold the bridge's transmitter, ms.
pub const XOFF_HOLDS_MS: RangeInclusive<u32> = 100..=60_000;

/// Parity of the Modbus line (8 data bits; 1 stop bit with parity, 2
/// without, as the Modbus serial-line specification asks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Parity {
    /// No parity, 2 stop bits.
    None,
    /// Even parity (the Modbus default).
    Even,
    /// Odd parity.
    Odd,
}

impl Parity {
    /// Code in the configuration block (bits 0-1 of byte 19).
    pub const fn code(self) -> u8 {
        match self {
            Parity::None => 0,
            Parity::Even => 1,
            Parity::Odd => 2,
        }
    }

    /// The parity with this code.
    pub const fn from_code(code: u8) -> Option<Parity> {
        match code {
            0 => Some(Parity::None),
            1 => Some(Parity::Even),
            2 => Some(Parity::Odd),
            _ => None,
        }
    }
}

/// What the upstream port speaks on a board with one upstream port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpstreamProtocol {
    /// Protocol B (the bridge).
    ProtocolB,
    /// Modbus RTU (the PLC gateway).
    ModbusRtu,
}

/// The Modbus RTU gateway's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ModbusConfig {
    /// The gateway's unit ID (1..=247).
    pub unit: u8,
    /// Line rate.
    pub baud: u32,
    /// Parity.
    pub parity: Parity,
    /// How often the gateway polls the controller for its cache, ms.
    pub poll_period_ms: u16,
    /// Axes polled and mapped (1..=8): axis blocks beyond them answer
    /// exception 02.
    pub axes: u8,
}

impl ModbusConfig {
    /// Unit 1, 115,200 baud, even parity, polled every 100 ms, 8 axes.
    pub const DEFAULT: ModbusConfig = ModbusConfig {
        unit: 1,
        baud: 115_200,
        parity: Parity::Even,
        poll_period_ms: 100,
        axes: 8,
    };
}

/// Which commands the bridge forwards to the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Policy {
    /// Every well-formed command (the default).
    ForwardAll,
    /// Queries only: the IDs of [`READ_ONLY`].
    ReadOnly,
    /// The IDs set in the list.
    Allow(AllowList),
}

/// The read-only preset: every message the catalogue says only reads (the
/// queries of TTA 4-3 and the 2003 spec, 200H the test call among them).
pub const READ_ONLY: &[u16] = &catalogue::QUERIES;

impl Policy {
    /// Code in the configuration block and the status reply.
    pub const fn code(&self) -> u8 {
        match self {
            Policy::ForwardAll => 0,
            Policy::ReadOnly => 1,
            Policy::Allow(_) => 2,
        }
    }

    /// Whether a command with message ID `id` may reach the controller.
    pub fn allows(&self, id: u16) -> bool {
        match self {
            Policy::ForwardAll => true,
            Policy::ReadOnly => catalogue::is_query(id),
            Policy::Allow(list) => list.contains(id),
        }
    }
}

/// A set of message IDs among 200H..2FFH (a 256-bit map).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AllowList([u8; 32]);

impl AllowList {
    /// The empty list.
    pub const fn new() -> Self {
        AllowList([0; 32])
    }

    /// The list with these IDs (others than 200H..2FFH are ignored).
    pub fn of(ids: &[u16]) -> Self {
        let mut l = AllowList::new();
        for &id in ids {
            l.insert(id);
        }
        l
    }

    /// Adds `id`; `false` if it is outside 200H..2FFH.
    pub fn insert(&mut self, id: u16) -> bool {
        match Self::slot(id).and_then(|(byte, bit)| self.0.get_mut(byte).map(|b| (b, bit))) {
            Some((b, bit)) => {
                *b |= bit;
                true
            }
            None => false,
        }
    }

    /// Whether `id` is in the list.
    pub fn contains(&self, id: u16) -> bool {
        Self::slot(id)
            .and_then(|(byte, bit)| self.0.get(byte).map(|b| b & bit != 0))
            .unwrap_or(false)
    }

    /// Number of IDs in the list.
    pub fn len(&self) -> u32 {
        self.0.iter().map(|b| b.count_ones()).sum()
    }

    /// Whether the list is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The 32-byte map as stored in the configuration block.
    pub const fn bytes(&self) -> [u8; 32] {
        self.0
    }

    /// The list with this 32-byte map.
    pub const fn from_bytes(map: [u8; 32]) -> Self {
        AllowList(map)
    }

    /// The IDs in the list, lowest first.
    pub fn ids(&self) -> impl Iterator<Item = u16> + '_ {
        (catalogue::LOWEST_ID..catalogue::LOWEST_ID + 0x100).filter(|&id| self.contains(id))
    }

    fn slot(id: u16) -> Option<(usize, u8)> {
        let i = id
            .checked_sub(catalogue::LOWEST_ID)
            .filter(|i| *i < 0x100)?;
        Some((usize::from(i / 8), 1 << (i % 8)))
    }
}

/// Where the configuration in force came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Source {
    /// Built-in defaults (no block was given).
    Default,
    /// A valid configuration block.
    Block,
    /// Defaults, because the block is blank (erased flash: no magic).
    Blank,
    /// Defaults, because the block is invalid (this reason).
    Invalid(BlockError),
}

impl Source {
    /// Code in the status reply: 0 default, 1 block, 2 blank, 3 invalid.
    pub const fn code(&self) -> u8 {
        match self {
            Source::Default => 0,
            Source::Block => 1,
            Source::Blank => 2,
            Source::Invalid(_) => 3,
        }
    }
}

/// Why a configuration block was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BlockError {
    /// Fewer than [`BLOCK_LEN`] bytes.
    TooShort,
    /// The CRC does not match.
    Crc,
    /// A layout version this firmware does not read.
    Version,
    /// A field holds a value outside its range (byte offset).
    Field(u8),
}

/// The bridge's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Upstream (host) baud rate.
    pub upstream_baud: u32,
    /// Downstream (controller) baud rate.
    pub downstream_baud: u32,
    /// The controller's station: commands for it are forwarded (policy
    /// permitting), commands for other stations are dropped.
    pub controller_station: Station,
    /// The bridge's own station (status query).
    pub bridge_station: Station,
    /// Upstream flow control.
    pub flow: FlowControl,
    /// Which commands reach the controller.
    pub policy: Policy,
    /// Whether the quit sequence ([`crate::codes::QUIT`]) ends the run
    /// (QEMU tests; off on hardware).
    pub quit_sequence: bool,
    /// The Modbus RTU gateway.
    pub modbus: ModbusConfig,
    /// What the upstream port speaks on a two-UART board (a board with a
    /// port of its own for Modbus ignores it).
    pub upstream: UpstreamProtocol,
    /// How long after a reply a copy of it may arrive on the controller
    /// line, ms (a converter that repeats frames); 0 for a direct wire (the
    /// line still notices copies and then expects them).
    pub duplicate_window_ms: u32,
    /// The longest an XOFF from the host holds the bridge's transmitter,
    /// ms: noise that looks like XOFF must not stop the bridge for good.
    pub xoff_hold_ms: u32,
}

impl Config {
    /// Station 99 (the spec's examples), bridge on station BB, 115,200
    /// baud both sides, XON/XOFF upstream, forward all, no quit sequence;
    /// Modbus as [`ModbusConfig::DEFAULT`], protocol B upstream, no
    /// duplicate window, an XOFF held at most 5 s.
    pub const DEFAULT: Config = Config {
        upstream_baud: 115_200,
        downstream_baud: 115_200,
        controller_station: Station(0x99),
        bridge_station: Station(0xBB),
        flow: FlowControl::XonXoff,
        policy: Policy::ForwardAll,
        quit_sequence: false,
        modbus: ModbusConfig::DEFAULT,
        upstream: UpstreamProtocol::ProtocolB,
        duplicate_window_ms: 0,
        xoff_hold_ms: 5_000,
    };

    /// Reads a configuration block: the configuration and where it came
    /// from. Never fails: a blank or invalid block gives [`Config::DEFAULT`].
    pub fn from_block(block: &[u8]) -> (Config, Source) {
        match Self::parse(block) {
            Ok(c) => (c, Source::Block),
            Err(_) if block.get(..4).is_some_and(|m| m != MAGIC) => {
                (Config::DEFAULT, Source::Blank)
            }
            Err(e) => (Config::DEFAULT, Source::Invalid(e)),
        }
    }

    /// Reads a configuration block, strictly: version 3, or 1 and 2 (64
    /// bytes) with the defaults for what they lack.
    pub fn parse(block: &[u8]) -> Result<Config, BlockError> {
        let version = block.get(4).copied().ok_or(BlockError::TooShort)?;
        let len = match version {
            1 | 2 => BLOCK_LEN_V2,
            _ => BLOCK_LEN,
        };
        let b = block.get(..len).ok_or(BlockError::TooShort)?;
        let (body, crc) = b.split_at(len - 4);
        if crc32(body).to_le_bytes() != crc {
            return Err(BlockError::Crc);
        }
        if body.get(..4) != Some(&MAGIC[..]) {
            return Err(BlockError::Field(0));
        }
        if !(1..=VERSION).contains(&version) {
            return Err(BlockError::Version);
        }
        let byte = |i: usize| body.get(i).copied().unwrap_or(0);
        let word = |i: usize| u32::from_le_bytes([byte(i), byte(i + 1), byte(i + 2), byte(i + 3)]);
        let flow = FlowControl::from_code(byte(5)).ok_or(BlockError::Field(5))?;
        let controller_station = Station(byte(6));
        let bridge_station = Station(byte(7));
        if bridge_station == controller_station {
            return Err(BlockError::Field(7));
        }
        let upstream_baud = word(8);
        if !BAUD_RATES.contains(&upstream_baud) {
            return Err(BlockError::Field(8));
        }
        let downstream_baud = word(12);
        if !BAUD_RATES.contains(&downstream_baud) {
            return Err(BlockError::Field(12));
        }
        let mut list = [0u8; 32];
        if let Some(src) = body.get(20..52) {
            list.copy_from_slice(src);
        }
        let policy = match byte(16) {
            0 => Policy::ForwardAll,
            1 => Policy::ReadOnly,
            2 => Policy::Allow(AllowList(list)),
            _ => return Err(BlockError::Field(16)),
        };
        let flags = byte(17);
        if flags & !1 != 0 {
            return Err(BlockError::Field(17));
        }
        let (modbus, upstream) = if version == 1 {
            // Before the gateway: its defaults.
            (ModbusConfig::DEFAULT, UpstreamProtocol::ProtocolB)
        } else {
            Self::parse_modbus(&byte, &word)?
        };
        let (duplicate_window_ms, xoff_hold_ms) = if version < 3 {
            (
                Config::DEFAULT.duplicate_window_ms,
                Config::DEFAULT.xoff_hold_ms,
            )
        } else {
            let window = word(60);
            if !DUPLICATE_WINDOWS_MS.contains(&window) {
                return Err(BlockError::Field(60));
            }
            let hold = word(64);
            if !XOFF_HOLDS_MS.contains(&hold) {
                return Err(BlockError::Field(64));
            }
            (window, hold)
        };
        Ok(Config {
            upstream_baud,
            downstream_baud,
            controller_station,
            bridge_station,
            flow,
            policy,
            quit_sequence: flags & 1 != 0,
            modbus,
            upstream,
            duplicate_window_ms,
            xoff_hold_ms,
        })
    }

    /// The Modbus fields of a version 2 or 3 block.
    fn parse_modbus(
        byte: &dyn Fn(usize) -> u8,
        word: &dyn Fn(usize) -> u32,
    ) -> Result<(ModbusConfig, UpstreamProtocol), BlockError> {
        let unit = byte(18);
        if !UNITS.contains(&unit) {
            return Err(BlockError::Field(18));
        }
        let bits = byte(19);
        let parity = Parity::from_code(bits & 0b11).ok_or(BlockError::Field(19))?;
        if bits & !0b111 != 0 {
            return Err(BlockError::Field(19));
        }
        let upstream = if bits & 0b100 != 0 {
            UpstreamProtocol::ModbusRtu
        } else {
            UpstreamProtocol::ProtocolB
        };
        let baud = word(52);
        if !BAUD_RATES.contains(&baud) {
            return Err(BlockError::Field(52));
        }
        let poll_period_ms = u16::from_le_bytes([byte(56), byte(57)]);
        if !POLL_PERIODS_MS.contains(&poll_period_ms) {
            return Err(BlockError::Field(56));
        }
        let axes = byte(58);
        if !AXES.contains(&axes) {
            return Err(BlockError::Field(58));
        }
        let modbus = ModbusConfig {
            unit,
            baud,
            parity,
            poll_period_ms,
            axes,
        };
        Ok((modbus, upstream))
    }

    /// The configuration block holding this configuration (version 3).
    pub fn to_block(&self) -> [u8; BLOCK_LEN] {
        fn put(b: &mut [u8], at: usize, bytes: &[u8]) {
            if let Some(dst) = b.get_mut(at..at + bytes.len()) {
                dst.copy_from_slice(bytes);
            }
        }
        let mut b = [0u8; BLOCK_LEN];
        put(&mut b, 0, &MAGIC);
        put(&mut b, 4, &[VERSION, self.flow.code()]);
        put(
            &mut b,
            6,
            &[self.controller_station.0, self.bridge_station.0],
        );
        put(&mut b, 8, &self.upstream_baud.to_le_bytes());
        put(&mut b, 12, &self.downstream_baud.to_le_bytes());
        put(
            &mut b,
            16,
            &[self.policy.code(), u8::from(self.quit_sequence)],
        );
        let m = &self.modbus;
        let speaks_modbus = self.upstream == UpstreamProtocol::ModbusRtu;
        put(
            &mut b,
            18,
            &[m.unit, m.parity.code() | u8::from(speaks_modbus) << 2],
        );
        if let Policy::Allow(list) = self.policy {
            put(&mut b, 20, &list.bytes());
        }
        put(&mut b, 52, &m.baud.to_le_bytes());
        put(&mut b, 56, &m.poll_period_ms.to_le_bytes());
        put(&mut b, 58, &[m.axes]);
        put(&mut b, 60, &self.duplicate_window_ms.to_le_bytes());
        put(&mut b, 64, &self.xoff_hold_ms.to_le_bytes());
        let crc = crc32(b.get(..BLOCK_LEN - 4).unwrap_or(&[]));
        put(&mut b, BLOCK_LEN - 4, &crc.to_le_bytes());
        b
    }
}

impl Default for Config {
    fn default() -> Self {
        Config::DEFAULT
    }
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`), bit by bit: it runs
/// at start and when the page is written, so no table is spent on it.
pub fn crc32(bytes: &[u8]) -> u32 {
    Crc32::new().update(bytes).finish()
}

/// [`crc32`] over bytes that come in pieces, or CRC-32C
/// ([`Crc32::castagnoli`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crc32 {
    sum: u32,
    poly: u32,
}

impl Crc32 {
    /// CRC-32 (IEEE 802.3), nothing summed yet.
    pub const fn new() -> Self {
        Crc32 {
            sum: !0,
            poly: 0xEDB8_8320,
        }
    }

    /// CRC-32C (Castagnoli, as iSCSI's), nothing summed yet: the check
    /// over a run of blocks that each end in their own CRC-32. A CRC is
    /// linear: a block followed by its own CRC-32 adds the same to any
    /// CRC-32 run over it, whatever the block holds, so a CRC-32 over the
    /// page could not tell one valid block from another; a CRC of another
    /// polynomial can.
    pub const fn castagnoli() -> Self {
        Crc32 {
            sum: !0,
            poly: 0x82F6_3B78,
        }
    }

    /// Sums `bytes`.
    pub fn update(mut self, bytes: &[u8]) -> Self {
        for &b in bytes {
            self.sum ^= u32::from(b);
            for _ in 0..8 {
                let mask = (self.sum & 1).wrapping_neg();
                self.sum = (self.sum >> 1) ^ (self.poly & mask);
            }
        }
        self
    }

    /// The CRC of everything summed.
    pub const fn finish(self) -> u32 {
        !self.sum
    }
}

impl Default for Crc32 {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_check_values() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(
            Crc32::castagnoli().update(b"123456789").finish(),
            0xE306_9283
        );
    }

    #[test]
    fn block_round_trip_and_rejections() {
        let cfg = Config {
            upstream_baud: 9_600,
            downstream_baud: 38_400,
            controller_station: Station(0x01),
            bridge_station: Station(0xFE),
            flow: FlowControl::RtsCts,
            policy: Policy::Allow(AllowList::of(&[0x212, 0x26D])),
            quit_sequence: true,
            modbus: ModbusConfig {
                unit: 17,
                baud: 19_200,
                parity: Parity::Odd,
                poll_period_ms: 250,
                axes: 2,
            },
            upstream: UpstreamProtocol::ModbusRtu,
            duplicate_window_ms: 8_000,
            xoff_hold_ms: 1_000,
        };
        let block = cfg.to_block();
        assert_eq!(Config::from_block(&block), (cfg, Source::Block));
        assert_eq!(
            Config::from_block(&[0xFF; BLOCK_LEN]),
            (Config::DEFAULT, Source::Blank)
        );
        let mut bad = block;
        bad[9] ^= 1;
        assert_eq!(Config::from_block(&bad).1, Source::Invalid(BlockError::Crc));
        let mut same = cfg;
        same.bridge_station = same.controller_station;
        assert_eq!(Config::parse(&same.to_block()), Err(BlockError::Field(7)));
        let mut baud = cfg;
        baud.upstream_baud = 1_200;
        assert_eq!(Config::parse(&baud.to_block()), Err(BlockError::Field(8)));
        assert_eq!(Config::parse(&block[..10]), Err(BlockError::TooShort));
        let mut unit = cfg;
        unit.modbus.unit = 0;
        assert_eq!(Config::parse(&unit.to_block()), Err(BlockError::Field(18)));
        let mut hold = cfg;
        hold.xoff_hold_ms = 50;
        assert_eq!(Config::parse(&hold.to_block()), Err(BlockError::Field(64)));
        let mut window = cfg;
        window.duplicate_window_ms = 60_001;
        assert_eq!(
            Config::parse(&window.to_block()),
            Err(BlockError::Field(60))
        );
    }

    #[test]
    fn a_version_1_block_reads_with_the_modbus_defaults() {
        // A block written by the firmware before the gateway: 9,600 baud
        // upstream, 38,400 downstream, RTS/CTS, read-only, stations 01/FE.
        let mut v1 = [0u8; BLOCK_LEN_V2];
        v1[..4].copy_from_slice(b"IAIB");
        v1[4..8].copy_from_slice(&[1, 2, 0x01, 0xFE]);
        v1[8..12].copy_from_slice(&9_600u32.to_le_bytes());
        v1[12..16].copy_from_slice(&38_400u32.to_le_bytes());
        v1[16] = 1;
        let crc = crc32(&v1[..60]);
        v1[60..].copy_from_slice(&crc.to_le_bytes());
        let (cfg, source) = Config::from_block(&v1);
        assert_eq!(source, Source::Block);
        assert_eq!(cfg.modbus, ModbusConfig::DEFAULT);
        assert_eq!(cfg.upstream, UpstreamProtocol::ProtocolB);
        assert_eq!((cfg.upstream_baud, cfg.policy), (9_600, Policy::ReadOnly));
        // Written back, it is a version 3 block with the same settings.
        assert_eq!(cfg.to_block()[4], 3);
        assert_eq!(Config::from_block(&cfg.to_block()), (cfg, Source::Block));
    }

    #[test]
    fn a_version_2_block_reads_with_the_line_defaults() {
        // A 64-byte block of the gateway's first layout: unit 17 at 19,200
        // baud, odd parity, polled every 250 ms, 2 axes.
        let mut v2 = [0u8; BLOCK_LEN_V2];
        v2[..4].copy_from_slice(b"IAIB");
        v2[4..8].copy_from_slice(&[2, 1, 0x99, 0xBB]);
        v2[8..12].copy_from_slice(&115_200u32.to_le_bytes());
        v2[12..16].copy_from_slice(&115_200u32.to_le_bytes());
        v2[18..20].copy_from_slice(&[17, 2]);
        v2[52..56].copy_from_slice(&19_200u32.to_le_bytes());
        v2[56..58].copy_from_slice(&250u16.to_le_bytes());
        v2[58] = 2;
        let crc = crc32(&v2[..60]);
        v2[60..].copy_from_slice(&crc.to_le_bytes());
        let (cfg, source) = Config::from_block(&v2);
        assert_eq!(source, Source::Block);
        assert_eq!(cfg.modbus.unit, 17);
        assert_eq!(cfg.modbus.parity, Parity::Odd);
        assert_eq!((cfg.duplicate_window_ms, cfg.xoff_hold_ms), (0, 5_000));
    }

    #[test]
    fn policies() {
        assert!(Policy::ForwardAll.allows(0x25B));
        assert!(Policy::ReadOnly.allows(0x212));
        assert!(!Policy::ReadOnly.allows(0x25B));
        assert!(!Policy::ReadOnly.allows(0x26D));
        let list = AllowList::of(&[0x212, 0x300]);
        assert_eq!(list.len(), 1);
        assert!(Policy::Allow(list).allows(0x212));
        assert!(!Policy::Allow(list).allows(0x213));
        assert!(!Policy::Allow(list).allows(0x300));
    }
}
