//! Who may read and change the gateway: the web block (the page's port,
//! and whether reading it needs the password) and the password's verifier.
//!
//! # Web block (16 bytes at [`WEB_AT`], little-endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `IAIW` |
//! | 4 | 1 | layout version, 1 |
//! | 5 | 1 | reads: 0 open to anyone, 1 the password too |
//! | 6 | 2 | the web page's TCP port (not 0) |
//! | 8 | 4 | 0 |
//! | 12 | 4 | CRC-32 of bytes 0..12 |
//!
//! # Verifier block (64 bytes at [`ACCESS_AT`])
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `IAIA` |
//! | 4 | 1 | layout version, 1 |
//! | 5 | 1 | 0 |
//! | 6 | 2 | rounds of SHA-256 |
//! | 8 | 16 | salt |
//! | 24 | 32 | verifier: SHA-256 of the salt and the password, then `rounds - 1` more times of itself and the salt |
//! | 56 | 4 | 0 |
//! | 60 | 4 | CRC-32 of bytes 0..60 |
//!
//! One password guards every write: the web page's, and the bridge's
//! configuration messages ([`super::wire`]). No valid verifier block means
//! no password yet: a fresh gateway takes no change but the password's.
//! The page keeps only the salt and the verifier; the block never leaves
//! the gateway. The rounds are few ([`ROUNDS`]: the loop must not stall for
//! long), so the verifier keeps the password out of the flash but does not
//! withstand an offline search for a weak one; online, a wrong password
//! shuts every check for [`LOCKOUT_MS`] ([`Gate`]).
//!
//! [`WEB_AT`]: super::page::WEB_AT
//! [`ACCESS_AT`]: super::page::ACCESS_AT

use core::ops::RangeInclusive;

use sha2::digest::generic_array::GenericArray;

use super::{crc32, BlockError};

/// Size of the web block.
pub const WEB_LEN: usize = 16;
/// Size of the verifier block.
pub const ACCESS_LEN: usize = 64;
/// First bytes of the web block.
pub const WEB_MAGIC: [u8; 4] = *b"IAIW";
/// First bytes of the verifier block.
pub const ACCESS_MAGIC: [u8; 4] = *b"IAIA";
/// Layout version of both blocks.
pub const VERSION: u8 = 1;
/// The web page's port unless the block names another.
pub const DEFAULT_WEB_PORT: u16 = 80;
/// SHA-256 rounds of a new verifier.
pub const ROUNDS: u16 = 64;
/// Bytes of a password.
pub const PASSWORD_LEN: RangeInclusive<usize> = 8..=64;
/// After a wrong password, every check fails for this long.
pub const LOCKOUT_MS: u32 = 1_000;

/// Who may read the web page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Reads {
    /// Anyone who reaches it.
    Open,
    /// Who gives the password (HTTP basic authentication).
    Password,
}

/// The web block's settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WebConfig {
    /// Who may read the page.
    pub reads: Reads,
    /// Its TCP port.
    pub port: u16,
}

impl WebConfig {
    /// Open reads on port 80.
    pub const DEFAULT: WebConfig = WebConfig {
        reads: Reads::Open,
        port: DEFAULT_WEB_PORT,
    };

    /// Reads a web block; never fails: a blank or invalid block gives
    /// [`WebConfig::DEFAULT`].
    pub fn from_block(block: &[u8]) -> WebConfig {
        Self::parse(block).unwrap_or(WebConfig::DEFAULT)
    }

    /// Reads a web block, strictly.
    pub fn parse(block: &[u8]) -> Result<WebConfig, BlockError> {
        let body = checked(block, WEB_LEN, WEB_MAGIC)?;
        let byte = |i: usize| body.get(i).copied().unwrap_or(0);
        let reads = match byte(5) {
            0 => Reads::Open,
            1 => Reads::Password,
            _ => return Err(BlockError::Field(5)),
        };
        let port = u16::from_le_bytes([byte(6), byte(7)]);
        if port == 0 {
            return Err(BlockError::Field(6));
        }
        Ok(WebConfig { reads, port })
    }

    /// The web block holding these settings.
    pub fn to_block(&self) -> [u8; WEB_LEN] {
        let mut b = [0u8; WEB_LEN];
        put(&mut b, 0, &WEB_MAGIC);
        let reads = match self.reads {
            Reads::Open => 0,
            Reads::Password => 1,
        };
        put(&mut b, 4, &[VERSION, reads]);
        put(&mut b, 6, &self.port.to_le_bytes());
        seal(&mut b);
        b
    }
}

impl Default for WebConfig {
    fn default() -> Self {
        WebConfig::DEFAULT
    }
}

/// The password's verifier, as the verifier block holds it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Verifier {
    rounds: u16,
    salt: [u8; 16],
    hash: [u8; 32],
}

/// Why a password was refused as a new one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PasswordError {
    /// Shorter or longer than [`PASSWORD_LEN`].
    Length,
    /// A control character (CR, LF, NUL...).
    Control,
}

