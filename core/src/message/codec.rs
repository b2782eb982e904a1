//! The generic field machinery every message declaration is built from.
//!
//! A message body is a sequence of fields. Each field pairs a Rust type
//! with a *codec* value that knows its wire form:
//!
//! | codec | Rust type | wire |
//! |---|---|---|
//! | [`FieldSpec`] | `u8`…`u64`, `i8`…`i64`, [`AxisPattern`], [`Reserved`]-free scalars | fixed-width hex/dec digits |
//! | [`FieldSpec`] with [`Radix::Text`](crate::field::Radix::Text) | `[u8; N]` | N raw characters |
//! | [`Fixed`] | [`Reserved`] | a literal (`"00"`) |
//! | [`Nested`] | any [`Wire`] struct | its own fields |
//! | [`Counted`] | [`Repeated`] | a count field, then that many items |
//! | [`CountedText`] | `&[u8]` | a count field, then that many raw characters |
//! | [`PerAxisCodec`] | [`PerAxis`] | one item per axis set in an axis pattern |
//! | [`Array`] | `[T; N]` | exactly N items |
//!
//! Repeat groups are lazy: parsing validates every item once and keeps a
//! slice of the frame; iterating decodes items on demand. Emitting takes
//! items from a slice. Neither allocates.

use core::marker::PhantomData;

use crate::axis::{AxisPattern, PerAxis};
use crate::error::{Error, Result};
use crate::field::{FieldSpec, Radix, Reader, Writer};

