//! Real variables (20FH, 24DH): a double's bit pattern as 16 hex digits,
//! in one of two word orders the frames do not reveal (a controller
//! setting). The manuals show only the plain order for 24DH; that writes
//! follow the same setting as reads is **inferred**.

use super::Scalar;

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
