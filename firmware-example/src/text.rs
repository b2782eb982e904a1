//! Text without `core::fmt` (its machinery costs several KiB of flash):
//! a byte [`Sink`] and the numbers the settings and the web page print,
//! decimal, hex, millimetres from 0.001 mm, IPv4 addresses.

/// Where text goes.
pub trait Sink {
    /// Appends `bytes`.
    fn put(&mut self, bytes: &[u8]);

    /// Appends `s`.
    fn str(&mut self, s: &str) {
        self.put(s.as_bytes());
    }
}

/// A sink that fills a byte buffer and counts what did not fit.
pub struct Buf<'a> {
    buf: &'a mut [u8],
    len: usize,
    /// Bytes that did not fit.
    pub lost: usize,
}

impl<'a> Buf<'a> {
    /// An empty sink over `buf`.
    pub fn new(buf: &'a mut [u8]) -> Self {
        Buf {
            buf,
            len: 0,
            lost: 0,
        }
    }

    /// What was written.
    pub fn bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or(&[])
    }

    /// Bytes written.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing was written.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl Sink for Buf<'_> {
    fn put(&mut self, bytes: &[u8]) {
        let room = self.buf.len().saturating_sub(self.len);
        let n = bytes.len().min(room);
        if let (Some(dst), Some(src)) = (self.buf.get_mut(self.len..self.len + n), bytes.get(..n)) {
            dst.copy_from_slice(src);
        }
        self.len += n;
        self.lost += bytes.len() - n;
    }
}

/// `n` in decimal.
pub fn dec(out: &mut dyn Sink, n: u64) {
    let mut digits = [0u8; 20];
    let mut at = digits.len();
    let mut n = n;
    loop {
        at -= 1;
        if let Some(d) = digits.get_mut(at) {
            *d = b'0' + (n % 10) as u8;
        }
        n /= 10;
        if n == 0 || at == 0 {
            break;
        }
    }
    out.put(digits.get(at..).unwrap_or(&[]));
}

/// `n` in decimal with a minus sign if negative.
pub fn signed(out: &mut dyn Sink, n: i64) {
    if n < 0 {
        out.put(b"-");
    }
    dec(out, n.unsigned_abs());
}

/// The low `digits` hex digits of `n`, upper case.
pub fn hex(out: &mut dyn Sink, n: u32, digits: u8) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    for i in (0..u32::from(digits.min(8))).rev() {
        let nibble = (n >> (4 * i)) & 0xF;
        out.put(&[HEX.get(nibble as usize).copied().unwrap_or(b'?')]);
    }
}

/// A length in 0.001 mm as millimetres with three decimals (`-25.500`).
pub fn mm(out: &mut dyn Sink, thousandths: i32) {
    let v = i64::from(thousandths);
    if v < 0 {
        out.put(b"-");
    }
    let a = v.unsigned_abs();
    dec(out, a / 1000);
    out.put(b".");
    let frac = a % 1000;
    if frac < 100 {
        out.put(b"0");
    }
    if frac < 10 {
        out.put(b"0");
    }
    dec(out, frac);
}

/// An IPv4 address, dotted.
pub fn ipv4(out: &mut dyn Sink, a: [u8; 4]) {
    for (i, b) in a.iter().enumerate() {
        if i > 0 {
            out.put(b".");
        }
        dec(out, u64::from(*b));
    }
}

/// A decimal number of at most 10 digits (`None`: empty, too long, not a
/// digit, or over `u32::MAX`).
pub fn parse_dec(s: &[u8]) -> Option<u32> {
    if s.is_empty() || s.len() > 10 {
        return None;
    }
    s.iter().try_fold(0u32, |acc, &b| {
        let d = u32::from(b.checked_sub(b'0').filter(|d| *d <= 9)?);
        acc.checked_mul(10)?.checked_add(d)
    })
}

/// Hex digits (either case), at most 8.
pub fn parse_hex(s: &[u8]) -> Option<u32> {
    if s.is_empty() || s.len() > 8 {
        return None;
    }
    s.iter()
        .try_fold(0u32, |acc, &b| Some(acc << 4 | (b as char).to_digit(16)?))
}

/// A dotted IPv4 address.
pub fn parse_ipv4(s: &[u8]) -> Option<[u8; 4]> {
    let mut out = [0u8; 4];
    let mut parts = s.split(|&b| b == b'.');
    for slot in out.iter_mut() {
        let p = parts.next()?;
        if p.len() > 3 {
            return None;
        }
        *slot = u8::try_from(parse_dec(p)?).ok()?;
    }
    parts.next().is_none().then_some(out)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    impl Sink for Vec<u8> {
        fn put(&mut self, bytes: &[u8]) {
            self.extend_from_slice(bytes);
        }
    }

    fn text(f: impl FnOnce(&mut dyn Sink)) -> std::string::String {
        let mut v = Vec::new();
        f(&mut v);
        std::string::String::from_utf8(v).unwrap()
    }

    #[test]
    fn positions_print_as_millimetres_without_floats() {
        assert_eq!(text(|o| mm(o, 25_500)), "25.500");
        assert_eq!(text(|o| mm(o, -25_500)), "-25.500");
        assert_eq!(text(|o| mm(o, 7)), "0.007");
        assert_eq!(text(|o| mm(o, -40)), "-0.040");
        assert_eq!(text(|o| mm(o, i32::MIN)), "-2147483.648");
        assert_eq!(text(|o| mm(o, i32::MAX)), "2147483.647");
    }

    #[test]
    fn numbers_both_ways() {
        assert_eq!(text(|o| dec(o, 0)), "0");
        assert_eq!(text(|o| dec(o, u64::MAX)), "18446744073709551615");
        assert_eq!(text(|o| signed(o, -12)), "-12");
        assert_eq!(text(|o| hex(o, 0x26D, 3)), "26D");
        assert_eq!(text(|o| ipv4(o, [10, 0, 2, 15])), "10.0.2.15");
        assert_eq!(parse_dec(b"4294967295"), Some(u32::MAX));
        assert_eq!(parse_dec(b"4294967296"), None);
        assert_eq!(parse_dec(b"12a"), None);
        assert_eq!(parse_dec(b""), None);
        assert_eq!(parse_hex(b"bB"), Some(0xBB));
        assert_eq!(parse_hex(b"x1"), None);
        assert_eq!(parse_ipv4(b"192.168.1.20"), Some([192, 168, 1, 20]));
        assert_eq!(parse_ipv4(b"192.168.1"), None);
        assert_eq!(parse_ipv4(b"192.168.1.256"), None);
        assert_eq!(parse_ipv4(b"1.2.3.4.5"), None);
        let mut small = [0u8; 4];
        let mut b = Buf::new(&mut small);
        b.str("123456");
        assert_eq!((b.bytes(), b.lost), (&b"1234"[..], 2));
    }
}
