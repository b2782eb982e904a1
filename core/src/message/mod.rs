//! Typed messages: each is a short declaration of its fields.
//!
//! The field codecs and repeat groups are re-exported here; a message is a struct declared with the crate's `wire!` macro, which lists
//! its fields in wire order, each with its Rust type and its codec. The
//! macro derives [`Wire`] (read, write and length of the body). A field may
//! end in `=> "unit"`; the macro also derives [`Fields`], which walks the
//! decoded values with their names, units and wire formats (for inspectors
//! and for checking the declarations against the catalogue).
//!
//! One table binds each [`crate::catalogue`] entry to its command type and
//! response type: it derives [`Message`] (parse from / emit to a whole
//! frame) and [`Request`] (which response answers which command), the
//! [`Command`] and [`Response`] enums and [`decode_any`], which turns any
//! checked frame into the matching typed message.
//!
//! ```
//! use iai_protocol_b::message::{Message, AxisStatusQuery};
//! use iai_protocol_b::axis::AxisPattern;
//! use iai_protocol_b::frame::Station;
//! let q = AxisStatusQuery { query_axis_pattern: AxisPattern::first(3) };
//! let mut buf = [0u8; 32];
//! let n = q.emit(Station(0x99), &mut buf).unwrap();
//! assert_eq!(&buf[..n], b"!99212078F\r\n");
//! ```

mod any;
mod declarations;

pub use crate::codec::*;
pub use any::*;
pub use declarations::*;

use crate::catalogue::MessageInfo;
use crate::checksum::ChecksumMode;
use crate::error::{Error, Result};
use crate::frame::{emit_frame, Frame, Header, Station, ENVELOPE_LEN, TRAILER_LEN};

/// A command or response: a field layout bound to its catalogue entry.
///
/// The ID is not written here but taken from the entry
/// ([`Message::INFO`]), so each ID stands once in the crate, in
/// [`crate::catalogue`].
pub trait Message<'a>: Wire<'a> {
    /// The catalogue entry of the message.
    const INFO: &'static MessageInfo;
    /// `Header::Command` for commands, `Header::Response` for responses.
    const HEADER: Header;
    /// The message ID.
    const ID: u16 = Self::INFO.id;

    /// Parses a checked frame as this message: header, ID, every field,
    /// and nothing left over.
    fn parse(frame: &Frame<'a>) -> Result<Self> {
        if frame.header() != Self::HEADER {
            return Err(Error::UnexpectedHeader {
                expected: Self::HEADER,
                found: frame.header(),
            });
        }
        if frame.code() != Self::ID {
            return Err(Error::UnexpectedMessageId {
                expected: Self::ID,
                found: frame.code(),
            });
        }
        let mut r = frame.reader();
        let v = Self::read(&mut r)?;
        r.finish()?;
        Ok(v)
    }

    /// Length of the whole frame [`Message::emit`] writes, header through
    /// LF: the buffer size it needs.
    fn emit_len(&self) -> usize {
        ENVELOPE_LEN + self.wire_len() + TRAILER_LEN
    }

    /// Emits the whole frame into `buf` with a computed checksum; returns
    /// its length.
    fn emit(&self, station: Station, buf: &mut [u8]) -> Result<usize> {
        self.emit_with(station, ChecksumMode::Compute, buf)
    }

    /// Emits the whole frame with the given checksum mode.
    fn emit_with(&self, station: Station, mode: ChecksumMode, buf: &mut [u8]) -> Result<usize> {
        emit_frame(buf, Self::HEADER, station, Self::ID, mode, |w| {
            self.write(w)
        })
    }
}

/// A command, with the type of the normal response that answers it.
///
/// ```
/// use iai_protocol_b::message::{AxisStatusQuery, Message, Request};
/// fn reply_id<'a, R: Request<'a>>() -> u16 {
///     <R::Response<'static> as Message<'static>>::ID
/// }
/// assert_eq!(reply_id::<AxisStatusQuery>(), AxisStatusQuery::ID);
/// ```
pub trait Request<'a>: Message<'a> {
    /// The normal response's type (borrowing the reply frame for `'r`).
    type Response<'r>: Message<'r>;
}

/// Declares a struct whose fields are read and written in order, each with
/// its codec; optionally a command or response with its message ID.
macro_rules! wire {
    (
        $(#[$sm:meta])*
        pub struct $name:ident <$lt:lifetime> {
            $( $(#[$fm:meta])* $fvis:vis $field:ident : $fty:ty = $codec:expr $(=> $unit:literal)? ),* $(,)?
        }
    ) => {
        $(#[$sm])*
        #[derive(Debug, Clone, Default, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name<$lt> { $( $(#[$fm])* $fvis $field: $fty ),* }
        impl<$lt> $crate::codec::Wire<$lt> for $name<$lt> {
            wire!(@body $lt; $( $field : $fty = $codec ),*);
        }
        impl<$lt> $crate::codec::Fields for $name<$lt> {
            wire!(@fields $( $field = $codec $(=> $unit)? ),*);
        }
    };
    (
        $(#[$sm:meta])*
        pub struct $name:ident {
            $( $(#[$fm:meta])* $fvis:vis $field:ident : $fty:ty = $codec:expr $(=> $unit:literal)? ),* $(,)?
        }
    ) => {
        $(#[$sm])*
        #[derive(Debug, Clone, Default, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name { $( $(#[$fm])* $fvis $field: $fty ),* }
        impl<'r> $crate::codec::Wire<'r> for $name {
            wire!(@body 'r; $( $field : $fty = $codec ),*);
        }
        impl $crate::codec::Fields for $name {
            wire!(@fields $( $field = $codec $(=> $unit)? ),*);
        }
    };
    (@body $lt:lifetime; $( $field:ident : $fty:ty = $codec:expr ),*) => {
        #[allow(unused_variables, clippy::redundant_locals)]
        fn read(r: &mut $crate::field::Reader<$lt>) -> $crate::error::Result<Self> {
            $( let $field: $fty = $crate::codec::FieldCodec::read(&$codec, r)?; )*
            Ok(Self { $( $field ),* })
        }
        #[allow(unused_variables)]
        fn write(&self, w: &mut $crate::field::Writer<'_>) -> $crate::error::Result<()> {
            let Self { $( $field ),* } = self;
            $( $crate::codec::FieldCodec::write(&$codec, $field, w)?; )*
            Ok(())
        }
        #[allow(unused_variables)]
        fn wire_len(&self) -> usize {
            let Self { $( $field ),* } = self;
            0 $( + $crate::codec::FieldCodec::len(&$codec, $field) )*
        }
    };
    (@fields $( $field:ident = $codec:expr $(=> $unit:literal)? ),*) => {
        #[allow(unused_variables)]
        fn fields(&self, v: &mut dyn $crate::codec::Visitor) {
            let Self { $( $field ),* } = self;
            $( $crate::codec::Inspect::inspect(
                &$codec, $field, $crate::codec::strip_raw(stringify!($field)), wire!(@unit $($unit)?), v,
            ); )*
        }
    };
    (@unit) => { "" };
    (@unit $unit:literal) => { $unit };
}
pub(crate) use wire;
