//! Codecs of single fields: numbers in fixed-width digits ([`FieldSpec`]),
//! raw text of a fixed length, a number that must stay 0 unless another
//! field allows it ([`ZeroUnless`], 216H), reserved literals ([`Fixed`]) and
//! nested structs ([`Nested`]). Each codec shows its values to a
//! [`Visitor`] too.

use super::{FieldCodec, Fields, Inspect, Value, Visitor, Wire};
use crate::axis::AxisPattern;
use crate::error::{Error, Result};
use crate::field::{FieldSpec, Radix, Reader, Writer};

/// Integer-like types carried in one numeric field.
pub trait Scalar: Copy {
    /// From an unsigned wire value; `None` if it does not fit the type.
    fn from_unsigned(v: u64) -> Option<Self>;
    /// From a sign-extended wire value; `None` if it does not fit the type.
    fn from_signed(v: i64) -> Option<Self>;
    /// As an unsigned wire value; `None` if negative.
    fn to_unsigned(self) -> Option<u64>;
    /// As a signed wire value; `None` if too large.
    fn to_signed(self) -> Option<i64>;
}

macro_rules! scalar_int {
    ($($t:ty),*) => {$(
        impl Scalar for $t {
            fn from_unsigned(v: u64) -> Option<Self> { <$t>::try_from(v).ok() }
            fn from_signed(v: i64) -> Option<Self> { <$t>::try_from(v).ok() }
            fn to_unsigned(self) -> Option<u64> { u64::try_from(self).ok() }
            fn to_signed(self) -> Option<i64> { i64::try_from(self).ok() }
        }
    )*};
}
scalar_int!(u8, u16, u32, u64, i8, i16, i32, i64);

impl Scalar for AxisPattern {
    fn from_unsigned(v: u64) -> Option<Self> {
        u8::try_from(v).ok().map(AxisPattern::from_bits)
    }
    fn from_signed(v: i64) -> Option<Self> {
        u8::try_from(v).ok().map(AxisPattern::from_bits)
    }
    fn to_unsigned(self) -> Option<u64> {
        Some(u64::from(self.bits()))
    }
    fn to_signed(self) -> Option<i64> {
        Some(i64::from(self.bits()))
    }
}

impl<'a, T: Scalar> FieldCodec<'a, T> for FieldSpec {
    fn read(&self, r: &mut Reader<'a>) -> Result<T> {
        let at = r.offset();
        let v = if self.signed {
            T::from_signed(r.signed(*self)?)
        } else {
            T::from_unsigned(r.unsigned(*self)?)
        };
        v.ok_or(Error::ValueOutOfRange { offset: at })
    }
    fn write(&self, value: &T, w: &mut Writer<'_>) -> Result<()> {
        let at = w.len();
        let out_of_range = Error::ValueOutOfRange { offset: at };
        if self.signed {
            w.signed(*self, value.to_signed().ok_or(out_of_range)?)
        } else {
            w.unsigned(*self, value.to_unsigned().ok_or(out_of_range)?)
        }
    }
    fn len(&self, _: &T) -> usize {
        FieldSpec::len(*self)
    }
}

/// A text field of exactly `N` raw characters.
impl<'a, const N: usize> FieldCodec<'a, [u8; N]> for FieldSpec {
    fn read(&self, r: &mut Reader<'a>) -> Result<[u8; N]> {
        let at = r.offset();
        if self.radix != Radix::Text || FieldSpec::len(*self) != N {
            return Err(Error::ValueOutOfRange { offset: at });
        }
        let mut out = [0u8; N];
        out.copy_from_slice(r.take(N)?);
        Ok(out)
    }
    fn write(&self, value: &[u8; N], w: &mut Writer<'_>) -> Result<()> {
        if self.radix != Radix::Text || FieldSpec::len(*self) != N {
            return Err(Error::ValueOutOfRange { offset: w.len() });
        }
        w.put(value)
    }
    fn len(&self, _: &[u8; N]) -> usize {
        N
    }
}

/// Codec of a numeric field that must hold 0 unless another field allows
/// a value (216H: the record number is used by type 5 only).
#[derive(Debug, Clone, Copy)]
pub struct ZeroUnless {
    /// The field's wire format.
    pub spec: FieldSpec,
    /// Whether a value other than 0 is allowed.
    pub allowed: bool,
}

