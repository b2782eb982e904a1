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
use crate::hex;

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

/// Value of one hex digit (either case), or `None`.
#[inline]
pub fn hex_value(byte: u8) -> Option<u8> {
    hex::value(byte)
}

/// The upper-case hex digit for a nibble (`n` is masked to 0..=15).
#[inline]
pub const fn hex_digit(n: u8) -> u8 {
    hex::digit(n)
}

/// Whether `byte` is a hex digit of either case.
#[inline]
pub fn is_hex_digit(byte: u8) -> bool {
    hex::is_digit(byte)
}

/// Writes `value` as upper-case hex digits filling `out` exactly: 2, 4
/// and 8 digits a field at a time ([`crate::hex`]), other widths a digit
/// at a time. Returns `false` if it does not fit.
#[inline]
fn put_hex(value: u64, out: &mut [u8]) -> bool {
    // Each arm writes what `encode_bytewise` writes, faster: deleting one is an equivalent mutant.
    match out.len() {
        8 => {
            if let (Ok(d), Ok(v)) = (<&mut [u8; 8]>::try_from(&mut *out), u32::try_from(value)) {
                hex::put8(v, d);
                return true;
            }
        }
        4 => {
            if let (Ok(d), Ok(v)) = (<&mut [u8; 4]>::try_from(&mut *out), u16::try_from(value)) {
                hex::put4(v, d);
                return true;
            }
        }
        2 => {
            if let (Ok(d), Ok(v)) = (<&mut [u8; 2]>::try_from(&mut *out), u8::try_from(value)) {
                hex::put2(v, d);
                return true;
            }
        }
        _ => {}
    }
    hex::encode_bytewise(value, out)
}

