//! The network settings: a 32-byte block of their own in the configuration
//! page, [`BLOCK_OFFSET`] bytes past the bridge's block
//! ([`crate::config`]), so that either block can change without the other.
//! A blank or invalid block gives [`NetConfig::DEFAULT`].
//!
//! # Network block (32 bytes, multi-byte numbers little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `IAIN` |
//! | 4 | 1 | layout version, 1 |
//! | 5 | 1 | addressing: 0 DHCP (with the fallback below), 1 static |
//! | 6 | 2 | TCP port of protocol B (not 0) |
//! | 8 | 4 | IPv4 address, in wire order (`10.0.2.15` is `0A 00 02 0F`): the static address, or the fallback with DHCP |
//! | 12 | 1 | prefix length, 1..=30 |
//! | 13 | 3 | 0 |
//! | 16 | 4 | default gateway, in wire order (`0.0.0.0`: none) |
//! | 20 | 8 | 0 |
//! | 28 | 4 | CRC-32 of bytes 0..28 (as [`crate::config::crc32`]) |
//!
//! With DHCP the address comes from the network's server (QEMU's user
//! network gives 10.0.2.15); if no lease arrives within
//! [`DHCP_FALLBACK_MS`], the block's address is used meanwhile (the
//! default: [`FALLBACK_ADDRESS`]/[`FALLBACK_PREFIX`], no gateway) and DHCP
//! goes on asking; a lease replaces it (a connection made on the fallback
//! address then breaks: the stack resets its socket at once, without a
//! word to the peer, and the bridge is free for the next host).

use core::ops::RangeInclusive;

use crate::config::{crc32, BlockError};

/// Where the network block starts, in bytes past the bridge's block: the
/// middle of the 1 KiB configuration page, well clear of the bridge's
/// block should it grow.
pub const BLOCK_OFFSET: usize = 512;
/// Size of the network block.
pub const BLOCK_LEN: usize = 32;
/// First bytes of a network block.
pub const MAGIC: [u8; 4] = *b"IAIN";
/// Layout version this firmware reads.
pub const VERSION: u8 = 1;
/// The TCP port of protocol B unless the block names another (5020: not a
/// registered service; Modbus TCP's 502 is left to a Modbus gateway).
pub const DEFAULT_PORT: u16 = 5020;
/// How long to wait for a DHCP lease before using the fallback address.
pub const DHCP_FALLBACK_MS: u32 = 10_000;
/// The fallback address with DHCP when the block gives none.
pub const FALLBACK_ADDRESS: [u8; 4] = [192, 168, 1, 20];
/// Its prefix length.
pub const FALLBACK_PREFIX: u8 = 24;
/// Prefix lengths an address may have.
pub const PREFIXES: RangeInclusive<u8> = 1..=30;

/// How the interface gets its address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Addressing {
    /// DHCP; [`NetConfig::address`] meanwhile if no lease comes within
    /// [`DHCP_FALLBACK_MS`].
    Dhcp,
    /// [`NetConfig::address`] always.
    Static,
}

/// An IPv4 address with its prefix length, and a gateway.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ipv4Setting {
    /// The address, in wire order.
    pub address: [u8; 4],
    /// Prefix length, 1..=30.
    pub prefix: u8,
    /// Default gateway, if any.
    pub gateway: Option<[u8; 4]>,
}

/// The network settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NetConfig {
    /// DHCP or static.
    pub addressing: Addressing,
    /// TCP port of protocol B.
    pub port: u16,
    /// The static address, or DHCP's fallback.
    pub address: Ipv4Setting,
}

/// Where the network settings came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NetSource {
    /// A valid network block.
    Block,
    /// Defaults: the block is blank (no magic).
    Blank,
    /// Defaults: the block is invalid.
    Invalid(BlockError),
}

impl NetConfig {
    /// DHCP with the fallback [`FALLBACK_ADDRESS`], port [`DEFAULT_PORT`].
    pub const DEFAULT: NetConfig = NetConfig {
        addressing: Addressing::Dhcp,
        port: DEFAULT_PORT,
        address: Ipv4Setting {
            address: FALLBACK_ADDRESS,
            prefix: FALLBACK_PREFIX,
            gateway: None,
        },
    };

