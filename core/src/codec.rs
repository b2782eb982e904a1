//! The generic field machinery every message declaration is built from.
//!
//! A message body is a sequence of fields. Each field pairs a Rust type
//! with a *codec* value that knows its wire form:
//!
//! | codec | Rust type | wire |
//! |---|---|---|
//! | [`FieldSpec`] | `u8`…`u64`, `i8`…`i64`, [`AxisPattern`], [`Reserved`]-free scalars | fixed-width hex/dec digits |
//! | [`FieldSpec`] with `Radix::Text` | `[u8; N]` | N raw characters |
//! | [`Fixed`] | [`Reserved`] | a literal (`"00"`) |
//! | [`Nested`] | any [`Wire`] struct | its own fields |
//! | [`Counted`] | [`Repeated`] | a count field, then that many items |
//! | [`CountedText`] | `&[u8]` | a count field, then that many raw characters |
//! | [`PerAxisCodec`] | [`PerAxis`] | one item per axis set in an axis pattern |
//! | [`Array`] | `[T; N]` | exactly N items |
//! | [`PerAxisUpTo`] | [`PerAxis`] | as [`PerAxisCodec`], at most `max` axes |
//! | [`CountedPer`] | [`Units`] | a count of units (8 ports per item), then the items |
//! | [`FieldSpec`] (16 hex digits) | [`RealWire`] | a real variable as sent (see [`WordOrder`]) |
//!
//! Every codec also implements [`Inspect`], which shows decoded values with
//! their names, units and wire formats to a [`Visitor`].
//!
//! The codecs of single fields, the per-axis and fixed-size groups, the
//! counted repeat groups (lazy: see [`Repeated`]), the visitor and the
//! real-variable words each have a submodule; every item is re-exported
//! here, so `codec::X` (and `message::X`) names them all.
//!
//! [`FieldSpec`]: crate::field::FieldSpec
//! [`AxisPattern`]: crate::axis::AxisPattern
//! [`PerAxis`]: crate::axis::PerAxis

mod field;
mod per_axis;
mod real;
mod repeated;
mod visit;

pub use field::*;
pub use per_axis::*;
pub use real::*;
pub use repeated::*;
pub use visit::*;

use crate::error::Result;
use crate::field::{Reader, Writer};

/// A value that reads and writes itself as a sequence of fields.
pub trait Wire<'a>: Sized {
    /// Reads the fields of `Self` from `r`.
    fn read(r: &mut Reader<'a>) -> Result<Self>;
    /// Writes the fields of `Self` to `w`.
    fn write(&self, w: &mut Writer<'_>) -> Result<()>;
    /// How many bytes [`Wire::write`] writes.
    fn wire_len(&self) -> usize;
}

/// Knows the wire form of values of type `T`.
pub trait FieldCodec<'a, T> {
    /// Reads one value.
    fn read(&self, r: &mut Reader<'a>) -> Result<T>;
    /// Writes one value.
    fn write(&self, value: &T, w: &mut Writer<'_>) -> Result<()>;
    /// How many bytes [`FieldCodec::write`] writes for `value`.
    fn len(&self, value: &T) -> usize;
}
