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
//! | [`CountedPer`] | [`Repeated`] | a count of units (8 ports per item), then the items |
//! | [`FieldSpec`] (16 hex digits) | [`RealWire`] | a real variable as sent (see [`WordOrder`]) |
//!
//! Every codec also implements [`Inspect`], which shows decoded values with
//! their names, units and wire formats to a [`Visitor`].
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
    fn len(&self, value: &PerAxis<T>) -> usize {
        value.iter().map(|v| self.item.len(v)).sum()
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
    fn len(&self, value: &[T; N]) -> usize {
        value.iter().map(|v| self.0.len(v)).sum()
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

impl<'a, T: Clone, C: FieldCodec<'a, T> + Copy> FieldCodec<'a, Repeated<'a, T, C>> for Counted<C> {
    fn read(&self, r: &mut Reader<'a>) -> Result<Repeated<'a, T, C>> {
        let count = read_count(self.count, self.max, r)?;
        read_items(count, self.item, r)
    }
    fn write(&self, value: &Repeated<'a, T, C>, w: &mut Writer<'_>) -> Result<()> {
        write_count(self.count, self.max, value.len(), w)?;
        value.write_items(&self.item, w)
    }
    fn len(&self, value: &Repeated<'a, T, C>) -> usize {
        self.count.len() + value.items_len(&self.item)
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
    fn len(&self, value: &&'a [u8]) -> usize {
        self.count.len() + value.len()
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

/// An empty group.
impl<T, C> Default for Repeated<'_, T, C> {
    fn default() -> Self {
        Repeated::from_slice(&[])
    }
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

impl<'a, T: Clone, C: FieldCodec<'a, T> + Copy> Repeated<'a, T, C> {
    /// Writes every item with `codec`, in normal form (upper-case digits)
    /// whatever case a parsed group arrived in.
    fn write_items(&self, codec: &C, w: &mut Writer<'_>) -> Result<()> {
        match self.items {
            Items::Wire { .. } => self.iter().try_for_each(|v| codec.write(&v, w)),
            Items::Slice(items) => items.iter().try_for_each(|v| codec.write(v, w)),
        }
    }
    /// Bytes the items take on the wire.
    fn items_len(&self, codec: &C) -> usize {
        match self.items {
            Items::Wire { .. } => self.iter().map(|v| codec.len(&v)).sum(),
            Items::Slice(items) => items.iter().map(|v| codec.len(v)).sum(),
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

// ------------------------------------------------------------ inspection

/// A decoded value as shown to a [`Visitor`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Value<'v> {
    /// An unsigned numeric field (bit patterns, counts, numbers).
    Unsigned(u64),
    /// A signed (two's complement) numeric field.
    Signed(i64),
    /// Raw characters: a text field or the literal of a reserved field.
    Text(&'v [u8]),
}

/// How one repeat group looks on the wire, for a [`Visitor`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GroupInfo {
    /// Items in this instance of the group.
    pub count: usize,
    /// Format of the count field that precedes the group, if it has one
    /// (axis-pattern and fixed-size groups have none).
    pub count_field: Option<FieldSpec>,
    /// Units the count field counts per item (8 for port and flag bytes,
    /// 1 elsewhere).
    pub per_item: usize,
    /// The value the count field holds: `count`, or for port and flag
    /// groups the number of ports or flags (`count` is that divided by 8,
    /// rounded up).
    pub units: usize,
    /// Largest item count the declaration accepts.
    pub max: usize,
}

/// Receives the fields of a message in wire order (see [`Fields`]).
pub trait Visitor {
    /// One leaf field: its name, unit (`""` if none), wire format and value.
    fn field(&mut self, name: &'static str, unit: &'static str, spec: FieldSpec, value: Value<'_>);
    /// A repeat group starts; its items follow, then [`Visitor::leave_group`].
    fn enter_group(&mut self, name: &'static str, group: GroupInfo) {
        let _ = (name, group);
    }
    /// The repeat group opened last ends.
    fn leave_group(&mut self) {}
}

/// Walks the fields of a value in wire order. Derived by `wire!`.
pub trait Fields {
    /// Calls `v` once per leaf field and around every repeat group.
    fn fields(&self, v: &mut dyn Visitor);
}

/// A codec that can show values of type `T` to a [`Visitor`].
pub trait Inspect<T: ?Sized> {
    /// Reports `value` as field `name` with `unit`.
    fn inspect(&self, value: &T, name: &'static str, unit: &'static str, v: &mut dyn Visitor);
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

pub(crate) fn inspect_items<'i, T: 'i, C: Inspect<T>>(
    codec: &C,
    items: impl Iterator<Item = &'i T>,
    name: &'static str,
    unit: &'static str,
    group: GroupInfo,
    v: &mut dyn Visitor,
) {
    v.enter_group(name, group);
    items.for_each(|item| codec.inspect(item, name, unit, v));
    v.leave_group();
}

impl<T, C: Inspect<T>> Inspect<PerAxis<T>> for PerAxisCodec<C> {
    fn inspect(
        &self,
        value: &PerAxis<T>,
        name: &'static str,
        unit: &'static str,
        v: &mut dyn Visitor,
    ) {
        let group = GroupInfo {
            count: value.len(),
            count_field: None,
            per_item: 1,
            units: value.len(),
            max: crate::axis::MAX_AXES,
        };
        inspect_items(&self.item, value.iter(), name, unit, group, v);
    }
}

impl<T, C: Inspect<T>, const N: usize> Inspect<[T; N]> for Array<C> {
    fn inspect(&self, value: &[T; N], name: &'static str, unit: &'static str, v: &mut dyn Visitor) {
        let group = GroupInfo {
            count: N,
            count_field: None,
            per_item: 1,
            units: value.len(),
            max: N,
        };
        inspect_items(&self.0, value.iter(), name, unit, group, v);
    }
}

fn inspect_repeated<'a, T: Clone, C: FieldCodec<'a, T> + Inspect<T> + Copy>(
    codec: &C,
    value: &Repeated<'a, T, C>,
    name: &'static str,
    unit: &'static str,
    group: GroupInfo,
    v: &mut dyn Visitor,
) {
    v.enter_group(name, group);
    value
        .iter()
        .for_each(|item| codec.inspect(&item, name, unit, v));
    v.leave_group();
}

impl<'a, T: Clone, C: FieldCodec<'a, T> + Inspect<T> + Copy> Inspect<Repeated<'a, T, C>>
    for Counted<C>
{
    fn inspect(
        &self,
        value: &Repeated<'a, T, C>,
        name: &'static str,
        unit: &'static str,
        v: &mut dyn Visitor,
    ) {
        let group = GroupInfo {
            count: value.len(),
            count_field: Some(self.count),
            per_item: 1,
            units: value.len(),
            max: self.max,
        };
        inspect_repeated(&self.item, value, name, unit, group, v);
    }
}

impl<'a> Inspect<&'a [u8]> for CountedText {
    fn inspect(
        &self,
        value: &&'a [u8],
        name: &'static str,
        unit: &'static str,
        v: &mut dyn Visitor,
    ) {
        let group = GroupInfo {
            count: value.len(),
            count_field: Some(self.count),
            per_item: 1,
            units: value.len(),
            max: self.max,
        };
        v.enter_group(name, group);
        value
            .chunks(1)
            .for_each(|c| v.field(name, unit, FieldSpec::text(1), Value::Text(c)));
        v.leave_group();
    }
}

// ------------------------------------------------------------ additions for the full catalogue

/// Codec of a per-axis group that allows at most `max` axes (2A2H's
/// interference zones have at most 4 coordinate axes).
#[derive(Debug, Clone, Copy)]
pub struct PerAxisUpTo<C> {
    /// Largest number of axes.
    pub max: usize,
    /// The unlimited codec.
    pub inner: PerAxisCodec<C>,
}

/// Like [`per_axis`], refusing patterns with more than `max` axes.
pub fn per_axis_up_to<C>(max: usize, pattern: impl AsPattern, item: C) -> PerAxisUpTo<C> {
    PerAxisUpTo {
        max,
        inner: per_axis(pattern, item),
    }
}

impl<C> PerAxisUpTo<C> {
    fn check(&self) -> Result<()> {
        let count = self.inner.pattern.count();
        if count > self.max {
            return Err(Error::CountTooLarge {
                count,
                max: self.max,
            });
        }
        Ok(())
    }
}

impl<'a, T, C: FieldCodec<'a, T>> FieldCodec<'a, PerAxis<T>> for PerAxisUpTo<C> {
    fn read(&self, r: &mut Reader<'a>) -> Result<PerAxis<T>> {
        self.check()?;
        self.inner.read(r)
    }
    fn write(&self, value: &PerAxis<T>, w: &mut Writer<'_>) -> Result<()> {
        self.check()?;
        self.inner.write(value, w)
    }
    fn len(&self, value: &PerAxis<T>) -> usize {
        self.inner.len(value)
    }
}

impl<T, C: Inspect<T>> Inspect<PerAxis<T>> for PerAxisUpTo<C> {
    fn inspect(
        &self,
        value: &PerAxis<T>,
        name: &'static str,
        unit: &'static str,
        v: &mut dyn Visitor,
    ) {
        let group = GroupInfo {
            count: value.len(),
            count_field: None,
            per_item: 1,
            units: value.len(),
            max: self.max,
        };
        inspect_items(&self.inner.item, value.iter(), name, unit, group, v);
    }
}

/// Codec of a count field that counts `per_item` units per item, followed
/// by the items: the port and flag queries (20BH, 20CH, 20DH) give a number
/// of ports or flags and send one 2-digit byte per 8 of them, the last
/// byte possibly partly used: `ceil(units / per_item)` items (2003 p. 19:
/// "2 bytes x (Max 8192 – 1)" of data for any number of ports).
#[derive(Debug, Clone, Copy)]
pub struct CountedPer<C> {
    /// Format of the count field.
    pub count: FieldSpec,
    /// Units per item (8 ports per byte).
    pub per_item: usize,
    /// Largest number of items.
    pub max: usize,
    /// Codec of one item.
    pub item: C,
}

/// A count of `per_item` units per item (at most `max` items), then the items.
pub const fn counted_per<C>(
    count: FieldSpec,
    per_item: usize,
    max: usize,
    item: C,
) -> CountedPer<C> {
    CountedPer {
        count,
        per_item,
        max,
        item,
    }
}

/// Items counted in units: the number the count field holds (ports,
/// flags) and the items that carry them (one per `per_item` units, the
/// last possibly partly used).
///
/// ```
/// use iai_protocol_b::message::{PortData, Repeated};
/// // 12 ports starting at the query's start port: two bytes, the second
/// // carrying ports 8..=11 in its low 4 bits.
/// let data: PortData = PortData { units: 12, items: Repeated::from_slice(&[0xA5, 0x0F]) };
/// assert_eq!(data.items.len(), 2);
/// ```
#[derive(Debug, Clone, Copy)]
pub struct Units<'a, T, C> {
    /// The value of the count field (ports, flags).
    pub units: usize,
    /// The items.
    pub items: Repeated<'a, T, C>,
}

/// No units, no items.
impl<T, C> Default for Units<'_, T, C> {
    fn default() -> Self {
        Units {
            units: 0,
            items: Repeated::default(),
        }
    }
}

impl<'a, T: Clone + PartialEq, C: FieldCodec<'a, T> + Copy> PartialEq for Units<'a, T, C> {
    fn eq(&self, other: &Self) -> bool {
        self.units == other.units && self.items == other.items
    }
}
impl<'a, T: Clone + Eq, C: FieldCodec<'a, T> + Copy> Eq for Units<'a, T, C> {}

#[cfg(feature = "defmt")]
impl<T, C> defmt::Format for Units<'_, T, C> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "Units({=usize} in {=usize} items)",
            self.units,
            self.items.len()
        )
    }
}

impl<C> CountedPer<C> {
    /// Items that carry `units` units.
    fn items_for(&self, units: usize) -> usize {
        units.div_ceil(self.per_item.max(1))
    }
}

fn read_items<'a, T, C: FieldCodec<'a, T> + Copy>(
    count: usize,
    item: C,
    r: &mut Reader<'a>,
) -> Result<Repeated<'a, T, C>> {
    let base = r.offset();
    let mut probe = r.clone();
    for _ in 0..count {
        item.read(&mut probe)?;
    }
    let bytes = r.take(probe.offset() - base)?;
    Ok(Repeated {
        items: Items::Wire {
            bytes,
            base,
            count,
            codec: item,
        },
        _t: PhantomData,
    })
}

impl<'a, T: Clone, C: FieldCodec<'a, T> + Copy> FieldCodec<'a, Units<'a, T, C>> for CountedPer<C> {
    fn read(&self, r: &mut Reader<'a>) -> Result<Units<'a, T, C>> {
        let at = r.offset();
        let units = r.unsigned(self.count)?;
        let units = usize::try_from(units).map_err(|_| Error::ValueOutOfRange { offset: at })?;
        let n = self.items_for(units);
        if n > self.max {
            return Err(Error::CountTooLarge {
                count: n,
                max: self.max,
            });
        }
        Ok(Units {
            units,
            items: read_items(n, self.item, r)?,
        })
    }
    fn write(&self, value: &Units<'a, T, C>, w: &mut Writer<'_>) -> Result<()> {
        let n = value.items.len();
        if n > self.max {
            return Err(Error::CountTooLarge {
                count: n,
                max: self.max,
            });
        }
        let expected = self.items_for(value.units);
        if n != expected {
            return Err(Error::CountMismatch { expected, found: n });
        }
        w.unsigned(self.count, value.units as u64)?;
        value.items.write_items(&self.item, w)
    }
    fn len(&self, value: &Units<'a, T, C>) -> usize {
        self.count.len() + value.items.items_len(&self.item)
    }
}

impl<'a, T: Clone, C: FieldCodec<'a, T> + Inspect<T> + Copy> Inspect<Units<'a, T, C>>
    for CountedPer<C>
{
    fn inspect(
        &self,
        value: &Units<'a, T, C>,
        name: &'static str,
        unit: &'static str,
        v: &mut dyn Visitor,
    ) {
        let group = GroupInfo {
            count: value.items.len(),
            count_field: Some(self.count),
            per_item: self.per_item,
            units: value.units,
            max: self.max,
        };
        inspect_repeated(&self.item, &value.items, name, unit, group, v);
    }
}

/// Order of the two 32-bit halves of a real variable on the wire (20FH, 24DH).
///
/// Which one a controller uses is a setting, not something the frames
/// reveal: X-SEL J/K Cartesian main application V0.41 or earlier, or bits
/// 0–3 of "Other parameter No. 46" equal to 0, select
/// [`WordOrder::LowWordFirst`]; otherwise the plain order is used. The
/// manuals show only the plain order for the write command 24DH; using the
/// same setting for both directions is an assumption (**inferred**).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WordOrder {
    /// The 16 digits are the double's bits, most significant first
    /// (`0x0123456789ABCDEF` → `0123456789ABCDEF`).
    MostSignificantFirst,
    /// The low 32-bit half is sent first (`0x0123456789ABCDEF` →
    /// `89ABCDEF01234567`), the legacy order.
    LowWordFirst,
}

/// The bit pattern of an IEEE-754 double (the core has no floats; convert
/// with `f64::from_bits` on the host).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RealValue(pub u64);

/// The 16 hex digits of a real variable exactly as sent, before the word
/// order is applied. Messages carry this form, so parsing never has to
/// guess the order; [`RealWire::value`] and [`RealValue::to_wire`] take it
/// explicitly (usually from [`crate::profile::Profile::real_word_order`]).
///
/// ```
/// use iai_protocol_b::message::{RealValue, RealWire, WordOrder};
/// let v = RealValue(0x0123_4567_89AB_CDEF);
/// assert_eq!(v.to_wire(WordOrder::LowWordFirst), RealWire(0x89AB_CDEF_0123_4567));
/// assert_eq!(v.to_wire(WordOrder::MostSignificantFirst), RealWire(v.0));
/// assert_eq!(RealWire(0x89AB_CDEF_0123_4567).value(WordOrder::LowWordFirst), v);
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RealWire(pub u64);

const fn swap_words(bits: u64, order: WordOrder) -> u64 {
    match order {
        WordOrder::MostSignificantFirst => bits,
        WordOrder::LowWordFirst => bits.rotate_left(32),
    }
}

impl RealWire {
    /// The double this wire word carries in `order`.
    pub const fn value(self, order: WordOrder) -> RealValue {
        RealValue(swap_words(self.0, order))
    }
}

impl RealValue {
    /// The wire word for this double in `order`.
    pub const fn to_wire(self, order: WordOrder) -> RealWire {
        RealWire(swap_words(self.0, order))
    }
}

impl Scalar for RealWire {
    fn from_unsigned(v: u64) -> Option<Self> {
        Some(RealWire(v))
    }
    fn from_signed(v: i64) -> Option<Self> {
        Some(RealWire(v as u64))
    }
    fn to_unsigned(self) -> Option<u64> {
        Some(self.0)
    }
    fn to_signed(self) -> Option<i64> {
        Some(self.0 as i64)
    }
}

/// `stringify!` of a raw identifier keeps its `r#`; field names shown to a
/// [`Visitor`] drop it (`r#type` → `type`).
#[doc(hidden)]
pub const fn strip_raw(name: &'static str) -> &'static str {
    match name.as_bytes() {
        [b'r', b'#', rest @ ..] => match core::str::from_utf8(rest) {
            Ok(s) => s,
            Err(_) => name,
        },
        _ => name,
    }
}