/// A field in `spec`'s format that must be 0 unless `rule(selector)`.
pub fn zero_unless(
    spec: FieldSpec,
    selector: impl core::borrow::Borrow<u8>,
    rule: fn(u8) -> bool,
) -> ZeroUnless {
    ZeroUnless {
        spec,
        allowed: rule(*selector.borrow()),
    }
}

impl<'a, T: Scalar> FieldCodec<'a, T> for ZeroUnless {
    fn read(&self, r: &mut Reader<'a>) -> Result<T> {
        let at = r.offset();
        let v: T = self.spec.read(r)?;
        if !self.allowed && v.to_unsigned() != Some(0) {
            return Err(Error::ValueOutOfRange { offset: at });
        }
        Ok(v)
    }
    fn write(&self, value: &T, w: &mut Writer<'_>) -> Result<()> {
        if !self.allowed && value.to_unsigned() != Some(0) {
            return Err(Error::ValueOutOfRange { offset: w.len() });
        }
        self.spec.write(value, w)
    }
    fn len(&self, _: &T) -> usize {
        self.spec.len()
    }
}

impl<T: Scalar> Inspect<T> for ZeroUnless {
    fn inspect(&self, value: &T, name: &'static str, unit: &'static str, v: &mut dyn Visitor) {
        self.spec.inspect(value, name, unit, v);
    }
}

/// A reserved field: nothing to store, its literal content is fixed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reserved;

/// Codec of a [`Reserved`] field: the literal it must hold.
#[derive(Debug, Clone, Copy)]
pub struct Fixed(pub &'static [u8]);

impl<'a> FieldCodec<'a, Reserved> for Fixed {
    fn read(&self, r: &mut Reader<'a>) -> Result<Reserved> {
        let at = r.offset();
        let got = r.take(self.0.len())?;
        if got.eq_ignore_ascii_case(self.0) {
            Ok(Reserved)
        } else {
            Err(Error::InvalidFixedField { offset: at })
        }
    }
    fn write(&self, _: &Reserved, w: &mut Writer<'_>) -> Result<()> {
        w.put(self.0)
    }
    fn len(&self, _: &Reserved) -> usize {
        self.0.len()
    }
}

/// Codec of a nested [`Wire`] struct (a record of a repeat group).
#[derive(Debug, Clone, Copy, Default)]
pub struct Nested;

impl<'a, T: Wire<'a>> FieldCodec<'a, T> for Nested {
    fn read(&self, r: &mut Reader<'a>) -> Result<T> {
        T::read(r)
    }
    fn write(&self, value: &T, w: &mut Writer<'_>) -> Result<()> {
        value.write(w)
    }
    fn len(&self, value: &T) -> usize {
        value.wire_len()
    }
}

impl<T: Scalar> Inspect<T> for FieldSpec {
    fn inspect(&self, value: &T, name: &'static str, unit: &'static str, v: &mut dyn Visitor) {
        let shown = if self.signed {
            Value::Signed(value.to_signed().unwrap_or(0))
        } else {
            Value::Unsigned(value.to_unsigned().unwrap_or(0))
        };
        v.field(name, unit, *self, shown);
    }
}

impl<const N: usize> Inspect<[u8; N]> for FieldSpec {
    fn inspect(
        &self,
        value: &[u8; N],
        name: &'static str,
        unit: &'static str,
        v: &mut dyn Visitor,
    ) {
        v.field(name, unit, *self, Value::Text(value));
    }
}

impl Inspect<Reserved> for Fixed {
    fn inspect(&self, _: &Reserved, name: &'static str, unit: &'static str, v: &mut dyn Visitor) {
        let width = u8::try_from(self.0.len()).unwrap_or(u8::MAX);
        let spec = if self.0.iter().all(|&b| crate::field::is_hex_digit(b)) {
            FieldSpec::hex(width)
        } else {
            FieldSpec::text(width)
        };
        v.field(name, unit, spec, Value::Text(self.0));
    }
}

impl<T: Fields> Inspect<T> for Nested {
    fn inspect(&self, value: &T, _: &'static str, _: &'static str, v: &mut dyn Visitor) {
        value.fields(v);
    }
}
