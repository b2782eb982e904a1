//! Hex digits a whole field at a time, and the checksum a word at a time:
//! the fast paths under the field codec, the position records and the
//! position streams.
//!
//! Every multi-digit field of a position record is 2, 4 or 8 digits wide.
//! [`put4`]/[`put8`] write 4 or 8 upper-case digits of a `u16`/`u32` in one
//! call and return what they add to the checksum; [`decode4`]/[`decode8`]
//! read 4 or 8 digits of either case and validate all of them with a
//! single comparison. [`sum`] adds bytes to a checksum a word at a time.
//! Fields of other widths use the per-byte paths ([`encode_bytewise`],
//! [`decode_bytewise`]), which are also the reference the fast paths are
//! tested against.
//!
//! # How
//! - Encoding looks up each byte of the value in a 256-entry table holding
//!   its two digits and their sum, so 8 digits and their checksum take four
//!   lookups. On a Cortex-M4 that is 21 instructions for 8 digits with the
//!   checksum, against 28 without it for spreading the nibbles over a word
//!   and adding `'0'` or `'A' - 10` with SWAR arithmetic.
//! - Decoding looks up each digit of a group of four in a table for its
//!   position in the group (`T12`, `T8`, `T4`, `T0`), which holds
//!   its value already shifted into place (bits 0-15), the byte itself
//!   (bits 24-31) and, for a byte that is not a hex digit, a marker in bits
//!   16-23 that no valid entry has. Adding the four entries gives the
//!   group's value, the low byte of the sum of its bytes (what it adds to
//!   the checksum) and, if any byte was bad, a non-zero bits 16-23 (k bad
//!   bytes add k × 0xFF there: never 0 for k from 1 to 4), so one test
//!   validates a group or a whole record. On a Cortex-M4 that is 4 loads,
//!   4 table loads and 3 additions for 4 digits with their sum.
//! - The checksum adds 4-byte words: bytes 0 and 2 of every word into one
//!   accumulator of two 16-bit lanes, bytes 1 and 3 into another (one
//!   `uxtb16` and one add each on a Cortex-M4), folded every 256 words
//!   before a lane can overflow.
//!
//! # Panic freedom
//! No indexing: table lookups use `get` with a `u8` index (the optimiser
//! sees it is in bounds), and the array forms take `&[u8; N]` so their
//! lengths are known. No arithmetic can overflow: sums are `u32` over at
//! most 1,024 bytes before they are folded, and table entries are added
//! with wrapping additions (only the low byte of their sum counts).

/// What a positional table ([`T0`]…[`T12`]) holds for a byte that is not
/// a hex digit: bits 16-23 set, where a valid digit's entry has none.
const MARK: u32 = 0x00FF_0000;

/// The value of `byte` as a hex digit of either case (a `const fn` for
/// the tables), or `None`.
const fn hex_value(byte: u8) -> Option<u32> {
    match byte {
        b'0'..=b'9' => Some((byte - b'0') as u32),
        b'A'..=b'F' => Some((byte - b'A' + 10) as u32),
        b'a'..=b'f' => Some((byte - b'a' + 10) as u32),
        _ => None,
    }
}

/// For every byte: its value as a hex digit shifted left by `shift` (bits
/// 0-15), and the byte itself (bits 24-31, what it adds to the checksum);
/// [`MARK`] for a byte that is not a hex digit. Bits 16-23 are clear in
/// every valid entry (see the module docs).
// Indexing in a const initialiser is checked at compile time: it cannot panic at run time.
#[allow(clippy::indexing_slicing)]
const fn positional(shift: u32) -> [u32; 256] {
    let mut t = [MARK; 256];
    let mut i = 0;
    // `<=` would add a pass for 256, byte 0 as a `u8`: no digit, no write (an equivalent mutant).
    while i < 256 {
        if let Some(v) = hex_value(i as u8) {
            // Disjoint bit fields, so adding them is or-ing them.
            t[i] = (v << shift) + ((i as u32) << 24);
        }
        i += 1;
    }
    t
}

/// The four [`positional`] tables, one after the other: one base address
/// for all four.
static TABLES: [[u32; 256]; 4] = [positional(12), positional(8), positional(4), positional(0)];
/// [`positional`] for the last digit of a group of four.
static T0: &[u32; 256] = &TABLES[3];
/// [`positional`] for the third digit of a group of four.
static T4: &[u32; 256] = &TABLES[2];
/// [`positional`] for the second digit of a group of four.
static T8: &[u32; 256] = &TABLES[1];
/// [`positional`] for the first digit of a group of four.
static T12: &[u32; 256] = &TABLES[0];

/// The entry of `byte` in `table`.
#[inline(always)]
fn entry(table: &[u32; 256], byte: u8) -> u32 {
    // A `u8` index is always in bounds of the 256 entries.
    table.get(usize::from(byte)).copied().unwrap_or(MARK)
}

