//! The one error type of the core.
//!
//! Every fallible function returns [`Error`]. It is `Copy`, a few bytes
//! large, and says exactly what was wrong and, where it helps, at which byte
//! offset of the frame (counted from the header byte, 0-based).

use crate::header::Header;

/// What went wrong while framing, parsing or emitting.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Error {
    /// The first byte of a frame is not `!`, `#`, `&` or `%`.
    InvalidHeader {
        /// The byte found.
        byte: u8,
    },
    /// A byte that must be a hex digit (`0-9`, `A-F`, `a-f`) is not.
    InvalidHexDigit {
        /// Offset of the byte in the frame.
        offset: usize,
        /// The byte found.
        byte: u8,
    },
    /// A byte of a decimal field is not `0-9`.
    InvalidDecimalDigit {
        /// Offset of the byte in the frame.
        offset: usize,
        /// The byte found.
        byte: u8,
    },
    /// The checksum SC does not match the bytes it covers.
    ChecksumMismatch {
        /// Low byte of the sum computed over header..body.
        computed: u8,
        /// The value carried in the frame.
        received: u8,
    },
    /// The frame carries `@@` instead of a checksum and the receive policy
    /// does not allow that for this kind of frame.
    ChecksumBypassRejected,
    /// CR was followed by something other than LF.
    MissingLineFeed {
        /// The byte found after CR.
        byte: u8,
    },
    /// LF arrived without the CR that must precede it.
    MissingCarriageReturn,
    /// A new header byte arrived before the current frame's CR LF: the
    /// frame was cut short (lost bytes) and is discarded.
    Truncated {
        /// Bytes of the cut frame that were discarded.
        len: usize,
    },
    /// The frame does not fit the receive buffer / the profile's limit.
    FrameTooLong {
        /// The limit in bytes (header through LF).
        limit: usize,
    },
    /// A frame ended before its 10-byte minimum (header, station, ID, SC, CR, LF).
    FrameTooShort {
        /// Length of the frame, header through LF.
        len: usize,
    },
    /// The frame is a different kind (`!`, `#`, `&`) than the one expected.
    UnexpectedHeader {
        /// Kind expected by the caller.
        expected: Header,
        /// Kind found.
        found: Header,
    },
    /// The frame carries another message ID than the one expected.
    UnexpectedMessageId {
        /// ID expected.
        expected: u16,
        /// ID found.
        found: u16,
    },
    /// The frame's station is not the one addressed.
    UnexpectedStation {
        /// Station expected.
        expected: u8,
        /// Station found.
        found: u8,
    },
    /// No message with this ID is known (in this direction, or to this profile).
    UnknownMessageId {
        /// The ID found.
        id: u16,
    },
    /// No reply was taken for the request with this ID: it failed, had
    /// none to take, or is not over.
    NoReply {
        /// The request's ID.
        id: u16,
    },
    /// An engine was run before anything was started on it.
    NotStarted,
    /// The message body ended before all its fields were read.
    BodyTooShort {
        /// Offset (in the frame) where the next field should have started.
        offset: usize,
    },
    /// Bytes are left in the body after the last field of the layout.
    TrailingBytes {
        /// Offset (in the frame) of the first unread byte.
        offset: usize,
    },
    /// A value does not fit its field (width, sign or the type it is read into).
    ValueOutOfRange {
        /// Offset (in the frame) of the field, or 0 when emitting.
        offset: usize,
    },
    /// A fixed (reserved) field does not hold its literal content.
    InvalidFixedField {
        /// Offset (in the frame) of the field.
        offset: usize,
    },
    /// A repeat group's number of items disagrees with the field that counts
    /// it (for example per-axis values versus the axis pattern).
    CountMismatch {
        /// Items the count field or axis pattern calls for.
        expected: usize,
        /// Items present.
        found: usize,
    },
    /// A repeat count exceeds the maximum the catalogue allows.
    CountTooLarge {
        /// The count.
        count: usize,
        /// The maximum.
        max: usize,
    },
    /// The output buffer is too small for the frame being emitted.
    BufferTooSmall,
    /// An axis number outside 1..=8, or named twice.
    InvalidAxis {
        /// The axis number.
        axis: u8,
    },
    /// The message is not available on the selected controller profile.
    NotSupportedByProfile {
        /// The message ID.
        id: u16,
    },
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Error::InvalidHeader { byte } => write!(f, "invalid header byte 0x{byte:02X}"),
            Error::InvalidHexDigit { offset, byte } => {
                write!(f, "byte 0x{byte:02X} at offset {offset} is not a hex digit")
            }
            Error::InvalidDecimalDigit { offset, byte } => {
                write!(
                    f,
                    "byte 0x{byte:02X} at offset {offset} is not a decimal digit"
                )
            }
            Error::ChecksumMismatch { computed, received } => {
                write!(
                    f,
                    "checksum {received:02X} received, {computed:02X} computed"
                )
            }
            Error::ChecksumBypassRejected => f.write_str("checksum bypass '@@' not accepted"),
            Error::MissingLineFeed { byte } => write!(f, "CR followed by 0x{byte:02X}, not LF"),
            Error::MissingCarriageReturn => f.write_str("LF without CR"),
            Error::Truncated { len } => write!(f, "frame cut short after {len} bytes"),
            Error::FrameTooLong { limit } => write!(f, "frame longer than {limit} bytes"),
            Error::FrameTooShort { len } => write!(f, "frame of {len} bytes is too short"),
            Error::UnexpectedHeader { expected, found } => {
                write!(f, "expected a {expected:?} frame, found {found:?}")
            }
            Error::UnexpectedMessageId { expected, found } => {
                write!(f, "expected message {expected:03X}H, found {found:03X}H")
            }
            Error::UnexpectedStation { expected, found } => {
                write!(f, "expected station {expected:02X}, found {found:02X}")
            }
            Error::UnknownMessageId { id } => write!(f, "unknown message ID {id:03X}H"),
            Error::NoReply { id } => write!(f, "no reply was taken for {id:03X}H"),
            Error::NotStarted => f.write_str("nothing was started on the engine"),
            Error::BodyTooShort { offset } => write!(f, "body ends early at offset {offset}"),
            Error::TrailingBytes { offset } => write!(f, "unexpected bytes from offset {offset}"),
            Error::ValueOutOfRange { offset } => {
                write!(f, "value out of range for its field at offset {offset}")
            }
            Error::InvalidFixedField { offset } => {
                write!(f, "reserved field at offset {offset} has the wrong content")
            }
            Error::CountMismatch { expected, found } => {
                write!(f, "{expected} items expected, {found} present")
            }
            Error::CountTooLarge { count, max } => write!(f, "count {count} exceeds maximum {max}"),
            Error::BufferTooSmall => f.write_str("output buffer too small"),
            Error::InvalidAxis { axis } => {
                write!(f, "axis {axis} is outside 1..=8 or named twice")
            }
            Error::NotSupportedByProfile { id } => {
                write!(
                    f,
                    "message {id:03X}H not supported by this controller profile"
                )
            }
        }
    }
}

