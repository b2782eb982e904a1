//! The checksum SC and the `@@` bypass.
//!
//! SC is the low byte of the sum of every byte from the header (`!`, `#`,
//! `&`) to the last body byte, sent as two upper-case hex digits. CR and LF
//! are not summed. A command may carry `@@` instead, which tells the
//! controller to skip its check (X-SEL spec 2003 pp. 10, 66).
//!
//! ```
//! use iai_protocol_b::checksum::Checksum;
//! // Worked example of the 2003 spec, p. 10: sum 254h -> SC "54".
//! assert_eq!(Checksum::of(b"!99209001005"), 0x54);
//! ```

use crate::header::Header;

/// A running checksum: the low byte of the sum of the bytes fed so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Checksum(u8);

impl Checksum {
    /// A checksum over no bytes.
    pub const fn new() -> Self {
        Checksum(0)
    }

    /// Adds one byte.
    #[inline]
    pub fn push(&mut self, byte: u8) {
        self.0 = self.0.wrapping_add(byte);
    }

    /// Adds every byte of `bytes` (a word at a time, [`crate::hex::sum`]).
    #[inline]
    pub fn update(&mut self, bytes: &[u8]) {
        self.0 = crate::hex::sum(self.0, bytes);
    }

    /// Adds a sum of bytes computed elsewhere, such as the one
    /// [`crate::hex::put8`] returns for the digits it wrote.
    #[inline]
    pub fn add_sum(&mut self, sum: u32) {
        self.0 = self.0.wrapping_add(sum as u8);
    }

    /// The checksum value.
    pub const fn value(self) -> u8 {
        self.0
    }

    /// The checksum of `bytes` in one call.
    pub fn of(bytes: &[u8]) -> u8 {
        let mut c = Checksum::new();
        c.update(bytes);
        c.value()
    }
}

/// What a frame carries in its two SC characters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChecksumField {
    /// A real checksum value.
    Sum(u8),
    /// `@@`: "do not check".
    Bypass,
}

/// How an emitter fills the SC characters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChecksumMode {
    /// Compute and send the real checksum (always recommended).
    #[default]
    Compute,
    /// Send `@@`. Only commands may carry it; the controller then skips its
    /// check. Offered for hosts that must mimic existing software.
    Bypass,
}

/// Which received frames may carry `@@` instead of a checksum.
///
/// The default is [`BypassPolicy::CommandsOnly`]: the controller accepts
/// `@@` on commands (2003 p. 10), so a controller simulator or a bridge
/// that receives commands from existing host software must too; but nothing
/// says a controller ever *sends* `@@` (captured replies carry real sums),
/// so a response with `@@` is refused rather than trusted unchecked.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BypassPolicy {
    /// `@@` is refused on every frame.
    Reject,
    /// `@@` is accepted on commands (`!`) and refused on responses.
    #[default]
    CommandsOnly,
    /// `@@` is accepted on every frame.
    Accept,
}

impl BypassPolicy {
    /// Whether a frame with this header may carry `@@`.
    pub const fn allows(self, header: Header) -> bool {
        match self {
            BypassPolicy::Reject => false,
            BypassPolicy::CommandsOnly => matches!(header, Header::Command),
            BypassPolicy::Accept => true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_sums() {
        // 2003 p. 10: "!99209001005" sums to 254h, SC "54".
        assert_eq!(Checksum::of(b"!99209001005"), 0x54);
        // A response without data: "#99232" + SC "2C".
        assert_eq!(Checksum::of(b"#99232"), 0x2C);
        assert_eq!(Checksum::of(b""), 0);
        assert_eq!(Checksum::of(&[0xFF, 0x02]), 0x01, "low byte of the sum");
    }

    #[test]
    fn running_sum() {
        let mut c = Checksum::new();
        assert_eq!(c, Checksum::default());
        assert_eq!(c.value(), 0);
        c.push(b'!');
        assert_eq!(c.value(), b'!');
        c.update(b"99209");
        c.update(b"");
        c.update(b"001005");
        assert_eq!(c.value(), 0x54);
        c.push(0xAC);
        assert_eq!(c.value(), 0x00, "wraps modulo 256");
        let mut d = Checksum::new();
        for &b in b"!99209001005" {
            d.push(b);
        }
        assert_eq!(d.value(), 0x54);
        // A sum computed elsewhere: only its low byte counts.
        let mut e = Checksum::new();
        e.add_sum(0x254);
        assert_eq!(e.value(), 0x54);
        e.add_sum(0x1AC);
        assert_eq!(e.value(), 0x00);
        // Long input takes the word-at-a-time path.
        let mut long = [0u8; 3000];
        for (i, b) in long.iter_mut().enumerate() {
            *b = (i * 7 + 3) as u8;
        }
        let expect = long.iter().fold(0u8, |s, &b| s.wrapping_add(b));
        assert_eq!(Checksum::of(&long), expect);
        let mut f = Checksum::new();
        f.update(&long[..1001]);
        f.update(&long[1001..]);
        assert_eq!(f.value(), expect);
    }

    #[test]
    fn bypass_policy() {
        use Header::{Command, Error, Response};
        assert_eq!(BypassPolicy::default(), BypassPolicy::CommandsOnly);
        assert_eq!(ChecksumMode::default(), ChecksumMode::Compute);
        let allows = |p: BypassPolicy| [Command, Response, Error].map(|h| p.allows(h));
        assert_eq!(allows(BypassPolicy::Reject), [false, false, false]);
        assert_eq!(allows(BypassPolicy::CommandsOnly), [true, false, false]);
        assert_eq!(allows(BypassPolicy::Accept), [true, true, true]);
    }
}
