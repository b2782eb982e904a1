//! The bridge's run-time configuration and the command policy.
//!
//! A board reads a [`Config`] at start from a 64-byte configuration block
//! in flash ([`Config::from_block`]); a blank or invalid block gives
//! [`Config::DEFAULT`] and the status query says which ([`Source`]).
//!
//! # Configuration block (64 bytes, multi-byte numbers little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `IAIB` |
//! | 4 | 1 | layout version, 1 |
//! | 5 | 1 | upstream flow control: 0 none, 1 XON/XOFF, 2 RTS/CTS |
//! | 6 | 1 | controller station (I/O parameter No. 91 of the controller) |
//! | 7 | 1 | the bridge's own station (must differ) |
//! | 8 | 4 | upstream baud rate |
//! | 12 | 4 | downstream baud rate |
//! | 16 | 1 | policy: 0 forward all, 1 read-only preset, 2 allow-list |
//! | 17 | 1 | flags: bit 0 = honour the quit sequence (QEMU test runs only) |
//! | 18 | 2 | 0 |
//! | 20 | 32 | allow-list: bit `id - 200H` (byte `(id - 200H) / 8`, bit `id % 8`) for IDs 200H..2FFH |
//! | 52 | 8 | 0 |
//! | 60 | 4 | CRC-32 (IEEE 802.3, as zlib's `crc32`) of bytes 0..60 |
//!
//! Baud rates must be one a TTA offers (9,600, 19,200, 38,400, 57,600,
//! 115,200; TTA p. 7). A board that cannot set a rate (QEMU ignores them)
//! still reports the configured one.

use iai_protocol_b::catalogue;
use iai_protocol_b::frame::Station;

use crate::serial::FlowControl;

/// Size of the configuration block.
pub const BLOCK_LEN: usize = 64;
/// First bytes of a configuration block.
pub const MAGIC: [u8; 4] = *b"IAIB";
/// Layout version this firmware reads.
pub const VERSION: u8 = 1;
/// Baud rates the TTA offers (TTA p. 7).
pub const BAUD_RATES: [u32; 5] = [9_600, 19_200, 38_400, 57_600, 115_200];

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
}

impl Config {
    /// Station 99 (the spec's examples), bridge on station BB, 115,200
    /// baud both sides, XON/XOFF upstream, forward all, no quit sequence.
    pub const DEFAULT: Config = Config {
        upstream_baud: 115_200,
        downstream_baud: 115_200,
        controller_station: Station(0x99),
        bridge_station: Station(0xBB),
        flow: FlowControl::XonXoff,
        policy: Policy::ForwardAll,
        quit_sequence: false,
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

    /// Reads a configuration block, strictly.
    pub fn parse(block: &[u8]) -> Result<Config, BlockError> {
        let b: &[u8; BLOCK_LEN] = block
            .get(..BLOCK_LEN)
            .and_then(|b| b.try_into().ok())
            .ok_or(BlockError::TooShort)?;
        let (body, crc) = b.split_at(60);
        if crc32(body).to_le_bytes() != crc {
            return Err(BlockError::Crc);
        }
        if body.get(..4) != Some(&MAGIC[..]) {
            return Err(BlockError::Field(0));
        }
        if body.get(4) != Some(&VERSION) {
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
        Ok(Config {
            upstream_baud,
            downstream_baud,
            controller_station,
            bridge_station,
            flow,
            policy,
            quit_sequence: flags & 1 != 0,
        })
    }

    /// The configuration block holding this configuration.
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
        if let Policy::Allow(list) = self.policy {
            put(&mut b, 20, &list.bytes());
        }
        let crc = crc32(b.get(..60).unwrap_or(&[]));
        put(&mut b, 60, &crc.to_le_bytes());
        b
    }
}

impl Default for Config {
    fn default() -> Self {
        Config::DEFAULT
    }
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`), bit by bit: it runs
/// once at start, so no table is spent on it.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
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
