//! The Sparkplug settings: a 256-byte block of their own in the
//! configuration page, [`BLOCK_OFFSET`] bytes past the bridge's block
//! ([`crate::config`]), beside the network block (`net/config.rs`). A
//! blank or invalid block gives [`SparkplugConfig::default`]: the edge
//! node off.
//!
//! # Sparkplug block (256 bytes, multi-byte numbers little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `IAIS` |
//! | 4 | 1 | layout version, 1 |
//! | 5 | 1 | flags: bit 0 the edge node is on, bit 1 DCMD commands allowed |
//! | 6 | 2 | broker TCP port (not 0) |
//! | 8 | 4 | broker IPv4 address, in wire order |
//! | 12 | 4 | position deadband, 0.001 mm (0: every change) |
//! | 16 | 2 | MQTT keep-alive, s (5..=600) |
//! | 18 | 2 | 0 |
//! | 20 | 32 | group ID |
//! | 52 | 32 | edge node ID (empty: `gw-` and the MAC address in hex) |
//! | 84 | 32 | MQTT user name (empty: none) |
//! | 116 | 32 | MQTT password (empty: none; needs a user name) |
//! | 148 | 32 | primary host ID (empty: none, no STATE awaited) |
//! | 180 | 72 | 0 |
//! | 252 | 4 | CRC-32 of bytes 0..252 (as [`crate::config::crc32`]) |
//!
//! Texts are UTF-8, padded with NULs. The IDs are topic levels: they may
//! not hold `/`, `+` or `#` (Sparkplug 3.0, topic namespace).

use crate::config::{crc32, BlockError};

/// Where the block starts in the configuration page.
pub const BLOCK_OFFSET: usize = crate::config::page::SPARKPLUG_AT;
/// Size of the block.
pub const BLOCK_LEN: usize = crate::config::page::SPARKPLUG_LEN;
/// First bytes of a Sparkplug block.
pub const MAGIC: [u8; 4] = *b"IAIS";
/// Layout version this firmware reads.
pub const VERSION: u8 = 1;
/// Longest text field.
pub const TEXT_LEN: usize = 32;
/// MQTT's registered port.
pub const DEFAULT_BROKER_PORT: u16 = 1883;

/// A text setting (up to [`TEXT_LEN`] bytes of UTF-8).
pub type Text = heapless::String<TEXT_LEN>;

/// The edge node's settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SparkplugConfig {
    /// The edge node runs.
    pub enabled: bool,
    /// DCMD commands reach the controller (through the command policy).
    pub commands: bool,
    /// The broker's IPv4 address.
    pub broker: [u8; 4],
    /// Its TCP port.
    pub port: u16,
    /// Position deadband, 0.001 mm.
    pub deadband: u32,
    /// MQTT keep-alive, s.
    pub keep_alive_s: u16,
    /// Sparkplug group ID.
    pub group: Text,
    /// Edge node ID (empty: one made from the MAC address).
    pub node: Text,
    /// MQTT user name.
    pub username: Text,
    /// MQTT password.
    pub password: Text,
    /// Primary host ID (empty: none).
    pub primary_host: Text,
}

impl SparkplugConfig {
    /// Reads a block; a blank or invalid one gives the defaults and
    /// the reason.
    pub fn from_block(block: &[u8]) -> (SparkplugConfig, Result<(), BlockError>) {
        match Self::parse(block) {
            Ok(c) => (c, Ok(())),
            Err(e) => (Self::default(), Err(e)),
        }
    }

    /// Reads a block, strictly.
    pub fn parse(block: &[u8]) -> Result<SparkplugConfig, BlockError> {
        let b = block.get(..BLOCK_LEN).ok_or(BlockError::TooShort)?;
        let (body, crc) = b.split_at(BLOCK_LEN - 4);
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
        let flags = byte(5);
        if flags & !0b11 != 0 {
            return Err(BlockError::Field(5));
        }
        let port = u16::from_le_bytes([byte(6), byte(7)]);
        if port == 0 {
            return Err(BlockError::Field(6));
        }
        let keep_alive_s = u16::from_le_bytes([byte(16), byte(17)]);
        if !(5..=600).contains(&keep_alive_s) {
            return Err(BlockError::Field(16));
        }
        let text = |at: u8, level: bool| {
            let raw = body
                .get(usize::from(at)..usize::from(at) + TEXT_LEN)
                .unwrap_or(&[]);
            parse_text(raw, level).ok_or(BlockError::Field(at))
        };
        let cfg = SparkplugConfig {
            enabled: flags & 1 != 0,
            commands: flags & 2 != 0,
            broker: [byte(8), byte(9), byte(10), byte(11)],
            port,
            deadband: u32::from_le_bytes([byte(12), byte(13), byte(14), byte(15)]),
            keep_alive_s,
            group: text(20, true)?,
            node: text(52, true)?,
            username: text(84, false)?,
            password: text(116, false)?,
            primary_host: text(148, true)?,
        };
        if cfg.group.is_empty() {
            return Err(BlockError::Field(20));
        }
        if cfg.username.is_empty() && !cfg.password.is_empty() {
            return Err(BlockError::Field(116));
        }
        Ok(cfg)
    }