/// Up to four digits at once: their value (bits 0-15), bits 16-23 set if
/// any byte is not a hex digit, and the low byte of the sum of the bytes
/// (bits 24-31) if none is. Each `entry` is one load; adding them costs
/// one instruction each.
///
/// Where a word can be loaded from any address, the four bytes come in one
/// load and are taken apart in registers: four byte loads would each want
/// a register of their own until they are looked up, which spills on a
/// Cortex-M with a whole record in flight. Armv6-M (no unaligned loads,
/// told apart as in [`sum`]) loads the bytes one by one.
#[inline(always)]
fn group4(d: &[u8; 4]) -> u32 {
    #[cfg(target_has_atomic = "32")]
    let [a, b, c, e] = {
        let w = u32::from_le_bytes(*d);
        [w as u8, (w >> 8) as u8, (w >> 16) as u8, (w >> 24) as u8]
    };
    #[cfg(not(target_has_atomic = "32"))]
    let [a, b, c, e] = *d;
    entry(T12, a)
        .wrapping_add(entry(T8, b))
        .wrapping_add(entry(T4, c))
        .wrapping_add(entry(T0, e))
}

/// [`group4`] for three digits.
#[inline(always)]
fn group3(d: &[u8; 3]) -> u32 {
    let [a, b, c] = *d;
    entry(T8, a)
        .wrapping_add(entry(T4, b))
        .wrapping_add(entry(T0, c))
}

/// [`group4`] for two digits.
#[inline(always)]
fn group2(d: &[u8; 2]) -> u32 {
    let [a, b] = *d;
    entry(T4, a).wrapping_add(entry(T0, b))
}

/// Whether a group (or the OR of groups) had only hex digits.
#[inline(always)]
const fn clean(g: u32) -> bool {
    g & MARK == 0
}

/// For every byte: its two upper-case digits (bits 0-7 the first digit,
/// 8-15 the second, so a little-endian store writes them in order) and
/// their sum (bits 16-31), what they add to the checksum.
// Indexing in a const initialiser is checked at compile time: it cannot panic at run time.
#[allow(clippy::indexing_slicing)]
static PAIRS: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let first = digit((i >> 4) as u8) as u32;
        let second = digit(i as u8) as u32;
        // Disjoint bit fields, so adding them is or-ing them.
        t[i] = first + (second << 8) + ((first + second) << 16);
        i += 1;
    }
    t
};

/// The upper-case hex digit of the low nibble of `n`.
#[inline]
pub const fn digit(n: u8) -> u8 {
    let n = n & 0xF;
    if n < 10 {
        b'0' + n
    } else {
        b'A' - 10 + n
    }
}

/// The value of `byte` as a hex digit of either case, or `None`.
#[inline]
pub fn value(byte: u8) -> Option<u8> {
    let v = entry(T0, byte);
    if single_is_digit(v) {
        Some(v as u8 & 0xF)
    } else {
        None
    }
}

/// Whether `byte` is a hex digit of either case.
#[inline]
pub fn is_digit(byte: u8) -> bool {
    single_is_digit(entry(T0, byte))
}

/// Whether one [`T0`] entry is a digit's: its bits 24-31 hold the byte,
/// at least `'0'`, where [`MARK`] has none. One comparison of the whole
/// word (testing bits 16-23 would do too, but invites a byte load at an
/// offset the table's address then has to be computed for, per byte).
#[inline(always)]
const fn single_is_digit(e: u32) -> bool {
    e >= (b'0' as u32) << 24
}

#[inline(always)]
fn pair(byte: u32) -> u32 {
    // Masked to 0..=255: always in bounds of the 256 entries.
    PAIRS.get((byte & 0xFF) as usize).copied().unwrap_or(0)
}

/// Writes the two upper-case digits of `v`; returns their sum (what they
/// add to the checksum).
///
/// ```
/// let mut out = [0u8; 2];
/// assert_eq!(iai_protocol_b::hex::put2(0x9B, &mut out), u32::from(b'9' + b'B'));
/// assert_eq!(&out, b"9B");
/// ```
#[inline]
pub fn put2(v: u8, out: &mut [u8; 2]) -> u32 {
    let p = pair(u32::from(v));
    *out = (p as u16).to_le_bytes();
    p >> 16
}

/// Writes the four upper-case digits of `v`; returns their sum.
///
/// ```
/// let mut out = [0u8; 4];
/// let sum = iai_protocol_b::hex::put4(0x1E, &mut out);
/// assert_eq!(&out, b"001E");
/// assert_eq!(sum, out.iter().map(|&b| u32::from(b)).sum());
/// ```
#[inline]
pub fn put4(v: u16, out: &mut [u8; 4]) -> u32 {
    let v = u32::from(v);
    let a = pair(v >> 8);
    let b = pair(v);
    // Disjoint halves, so adding them is or-ing them.
    *out = ((a & 0xFFFF) + (b << 16)).to_le_bytes();
    (a >> 16) + (b >> 16)
}

/// Writes the eight upper-case digits of `v`; returns their sum.
///
/// ```
/// let mut out = [0u8; 8];
/// // -400.000 mm in a signed 8-digit field (2003 p. 65).
/// iai_protocol_b::hex::put8(-400_000i32 as u32, &mut out);
/// assert_eq!(&out, b"FFF9E580");
/// ```
#[inline]
pub fn put8(v: u32, out: &mut [u8; 8]) -> u32 {
    let a = pair(v >> 24);
    let b = pair(v >> 16);
    let c = pair(v >> 8);
    let d = pair(v);
    // Disjoint halves, so adding them is or-ing them.
    let first = (a & 0xFFFF) + (b << 16);
    let second = (c & 0xFFFF) + (d << 16);
    *out = (u64::from(first) + (u64::from(second) << 32)).to_le_bytes();
    (a >> 16) + (b >> 16) + (c >> 16) + (d >> 16)
}