    /// Reads a network block; never fails: a blank or invalid block gives
    /// [`NetConfig::DEFAULT`].
    pub fn from_block(block: &[u8]) -> (NetConfig, NetSource) {
        match Self::parse(block) {
            Ok(c) => (c, NetSource::Block),
            Err(_) if block.get(..4).is_some_and(|m| m != MAGIC) => {
                (NetConfig::DEFAULT, NetSource::Blank)
            }
            Err(e) => (NetConfig::DEFAULT, NetSource::Invalid(e)),
        }
    }

    /// Reads a network block, strictly.
    pub fn parse(block: &[u8]) -> Result<NetConfig, BlockError> {
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
        let quad = |i: usize| [byte(i), byte(i + 1), byte(i + 2), byte(i + 3)];
        let addressing = match byte(5) {
            0 => Addressing::Dhcp,
            1 => Addressing::Static,
            _ => return Err(BlockError::Field(5)),
        };
        let port = u16::from_le_bytes([byte(6), byte(7)]);
        if port == 0 {
            return Err(BlockError::Field(6));
        }
        let address = quad(8);
        if !is_host_address(address) {
            return Err(BlockError::Field(8));
        }
        let prefix = byte(12);
        if !PREFIXES.contains(&prefix) {
            return Err(BlockError::Field(12));
        }
        let gateway = quad(16);
        let gateway = if gateway == [0; 4] {
            None
        } else if is_host_address(gateway) {
            Some(gateway)
        } else {
            return Err(BlockError::Field(16));
        };
        Ok(NetConfig {
            addressing,
            port,
            address: Ipv4Setting {
                address,
                prefix,
                gateway,
            },
        })
    }

    /// The network block holding these settings.
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
                match self.addressing {
                    Addressing::Dhcp => 0,
                    Addressing::Static => 1,
                },
            ],
        );
        put(6, &self.port.to_le_bytes());
        put(8, &self.address.address);
        put(12, &[self.address.prefix]);
        put(16, &self.address.gateway.unwrap_or([0; 4]));
        let crc = crc32(b.get(..BLOCK_LEN - 4).unwrap_or(&[]));
        if let Some(dst) = b.get_mut(BLOCK_LEN - 4..) {
            dst.copy_from_slice(&crc.to_le_bytes());
        }
        b
    }
}

impl Default for NetConfig {
    fn default() -> Self {
        NetConfig::DEFAULT
    }
}

/// Whether `a` can be a host's unicast address (not 0.0.0.0/8, loopback,
/// multicast or reserved).
pub(crate) fn is_host_address(a: [u8; 4]) -> bool {
    !matches!(a[0], 0 | 127 | 224..=255)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_round_trip_and_rejections() {
        let cfg = NetConfig {
            addressing: Addressing::Static,
            port: 6020,
            address: Ipv4Setting {
                address: [10, 0, 2, 15],
                prefix: 24,
                gateway: Some([10, 0, 2, 2]),
            },
        };
        let block = cfg.to_block();
        assert_eq!(NetConfig::from_block(&block), (cfg, NetSource::Block));
        assert_eq!(
            NetConfig::from_block(&[0xFF; BLOCK_LEN]),
            (NetConfig::DEFAULT, NetSource::Blank)
        );
        let mut bad = block;
        bad[7] ^= 1;
        assert_eq!(
            NetConfig::from_block(&bad).1,
            NetSource::Invalid(BlockError::Crc)
        );
        let zero_port = NetConfig { port: 0, ..cfg };
        assert_eq!(
            NetConfig::parse(&zero_port.to_block()),
            Err(BlockError::Field(6))
        );
        let mut wide = cfg;
        wide.address.prefix = 31;
        assert_eq!(
            NetConfig::parse(&wide.to_block()),
            Err(BlockError::Field(12))
        );
        let mut multicast = cfg;
        multicast.address.address = [224, 0, 0, 1];
        assert_eq!(
            NetConfig::parse(&multicast.to_block()),
            Err(BlockError::Field(8))
        );
        assert_eq!(NetConfig::parse(&block[..20]), Err(BlockError::TooShort));
        assert_eq!(
            NetConfig::parse(&NetConfig::DEFAULT.to_block()),
            Ok(NetConfig::DEFAULT)
        );
    }
}
