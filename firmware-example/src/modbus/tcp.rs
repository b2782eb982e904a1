//! Modbus TCP framing (Modbus Messaging on TCP/IP, 3.1): each request is
//! an ADU of a 7-byte MBAP header (transaction ID, protocol ID 0, the
//! length of what follows, unit ID) and the PDU, back to back on the
//! connection. The answer echoes the transaction and protocol IDs and the
//! unit ID.
//!
//! A connection is cut into ADUs by their length field ([`adu_len`]); a
//! length that no ADU has (under 2, over 254) means the stream cannot be
//! followed any more, and the connection is closed. A whole ADU whose
//! protocol ID is not 0 (not Modbus), or whose length does not fit its
//! function code, is dropped without an answer ([`check`]), and the next
//! one is read.
//!
//! Units: the configured unit ID (as on RTU) and [`GATEWAY_UNIT`] both
//! address the gateway itself, and the answer carries the unit the
//! request named; unit 0 is a broadcast (writes carried out, nothing
//! answered); other units get no answer.

/// Longest ADU: the MBAP header (7 bytes) and a PDU of up to 253.
pub const MAX_ADU: usize = 260;
/// Bytes of the header before the unit ID (transaction ID, protocol ID,
/// length): the unit ID is at this offset.
pub const UNIT_AT: usize = 6;
/// Unit 255 (FFH): the Modbus TCP implementation guide's unit ID for a
/// server addressed by its IP address alone, accepted beside the
/// configured unit over TCP only (on an RTU line 255 is no unit of ours).
pub const GATEWAY_UNIT: u8 = 0xFF;
/// Smallest length field: the unit ID and a function code.
pub const MIN_LENGTH: usize = 2;
/// Largest length field: the unit ID and a PDU of 253 bytes.
pub const MAX_LENGTH: usize = 254;

/// A Modbus TCP response (at most [`MAX_ADU`] bytes).
pub type Response = heapless::Vec<u8, MAX_ADU>;

/// Why an ADU was not answered, or a connection not followed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dropped {
    /// The length field is out of 2..=254: the connection is closed.
    Framing,
    /// The protocol ID is not 0: not Modbus, dropped.
    Protocol,
    /// The length does not fit the function code (or the length field
    /// disagrees with the ADU's size): dropped.
    Length,
}

/// The size of the ADU that starts with `head` (at least its first six
/// bytes: `None` while fewer have arrived), from its length field; or
/// [`Dropped::Framing`] if that field is out of range.
pub fn adu_len(head: &[u8]) -> Option<Result<usize, Dropped>> {
    let hi = *head.get(4)?;
    let lo = *head.get(5)?;
    let length = usize::from(u16::from_be_bytes([hi, lo]));
    Some(if (MIN_LENGTH..=MAX_LENGTH).contains(&length) {
        Ok(UNIT_AT + length)
    } else {
        Err(Dropped::Framing)
    })
}

/// Checks a whole ADU: its protocol ID, its length field against its size,
/// and its size for its function code (as [`super::rtu::check`] does for
/// an RTU frame).
pub fn check(adu: &[u8]) -> Result<(), Dropped> {
    if adu.get(2..4) != Some(&[0, 0][..]) {
        return Err(Dropped::Protocol);
    }
    match adu_len(adu) {
        Some(Ok(n)) if n == adu.len() => {}
        _ => return Err(Dropped::Length),
    }
    // Unit ID and PDU.
    let n = adu.len() - UNIT_AT;
    let fits = match adu.get(UNIT_AT + 1) {
        Some(1..=6) => n == 6,
        Some(15 | 16) => adu
            .get(UNIT_AT + 6)
            .is_some_and(|&b| n == 7 + usize::from(b)),
        Some(_) => n >= MIN_LENGTH,
        None => false,
    };
    if fits {
        Ok(())
    } else {
        Err(Dropped::Length)
    }
}