/// The two upper-case digits of `v`.
#[inline]
pub fn encode2(v: u8) -> [u8; 2] {
    let mut out = [0; 2];
    put2(v, &mut out);
    out
}

/// The four upper-case digits of `v`.
#[inline]
pub fn encode4(v: u16) -> [u8; 4] {
    let mut out = [0; 4];
    put4(v, &mut out);
    out
}

/// The eight upper-case digits of `v`.
#[inline]
pub fn encode8(v: u32) -> [u8; 8] {
    let mut out = [0; 8];
    put8(v, &mut out);
    out
}

/// The value of two hex digits of either case; `None` if either is not a
/// hex digit.
#[inline]
pub fn decode2(d: &[u8; 2]) -> Option<u8> {
    let g = group2(d);
    if clean(g) {
        Some(g as u8)
    } else {
        None
    }
}

/// The value of four hex digits of either case; `None` if any is not a
/// hex digit.
///
/// ```
/// use iai_protocol_b::hex::decode4;
/// assert_eq!(decode4(b"26dH"), None);
/// assert_eq!(decode4(b"026d"), Some(0x26D));
/// ```
#[inline]
pub fn decode4(d: &[u8; 4]) -> Option<u16> {
    let g = group4(d);
    if clean(g) {
        Some(g as u16)
    } else {
        None
    }
}

/// The value of eight hex digits of either case; `None` if any is not a
/// hex digit.
///
/// ```
/// use iai_protocol_b::hex::decode8;
/// assert_eq!(decode8(b"FFF9E580").map(|v| v as i32), Some(-400_000));
/// assert_eq!(decode8(b"FFF9E58G"), None);
/// ```
#[inline]
pub fn decode8(d: &[u8; 8]) -> Option<u32> {
    let (hi, lo) = halves(d);
    if clean(hi | lo) {
        Some(join(hi, lo))
    } else {
        None
    }
}

/// The two [`group4`]s of eight digits.
#[inline(always)]
fn halves(d: &[u8; 8]) -> (u32, u32) {
    let (hi, lo) = d.split_at(4);
    match (<&[u8; 4]>::try_from(hi), <&[u8; 4]>::try_from(lo)) {
        (Ok(hi), Ok(lo)) => (group4(hi), group4(lo)),
        // Eight bytes split at 4: never taken.
        _ => (MARK, MARK),
    }
}

/// The value of eight digits from their two groups (one `pkhbt` on a
/// Cortex-M4).
#[inline(always)]
fn join(hi: u32, lo: u32) -> u32 {
    // Disjoint halves, so `^` would give the same word: an equivalent mutant.
    (hi << 16) | (lo & 0xFFFF)
}

/// Decodes many fields and validates them all with one comparison at the
/// end: for a whole record, one check instead of one per field.
///
/// The values it returns are meaningful only if [`Batch::is_valid`] says
/// so afterwards; otherwise some byte was not a hex digit (find which with
/// [`first_invalid`] or the per-byte path).
///
/// ```
/// use iai_protocol_b::hex::Batch;
/// let mut b = Batch::new();
/// let axes = b.decode2(b"03");
/// let speed = b.decode4(b"0064");
/// let x = b.decode8(b"FFFF9C64") as i32;
/// assert!(b.is_valid());
/// assert_eq!((axes, speed, x), (3, 100, -25_500));
/// b.decode2(b"0x");
/// assert!(!b.is_valid());
/// ```
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Batch {
    /// The OR of every group: bits 16-23 set once a byte was not a hex
    /// digit.
    seen: u32,
    /// The sum of every byte decoded (what they add to the checksum).
    sum: u32,
}

impl Batch {
    /// A batch that has seen no digit.
    pub const fn new() -> Self {
        Batch { seen: 0, sum: 0 }
    }

    /// Two digits (see [`decode2`]).
    #[inline(always)]
    pub fn decode2(&mut self, d: &[u8; 2]) -> u8 {
        let g = group2(d);
        self.seen |= g;
        self.sum += d.iter().map(|&b| u32::from(b)).sum::<u32>();
        g as u8
    }

    /// Four digits (see [`decode4`]).
    #[inline(always)]
    pub fn decode4(&mut self, d: &[u8; 4]) -> u16 {
        let g = group4(d);
        self.seen |= g;
        self.sum += d.iter().map(|&b| u32::from(b)).sum::<u32>();
        g as u16
    }

    /// Eight digits (see [`decode8`]).
    #[inline(always)]
    pub fn decode8(&mut self, d: &[u8; 8]) -> u32 {
        let (hi, lo) = halves(d);
        self.seen |= hi | lo;
        self.sum += d.iter().map(|&b| u32::from(b)).sum::<u32>();
        join(hi, lo)
    }

    /// The sum of every byte decoded so far (what they add to the
    /// checksum), valid digits or not.
    #[inline(always)]
    pub fn sum(&self) -> u32 {
        self.sum
    }

    /// Whether every byte decoded so far was a hex digit.
    #[inline(always)]
    pub fn is_valid(&self) -> bool {
        clean(self.seen)
    }
}