/// A value that reads and writes itself as a sequence of fields.
pub trait Wire<'a>: Sized {
    /// Reads the fields of `Self` from `r`.
    fn read(r: &mut Reader<'a>) -> Result<Self>;
    /// Writes the fields of `Self` to `w`.
    fn write(&self, w: &mut Writer<'_>) -> Result<()>;
}

/// Knows the wire form of values of type `T`.
pub trait FieldCodec<'a, T> {
    /// Reads one value.
    fn read(&self, r: &mut Reader<'a>) -> Result<T>;
    /// Writes one value.
    fn write(&self, value: &T, w: &mut Writer<'_>) -> Result<()>;
}

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
}

/// A text field of exactly `N` raw characters.
impl<'a, const N: usize> FieldCodec<'a, [u8; N]> for FieldSpec {
    fn read(&self, r: &mut Reader<'a>) -> Result<[u8; N]> {
        let at = r.offset();
        if self.radix != Radix::Text || self.len() != N {
            return Err(Error::ValueOutOfRange { offset: at });
        }
        let mut out = [0u8; N];
        out.copy_from_slice(r.take(N)?);
        Ok(out)
    }
    fn write(&self, value: &[u8; N], w: &mut Writer<'_>) -> Result<()> {
        if self.radix != Radix::Text || self.len() != N {
            return Err(Error::ValueOutOfRange { offset: w.len() });
        }
        w.put(value)
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
}

/// Anything an axis-pattern argument can be taken from: the pattern itself
/// (while parsing) or a reference to it (while emitting).
pub trait AsPattern {
    /// The pattern.
    fn pattern(&self) -> AxisPattern;
}
impl AsPattern for AxisPattern {
    fn pattern(&self) -> AxisPattern {
        *self
    }
}
impl<T: AsPattern + ?Sized> AsPattern for &T {
    fn pattern(&self) -> AxisPattern {
        (**self).pattern()
    }
}

/// Codec of a per-axis group: one item per axis set in `pattern`.
#[derive(Debug, Clone, Copy)]
pub struct PerAxisCodec<C> {
    /// The axis pattern that decides the count.
    pub pattern: AxisPattern,
    /// Codec of one item.
    pub item: C,
}

/// One item per axis set in `pattern`, each in `item`'s format.
pub fn per_axis<C>(pattern: impl AsPattern, item: C) -> PerAxisCodec<C> {
    PerAxisCodec {
        pattern: pattern.pattern(),
        item,
    }
}

impl<'a, T, C: FieldCodec<'a, T>> FieldCodec<'a, PerAxis<T>> for PerAxisCodec<C> {
    fn read(&self, r: &mut Reader<'a>) -> Result<PerAxis<T>> {
        let mut out = PerAxis::new();
        for _ in 0..self.pattern.count() {
            let v = self.item.read(r)?;
            out.push(v).map_err(|_| Error::CountTooLarge {
                count: self.pattern.count(),
                max: crate::axis::MAX_AXES,
            })?;
        }
        Ok(out)
    }
    fn write(&self, value: &PerAxis<T>, w: &mut Writer<'_>) -> Result<()> {
        if value.len() != self.pattern.count() {
            return Err(Error::CountMismatch {
                expected: self.pattern.count(),
                found: value.len(),
            });
        }
        value.iter().try_for_each(|v| self.item.write(v, w))
    }
}

/// Codec of exactly `N` items (`fixed:N` groups).
#[derive(Debug, Clone, Copy)]
pub struct Array<C>(pub C);

impl<'a, T: Copy + Default, C: FieldCodec<'a, T>, const N: usize> FieldCodec<'a, [T; N]>
    for Array<C>
{
    fn read(&self, r: &mut Reader<'a>) -> Result<[T; N]> {
        let mut out = [T::default(); N];
        for slot in out.iter_mut() {
            *slot = self.0.read(r)?;
        }
        Ok(out)
    }
    fn write(&self, value: &[T; N], w: &mut Writer<'_>) -> Result<()> {
        value.iter().try_for_each(|v| self.0.write(v, w))
    }
}

/// Codec of a count field immediately followed by that many items.
#[derive(Debug, Clone, Copy)]
pub struct Counted<C> {
    /// Format of the count field.
    pub count: FieldSpec,
    /// Largest count the catalogue allows.
    pub max: usize,
    /// Codec of one item.
    pub item: C,
}

/// A count field in `count`'s format (at most `max`), then the items.
pub const fn counted<C>(count: FieldSpec, max: usize, item: C) -> Counted<C> {
    Counted { count, max, item }
}

fn read_count(spec: FieldSpec, max: usize, r: &mut Reader<'_>) -> Result<usize> {
    let at = r.offset();
    let n = r.unsigned(spec)?;
    let n = usize::try_from(n).map_err(|_| Error::ValueOutOfRange { offset: at })?;
    if n > max {
        return Err(Error::CountTooLarge { count: n, max });
    }
    Ok(n)
}

fn write_count(spec: FieldSpec, max: usize, n: usize, w: &mut Writer<'_>) -> Result<()> {
    if n > max {
        return Err(Error::CountTooLarge { count: n, max });
    }
    w.unsigned(spec, n as u64)
}

impl<'a, T, C: FieldCodec<'a, T> + Copy> FieldCodec<'a, Repeated<'a, T, C>> for Counted<C> {
    fn read(&self, r: &mut Reader<'a>) -> Result<Repeated<'a, T, C>> {
        let count = read_count(self.count, self.max, r)?;
        let base = r.offset();
        let mut probe = r.clone();
        for _ in 0..count {
            self.item.read(&mut probe)?;
        }
        let bytes = r.take(probe.offset() - base)?;
        Ok(Repeated {
            items: Items::Wire {
                bytes,
                base,
                count,
                codec: self.item,
            },
            _t: PhantomData,
        })
    }
    fn write(&self, value: &Repeated<'a, T, C>, w: &mut Writer<'_>) -> Result<()> {
        write_count(self.count, self.max, value.len(), w)?;
        match value.items {
            Items::Wire { bytes, .. } => w.put(bytes),
            Items::Slice(items) => items.iter().try_for_each(|v| self.item.write(v, w)),
        }
    }
}

/// Codec of a count field followed by that many raw characters (216H message).
#[derive(Debug, Clone, Copy)]
pub struct CountedText {
    /// Format of the count field.
    pub count: FieldSpec,
    /// Largest count.
    pub max: usize,
}

impl<'a> FieldCodec<'a, &'a [u8]> for CountedText {
    fn read(&self, r: &mut Reader<'a>) -> Result<&'a [u8]> {
        let n = read_count(self.count, self.max, r)?;
        r.take(n)
    }
    fn write(&self, value: &&'a [u8], w: &mut Writer<'_>) -> Result<()> {
        write_count(self.count, self.max, value.len(), w)?;
        w.put(value)
    }
}

#[derive(Debug, Clone, Copy)]
enum Items<'a, T, C> {
    Wire {
        bytes: &'a [u8],
        base: usize,
        count: usize,
        codec: C,
    },
    Slice(&'a [T]),
}

/// A repeat group: items parsed lazily from a frame, or borrowed from a
/// slice for emitting.
///
/// ```
/// use iai_protocol_b::message::Repeated;
/// use iai_protocol_b::field::FieldSpec;
/// let vars = [1i32, -2, 3];
/// let group: Repeated<'_, i32, FieldSpec> = Repeated::from_slice(&vars);
/// assert_eq!(group.len(), 3);
/// assert!(group.iter().eq([1, -2, 3]));
/// ```
#[derive(Debug, Clone, Copy)]
pub struct Repeated<'a, T, C> {
    items: Items<'a, T, C>,
    _t: PhantomData<T>,
}

impl<'a, T, C> Repeated<'a, T, C> {
    /// A group of the items of `items`, for emitting.
    pub const fn from_slice(items: &'a [T]) -> Self {
        Repeated {
            items: Items::Slice(items),
            _t: PhantomData,
        }
    }
    /// Number of items.
    pub fn len(&self) -> usize {
        match self.items {
            Items::Wire { count, .. } => count,
            Items::Slice(s) => s.len(),
        }
    }
    /// Whether the group has no items.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The raw wire bytes of the items, if the group was parsed.
    pub fn wire_bytes(&self) -> Option<&'a [u8]> {
        match self.items {
            Items::Wire { bytes, .. } => Some(bytes),
            Items::Slice(_) => None,
        }
    }
}