impl Verifier {
    /// The verifier of `password` with `salt` ([`ROUNDS`] rounds); the
    /// password must be [`PASSWORD_LEN`] bytes, none a control character.
    pub fn new(password: &[u8], salt: [u8; 16]) -> Result<Verifier, PasswordError> {
        if !PASSWORD_LEN.contains(&password.len()) {
            return Err(PasswordError::Length);
        }
        if password.iter().any(|b| b.is_ascii_control()) {
            return Err(PasswordError::Control);
        }
        Ok(Verifier {
            rounds: ROUNDS,
            salt,
            hash: stretch(password, &salt, ROUNDS),
        })
    }

    /// A salt from `entropy` (what the gateway has that differs between
    /// boots and moments: it need not be secret, only not repeat).
    pub fn salt_from(entropy: &[u8]) -> [u8; 16] {
        let d = sha256(&[b"iai-gateway salt", entropy]);
        let mut salt = [0u8; 16];
        for (s, h) in salt.iter_mut().zip(d) {
            *s = h;
        }
        salt
    }

    /// Whether `password` is the one (compared in constant time).
    pub fn accepts(&self, password: &[u8]) -> bool {
        let h = stretch(password, &self.salt, self.rounds);
        h.iter()
            .zip(self.hash.iter())
            .fold(0u8, |acc, (a, b)| acc | (a ^ b))
            == 0
    }

    /// Reads a verifier block: `None` if blank or invalid (no password).
    pub fn from_block(block: &[u8]) -> Option<Verifier> {
        let body = checked(block, ACCESS_LEN, ACCESS_MAGIC).ok()?;
        let rounds = u16::from_le_bytes([*body.get(6)?, *body.get(7)?]);
        let mut salt = [0u8; 16];
        salt.copy_from_slice(body.get(8..24)?);
        let mut hash = [0u8; 32];
        hash.copy_from_slice(body.get(24..56)?);
        (rounds > 0).then_some(Verifier { rounds, salt, hash })
    }

    /// The verifier block holding it.
    pub fn to_block(&self) -> [u8; ACCESS_LEN] {
        let mut b = [0u8; ACCESS_LEN];
        put(&mut b, 0, &ACCESS_MAGIC);
        put(&mut b, 4, &[VERSION, 0]);
        put(&mut b, 6, &self.rounds.to_le_bytes());
        put(&mut b, 8, &self.salt);
        put(&mut b, 24, &self.hash);
        seal(&mut b);
        b
    }
}

/// SHA-256 of the salt and the password, then `rounds - 1` more times of
/// the last hash and the salt.
fn stretch(password: &[u8], salt: &[u8; 16], rounds: u16) -> [u8; 32] {
    let mut h = sha256(&[salt, password]);
    for _ in 1..rounds {
        h = sha256(&[&h, salt]);
    }
    h
}

/// SHA-256's initial hash value (FIPS 180-4, 5.3.3).
const IV: [u32; 8] = [
    0x6a09_e667,
    0xbb67_ae85,
    0x3c6e_f372,
    0xa54f_f53a,
    0x510e_527f,
    0x9b05_688c,
    0x1f83_d9ab,
    0x5be0_cd19,
];

/// SHA-256 of `parts` one after the other: sha2's compression, with the
/// message padded here (FIPS 180-4, 5.1.1), which keeps about 250 bytes
/// of the digest wrapper's frames off the stack; the check runs deep in
/// the bridge's loop.
fn sha256(parts: &[&[u8]]) -> [u8; 32] {
    let mut h = Blocks {
        state: IV,
        block: GenericArray::default(),
        at: 0,
    };
    let mut bits = 0u64;
    for part in parts {
        for &b in *part {
            h.push(b);
            bits = bits.wrapping_add(8);
        }
    }
    h.push(0x80);
    while h.at != 56 {
        h.push(0);
    }
    for b in bits.to_be_bytes() {
        h.push(b);
    }
    let mut out = [0u8; 32];
    for (o, w) in out.chunks_exact_mut(4).zip(h.state) {
        o.copy_from_slice(&w.to_be_bytes());
    }
    out
}

/// The hash state and the block being filled.
struct Blocks {
    state: [u32; 8],
    block: GenericArray<u8, sha2::digest::consts::U64>,
    at: usize,
}

impl Blocks {
    fn push(&mut self, b: u8) {
        if let Some(slot) = self.block.get_mut(self.at) {
            *slot = b;
        }
        self.at += 1;
        if self.at == 64 {
            sha2::compress256(&mut self.state, core::slice::from_ref(&self.block));
            self.at = 0;
        }
    }
}

/// The checks of the password, shut for [`LOCKOUT_MS`] after a wrong one.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Gate {
    shut_until: Option<u32>,
    /// Wrong passwords so far.
    pub failures: u32,
}

/// What a check of the password found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Check {
    /// The password is right.
    Granted,
    /// No password is set yet.
    NoPassword,
    /// Wrong (the checks are shut for [`LOCKOUT_MS`]).
    Wrong,
    /// Not checked: a wrong password came less than [`LOCKOUT_MS`] ago.
    Shut,
}