/// A [`Batch`] that keeps only the low byte of the sum, which is all a
/// checksum needs, for at most 255 digits: the stream decoder's record
/// path (a record has at most 84).
///
/// Each group's sum comes out of the same table loads as its value (bits
/// 24-31 of [`group4`]), and its bits 16-31 are added to one accumulator:
/// one instruction per group for the check and the sum together. A group
/// with k bad bytes has `k × 0xFF` in bits 16-23, and since bits 24-31
/// only carry upwards, the accumulator's low byte is `-K` modulo 256 for K
/// bad bytes in all: 0 exactly when K is 0, as K < 256. Its bits 8-31 are
/// then the sum of the groups' byte sums, whose low byte is the checksum's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct ModBatch {
    /// Bits 16-31 of every group added up (see above).
    acc: u32,
}

impl ModBatch {
    #[inline(always)]
    fn add(&mut self, g: u32) {
        self.acc = self.acc.wrapping_add(g >> 16);
    }
}

/// The decoding half of [`Batch`] and [`ModBatch`]: what the whole-field
/// record reader needs of either.
pub(crate) trait Digits {
    /// Two digits.
    fn decode2(&mut self, d: &[u8; 2]) -> u8;
    /// Three digits.
    fn decode3(&mut self, d: &[u8; 3]) -> u16;
    /// Four digits.
    fn decode4(&mut self, d: &[u8; 4]) -> u16;
    /// Eight digits.
    fn decode8(&mut self, d: &[u8; 8]) -> u32;
    /// Whether every byte so far was a hex digit.
    fn is_valid(&self) -> bool;
    /// The sum of the bytes so far; [`ModBatch`]: only its low byte.
    fn sum(&self) -> u32;
}

impl Digits for Batch {
    #[inline(always)]
    fn decode2(&mut self, d: &[u8; 2]) -> u8 {
        Batch::decode2(self, d)
    }
    #[inline(always)]
    fn decode3(&mut self, d: &[u8; 3]) -> u16 {
        let g = group3(d);
        self.seen |= g;
        self.sum += d.iter().map(|&b| u32::from(b)).sum::<u32>();
        g as u16
    }
    #[inline(always)]
    fn decode4(&mut self, d: &[u8; 4]) -> u16 {
        Batch::decode4(self, d)
    }
    #[inline(always)]
    fn decode8(&mut self, d: &[u8; 8]) -> u32 {
        Batch::decode8(self, d)
    }
    #[inline(always)]
    fn is_valid(&self) -> bool {
        Batch::is_valid(self)
    }
    #[inline(always)]
    fn sum(&self) -> u32 {
        Batch::sum(self)
    }
}

impl Digits for ModBatch {
    #[inline(always)]
    fn decode2(&mut self, d: &[u8; 2]) -> u8 {
        let g = group2(d);
        self.add(g);
        g as u8
    }
    #[inline(always)]
    fn decode3(&mut self, d: &[u8; 3]) -> u16 {
        let g = group3(d);
        self.add(g);
        g as u16
    }
    #[inline(always)]
    fn decode4(&mut self, d: &[u8; 4]) -> u16 {
        let g = group4(d);
        self.add(g);
        g as u16
    }
    #[inline(always)]
    fn decode8(&mut self, d: &[u8; 8]) -> u32 {
        let (hi, lo) = halves(d);
        self.add(hi);
        self.add(lo);
        join(hi, lo)
    }
    #[inline(always)]
    fn is_valid(&self) -> bool {
        self.acc & 0xFF == 0
    }
    #[inline(always)]
    fn sum(&self) -> u32 {
        self.acc >> 8
    }
}

/// The index of the first byte of `digits` that is not a hex digit.
pub fn first_invalid(digits: &[u8]) -> Option<usize> {
    digits.iter().position(|&b| !is_digit(b))
}

/// Writes `value` as upper-case digits filling `out`, one digit at a time
/// (any width). Returns `false` if the value does not fit; `out` then holds
/// its low digits.
pub fn encode_bytewise(mut value: u64, out: &mut [u8]) -> bool {
    for slot in out.iter_mut().rev() {
        *slot = digit((value & 0xF) as u8);
        value >>= 4;
    }
    value == 0
}

/// Reads digits of either case one at a time (any width; beyond 16 digits
/// only the last 16 count). `Err` holds the index of the first byte that is
/// not a hex digit.
pub fn decode_bytewise(digits: &[u8]) -> Result<u64, usize> {
    let mut v: u64 = 0;
    for (i, &b) in digits.iter().enumerate() {
        match value(b) {
            Some(d) => v = (v << 4) + u64::from(d),
            None => return Err(i),
        }
    }
    Ok(v)
}

/// `acc` plus every byte of `bytes`, modulo 256, one byte at a time.
pub fn sum_bytewise(acc: u8, bytes: &[u8]) -> u8 {
    // Eight bytes a round: one load and one add each on any core.
    let mut total = u32::from(acc);
    let mut rounds = bytes.chunks_exact(8);
    for r in &mut rounds {
        for &b in r {
            total = total.wrapping_add(u32::from(b));
        }
    }
    for &b in rounds.remainder() {
        total = total.wrapping_add(u32::from(b));
    }
    total as u8
}

/// Bytes summed between two folds of the lane accumulators: 256 words, so
/// that a 16-bit lane (at most 255 per word) cannot overflow.
const BLOCK: usize = 1024;

