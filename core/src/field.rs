//! Fixed-width fields: hex and decimal digits, signed and unsigned, raw text.
//!
//! Every field is sent at its full width with leading zeros. A signed field
//! is two's complement over the whole width ("sign extension", 2003 p. 65):
//! −400.000 mm in an 8-digit 0.001 mm field is `FFF9E580`. A value that does
//! not fit its width is an [`Error::ValueOutOfRange`], never truncated.
//!
//! ```
//! use iai_protocol_b::field::{FieldSpec, encode_signed, decode_signed};
//! let spec = FieldSpec::signed_hex(8);
//! let mut out = [0u8; 8];
//! encode_signed(spec, -400_000, &mut out).unwrap();
//! assert_eq!(&out, b"FFF9E580");
//! assert_eq!(decode_signed(spec, b"FFF9E580", 0).unwrap(), -400_000);
//! ```

use crate::error::{Error, Result};

/// How the characters of a field encode its value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Radix {
    /// Hexadecimal digits, most significant first (`'XX(h)'`).
    Hex,
    /// Decimal digits (`'XX(d)'`, only 216H's reserved fields).
    Dec,
    /// Raw characters, not encoded (200H test string, 216H message).
    Text,
}

/// The wire format of one field: width in characters, radix, signedness.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FieldSpec {
    /// Width in characters (1..=16).
    pub width: u8,
    /// Digit encoding.
    pub radix: Radix,
    /// Two's complement over the whole width.
    pub signed: bool,
}

impl FieldSpec {
    /// An unsigned hex field of `width` characters.
    pub const fn hex(width: u8) -> Self {
        FieldSpec {
            width,
            radix: Radix::Hex,
            signed: false,
        }
    }
    /// A signed (two's complement) hex field of `width` characters.
    pub const fn signed_hex(width: u8) -> Self {
        FieldSpec {
            width,
            radix: Radix::Hex,
            signed: true,
        }
    }
    /// An unsigned decimal field of `width` characters.
    pub const fn dec(width: u8) -> Self {
        FieldSpec {
            width,
            radix: Radix::Dec,
            signed: false,
        }
    }
    /// A raw text field of `width` characters.
    pub const fn text(width: u8) -> Self {
        FieldSpec {
            width,
            radix: Radix::Text,
            signed: false,
        }
    }
    /// Whether the spec can be encoded: width 1..=16 for numbers (a
    /// 64-bit value), any width for text.
    pub const fn is_valid(self) -> bool {
        match self.radix {
            Radix::Text => true,
            Radix::Hex => self.width >= 1 && self.width <= 16,
            Radix::Dec => self.width >= 1 && self.width <= 19,
        }
    }
    /// Width in bytes on the wire.
    pub const fn len(self) -> usize {
        self.width as usize
    }
    /// Whether the field has zero width (never the case in the catalogue).
    pub const fn is_empty(self) -> bool {
        self.width == 0
    }
    /// Largest unsigned value the field holds (hex: 16^w − 1, dec: 10^w − 1).
    pub const fn max_unsigned(self) -> u64 {
        match self.radix {
            Radix::Dec => {
                let mut m: u64 = 1;
                let mut i = 0;
                while i < self.width && i < 19 {
                    m = m.saturating_mul(10);
                    i += 1;
                }
                m - 1
            }
            _ => {
                if self.width >= 16 {
                    u64::MAX
                } else {
                    (1u64 << (4 * self.width as u32)) - 1
                }
            }
        }
    }
    /// Range of a signed hex field: −16^w/2 ..= 16^w/2 − 1.
    pub const fn signed_range(self) -> (i64, i64) {
        if self.width == 0 {
            (0, 0)
        } else if self.width >= 16 {
            (i64::MIN, i64::MAX)
        } else {
            let half = 1i64 << (4 * self.width as u32 - 1);
            (-half, half - 1)
        }
    }
}

/// Digit values of every byte: 0..=15 for hex digits of either case, 0xFF otherwise.
// Indexing in a const initialiser is checked at compile time: it cannot panic at run time.
#[allow(clippy::indexing_slicing)]
const HEX_VALUES: [u8; 256] = {
    let mut t = [0xFFu8; 256];
    let mut i = 0;
    while i < 10 {
        t[b'0' as usize + i] = i as u8;
        i += 1;
    }
    let mut i = 0;
    while i < 6 {
        t[b'A' as usize + i] = 10 + i as u8;
        t[b'a' as usize + i] = 10 + i as u8;
        i += 1;
    }
    t
};

/// Value of one hex digit (either case), or `None`.
#[inline]
pub fn hex_value(byte: u8) -> Option<u8> {
    match HEX_VALUES.get(usize::from(byte)) {
        Some(&v) if v < 16 => Some(v),
        _ => None,
    }
}