impl core::error::Error for Error {}

/// Why an engine ([`crate::client`], [`crate::transfer`],
/// [`crate::readback`]) or a driver loop ([`crate::engine`]) stopped. `E`
/// is the UART driver's error; the engines themselves never produce
/// [`Failure::Io`] (their `E` is [`Infallible`](core::convert::Infallible)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Failure<E = core::convert::Infallible> {
    /// No valid reply after this many sends of a command that is safe to
    /// repeat: it may or may not have run.
    Timeout {
        /// Sends made.
        sends: u8,
    },
    /// No valid reply to a command that is unsafe to repeat (a relative
    /// move): it may have run, possibly more than once if resending was
    /// allowed. Check the controller's state (212H) before anything else.
    OutcomeUnknown {
        /// Sends made.
        sends: u8,
    },
    /// The controller (or a bridge on the way, with a code of its own)
    /// answered with an error response. Not resent (2003 pp. 13, 66).
    Controller {
        /// The code (the meaning is in the controller's manual).
        code: u16,
        /// The 216H detail, if it was asked for and came.
        detail: Option<ErrorDetail>,
    },
    /// A written frame still read back different after the allowed
    /// rewrites.
    Mismatch {
        /// The first differing position.
        first_position: u16,
        /// How many of the frame's records differ.
        records: u16,
    },
    /// A written frame's read-back lacked one of its records: the frame
    /// reached the controller with a corruption its SC cannot show (two
    /// bit flips that cancel) in a record's number, so that record was
    /// stored at another position, which no read-back of the transfer
    /// covers. The transfer rewrote and verified its frames to the end, but
    /// a position written before (or one outside the table) may hold the
    /// stray record: read the table back, or write it again.
    Misplaced {
        /// The first position whose record was not where it was written.
        position: u16,
    },
    /// Record number `index` (0-based, in source order) cannot be encoded.
    InvalidRecord {
        /// Index of the record.
        index: u32,
        /// Why.
        error: Error,
    },
    /// The line repeats frames or answers out of order (it heard frames
    /// it could not place, [`crate::line::Heard::Unplaced`]) and asking
    /// again did not give a reply that a proof of order confirmed: the
    /// reply taken may be a copy of an earlier one. Declare the line's
    /// duplicate window (`LineConfig::duplicate_window_ms`).
    Unconfirmed {
        /// Frames the line could not place.
        unplaced: u32,
    },
    /// A command could not be emitted, a reply not parsed as the type
    /// asked for, or the configuration cannot work.
    Protocol(Error),
    /// The link ended: a read returned no bytes although the driver said
    /// it was ready (a closed socket).
    Closed,
    /// The driver failed.
    Io(E),
}

