//! The envelope's vocabulary: frame kinds, stations and message IDs.
//!
//! This is the lowest layer: it imports nothing from the crate, and every
//! other module (checksum, errors, framing, catalogue) builds on it.

/// The kind of frame, from its first byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Header {
    /// `!`: a command from the host.
    Command,
    /// `#`: a normal response from the controller.
    Response,
    /// `&` (or `%`): an error response from the controller.
    Error,
}

impl Header {
    /// The kind a header byte starts, if any.
    ///
    /// `%` is read as an error response too: the 2003 appendix names it
    /// (2003 p. 65) while every table uses `&`, which is what the core sends.
    ///
    /// ```
    /// use iai_protocol_b::frame::Header;
    /// assert_eq!(Header::from_byte(b'&'), Some(Header::Error));
    /// assert_eq!(Header::from_byte(b'%'), Some(Header::Error));
    /// assert_eq!(Header::from_byte(b'?'), None);
    /// ```
    pub const fn from_byte(byte: u8) -> Option<Header> {
        match byte {
            b'!' => Some(Header::Command),
            b'#' => Some(Header::Response),
            b'&' | b'%' => Some(Header::Error),
            _ => None,
        }
    }

    /// The byte the core sends for this kind.
    pub const fn byte(self) -> u8 {
        match self {
            Header::Command => b'!',
            Header::Response => b'#',
            Header::Error => b'&',
        }
    }
}

/// A station code (I/O parameter No. 91; `99` is the usual value).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Station(pub u8);

impl Default for Station {
    fn default() -> Self {
        Station(0x99)
    }
}

/// A message ID (3 hex digits), e.g. `MessageId(0x26D)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MessageId(pub u16);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_header_byte_round_trips_and_nothing_else_is_a_header() {
        for b in 0..=255u8 {
            match Header::from_byte(b) {
                Some(h) if b == b'%' => assert_eq!(h, Header::Error),
                Some(h) => assert_eq!(h.byte(), b),
                None => assert!(!matches!(b, b'!' | b'#' | b'&' | b'%')),
            }
        }
    }

    #[test]
    fn the_usual_station_is_the_default() {
        assert_eq!(Station::default(), Station(0x99));
    }
}