/// `acc` plus every byte of `bytes`, modulo 256, a 4-byte word at a time
/// (see the module docs).
///
/// ```
/// // The worked example of the 2003 spec, p. 10: sum 254h, SC "54".
/// assert_eq!(iai_protocol_b::hex::sum(0, b"!99209001005"), 0x54);
/// ```
pub fn sum(acc: u8, bytes: &[u8]) -> u8 {
    // Armv6-M (Cortex-M0/M0+) cannot load a word from an unaligned
    // address, so a word costs it four byte loads: it adds bytes. Lacking
    // compare-and-swap is what tells it apart in a stable `cfg`.
    #[cfg(not(target_has_atomic = "32"))]
    return sum_bytewise(acc, bytes);
    #[cfg(target_has_atomic = "32")]
    sum_words(acc, bytes)
}

/// [`sum`] a word at a time, on any target (tested against
/// [`sum_bytewise`] on the host whatever `sum` picks).
#[inline]
pub fn sum_words(acc: u8, bytes: &[u8]) -> u8 {
    let mut total = u32::from(acc);
    for block in bytes.chunks(BLOCK) {
        let mut even = 0u32;
        let mut odd = 0u32;
        let mut words = block.chunks_exact(4);
        for w in &mut words {
            let w = match <[u8; 4]>::try_from(w) {
                Ok(w) => u32::from_le_bytes(w),
                // chunks_exact yields 4 bytes: never taken.
                Err(_) => 0,
            };
            even += w & 0x00FF_00FF;
            odd += (w >> 8) & 0x00FF_00FF;
        }
        total = total
            .wrapping_add(even)
            .wrapping_add(even >> 16)
            .wrapping_add(odd)
            .wrapping_add(odd >> 16);
        total = u32::from(sum_bytewise(total as u8, words.remainder()));
    }
    total as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic stream of `u32` (xorshift).
    fn xorshift(seed: u32) -> impl Iterator<Item = u32> {
        let mut x = seed | 1;
        core::iter::repeat_with(move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        })
    }

    fn lower(d: &[u8]) -> [u8; 8] {
        let mut out = [0u8; 8];
        for (o, &b) in out.iter_mut().zip(d) {
            *o = b.to_ascii_lowercase();
        }
        out
    }

    #[test]
    fn golden_digits() {
        assert_eq!(&encode2(0x00), b"00");
        assert_eq!(&encode2(0x9B), b"9B");
        assert_eq!(&encode2(0xFF), b"FF");
        assert_eq!(&encode4(0x0000), b"0000");
        assert_eq!(&encode4(0x001E), b"001E");
        assert_eq!(&encode4(0x26D0), b"26D0");
        assert_eq!(&encode4(0xFFFF), b"FFFF");
        assert_eq!(&encode8(0x0000_0000), b"00000000");
        assert_eq!(&encode8(0x0001_86A0), b"000186A0");
        assert_eq!(&encode8(0xFFFF_9C64), b"FFFF9C64");
        assert_eq!(&encode8(0xFFF9_E580), b"FFF9E580");
        assert_eq!(&encode8(0x0123_4567), b"01234567");
        assert_eq!(&encode8(0x89AB_CDEF), b"89ABCDEF");
        assert_eq!(decode2(b"9b"), Some(0x9B));
        assert_eq!(decode2(b"9B"), Some(0x9B));
        assert_eq!(decode2(b"FF"), Some(0xFF));
        assert_eq!(decode4(b"001E"), Some(0x1E));
        assert_eq!(decode4(b"ffff"), Some(0xFFFF));
        assert_eq!(decode4(b"FFFF"), Some(0xFFFF));
        assert_eq!(decode8(b"FFFF9C64"), Some(0xFFFF_9C64));
        assert_eq!(decode8(b"ffffffff"), Some(u32::MAX));
        assert_eq!(decode8(b"89abcdef"), Some(0x89AB_CDEF));
        assert_eq!(decode8(b"00000000"), Some(0));
        for bad in [
            b"0x12", b"12 4", b"-001", b"FFFG", b"fffg", b"@000", b"000`",
        ] {
            assert_eq!(decode4(bad), None, "{bad:?}");
        }
        assert_eq!(decode2(b"G0"), None);
        assert_eq!(decode2(b"0g"), None);
    }

    #[test]
    fn per_byte_digits() {
        let digits = b"0123456789ABCDEF";
        for (n, &d) in (0u8..).zip(digits) {
            assert_eq!(digit(n), d);
            assert_eq!(digit(n | 0xF0), d, "only the low nibble counts");
            assert_eq!(value(d), Some(n));
            assert_eq!(value(d.to_ascii_lowercase()), Some(n));
        }
        let valid = |b: u8| b.is_ascii_hexdigit();
        for b in 0..=255u8 {
            assert_eq!(is_digit(b), valid(b), "{b:#04X}");
            assert_eq!(value(b).is_some(), valid(b), "{b:#04X}");
        }
    }

    #[test]
    fn put_returns_the_checksum_of_its_digits() {
        for v in xorshift(7).take(2000) {
            let mut o2 = [0u8; 2];
            let mut o4 = [0u8; 4];
            let mut o8 = [0u8; 8];
            assert_eq!(
                put2(v as u8, &mut o2),
                o2.iter().map(|&b| u32::from(b)).sum()
            );
            assert_eq!(
                put4(v as u16, &mut o4),
                o4.iter().map(|&b| u32::from(b)).sum()
            );
            assert_eq!(put8(v, &mut o8), o8.iter().map(|&b| u32::from(b)).sum());
        }
        let mut o8 = [0u8; 8];
        assert_eq!(put8(0xFFFF_FFFF, &mut o8), 8 * u32::from(b'F'));
        assert_eq!(put8(0, &mut o8), 8 * u32::from(b'0'));
    }

    #[test]
    fn every_u16_both_ways_both_cases() {
        for v in 0..=u16::MAX {
            let d = encode4(v);
            let mut reference = [0u8; 4];
            assert!(encode_bytewise(u64::from(v), &mut reference));
            assert_eq!(d, reference, "{v:#06X}");
            assert_eq!(decode4(&d), Some(v));
            let l = lower(&d);
            assert_eq!(decode4(&[l[0], l[1], l[2], l[3]]), Some(v));
            // The same value as the low half of eight digits, and high half.
            let mut e = [b'0'; 8];
            e[4..].copy_from_slice(&d);
            assert_eq!(decode8(&e), Some(u32::from(v)));
            e[..4].copy_from_slice(&d);
            assert_eq!(decode8(&e), Some(u32::from(v) << 16 | u32::from(v)));
            assert_eq!(encode8(u32::from(v) << 16 | u32::from(v)), e);
            if let Ok(b) = u8::try_from(v) {
                assert_eq!(encode2(b), [d[2], d[3]]);
                assert_eq!(decode2(&[d[2], d[3]]), Some(b));
                assert_eq!(decode2(&[l[2], l[3]]), Some(b));
            }
        }
    }

    #[test]
    fn u32_against_the_per_byte_path() {
        let edges = [0, 1, 9, 10, 15, 16, 0x7FFF_FFFF, 0x8000_0000, u32::MAX];
        for v in xorshift(1).take(100_000).chain(edges) {
            let d = encode8(v);
            let mut reference = [0u8; 8];
            assert!(encode_bytewise(u64::from(v), &mut reference));
            assert_eq!(d, reference, "{v:#010X}");
            assert_eq!(decode8(&d), Some(v));
            assert_eq!(decode8(&lower(&d)), Some(v));
            assert_eq!(decode_bytewise(&d), Ok(u64::from(v)));
        }
    }

    /// Every byte value in every digit position: the group is accepted
    /// exactly when the byte is a hex digit, with the per-byte value.
    #[test]
    fn every_byte_in_every_position() {
        let base = *b"07aF3c9E";
        for pos in 0..8 {
            for b in 0..=255u8 {
                let mut d = base;
                d[pos] = b;
                let expect = decode_bytewise(&d).ok().map(|v| v as u32);
                assert_eq!(expect.is_some(), b.is_ascii_hexdigit());
                assert_eq!(decode8(&d), expect, "byte {b:#04X} at {pos}");
                let (hi, lo) = d.split_at(4);
                let four = |s: &[u8]| decode4(&[s[0], s[1], s[2], s[3]]);
                let expect4 = |s: &[u8]| decode_bytewise(s).ok().map(|v| v as u16);
                assert_eq!(four(hi), expect4(hi));
                assert_eq!(four(lo), expect4(lo));
                if pos < 2 {
                    let two = [d[0], d[1]];
                    assert_eq!(decode2(&two), decode_bytewise(&two).ok().map(|v| v as u8));
                }
                assert_eq!(first_invalid(&d), (!b.is_ascii_hexdigit()).then_some(pos));
            }
        }
    }

    #[test]
    fn a_batch_is_valid_exactly_when_every_group_is() {
        let groups: [&[u8]; 6] = [b"00", b"ff", b"1E00", b"abcd", b"FFFF9C64", b"7fffffff"];
        let mut clean = Batch::new();
        assert!(clean.is_valid());
        for g in groups {
            match g.len() {
                2 => assert_eq!(
                    Some(clean.decode2(g.try_into().unwrap())),
                    decode2(g.try_into().unwrap())
                ),
                4 => assert_eq!(
                    Some(clean.decode4(g.try_into().unwrap())),
                    decode4(g.try_into().unwrap())
                ),
                _ => assert_eq!(
                    Some(clean.decode8(g.try_into().unwrap())),
                    decode8(g.try_into().unwrap())
                ),
            }
        }
        assert!(clean.is_valid());
        let all: u32 = groups
            .iter()
            .flat_map(|g| g.iter())
            .map(|&b| u32::from(b))
            .sum();
        assert_eq!(clean.sum(), all);
        // One bad byte anywhere in any group spoils the batch.
        for (k, g) in groups.iter().enumerate() {
            for pos in 0..g.len() {
                for bad in [b'G', b'g', b'/', b':', b'@', b'`', 0x00, 0x80, 0xFF] {
                    let mut b = Batch::new();
                    for (j, h) in groups.iter().enumerate() {
                        let mut d = [0u8; 8];
                        d[..h.len()].copy_from_slice(h);
                        if j == k {
                            d[pos] = bad;
                        }
                        match h.len() {
                            2 => drop(b.decode2(&[d[0], d[1]])),
                            4 => drop(b.decode4(&[d[0], d[1], d[2], d[3]])),
                            _ => drop(b.decode8(&d)),
                        }
                    }
                    assert!(!b.is_valid(), "{bad:#04X} at {pos} of group {k}");
                }
            }
        }
        // Every byte value as the last digit of a 2-digit group (the group
        // whose marker is shifted least).
        for x in 0..=255u8 {
            let mut b = Batch::new();
            let v = b.decode2(&[b'A', x]);
            assert_eq!(b.is_valid(), x.is_ascii_hexdigit(), "{x:#04X}");
            if b.is_valid() {
                assert_eq!(Some(v), decode2(&[b'A', x]));
            }
        }
    }

    /// Two bad fields in one record: each group's marker is 0xFF in bits
    /// 16-23, and the batch must keep both rather than let one cancel the
    /// other (xor-ing markers would: 0xFF ^ 0xFF is 0).
    #[test]
    fn a_batch_keeps_the_marks_of_two_bad_fields() {
        let mut b = Batch::new();
        b.decode2(b"G0");
        b.decode2(b"0G");
        assert!(!b.is_valid(), "two bad 2-digit fields");
        let mut b = Batch::new();
        b.decode4(b"0G00");
        b.decode4(b"000G");
        assert!(!b.is_valid(), "two bad 4-digit fields");
        let mut b = Batch::new();
        b.decode8(b"G0000000");
        b.decode8(b"FFFF9C6G");
        assert!(!b.is_valid(), "two bad 8-digit fields");
        // One bad digit in each half of one 8-digit field.
        let mut b = Batch::new();
        b.decode8(b"0G009C6G");
        assert!(!b.is_valid(), "a bad digit in each half");
        // Three digits (the record reader's 3-digit fields) through `Digits`.
        let mut b = Batch::new();
        assert_eq!(Digits::decode3(&mut b, b"26D"), 0x26D);
        assert!(Digits::is_valid(&b));
        assert_eq!(Digits::sum(&b), u32::from(b'2' + b'6' + b'D'));
        Digits::decode3(&mut b, b"2G6");
        assert!(!Digits::is_valid(&b), "one bad 3-digit field");
        Digits::decode3(&mut b, b"G26");
        assert!(!Digits::is_valid(&b), "two bad 3-digit fields");
        assert_eq!(
            Digits::sum(&b),
            3 * u32::from(b'2' + b'6') + u32::from(b'D' + 2 * b'G')
        );
    }

    #[test]
    fn positional_tables() {
        for b in 0..=255u8 {
            let v = decode_bytewise(&[b]).ok().map(|v| v as u32);
            for (t, shift) in [(T0, 0), (T4, 4), (T8, 8), (T12, 12)] {
                let e = entry(t, b);
                match v {
                    Some(v) => assert_eq!(e, (v << shift) | (u32::from(b) << 24), "{b:#04X}"),
                    None => assert_eq!(e, MARK, "{b:#04X}"),
                }
            }
            assert_eq!(value(b).map(u32::from), v);
        }
    }

    /// Digits as a `ModBatch` reads them, by group width.
    fn mod_decode(m: &mut ModBatch, g: &[u8]) -> u32 {
        match g.len() {
            2 => u32::from(Digits::decode2(m, g.try_into().unwrap())),
            3 => u32::from(Digits::decode3(m, g.try_into().unwrap())),
            4 => u32::from(Digits::decode4(m, g.try_into().unwrap())),
            _ => Digits::decode8(m, g.try_into().unwrap()),
        }
    }

    #[test]
    fn a_mod_batch_gives_values_and_the_low_byte_of_the_sum() {
        let mut next = xorshift(21);
        let widths = [2usize, 3, 4, 8];
        for _ in 0..3000 {
            // Up to a whole record's worth of digits (84), in both cases.
            let mut m = ModBatch::default();
            let mut b = Batch::new();
            let mut total = 0u32;
            let mut digits = 0;
            while digits < 76 {
                let w = widths[(next.next().unwrap() % 4) as usize];
                let r = next.next().unwrap();
                let mut g = [0u8; 8];
                for (k, d) in g[..w].iter_mut().enumerate() {
                    let x = digit((r >> (4 * k)) as u8);
                    *d = if (r >> (28 - k)) & 1 == 1 {
                        x.to_ascii_lowercase()
                    } else {
                        x
                    };
                }
                let g = &g[..w];
                let expect = decode_bytewise(g).unwrap() as u32;
                assert_eq!(mod_decode(&mut m, g), expect, "{g:?}");
                let via_batch = match w {
                    2 => u32::from(b.decode2(g.try_into().unwrap())),
                    3 => u32::from(Digits::decode3(&mut b, g.try_into().unwrap())),
                    4 => u32::from(b.decode4(g.try_into().unwrap())),
                    _ => b.decode8(g.try_into().unwrap()),
                };
                assert_eq!(via_batch, expect);
                total += g.iter().map(|&x| u32::from(x)).sum::<u32>();
                digits += w;
            }
            assert!(Digits::is_valid(&m));
            assert_eq!(Digits::sum(&m) as u8, total as u8);
            assert_eq!(Digits::sum(&b), total, "a Batch keeps the whole sum");
        }
    }

    /// Bad bytes anywhere, up to one in every position of a record's worth
    /// of groups: never taken for valid.
    #[test]
    fn a_mod_batch_sees_every_bad_byte() {
        let groups: [&[u8]; 6] = [b"0001", b"ff", b"1e00", b"ABC", b"FFFF9C64", b"7fffffff"];
        let all: usize = groups.iter().map(|g| g.len()).sum();
        let mut next = xorshift(8);
        let bad = [b'G', b'g', b'/', b':', b'@', b'`', 0x00, 0x80, 0xFF, b'\r'];
        for _ in 0..20_000 {
            // Which positions are bad: one, a few or all of them.
            let pick = next.next().unwrap();
            let k = match pick % 4 {
                0 => 1,
                1 => 2 + (pick >> 8) as usize % 4,
                2 => (pick >> 8) as usize % all + 1,
                _ => all,
            };
            let mut flagged = [false; 32];
            let mut placed = 0;
            while placed < k {
                let at = next.next().unwrap() as usize % all;
                if !flagged[at] {
                    flagged[at] = true;
                    placed += 1;
                }
            }
            let mut m = ModBatch::default();
            let mut at = 0;
            for _ in 0..3 {
                at = 0;
                let mut m1 = ModBatch::default();
                for g in groups {
                    let mut d = [0u8; 8];
                    d[..g.len()].copy_from_slice(g);
                    for (j, x) in d[..g.len()].iter_mut().enumerate() {
                        if flagged[at + j] {
                            *x = bad[(next.next().unwrap() % bad.len() as u32) as usize];
                        }
                    }
                    mod_decode(&mut m1, &d[..g.len()]);
                    mod_decode(&mut m, &d[..g.len()]);
                    at += g.len();
                }
                assert!(!Digits::is_valid(&m1), "{k} bad of {at}");
            }
            assert!(!Digits::is_valid(&m), "{k} bad of {at}, three times over");
        }
        // Every byte in every position of each width.
        for w in [2usize, 3, 4, 8] {
            for pos in 0..w {
                for x in 0..=255u8 {
                    let mut d = *b"8a6F0c9E";
                    d[pos] = x;
                    let mut m = ModBatch::default();
                    let v = mod_decode(&mut m, &d[..w]);
                    assert_eq!(Digits::is_valid(&m), x.is_ascii_hexdigit(), "{x:#04X}");
                    if x.is_ascii_hexdigit() {
                        assert_eq!(u64::from(v), decode_bytewise(&d[..w]).unwrap());
                    }
                }
            }
        }
    }

    #[test]
    fn two_bad_digits_are_still_bad() {
        // A bad digit's marker must not be cancelled by another's.
        for b in [0u8, b'G', b'g', 0x80, 0xFF] {
            for i in 0..8 {
                for j in i + 1..8 {
                    let mut d = *b"12345678";
                    d[i] = b;
                    d[j] = b;
                    assert_eq!(decode8(&d), None);
                }
            }
        }
    }

    #[test]
    fn per_byte_paths() {
        let mut out = [0u8; 3];
        assert!(encode_bytewise(0xABC, &mut out));
        assert_eq!(&out, b"ABC");
        assert!(!encode_bytewise(0x1000, &mut out), "does not fit 3 digits");
        assert_eq!(&out, b"000");
        let mut out = [0u8; 16];
        assert!(encode_bytewise(u64::MAX, &mut out));
        assert_eq!(&out, b"FFFFFFFFFFFFFFFF");
        assert!(encode_bytewise(0, &mut []));
        assert!(!encode_bytewise(1, &mut []));
        assert_eq!(decode_bytewise(b"26d"), Ok(0x26D));
        assert_eq!(decode_bytewise(b""), Ok(0));
        assert_eq!(decode_bytewise(b"FFFFFFFFFFFFFFFF"), Ok(u64::MAX));
        assert_eq!(decode_bytewise(b"12x4"), Err(2));
        assert_eq!(decode_bytewise(b"x234"), Err(0));
        assert_eq!(first_invalid(b"1234"), None);
        assert_eq!(first_invalid(b"12 4"), Some(2));
    }

    #[test]
    fn golden_sums() {
        // 2003 p. 10: "!99209001005" sums to 254h.
        assert_eq!(sum(0, b"!99209001005"), 0x54);
        assert_eq!(sum_bytewise(0, b"!99209001005"), 0x54);
        assert_eq!(sum(0x10, b"!99209001005"), 0x64);
        assert_eq!(sum(0xFF, &[]), 0xFF);
        assert_eq!(sum(0, &[0xFF; 4]), 0xFC);
        assert_eq!(sum(0, &[1, 2, 3, 4, 5]), 15);
    }

    #[test]
    fn sums_against_the_per_byte_path() {
        let mut bytes = [0u8; 2600];
        for (b, r) in bytes.iter_mut().zip(xorshift(3)) {
            *b = r as u8;
        }
        for start in 0..8 {
            for len in (0..=2592).filter(|l| *l < 40 || l % 37 == 0 || *l > 2560) {
                let s = &bytes[start..start + len];
                for acc in [0u8, 0x5A, 0xFF] {
                    assert_eq!(sum(acc, s), sum_bytewise(acc, s), "{start}+{len}");
                    assert_eq!(sum_words(acc, s), sum_bytewise(acc, s), "{start}+{len}");
                }
            }
        }
    }

    #[test]
    fn sums_of_long_runs_of_0xff_do_not_overflow_a_lane() {
        let ff = [0xFFu8; 5000];
        for len in [1023, 1024, 1025, 2048, 4096, 5000] {
            assert_eq!(
                sum_words(0, &ff[..len]),
                sum_bytewise(0, &ff[..len]),
                "{len}"
            );
        }
    }
}
