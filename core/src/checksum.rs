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

    /// Adds every byte of `bytes`.
    #[inline]
    pub fn update(&mut self, bytes: &[u8]) {
        self.0 = bytes.iter().fold(self.0, |s, &b| s.wrapping_add(b));
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