/// The value of 2, 4 or 8 hex digits a field at a time; `None` for other
/// widths and for any byte that is not a hex digit (the per-digit path
/// then says which).
#[inline]
fn hex_fast(digits: &[u8]) -> Option<u64> {
    // `None` sends the caller down the per-digit path to the same value: an equivalent mutant.
    if let Ok(d) = <&[u8; 8]>::try_from(digits) {
        hex::decode8(d).map(u64::from)
    } else if let Ok(d) = <&[u8; 4]>::try_from(digits) {
        hex::decode4(d).map(u64::from)
    } else if let Ok(d) = <&[u8; 2]>::try_from(digits) {
        hex::decode2(d).map(u64::from)
    } else {
        None
    }
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
    // Two's complement over the width (the mask is all ones at 16 digits).
    put_hex((value as u64) & spec.max_unsigned(), out);
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
            if let Some(v) = hex_fast(digits) {
                return Ok(v);
            }
            for (i, &b) in digits.iter().enumerate() {
                let d = hex_value(b).ok_or(Error::InvalidHexDigit {
                    offset: offset + i,
                    byte: b,
                })?;
                value = (value << 4) + u64::from(d);
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
    /// The bytes not yet read, without taking them.
    pub fn rest(&self) -> &'a [u8] {
        self.bytes.get(self.pos..).unwrap_or(&[])
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
    /// The room left after what was written, to fill before
    /// [`Writer::reserve`]-ing it.
    pub fn spare(&mut self) -> &mut [u8] {
        self.buf.get_mut(self.len..).unwrap_or(&mut [])
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs() {
        assert_eq!(
            FieldSpec::hex(4),
            FieldSpec {
                width: 4,
                radix: Radix::Hex,
                signed: false
            }
        );
        assert_eq!(
            FieldSpec::signed_hex(8),
            FieldSpec {
                width: 8,
                radix: Radix::Hex,
                signed: true
            }
        );
        assert_eq!(
            FieldSpec::dec(3),
            FieldSpec {
                width: 3,
                radix: Radix::Dec,
                signed: false
            }
        );
        assert_eq!(
            FieldSpec::text(10),
            FieldSpec {
                width: 10,
                radix: Radix::Text,
                signed: false
            }
        );
        assert_eq!(FieldSpec::hex(7).len(), 7);
        assert!(!FieldSpec::hex(1).is_empty());
        assert!(FieldSpec::hex(0).is_empty());
        let valid = |s: FieldSpec| s.is_valid();
        assert!(!valid(FieldSpec::hex(0)) && valid(FieldSpec::hex(1)));
        assert!(valid(FieldSpec::hex(16)) && !valid(FieldSpec::hex(17)));
        assert!(!valid(FieldSpec::dec(0)) && valid(FieldSpec::dec(1)));
        assert!(valid(FieldSpec::dec(19)) && !valid(FieldSpec::dec(20)));
        assert!(valid(FieldSpec::text(0)) && valid(FieldSpec::text(200)));
    }

    #[test]
    fn ranges() {
        let max = |s: FieldSpec| s.max_unsigned();
        assert_eq!(max(FieldSpec::hex(1)), 0xF);
        assert_eq!(max(FieldSpec::hex(2)), 0xFF);
        assert_eq!(max(FieldSpec::hex(8)), 0xFFFF_FFFF);
        assert_eq!(max(FieldSpec::hex(15)), (1 << 60) - 1);
        assert_eq!(max(FieldSpec::hex(16)), u64::MAX);
        assert_eq!(max(FieldSpec::hex(17)), u64::MAX);
        assert_eq!(max(FieldSpec::text(3)), 0xFFF, "text counts as hex");
        assert_eq!(max(FieldSpec::dec(0)), 0);
        assert_eq!(max(FieldSpec::dec(1)), 9);
        assert_eq!(max(FieldSpec::dec(3)), 999);
        assert_eq!(max(FieldSpec::dec(19)), 9_999_999_999_999_999_999);
        assert_eq!(max(FieldSpec::dec(25)), 9_999_999_999_999_999_999);
        let range = |w| FieldSpec::signed_hex(w).signed_range();
        assert_eq!(range(0), (0, 0));
        assert_eq!(range(1), (-8, 7));
        assert_eq!(range(2), (-128, 127));
        assert_eq!(range(8), (i64::from(i32::MIN), i64::from(i32::MAX)));
        assert_eq!(range(15), (-(1 << 59), (1 << 59) - 1));
        assert_eq!(range(16), (i64::MIN, i64::MAX));
        assert_eq!(range(20), (i64::MIN, i64::MAX));
    }

    #[test]
    fn digits_of_every_byte() {
        let digits = b"0123456789ABCDEF";
        for (n, &d) in (0u8..).zip(digits) {
            assert_eq!(hex_digit(n), d);
            assert_eq!(hex_digit(n + 0x10), d);
            assert_eq!(hex_value(d), Some(n));
            assert_eq!(hex_value(d.to_ascii_lowercase()), Some(n));
        }
        for b in 0..=255u8 {
            assert_eq!(is_hex_digit(b), b.is_ascii_hexdigit(), "{b:#04X}");
            assert_eq!(hex_value(b).is_some(), b.is_ascii_hexdigit(), "{b:#04X}");
        }
    }

    fn enc(spec: FieldSpec, v: u64) -> Result<[u8; 16]> {
        let mut out = [b'.'; 16];
        let n = spec.len().min(16);
        encode_unsigned(spec, v, &mut out[..n])?;
        Ok(out)
    }

    fn enc_s(spec: FieldSpec, v: i64) -> Result<[u8; 16]> {
        let mut out = [b'.'; 16];
        let n = spec.len().min(16);
        encode_signed(spec, v, &mut out[..n])?;
        Ok(out)
    }

    const OUT: Result<[u8; 16]> = Err(Error::ValueOutOfRange { offset: 0 });

    #[test]
    fn encode_unsigned_golden() {
        assert_eq!(&enc(FieldSpec::hex(4), 0x1E).unwrap()[..5], b"001E.");
        assert_eq!(&enc(FieldSpec::hex(2), 0xFF).unwrap()[..3], b"FF.");
        assert_eq!(enc(FieldSpec::hex(2), 0x100), OUT);
        assert_eq!(&enc(FieldSpec::hex(3), 0x26D).unwrap()[..3], b"26D");
        assert_eq!(
            &enc(FieldSpec::hex(16), u64::MAX).unwrap(),
            b"FFFFFFFFFFFFFFFF"
        );
        assert_eq!(&enc(FieldSpec::dec(3), 42).unwrap()[..4], b"042.");
        assert_eq!(&enc(FieldSpec::dec(3), 999).unwrap()[..3], b"999");
        assert_eq!(enc(FieldSpec::dec(3), 1000), OUT);
        assert_eq!(&enc(FieldSpec::dec(1), 7).unwrap()[..2], b"7.");
        assert_eq!(enc(FieldSpec::text(3), 1), OUT);
        assert_eq!(enc(FieldSpec::hex(0), 0), OUT);
        assert_eq!(enc(FieldSpec::hex(17), 0), OUT);
        // The output must be exactly the field's width.
        let mut long = [0u8; 5];
        assert_eq!(
            encode_unsigned(FieldSpec::hex(4), 1, &mut long),
            Err(Error::ValueOutOfRange { offset: 0 })
        );
        let mut short = [0u8; 3];
        assert_eq!(
            encode_unsigned(FieldSpec::hex(4), 1, &mut short),
            Err(Error::ValueOutOfRange { offset: 0 })
        );
    }

    #[test]
    fn encode_signed_golden() {
        let s8 = FieldSpec::signed_hex(8);
        // 2003 p. 65: -400.000 mm in 0.001 mm.
        assert_eq!(&enc_s(s8, -400_000).unwrap()[..8], b"FFF9E580");
        assert_eq!(&enc_s(s8, -25_500).unwrap()[..9], b"FFFF9C64.");
        assert_eq!(&enc_s(s8, 100_000).unwrap()[..8], b"000186A0");
        assert_eq!(&enc_s(s8, i64::from(i32::MAX)).unwrap()[..8], b"7FFFFFFF");
        assert_eq!(&enc_s(s8, i64::from(i32::MIN)).unwrap()[..8], b"80000000");
        assert_eq!(enc_s(s8, i64::from(i32::MAX) + 1), OUT);
        assert_eq!(enc_s(s8, i64::from(i32::MIN) - 1), OUT);
        let s2 = FieldSpec::signed_hex(2);
        assert_eq!(&enc_s(s2, -1).unwrap()[..2], b"FF");
        assert_eq!(&enc_s(s2, -128).unwrap()[..2], b"80");
        assert_eq!(&enc_s(s2, 127).unwrap()[..2], b"7F");
        assert_eq!(enc_s(s2, 128), OUT);
        assert_eq!(enc_s(s2, -129), OUT);
        let s16 = FieldSpec::signed_hex(16);
        assert_eq!(&enc_s(s16, -1).unwrap(), b"FFFFFFFFFFFFFFFF");
        assert_eq!(&enc_s(s16, i64::MIN).unwrap(), b"8000000000000000");
        assert_eq!(&enc_s(s16, i64::MAX).unwrap(), b"7FFFFFFFFFFFFFFF");
        assert_eq!(enc_s(FieldSpec::signed_hex(17), 0), OUT);
        assert_eq!(enc_s(FieldSpec::signed_hex(0), 0), OUT);
        // Unsigned specs take the unsigned path: no negative values.
        assert_eq!(&enc_s(FieldSpec::hex(2), 0xAB).unwrap()[..2], b"AB");
        assert_eq!(enc_s(FieldSpec::hex(2), -1), OUT);
        let signed_dec = FieldSpec {
            width: 3,
            radix: Radix::Dec,
            signed: true,
        };
        assert_eq!(&enc_s(signed_dec, 12).unwrap()[..3], b"012");
        assert_eq!(enc_s(signed_dec, -1), OUT);
        let mut wrong = [0u8; 7];
        assert_eq!(
            encode_signed(s8, 0, &mut wrong),
            Err(Error::ValueOutOfRange { offset: 0 })
        );
    }

    #[test]
    fn decode_golden() {
        let h4 = FieldSpec::hex(4);
        assert_eq!(decode_unsigned(h4, b"001E", 0), Ok(0x1E));
        assert_eq!(decode_unsigned(h4, b"26dF", 0), Ok(0x26DF));
        assert_eq!(
            decode_unsigned(h4, b"12x4", 10),
            Err(Error::InvalidHexDigit {
                offset: 12,
                byte: b'x'
            })
        );
        assert_eq!(
            decode_unsigned(h4, b"123", 10),
            Err(Error::BodyTooShort { offset: 10 })
        );
        assert_eq!(
            decode_unsigned(FieldSpec::hex(0), b"", 3),
            Err(Error::ValueOutOfRange { offset: 3 })
        );
        assert_eq!(
            decode_unsigned(FieldSpec::hex(16), b"FFFFFFFFFFFFFFFF", 0),
            Ok(u64::MAX)
        );
        let d3 = FieldSpec::dec(3);
        assert_eq!(decode_unsigned(d3, b"042", 0), Ok(42));
        assert_eq!(decode_unsigned(d3, b"999", 0), Ok(999));
        assert_eq!(
            decode_unsigned(d3, b"0A2", 5),
            Err(Error::InvalidDecimalDigit {
                offset: 6,
                byte: b'A'
            })
        );
        assert_eq!(
            decode_unsigned(d3, b"/00", 5),
            Err(Error::InvalidDecimalDigit {
                offset: 5,
                byte: b'/'
            })
        );
        assert_eq!(
            decode_unsigned(FieldSpec::dec(19), b"9999999999999999999", 0),
            Ok(9_999_999_999_999_999_999)
        );
        assert_eq!(
            decode_unsigned(FieldSpec::text(2), b"ab", 4),
            Err(Error::ValueOutOfRange { offset: 4 })
        );
    }

    #[test]
    fn decode_signed_golden() {
        let s8 = FieldSpec::signed_hex(8);
        assert_eq!(decode_signed(s8, b"FFF9E580", 0), Ok(-400_000));
        assert_eq!(decode_signed(s8, b"fff9e580", 0), Ok(-400_000));
        assert_eq!(decode_signed(s8, b"7FFFFFFF", 0), Ok(i64::from(i32::MAX)));
        assert_eq!(decode_signed(s8, b"80000000", 0), Ok(i64::from(i32::MIN)));
        assert_eq!(decode_signed(s8, b"000186A0", 0), Ok(100_000));
        let s2 = FieldSpec::signed_hex(2);
        assert_eq!(decode_signed(s2, b"FF", 0), Ok(-1));
        assert_eq!(decode_signed(s2, b"80", 0), Ok(-128));
        assert_eq!(decode_signed(s2, b"7F", 0), Ok(127));
        assert_eq!(decode_signed(FieldSpec::signed_hex(1), b"8", 0), Ok(-8));
        assert_eq!(decode_signed(FieldSpec::signed_hex(1), b"7", 0), Ok(7));
        assert_eq!(decode_signed(FieldSpec::hex(2), b"FF", 0), Ok(255));
        let s16 = FieldSpec::signed_hex(16);
        assert_eq!(decode_signed(s16, b"FFFFFFFFFFFFFFFF", 0), Ok(-1));
        assert_eq!(decode_signed(s16, b"8000000000000000", 0), Ok(i64::MIN));
        assert_eq!(
            decode_signed(s8, b"FFF9E58G", 20),
            Err(Error::InvalidHexDigit {
                offset: 27,
                byte: b'G'
            })
        );
    }

    #[test]
    fn signed_round_trips_at_every_width() {
        for w in 1..=16u8 {
            let spec = FieldSpec::signed_hex(w);
            let (min, max) = spec.signed_range();
            for v in [min, min + 1, -1, 0, 1, max - 1, max] {
                let out = enc_s(spec, v).unwrap();
                assert_eq!(decode_signed(spec, &out[..spec.len()], 0), Ok(v), "w={w}");
            }
        }
    }

    #[test]
    fn reader() {
        let mut r = Reader::new(b"001EFFFF9C64zz", 10);
        assert_eq!((r.offset(), r.remaining()), (10, 14));
        assert_eq!(r.unsigned(FieldSpec::hex(4)), Ok(0x1E));
        assert_eq!((r.offset(), r.remaining()), (14, 10));
        assert_eq!(r.signed(FieldSpec::signed_hex(8)), Ok(-25_500));
        assert_eq!(r.finish(), Err(Error::TrailingBytes { offset: 22 }));
        assert_eq!(
            r.unsigned(FieldSpec::hex(2)),
            Err(Error::InvalidHexDigit {
                offset: 22,
                byte: b'z'
            })
        );
        assert_eq!(r.remaining(), 0, "the digits were taken");
        assert_eq!(r.finish(), Ok(()));
        assert_eq!(r.take(1), Err(Error::BodyTooShort { offset: 24 }));
        assert_eq!(r.take(0), Ok(&b""[..]));

        let mut r = Reader::new(b"12345", 6);
        assert_eq!(r.rest(), b"12345");
        assert_eq!(r.take(2), Ok(&b"12"[..]));
        assert_eq!(r.rest(), b"345", "rest does not take");
        assert_eq!(r.rest(), b"345");
        assert_eq!(r.take(usize::MAX), Err(Error::BodyTooShort { offset: 8 }));
        assert_eq!(r.take(4), Err(Error::BodyTooShort { offset: 8 }));
        assert_eq!(r.take(3), Ok(&b"345"[..]));
        assert_eq!(
            Reader::new(b"0", 6).signed(FieldSpec::signed_hex(2)),
            Err(Error::BodyTooShort { offset: 6 })
        );
    }

    #[test]
    fn moving_bytes_within_a_buffer() {
        let mut b = *b"0123456789";
        // Down and up, overlapping, up to the very end.
        assert!(move_within(&mut b, 2, 8, 0));
        assert_eq!(&b, b"2345678989");
        let mut b = *b"0123456789";
        assert!(move_within(&mut b, 0, 8, 2));
        assert_eq!(&b, b"0101234567");
        let mut b = *b"0123456789";
        assert!(move_within(&mut b, 9, 1, 0));
        assert_eq!(&b, b"9123456789");
        assert!(move_within(&mut b, 0, 0, 10), "nothing to move, at the end");
        // A range past the end (source or destination) moves nothing.
        for (src, len, dst) in [(9, 2, 0), (0, 2, 9), (11, 0, 0), (0, 11, 0), (0, 1, 10)] {
            let mut b = *b"0123456789";
            assert!(!move_within(&mut b, src, len, dst), "{src} {len} {dst}");
            assert_eq!(&b, b"0123456789");
        }
        let mut b = *b"0123456789";
        assert!(!move_within(&mut b, usize::MAX, 2, 0));
        assert!(!move_within(&mut b, 0, 2, usize::MAX));
        assert_eq!(&b, b"0123456789");
    }

    #[test]
    fn writer() {
        let mut buf = [b'.'; 12];
        let mut w = Writer::new(&mut buf);
        assert!(w.is_empty());
        w.put(b"!").unwrap();
        w.unsigned(FieldSpec::hex(2), 0x99).unwrap();
        assert_eq!((w.len(), w.written()), (3, &b"!99"[..]));
        assert!(!w.is_empty());
        assert_eq!(
            w.unsigned(FieldSpec::hex(2), 0x100),
            Err(Error::ValueOutOfRange { offset: 3 })
        );
        assert_eq!(
            w.signed(FieldSpec::signed_hex(2), -129),
            Err(Error::ValueOutOfRange { offset: 3 })
        );
        assert_eq!(w.written(), b"!99", "a failed field leaves nothing");
        w.signed(FieldSpec::signed_hex(2), -1).unwrap();
        assert_eq!(w.written(), b"!99FF");
        assert_eq!(w.unsigned(FieldSpec::hex(8), 0), Err(Error::BufferTooSmall));
        assert_eq!(w.signed(FieldSpec::hex(8), 0), Err(Error::BufferTooSmall));
        assert_eq!(w.len(), 5);
        assert_eq!(w.reserve(usize::MAX), Err(Error::BufferTooSmall));
        w.patch_unsigned(1, FieldSpec::hex(2), 0x01).unwrap();
        assert_eq!(w.written(), b"!01FF");
        // A patch must lie within what was written.
        w.patch_unsigned(3, FieldSpec::hex(2), 0xAB).unwrap();
        assert_eq!(w.written(), b"!01AB");
        assert_eq!(
            w.patch_unsigned(4, FieldSpec::hex(2), 0),
            Err(Error::BufferTooSmall)
        );
        assert_eq!(
            w.patch_unsigned(usize::MAX, FieldSpec::hex(2), 0),
            Err(Error::BufferTooSmall)
        );
        assert_eq!(
            w.patch_unsigned(1, FieldSpec::hex(2), 0x100),
            Err(Error::ValueOutOfRange { offset: 0 })
        );
        w.truncate(9);
        assert_eq!(w.len(), 5, "truncate never extends");
        w.truncate(2);
        assert_eq!(w.written(), b"!0");
        let r = w.reserve(10).unwrap();
        assert_eq!(r.len(), 10);
        assert_eq!(w.len(), 12);
        assert_eq!(w.reserve(1), Err(Error::BufferTooSmall));
        assert_eq!(w.reserve(0).map(|s| s.len()), Ok(0));

        let mut buf = *b"!99209001005....";
        let mut w = Writer::resume(&mut buf, 12);
        assert_eq!(w.written(), b"!99209001005");
        assert_eq!(w.spare(), b"....");
        w.spare()[0] = b'5';
        assert_eq!(w.len(), 12, "spare does not reserve");
        assert_eq!(w.reserve(1).map(|s| s[0]), Ok(b'5'));
        assert_eq!(w.spare(), b"...");
        let w = Writer::resume(&mut buf, 100);
        assert_eq!(w.len(), 16, "clamped to the buffer");
    }
}