/// The upper-case hex digit for a nibble (`n` is masked to 0..=15).
#[inline]
pub const fn hex_digit(n: u8) -> u8 {
    let n = n & 0xF;
    if n < 10 {
        b'0' + n
    } else {
        b'A' - 10 + n
    }
}

/// Whether `byte` is a hex digit of either case.
#[inline]
pub fn is_hex_digit(byte: u8) -> bool {
    hex_value(byte).is_some()
}

/// Writes `value` as upper-case hex digits filling `out` exactly.
/// Returns `false` if it does not fit.
#[inline]
fn put_hex(mut value: u64, out: &mut [u8]) -> bool {
    for slot in out.iter_mut().rev() {
        *slot = hex_digit((value & 0xF) as u8);
        value >>= 4;
    }
    value == 0
}

/// Writes an unsigned value into `out` (whose length must be the field width).
pub fn encode_unsigned(spec: FieldSpec, value: u64, out: &mut [u8]) -> Result<()> {
    if !spec.is_valid() || out.len() != spec.len() || value > spec.max_unsigned() {
        return Err(Error::ValueOutOfRange { offset: 0 });
    }
    match spec.radix {
        Radix::Hex => {
            put_hex(value, out);
        }
        Radix::Dec => {
            let mut v = value;
            for slot in out.iter_mut().rev() {
                *slot = b'0' + (v % 10) as u8;
                v /= 10;
            }
        }
        Radix::Text => return Err(Error::ValueOutOfRange { offset: 0 }),
    }
    Ok(())
}

/// Writes a signed value (two's complement over the width) into `out`.
pub fn encode_signed(spec: FieldSpec, value: i64, out: &mut [u8]) -> Result<()> {
    if !spec.signed || spec.radix != Radix::Hex {
        return match u64::try_from(value) {
            Ok(v) => encode_unsigned(spec, v, out),
            Err(_) => Err(Error::ValueOutOfRange { offset: 0 }),
        };
    }
    let (min, max) = spec.signed_range();
    if !spec.is_valid() || out.len() != spec.len() || value < min || value > max {
        return Err(Error::ValueOutOfRange { offset: 0 });
    }
    let bits = if spec.width >= 16 {
        value as u64
    } else {
        (value as u64) & spec.max_unsigned()
    };
    put_hex(bits, out);
    Ok(())
}

/// Reads an unsigned value from the digits of one field. `offset` is the
/// field's position in the frame, used in errors.
pub fn decode_unsigned(spec: FieldSpec, digits: &[u8], offset: usize) -> Result<u64> {
    if !spec.is_valid() {
        return Err(Error::ValueOutOfRange { offset });
    }
    if digits.len() != spec.len() {
        return Err(Error::BodyTooShort { offset });
    }
    let mut value: u64 = 0;
    match spec.radix {
        Radix::Hex => {
            for (i, &b) in digits.iter().enumerate() {
                let d = hex_value(b).ok_or(Error::InvalidHexDigit {
                    offset: offset + i,
                    byte: b,
                })?;
                value = (value << 4) | u64::from(d);
            }
        }
        Radix::Dec => {
            for (i, &b) in digits.iter().enumerate() {
                if !b.is_ascii_digit() {
                    return Err(Error::InvalidDecimalDigit {
                        offset: offset + i,
                        byte: b,
                    });
                }
                value = value.wrapping_mul(10).wrapping_add(u64::from(b - b'0'));
            }
        }
        Radix::Text => return Err(Error::ValueOutOfRange { offset }),
    }
    Ok(value)
}

/// Reads a value, sign-extending it when the field is signed.
pub fn decode_signed(spec: FieldSpec, digits: &[u8], offset: usize) -> Result<i64> {
    let raw = decode_unsigned(spec, digits, offset)?;
    if !spec.signed || spec.width >= 16 {
        return Ok(raw as i64);
    }
    let shift = 64 - 4 * u32::from(spec.width);
    Ok(raw.checked_shl(shift).map_or(0, |v| (v as i64) >> shift))
}

/// Moves `len` bytes of `buf` from `src` to `dst` (the ranges may overlap);
/// `false`, moving nothing, if either range is not inside `buf`.
///
/// Byte by byte rather than `copy_within`: the compiler cannot always see
/// that the bounds checked here make `copy_within`'s own assertion dead,
/// and the crate must keep no panic path. It runs on rare paths only
/// (carrying records to the next frame, decoding a failed frame again).
pub(crate) fn move_within(buf: &mut [u8], src: usize, len: usize, dst: usize) -> bool {
    let (Some(src_end), Some(dst_end)) = (src.checked_add(len), dst.checked_add(len)) else {
        return false;
    };
    if src_end > buf.len() || dst_end > buf.len() {
        return false;
    }
    let mut step = |i: usize| {
        if let Some(&b) = buf.get(src + i) {
            if let Some(slot) = buf.get_mut(dst + i) {
                *slot = b;
            }
        }
    };
    if dst <= src {
        (0..len).for_each(&mut step);
    } else {
        (0..len).rev().for_each(&mut step);
    }
    true
}