impl<E> From<Error> for Failure<E> {
    fn from(e: Error) -> Self {
        Failure::Protocol(e)
    }
}

impl Failure {
    /// The same failure under a driver error type (an engine never fails
    /// with [`Failure::Io`]).
    pub const fn widen<E>(self) -> Failure<E> {
        match self {
            Failure::Timeout { sends } => Failure::Timeout { sends },
            Failure::OutcomeUnknown { sends } => Failure::OutcomeUnknown { sends },
            Failure::Controller { code, detail } => Failure::Controller { code, detail },
            Failure::Mismatch {
                first_position,
                records,
            } => Failure::Mismatch {
                first_position,
                records,
            },
            Failure::Misplaced { position } => Failure::Misplaced { position },
            Failure::InvalidRecord { index, error } => Failure::InvalidRecord { index, error },
            Failure::Unconfirmed { unplaced } => Failure::Unconfirmed { unplaced },
            Failure::Protocol(e) => Failure::Protocol(e),
            Failure::Closed => Failure::Closed,
            Failure::Io(never) => match never {},
        }
    }
}

impl<E: core::fmt::Debug> core::fmt::Display for Failure<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Failure::Timeout { sends } => {
                write!(f, "no valid reply after {sends} send(s)")
            }
            Failure::OutcomeUnknown { sends } => write!(
                f,
                "no valid reply after {sends} send(s) of a command unsafe to repeat: it may have run"
            ),
            Failure::Controller { code, detail: None } => {
                write!(f, "the controller answered with error {code:03X}")
            }
            Failure::Controller {
                code,
                detail: Some(d),
            } => write!(
                f,
                "the controller answered with error {code:03X} (216H: error {:03X}, details {}, {}, {}, {})",
                d.error_number, d.detail_1, d.detail_2, d.detail_3, d.detail_4
            ),
            Failure::Mismatch {
                first_position,
                records,
            } => write!(
                f,
                "{records} record(s) read back different, the first at position {first_position}"
            ),
            Failure::Misplaced { position } => write!(
                f,
                "the record of position {position} was not stored there (a frame corrupted in a way its checksum cannot show): another position may hold it; read the table back or write it again"
            ),
            Failure::InvalidRecord { index, error } => {
                write!(f, "record {index} cannot be encoded: {error}")
            }
            Failure::Unconfirmed { unplaced } => write!(
                f,
                "the line repeats frames ({unplaced} it could not place) and no reply could be confirmed: declare its duplicate window"
            ),
            Failure::Protocol(e) => write!(f, "{e}"),
            Failure::Closed => f.write_str("the link closed"),
            Failure::Io(e) => write!(f, "I/O error: {e:?}"),
        }
    }
}

impl<E: core::fmt::Debug> core::error::Error for Failure<E> {}

/// The numbers of a 216H error detail (TTA pp. 32-33), kept with the `&`
/// code they explain. The message string (always empty on the TTA, TTA
/// p. 33) is not kept: read 216H yourself for it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ErrorDetail {
    /// The error number the controller reports.
    pub error_number: u16,
    /// Detail 1: program number (system-down errors: type).
    pub detail_1: u32,
    /// Detail 2: step number (system-down: error code).
    pub detail_2: u32,
    /// Detail 3: axis number (system-down: information 1).
    pub detail_3: u32,
    /// Detail 4: position number, negative for an interpolation point
    /// (system-down: information 2).
    pub detail_4: i32,
    /// Details 5 to 8 (meanings undocumented).
    pub detail_5_to_8: [u32; 4],
    /// Whether `error_number` equals the code of the error response (the
    /// latest system error is taken to be the one the `&` reported: an
    /// **inference**, which this says whether it holds).
    pub matches_code: bool,
}

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = core::result::Result<T, E>;