impl<'a, T: Clone, C: FieldCodec<'a, T> + Copy> Repeated<'a, T, C> {
    /// The items in wire order.
    pub fn iter(&self) -> RepeatedIter<'a, T, C> {
        match self.items {
            Items::Wire {
                bytes,
                base,
                count,
                codec,
            } => RepeatedIter {
                inner: IterInner::Wire {
                    r: Reader::new(bytes, base),
                    left: count,
                    codec,
                },
            },
            Items::Slice(s) => RepeatedIter {
                inner: IterInner::Slice(s.iter()),
            },
        }
    }
}

impl<'a, T: Clone + PartialEq, C: FieldCodec<'a, T> + Copy> PartialEq for Repeated<'a, T, C> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}
impl<'a, T: Clone + Eq, C: FieldCodec<'a, T> + Copy> Eq for Repeated<'a, T, C> {}

#[cfg(feature = "defmt")]
impl<T, C> defmt::Format for Repeated<'_, T, C> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "Repeated({=usize} items)", self.len())
    }
}

enum IterInner<'a, T, C> {
    Wire {
        r: Reader<'a>,
        left: usize,
        codec: C,
    },
    Slice(core::slice::Iter<'a, T>),
}

/// Iterator over a [`Repeated`] group.
pub struct RepeatedIter<'a, T, C> {
    inner: IterInner<'a, T, C>,
}

impl<'a, T: Clone, C: FieldCodec<'a, T>> Iterator for RepeatedIter<'a, T, C> {
    type Item = T;
    fn next(&mut self) -> Option<T> {
        match &mut self.inner {
            IterInner::Wire { r, left, codec } => {
                if *left == 0 {
                    return None;
                }
                *left -= 1;
                // Items were validated when the group was parsed.
                codec.read(r).ok()
            }
            IterInner::Slice(it) => it.next().cloned(),
        }
    }
}