    /// The block holding these settings (texts cut to [`TEXT_LEN`]).
    pub fn to_block(&self) -> [u8; BLOCK_LEN] {
        let mut b = [0u8; BLOCK_LEN];
        let mut put = |at: usize, bytes: &[u8]| {
            if let Some(dst) = b.get_mut(at..at + bytes.len()) {
                dst.copy_from_slice(bytes);
            }
        };
        put(0, &MAGIC);
        put(
            4,
            &[
                VERSION,
                u8::from(self.enabled) | u8::from(self.commands) << 1,
            ],
        );
        put(6, &self.port.to_le_bytes());
        put(8, &self.broker);
        put(12, &self.deadband.to_le_bytes());
        put(16, &self.keep_alive_s.to_le_bytes());
        put(20, self.group.as_bytes());
        put(52, self.node.as_bytes());
        put(84, self.username.as_bytes());
        put(116, self.password.as_bytes());
        put(148, self.primary_host.as_bytes());
        let crc = crc32(b.get(..BLOCK_LEN - 4).unwrap_or(&[]));
        if let Some(dst) = b.get_mut(BLOCK_LEN - 4..) {
            dst.copy_from_slice(&crc.to_le_bytes());
        }
        b
    }
}

impl Default for SparkplugConfig {
    /// Off; group `IAI`, node ID from the MAC address, broker port 1883,
    /// deadband 0.010 mm, keep-alive 30 s, no commands.
    fn default() -> Self {
        SparkplugConfig {
            enabled: false,
            commands: false,
            broker: [0; 4],
            port: DEFAULT_BROKER_PORT,
            deadband: 10,
            keep_alive_s: 30,
            group: text_of("IAI"),
            node: Text::new(),
            username: Text::new(),
            password: Text::new(),
            primary_host: Text::new(),
        }
    }
}

/// `s` as a [`Text`], cut after the last character that fits.
pub fn text_of(s: &str) -> Text {
    let mut t = Text::new();
    for c in s.chars() {
        if t.push(c).is_err() {
            break;
        }
    }
    t
}

/// A NUL-padded UTF-8 field; `level`: a topic level (no `/`, `+`, `#`).
/// `None` if it is not UTF-8, has a NUL inside, or `level` forbids it.
fn parse_text(raw: &[u8], level: bool) -> Option<Text> {
    let end = raw.iter().position(|&b| b == 0).unwrap_or(raw.len());
    let (s, pad) = raw.split_at(end);
    if pad.iter().any(|&b| b != 0) {
        return None;
    }
    let s = core::str::from_utf8(s).ok()?;
    if level && !is_topic_level(s) {
        return None;
    }
    Text::try_from(s).ok()
}

/// Whether `s` can be a Sparkplug ID (a topic level).
pub fn is_topic_level(s: &str) -> bool {
    !s.contains(['/', '+', '#'])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_round_trip_and_rejections() {
        let cfg = SparkplugConfig {
            enabled: true,
            commands: true,
            broker: [10, 0, 2, 2],
            port: 18_830,
            deadband: 50,
            keep_alive_s: 20,
            group: text_of("Plant 1"),
            node: text_of("robot-7"),
            username: text_of("gw"),
            password: text_of("secret"),
            primary_host: text_of("scada"),
        };
        let block = cfg.to_block();
        assert_eq!(&block[..4], b"IAIS");
        assert_eq!(block[5], 0b11);
        assert_eq!(&block[8..12], [10, 0, 2, 2]);
        assert_eq!(SparkplugConfig::from_block(&block), (cfg.clone(), Ok(())));
        assert_eq!(
            SparkplugConfig::from_block(&[0xFF; BLOCK_LEN]),
            (SparkplugConfig::default(), Err(BlockError::Crc))
        );
        let slash = SparkplugConfig {
            node: text_of("a/b"),
            ..cfg.clone()
        };
        assert_eq!(
            SparkplugConfig::parse(&slash.to_block()),
            Err(BlockError::Field(52))
        );
        let no_user = SparkplugConfig {
            username: Text::new(),
            ..cfg.clone()
        };
        assert_eq!(
            SparkplugConfig::parse(&no_user.to_block()),
            Err(BlockError::Field(116))
        );
        let mut bad = block;
        bad[6..8].fill(0);
        let crc = crc32(&bad[..252]);
        bad[252..].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(SparkplugConfig::parse(&bad), Err(BlockError::Field(6)));
        assert_eq!(
            SparkplugConfig::parse(&block[..100]),
            Err(BlockError::TooShort)
        );
    }
}
