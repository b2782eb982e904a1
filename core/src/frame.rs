//! The frame envelope: a checked zero-copy view ([`Frame`]) and the emitter.
//!
//! ```text
//! '!' | station (2 hex) | message ID (3 hex) | body … | SC (2 hex) | CR | LF   command
//! '#' | station (2 hex) | message ID (3 hex) | body … | SC (2 hex) | CR | LF   normal response
//! '&' | station (2 hex) | error code (3 hex)          | SC (2 hex) | CR | LF   error response
//! ```
//!
//! An error response carries an error code where other frames carry the
//! message ID. `%` is accepted as an error header too: the 2003 appendix
//! (p. 65) names it, while every table uses `&`; `&` is what the core sends.
//!
//! Body bytes are hex digits except inside the raw-text field of the two
//! messages that have one (200H, 216H response): the catalogue's
//! [`text_span`] says where.
//!
//! # Panic freedom
//! [`Frame::new_checked`] validates the envelope once; every accessor after
//! that is infallible and uses no indexing that could panic. Emitting writes
//! into a caller's buffer and reports [`Error::BufferTooSmall`] instead of
//! overrunning it.

use crate::catalogue::text_span;
use crate::checksum::{BypassPolicy, Checksum, ChecksumField, ChecksumMode};
use crate::error::{Error, Result};
use crate::field::{hex_digit, hex_value, FieldSpec, Reader, Writer};

/// Bytes before the body: header, station, message ID.
pub const ENVELOPE_LEN: usize = 6;
/// Bytes after the body: SC, CR, LF.
pub const TRAILER_LEN: usize = 4;
/// The shortest frame: a response without data, or an error response.
pub const MIN_FRAME_LEN: usize = ENVELOPE_LEN + TRAILER_LEN;

pub use crate::header::{Header, MessageId, Station};

fn hex_pair(bytes: &[u8], at: usize) -> Result<u8> {
    let mut v = 0u8;
    for i in at..at + 2 {
        let b = bytes.get(i).copied().unwrap_or(0);
        let d = hex_value(b).ok_or(Error::InvalidHexDigit { offset: i, byte: b })?;
        v = (v << 4) | d;
    }
    Ok(v)
}

fn hex_triple(bytes: &[u8], at: usize) -> Result<u16> {
    let mut v = 0u16;
    for i in at..at + 3 {
        let b = bytes.get(i).copied().unwrap_or(0);
        let d = hex_value(b).ok_or(Error::InvalidHexDigit { offset: i, byte: b })?;
        v = (v << 4) | u16::from(d);
    }
    Ok(v)
}

/// Checks a complete frame (header through LF) and returns the fields of
/// its envelope. Body bytes are checked to be hex digits except inside the
/// message's text span (see [`text_span`]).
pub(crate) fn validate(bytes: &[u8], policy: BypassPolicy) -> Result<Envelope> {
    let len = bytes.len();
    if len < MIN_FRAME_LEN {
        return Err(Error::FrameTooShort { len });
    }
    let first = bytes.first().copied().unwrap_or(0);
    let header = Header::from_byte(first).ok_or(Error::InvalidHeader { byte: first })?;
    let station = hex_pair(bytes, 1)?;
    let code = hex_triple(bytes, 3)?;
    let sc_at = len - TRAILER_LEN;
    match (bytes.get(len - 2), bytes.get(len - 1)) {
        (Some(b'\r'), Some(b'\n')) => {}
        (Some(b'\r'), Some(&b)) => return Err(Error::MissingLineFeed { byte: b }),
        _ => return Err(Error::MissingCarriageReturn),
    }
    let body = bytes.get(ENVELOPE_LEN..sc_at).unwrap_or(&[]);
    let text = text_span(header, bytes);
    // A text field must end before SC (the decoder would read on as text).
    if text.is_some_and(|(_, e)| e > sc_at) {
        return Err(Error::BodyTooShort { offset: sc_at });
    }
    for (i, &b) in body.iter().enumerate() {
        let at = ENVELOPE_LEN + i;
        let in_text = text.is_some_and(|(s, e)| at >= s && at < e);
        if !in_text && hex_value(b).is_none() {
            return Err(Error::InvalidHexDigit {
                offset: at,
                byte: b,
            });
        }
    }
    let sc = bytes.get(sc_at..sc_at + 2).unwrap_or(&[]);
    let checksum = if sc == b"@@" {
        if !policy.allows(header) {
            return Err(Error::ChecksumBypassRejected);
        }
        ChecksumField::Bypass
    } else {
        let received = hex_pair(bytes, sc_at)?;
        let computed = Checksum::of(bytes.get(..sc_at).unwrap_or(&[]));
        if computed != received {
            return Err(Error::ChecksumMismatch { computed, received });
        }
        ChecksumField::Sum(received)
    };
    Ok(Envelope {
        header,
        station: Station(station),
        code,
        checksum,
    })
}

