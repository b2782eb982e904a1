//! Typed messages: each is a short declaration of its fields.
//!
//! The generic machinery (field codecs, repeat groups) lives in [`codec`];
//! a message is a struct declared with the crate's `wire!` macro, which lists
//! its fields in wire order, each with its Rust type and its codec. The
//! macro derives [`Wire`] (read/write of the body) and, for commands and
//! responses, [`Message`] (parse from / emit to a whole frame). A field may
//! end in `=> "unit"`; the macro also derives [`Fields`], which walks the
//! decoded values with their names, units and wire formats (for inspectors
//! and for checking the declarations against the catalogue).
//!
//! [`decode_any`] turns any checked frame into the matching typed message.
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
pub mod codec;
mod declarations;

pub use any::*;
pub use codec::*;
pub use declarations::*;

use crate::checksum::ChecksumMode;
use crate::error::{Error, Result};
use crate::frame::{emit_frame, Frame, Header, Station};

/// A command or response with a fixed message ID and header.
pub trait Message<'a>: Wire<'a> {
    /// The message ID.
    const ID: u16;
    /// `Header::Command` for commands, `Header::Response` for responses.
    const HEADER: Header;

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

/// Declares a struct whose fields are read and written in order, each with
/// its codec; optionally a command or response with its message ID.
macro_rules! wire {
    (
        $(#[$sm:meta])*
        $([$kind:ident $id:literal])?
        pub struct $name:ident <$lt:lifetime> {
            $( $(#[$fm:meta])* $fvis:vis $field:ident : $fty:ty = $codec:expr $(=> $unit:literal)? ),* $(,)?
        }
    ) => {
        $(#[$sm])*
        #[derive(Debug, Clone, Default, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name<$lt> { $( $(#[$fm])* $fvis $field: $fty ),* }
        impl<$lt> $crate::message::Wire<$lt> for $name<$lt> {
            wire!(@body $lt; $( $field : $fty = $codec ),*);
        }
        impl<$lt> $crate::message::Fields for $name<$lt> {
            wire!(@fields $( $field = $codec $(=> $unit)? ),*);
        }
        $( wire!(@message $kind $id; $name<$lt>; $lt); )?
    };
    (
        $(#[$sm:meta])*
        $([$kind:ident $id:literal])?
        pub struct $name:ident {
            $( $(#[$fm:meta])* $fvis:vis $field:ident : $fty:ty = $codec:expr $(=> $unit:literal)? ),* $(,)?
        }
    ) => {
        $(#[$sm])*
        #[derive(Debug, Clone, Default, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name { $( $(#[$fm])* $fvis $field: $fty ),* }
        impl<'r> $crate::message::Wire<'r> for $name {
            wire!(@body 'r; $( $field : $fty = $codec ),*);
        }
        impl $crate::message::Fields for $name {
            wire!(@fields $( $field = $codec $(=> $unit)? ),*);
        }
        $( wire!(@message $kind $id; $name; 'r); )?
    };
    (@body $lt:lifetime; $( $field:ident : $fty:ty = $codec:expr ),*) => {
        #[allow(unused_variables, clippy::redundant_locals)]
        fn read(r: &mut $crate::field::Reader<$lt>) -> $crate::error::Result<Self> {
            $( let $field: $fty = $crate::message::FieldCodec::read(&$codec, r)?; )*
            Ok(Self { $( $field ),* })
        }
        #[allow(unused_variables)]
        fn write(&self, w: &mut $crate::field::Writer<'_>) -> $crate::error::Result<()> {
            let Self { $( $field ),* } = self;
            $( $crate::message::FieldCodec::write(&$codec, $field, w)?; )*
            Ok(())
        }
    };
    (@fields $( $field:ident = $codec:expr $(=> $unit:literal)? ),*) => {
        #[allow(unused_variables)]
        fn fields(&self, v: &mut dyn $crate::message::Visitor) {
            let Self { $( $field ),* } = self;
            $( $crate::message::Inspect::inspect(
                &$codec, $field, $crate::message::strip_raw(stringify!($field)), wire!(@unit $($unit)?), v,
            ); )*
        }
    };
    (@unit) => { "" };
    (@unit $unit:literal) => { $unit };
    (@message command $id:literal; $ty:ty; $lt:lifetime) => {
        impl<$lt> $crate::message::Message<$lt> for $ty {
            const ID: u16 = $id;
            const HEADER: $crate::frame::Header = $crate::frame::Header::Command;
        }
    };
    (@message response $id:literal; $ty:ty; $lt:lifetime) => {
        impl<$lt> $crate::message::Message<$lt> for $ty {
            const ID: u16 = $id;
            const HEADER: $crate::frame::Header = $crate::frame::Header::Response;
        }
    };
}
pub(crate) use wire;

/// Frames are scanned for text fields up to this many bytes in.
pub const TEXT_SPAN_KNOWN_BY: usize = declarations::ERROR_DETAIL_MESSAGE_AT;

/// Frame offsets `[start, end)` of the raw-text field of a frame, if its
/// message has one, given the frame's first bytes (`prefix`).
///
/// Only 200H (test string, both directions) and the 216H response (message
/// string) carry raw characters; everywhere else every body byte is a hex
/// digit. Returns `None` while `prefix` is too short to tell.
pub fn text_span(header: Header, prefix: &[u8]) -> Option<(usize, usize)> {
    let code = prefix.get(3..6)?;
    match (header, code) {
        (Header::Command | Header::Response, b"200") => Some(declarations::TEST_STRING_SPAN),
        (Header::Response, b"216") => {
            let at = declarations::ERROR_DETAIL_MESSAGE_AT;
            let count = prefix.get(at - 2..at)?;
            let n = crate::field::decode_unsigned(crate::field::FieldSpec::hex(2), count, at - 2)
                .ok()?;
            Some((at, at + n as usize))
        }
        _ => None,
    }
}
