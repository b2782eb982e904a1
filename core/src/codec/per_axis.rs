//! Groups whose count is not on the wire: one item per axis set in an
//! axis pattern ([`PerAxisCodec`], [`PerAxisUpTo`]) and fixed-size arrays
//! ([`Array`]). Items are decoded when the group is read.

use super::{inspect_items, FieldCodec, GroupInfo, Inspect, Visitor};
use crate::axis::{AxisPattern, PerAxis};
use crate::error::{Error, Result};
use crate::field::{Reader, Writer};

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