/// The decoded envelope of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Envelope {
    pub header: Header,
    pub station: Station,
    pub code: u16,
    pub checksum: ChecksumField,
}

/// A checked view of one complete frame, header through LF.
///
/// Obtained from [`Frame::new_checked`] or from the
/// [`FrameDecoder`](crate::decoder::FrameDecoder). The header, station, ID
/// and checksum are known valid; the body is known to be hex digits outside
/// the text fields. Its meaning is up to the message layouts
/// ([`crate::message`]).
///
/// ```
/// use iai_protocol_b::frame::{Frame, Header, Station, MessageId};
/// use iai_protocol_b::checksum::BypassPolicy;
/// let f = Frame::new_checked(b"#992322C\r\n", BypassPolicy::default()).unwrap();
/// assert_eq!(f.header(), Header::Response);
/// assert_eq!(f.station(), Station(0x99));
/// assert_eq!(f.message_id(), Some(MessageId(0x232)));
/// assert!(f.body().is_empty());
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    bytes: &'a [u8],
    env: Envelope,
}

impl<'a> Frame<'a> {
    /// Checks `bytes` as one complete frame.
    pub fn new_checked(bytes: &'a [u8], policy: BypassPolicy) -> Result<Self> {
        let env = validate(bytes, policy)?;
        Ok(Frame { bytes, env })
    }
    pub(crate) fn from_parts(bytes: &'a [u8], env: Envelope) -> Self {
        Frame { bytes, env }
    }
    /// The frame kind.
    pub fn header(&self) -> Header {
        self.env.header
    }
    /// The station code.
    pub fn station(&self) -> Station {
        self.env.station
    }
    /// The message ID; `None` for an error response.
    pub fn message_id(&self) -> Option<MessageId> {
        match self.env.header {
            Header::Error => None,
            _ => Some(MessageId(self.env.code)),
        }
    }
    /// The error code of an error response; `None` otherwise.
    pub fn error_code(&self) -> Option<u16> {
        match self.env.header {
            Header::Error => Some(self.env.code),
            _ => None,
        }
    }
    /// The 3-digit value after the station: message ID or error code.
    pub fn code(&self) -> u16 {
        self.env.code
    }
    /// The data between the message ID and SC.
    pub fn body(&self) -> &'a [u8] {
        self.bytes
            .get(ENVELOPE_LEN..self.bytes.len().saturating_sub(TRAILER_LEN))
            .unwrap_or(&[])
    }
    /// A field reader over the body (offsets counted from the header).
    pub fn reader(&self) -> Reader<'a> {
        Reader::new(self.body(), ENVELOPE_LEN)
    }
    /// The checksum the frame carried.
    pub fn checksum(&self) -> ChecksumField {
        self.env.checksum
    }
    /// The whole frame, header through LF.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }
    /// Length in bytes, header through LF.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }
    /// Always false: a frame has at least 10 bytes.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for Frame<'_> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "Frame({=[u8]:a})", self.bytes)
    }
}

/// Header, station and code (message ID, or error code for `&`) of a
/// frame's first [`ENVELOPE_LEN`] bytes, if they read as such.
///
/// ```
/// use iai_protocol_b::frame::{read_envelope, Header, Station};
/// assert_eq!(read_envelope(b"!99212"), Some((Header::Command, Station(0x99), 0x212)));
/// assert_eq!(read_envelope(b"&99C74"), Some((Header::Error, Station(0x99), 0xC74)));
/// assert_eq!(read_envelope(b"#9G212"), None);
/// ```
pub fn read_envelope(bytes: &[u8]) -> Option<(Header, Station, u16)> {
    let header = Header::from_byte(*bytes.first()?)?;
    let station = crate::field::decode_unsigned(FieldSpec::hex(2), bytes.get(1..3)?, 1).ok()?;
    let code = crate::field::decode_unsigned(FieldSpec::hex(3), bytes.get(3..6)?, 3).ok()?;
    Some((header, Station(station as u8), code as u16))
}

/// Writes the envelope start: header, station, code (3 hex digits).
pub fn emit_envelope(
    w: &mut Writer<'_>,
    header: Header,
    station: Station,
    code: u16,
) -> Result<()> {
    w.put(&[header.byte()])?;
    w.unsigned(FieldSpec::hex(2), u64::from(station.0))?;
    w.unsigned(FieldSpec::hex(3), u64::from(code))
}

/// Appends SC (or `@@`), CR and LF after everything written so far.
pub fn emit_trailer(w: &mut Writer<'_>, mode: ChecksumMode) -> Result<()> {
    let sc = match mode {
        ChecksumMode::Compute => {
            let s = Checksum::of(w.written());
            [hex_digit(s >> 4), hex_digit(s)]
        }
        ChecksumMode::Bypass => *b"@@",
    };
    w.put(&sc)?;
    w.put(b"\r\n")
}

