//! Axis patterns: which of the (up to 8) axes a command or record concerns.
//!
//! Bit 0 is axis 1 (2003 p. 65: axes 1, 2 and 4 → `0B`). Per-axis values
//! follow the pattern in ascending axis order; that order is **inferred**
//! from the bit numbering (neither manual states it outright).

use crate::error::{Error, Result};

/// The largest number of axes a controller has.
pub const MAX_AXES: usize = 8;

/// Per-axis values of one record, in ascending axis order (at most 8).
pub type PerAxis<T> = heapless::Vec<T, MAX_AXES>;

/// A set of axes, bit 0 = axis 1.
///
/// ```
/// use iai_protocol_b::axis::AxisPattern;
/// let p = AxisPattern::from_axes(&[1, 2, 4]).unwrap();
/// assert_eq!(p.bits(), 0x0B);
/// assert_eq!(p.count(), 3);
/// assert!(p.iter().eq([1, 2, 4]));
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AxisPattern(u8);

impl AxisPattern {
    /// No axis.
    pub const NONE: AxisPattern = AxisPattern(0);
    /// All 8 axes.
    pub const ALL: AxisPattern = AxisPattern(0xFF);

    /// The pattern with these bits (bit 0 = axis 1).
    pub const fn from_bits(bits: u8) -> Self {
        AxisPattern(bits)
    }
    /// The raw bits.
    pub const fn bits(self) -> u8 {
        self.0
    }
    /// Axes 1..=`n` (n ≥ 8 gives all axes).
    pub const fn first(n: u8) -> Self {
        if n >= 8 {
            AxisPattern::ALL
        } else {
            AxisPattern((1u8 << n) - 1)
        }
    }
    /// The pattern of these axis numbers (1..=8); `None` if one is out of range.
    pub fn from_axes(axes: &[u8]) -> Option<Self> {
        axes.iter().try_fold(AxisPattern(0), |p, &a| p.with(a))
    }
    /// The pattern of these axis numbers (1..=8, any order, repeats
    /// allowed); [`Error::InvalidAxis`] for one out of range.
    pub fn of(axes: &[u8]) -> Result<Self> {
        axes.iter().try_fold(AxisPattern(0), |p, &a| {
            p.with(a).ok_or(Error::InvalidAxis { axis: a })
        })
    }
    /// This pattern plus axis `axis` (1..=8); `None` if out of range.
    pub const fn with(self, axis: u8) -> Option<Self> {
        if axis >= 1 && axis <= 8 {
            Some(AxisPattern(self.0 | (1 << (axis - 1))))
        } else {
            None
        }
    }
    /// Whether axis `axis` (1..=8) is set.
    pub const fn contains(self, axis: u8) -> bool {
        axis >= 1 && axis <= 8 && self.0 & (1 << (axis - 1)) != 0
    }
    /// Number of axes set (the "effective axes").
    pub const fn count(self) -> usize {
        self.0.count_ones() as usize
    }
    /// Whether no axis is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// The axis numbers set, ascending.
    pub fn iter(self) -> impl Iterator<Item = u8> + Clone {
        (1u8..=8).filter(move |&a| self.contains(a))
    }
}

/// The pattern and the per-axis values of `(axis, value)` pairs, in
/// ascending axis order whatever order the pairs come in: the one way the
/// typed commands and records build their per-axis groups, so that the
/// pattern and the number of values always agree.
///
/// An axis outside 1..=8, or named twice, is [`Error::InvalidAxis`].
///
/// ```
/// use iai_protocol_b::axis::{per_axis_values, AxisPattern};
/// let (p, v) = per_axis_values(&[(4, 40), (1, 10), (2, 20)]).unwrap();
/// assert_eq!(p, AxisPattern::from_bits(0x0B));
/// assert_eq!(v.as_slice(), &[10, 20, 40]);
/// assert!(per_axis_values(&[(1, 0), (1, 0)]).is_err());
/// assert!(per_axis_values(&[(9, 0)]).is_err());
/// ```
pub fn per_axis_values<T: Copy>(pairs: &[(u8, T)]) -> Result<(AxisPattern, PerAxis<T>)> {
    let mut pattern = AxisPattern::NONE;
    for &(axis, _) in pairs {
        if pattern.contains(axis) {
            return Err(Error::InvalidAxis { axis });
        }
        pattern = pattern.with(axis).ok_or(Error::InvalidAxis { axis })?;
    }
    let mut values = PerAxis::new();
    for axis in pattern.iter() {
        if let Some(&(_, v)) = pairs.iter().find(|(a, _)| *a == axis) {
            values.push(v).map_err(|_| Error::InvalidAxis { axis })?;
        }
    }
    Ok((pattern, values))
}

impl From<u8> for AxisPattern {
    fn from(bits: u8) -> Self {
        AxisPattern(bits)
    }
}

impl From<AxisPattern> for u8 {
    fn from(p: AxisPattern) -> u8 {
        p.0
    }
}