impl Gate {
    /// An open gate.
    pub const fn new() -> Self {
        Gate {
            shut_until: None,
            failures: 0,
        }
    }

    /// Checks `password` against `verifier` at `now`.
    pub fn check(&mut self, verifier: Option<&Verifier>, password: &[u8], now: u32) -> Check {
        let Some(v) = verifier else {
            return Check::NoPassword;
        };
        if let Some(until) = self.shut_until {
            if (until.wrapping_sub(now) as i32) > 0 {
                return Check::Shut;
            }
            self.shut_until = None;
        }
        if v.accepts(password) {
            Check::Granted
        } else {
            self.failures = self.failures.wrapping_add(1);
            self.shut_until = Some(now.wrapping_add(LOCKOUT_MS));
            Check::Wrong
        }
    }
}

/// The body of a block of `len` bytes with `magic` and version
/// [`VERSION`] whose CRC-32 (its last 4 bytes) is right.
fn checked(block: &[u8], len: usize, magic: [u8; 4]) -> Result<&[u8], BlockError> {
    let b = block.get(..len).ok_or(BlockError::TooShort)?;
    let (body, crc) = b.split_at(len - 4);
    if crc32(body).to_le_bytes() != crc {
        return Err(BlockError::Crc);
    }
    if body.get(..4) != Some(&magic[..]) {
        return Err(BlockError::Field(0));
    }
    if body.get(4) != Some(&VERSION) {
        return Err(BlockError::Version);
    }
    Ok(body)
}

fn put(b: &mut [u8], at: usize, bytes: &[u8]) {
    if let Some(dst) = b.get_mut(at..at + bytes.len()) {
        dst.copy_from_slice(bytes);
    }
}

/// Writes the CRC-32 of all but the last 4 bytes into them.
fn seal(b: &mut [u8]) {
    let n = b.len().saturating_sub(4);
    let crc = crc32(b.get(..n).unwrap_or(&[]));
    put(b, n, &crc.to_le_bytes());
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn a_verifier_accepts_its_password_only_and_survives_its_block() {
        let salt = Verifier::salt_from(b"boot 1, tick 2");
        let v = Verifier::new(b"correct horse", salt).unwrap();
        assert!(v.accepts(b"correct horse"));
        assert!(!v.accepts(b"correct hors"));
        assert!(!v.accepts(b""));
        let block = v.to_block();
        assert_eq!(&block[..4], b"IAIA");
        // The password is nowhere in the block.
        assert!(!block.windows(13).any(|w| w == b"correct horse"));
        assert_eq!(Verifier::from_block(&block), Some(v));
        let mut bad = block;
        bad[30] ^= 1;
        assert_eq!(Verifier::from_block(&bad), None);
        assert_eq!(Verifier::from_block(&[0xFF; ACCESS_LEN]), None);
        // Another salt, another verifier.
        let other = Verifier::new(b"correct horse", Verifier::salt_from(b"boot 2")).unwrap();
        assert_ne!(other.to_block(), block);
        assert_eq!(Verifier::new(b"short", salt), Err(PasswordError::Length));
        assert_eq!(
            Verifier::new(b"line\r\nbreak", salt),
            Err(PasswordError::Control)
        );
    }

    #[test]
    fn the_short_sha256_is_sha2_s() {
        use sha2::{Digest, Sha256};
        for len in [0usize, 1, 55, 56, 63, 64, 65, 80, 119, 200] {
            let msg: std::vec::Vec<u8> = (0..len).map(|i| i as u8).collect();
            let (a, b) = msg.split_at(len / 3);
            let want: [u8; 32] = Sha256::digest(&msg).into();
            assert_eq!(sha256(&[a, b]), want, "{len} bytes");
        }
    }

    #[test]
    fn a_wrong_password_shuts_the_gate_for_a_second() {
        let v = Verifier::new(b"12345678", [7; 16]).unwrap();
        let mut gate = Gate::new();
        assert_eq!(gate.check(None, b"12345678", 0), Check::NoPassword);
        assert_eq!(gate.check(Some(&v), b"12345678", 0), Check::Granted);
        assert_eq!(gate.check(Some(&v), b"87654321", 10), Check::Wrong);
        assert_eq!(gate.check(Some(&v), b"12345678", 500), Check::Shut);
        assert_eq!(gate.check(Some(&v), b"12345678", 1_010), Check::Granted);
        assert_eq!(gate.failures, 1);
    }

    #[test]
    fn web_block_round_trip() {
        let w = WebConfig {
            reads: Reads::Password,
            port: 8080,
        };
        assert_eq!(WebConfig::parse(&w.to_block()), Ok(w));
        assert_eq!(WebConfig::from_block(&[0xFF; 16]), WebConfig::DEFAULT);
        let zero = WebConfig { port: 0, ..w };
        assert_eq!(
            WebConfig::parse(&zero.to_block()),
            Err(BlockError::Field(6))
        );
    }
}