/// Emits a whole frame into `buf`: envelope, the body written by `body`,
/// then SC CR LF. Returns the frame length. On error nothing useful is in
/// `buf` and the error says why.
///
/// ```
/// use iai_protocol_b::frame::{emit_frame, Header, Station};
/// use iai_protocol_b::checksum::ChecksumMode;
/// let mut buf = [0u8; 16];
/// let n = emit_frame(&mut buf, Header::Command, Station(0x99), 0x209, ChecksumMode::Compute, |w| {
///     w.put(b"001005")
/// }).unwrap();
/// assert_eq!(&buf[..n], b"!9920900100554\r\n");
/// ```
pub fn emit_frame(
    buf: &mut [u8],
    header: Header,
    station: Station,
    code: u16,
    mode: ChecksumMode,
    body: impl FnOnce(&mut Writer<'_>) -> Result<()>,
) -> Result<usize> {
    let mut w = Writer::new(buf);
    emit_envelope(&mut w, header, station, code)?;
    body(&mut w)?;
    emit_trailer(&mut w, mode)?;
    Ok(w.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_2003_worked_examples() {
        // 2003 p. 10: "!99209001005" sums to 254h, SC "54".
        let f = Frame::new_checked(b"!9920900100554\r\n", BypassPolicy::Reject).unwrap();
        assert_eq!(f.header(), Header::Command);
        assert_eq!(f.station(), Station(0x99));
        assert_eq!(f.message_id(), Some(MessageId(0x209)));
        assert_eq!(f.body(), b"001005");
        assert_eq!(f.checksum(), ChecksumField::Sum(0x54));
        // 2003 p. 66: "!99209000032", SC "53".
        assert!(Frame::new_checked(b"!9920900003253\r\n", BypassPolicy::Reject).is_ok());
    }

    #[test]
    fn emitting_gives_the_same_bytes() {
        let mut buf = [0u8; 16];
        let n = emit_frame(
            &mut buf,
            Header::Command,
            Station(0x99),
            0x209,
            ChecksumMode::Compute,
            |w| w.put(b"001005"),
        )
        .unwrap();
        assert_eq!(&buf[..n], b"!9920900100554\r\n");
        let n = emit_frame(
            &mut buf,
            Header::Command,
            Station(0x99),
            0x232,
            ChecksumMode::Bypass,
            |w| w.put(b"071"),
        )
        .unwrap();
        assert_eq!(&buf[..n], b"!99232071@@\r\n");
        assert_eq!(
            emit_frame(
                &mut buf[..9],
                Header::Response,
                Station(0x99),
                0x232,
                ChecksumMode::Compute,
                |_| Ok(())
            ),
            Err(Error::BufferTooSmall)
        );
    }

    #[test]
    fn bypass_only_where_the_policy_allows() {
        let cmd = b"!99232071@@\r\n";
        assert!(Frame::new_checked(cmd, BypassPolicy::CommandsOnly).is_ok());
        assert_eq!(
            Frame::new_checked(cmd, BypassPolicy::Reject),
            Err(Error::ChecksumBypassRejected)
        );
        assert_eq!(
            Frame::new_checked(b"#99232@@\r\n", BypassPolicy::CommandsOnly),
            Err(Error::ChecksumBypassRejected)
        );
    }

    #[test]
    fn error_responses_carry_a_code_not_an_id() {
        for header in [b'&', b'%'] {
            let mut f = *b"&99C7446\r\n";
            f[0] = header;
            let sum = crate::checksum::Checksum::of(&f[..6]);
            f[6] = hex_digit(sum >> 4);
            f[7] = hex_digit(sum);
            let frame = Frame::new_checked(&f, BypassPolicy::Reject).unwrap();
            assert_eq!(frame.header(), Header::Error);
            assert_eq!(frame.error_code(), Some(0xC74));
            assert_eq!(frame.message_id(), None);
        }
    }

    #[test]
    fn every_envelope_fault_has_its_error() {
        let p = BypassPolicy::Reject;
        assert_eq!(
            Frame::new_checked(b"#9923\r\n", p),
            Err(Error::FrameTooShort { len: 7 })
        );
        assert_eq!(
            Frame::new_checked(b"?992322C\r\n", p),
            Err(Error::InvalidHeader { byte: b'?' })
        );
        assert_eq!(
            Frame::new_checked(b"#992322D\r\n", p),
            Err(Error::ChecksumMismatch {
                computed: 0x2C,
                received: 0x2D
            })
        );
        assert_eq!(
            Frame::new_checked(b"#99232x2C\r\n", p),
            Err(Error::InvalidHexDigit {
                offset: 6,
                byte: b'x'
            })
        );
        assert_eq!(
            Frame::new_checked(b"#992322C\rX", p),
            Err(Error::MissingLineFeed { byte: b'X' })
        );
    }
}
