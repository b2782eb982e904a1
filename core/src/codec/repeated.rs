//! Counted repeat groups: a count field, then that many items
//! ([`Counted`], [`CountedText`]) or the items that carry that many units
//! ([`CountedPer`], 8 ports or flags per byte, 2003 p. 19).
//!
//! A parsed group is lazy: parsing validates every item once and keeps a
//! slice of the frame ([`Repeated`]); iterating decodes items on demand.
//! Emitting takes items from a slice. Neither allocates.

use core::marker::PhantomData;

use super::{FieldCodec, GroupInfo, Inspect, Value, Visitor};
use crate::error::{Error, Result};
use crate::field::{FieldSpec, Reader, Writer};

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