/// A cursor over the body of a received frame.
///
/// Reading never panics: running past the end is
/// [`Error::BodyTooShort`]. Offsets in errors are frame offsets.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    base: usize,
}

impl<'a> Reader<'a> {
    /// A reader over `bytes`, whose first byte sits at frame offset `base`.
    pub const fn new(bytes: &'a [u8], base: usize) -> Self {
        Reader {
            bytes,
            pos: 0,
            base,
        }
    }
    /// Frame offset of the next byte.
    pub const fn offset(&self) -> usize {
        self.base + self.pos
    }
    /// Bytes not yet read.
    pub fn remaining(&self) -> usize {
        self.bytes.len().saturating_sub(self.pos)
    }
    /// Takes the next `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).ok_or(Error::BodyTooShort {
            offset: self.offset(),
        })?;
        let s = self.bytes.get(self.pos..end).ok_or(Error::BodyTooShort {
            offset: self.offset(),
        })?;
        self.pos = end;
        Ok(s)
    }
    /// Reads one unsigned field.
    pub fn unsigned(&mut self, spec: FieldSpec) -> Result<u64> {
        let at = self.offset();
        let digits = self.take(spec.len())?;
        decode_unsigned(spec, digits, at)
    }
    /// Reads one field, sign-extended if the spec is signed.
    pub fn signed(&mut self, spec: FieldSpec) -> Result<i64> {
        let at = self.offset();
        let digits = self.take(spec.len())?;
        decode_signed(spec, digits, at)
    }
    /// Fails with [`Error::TrailingBytes`] unless everything was read.
    pub fn finish(&self) -> Result<()> {
        if self.remaining() == 0 {
            Ok(())
        } else {
            Err(Error::TrailingBytes {
                offset: self.offset(),
            })
        }
    }
}

/// A cursor that fills a caller's byte buffer; running out of room is
/// [`Error::BufferTooSmall`], never a panic.
#[derive(Debug)]
pub struct Writer<'b> {
    buf: &'b mut [u8],
    len: usize,
}

impl<'b> Writer<'b> {
    /// A writer filling `buf` from its start.
    pub fn new(buf: &'b mut [u8]) -> Self {
        Writer { buf, len: 0 }
    }
    /// A writer continuing after the first `len` bytes of `buf`
    /// (clamped to its length).
    pub fn resume(buf: &'b mut [u8], len: usize) -> Self {
        let len = len.min(buf.len());
        Writer { buf, len }
    }
    /// Bytes written so far.
    pub const fn len(&self) -> usize {
        self.len
    }
    /// Whether nothing was written yet.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// The bytes written so far.
    pub fn written(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }
    /// Reserves the next `n` bytes and returns them for filling.
    pub fn reserve(&mut self, n: usize) -> Result<&mut [u8]> {
        let start = self.len;
        let end = start.checked_add(n).ok_or(Error::BufferTooSmall)?;
        let s = self.buf.get_mut(start..end).ok_or(Error::BufferTooSmall)?;
        self.len = end;
        Ok(s)
    }
    /// Appends raw bytes.
    pub fn put(&mut self, bytes: &[u8]) -> Result<()> {
        self.reserve(bytes.len())?.copy_from_slice(bytes);
        Ok(())
    }
    /// Appends an unsigned field.
    pub fn unsigned(&mut self, spec: FieldSpec, value: u64) -> Result<()> {
        let mark = self.len;
        let r = self
            .reserve(spec.len())
            .and_then(|out| encode_unsigned(spec, value, out));
        self.undo_on_error(mark, r)
    }
    /// Appends a signed field (two's complement if the spec is signed).
    pub fn signed(&mut self, spec: FieldSpec, value: i64) -> Result<()> {
        let mark = self.len;
        let r = self
            .reserve(spec.len())
            .and_then(|out| encode_signed(spec, value, out));
        self.undo_on_error(mark, r)
    }
    /// On error, drops the partial field and reports it at its frame offset.
    fn undo_on_error(&mut self, mark: usize, r: Result<()>) -> Result<()> {
        if r.is_err() {
            self.len = mark;
        }
        r.map_err(|e| match e {
            Error::ValueOutOfRange { .. } => Error::ValueOutOfRange { offset: mark },
            other => other,
        })
    }
    /// Overwrites an unsigned field already written at `at`.
    pub fn patch_unsigned(&mut self, at: usize, spec: FieldSpec, value: u64) -> Result<()> {
        let end = at
            .checked_add(spec.len())
            .filter(|&e| e <= self.len)
            .ok_or(Error::BufferTooSmall)?;
        let out = self.buf.get_mut(at..end).ok_or(Error::BufferTooSmall)?;
        encode_unsigned(spec, value, out)
    }
    /// Drops everything after the first `len` bytes.
    pub fn truncate(&mut self, len: usize) {
        self.len = self.len.min(len);
    }
}
