//! Escaping of frame bytes as ASCII (the fixture-file convention: `\r`,
//! `\n`, `\\`, `\xNN`), JSON strings, and number parsing for arguments.

/// Bytes as escaped ASCII: printable characters as themselves, CR and LF
/// as `\r` and `\n`, a backslash doubled, anything else as `\xNN`.
pub fn escape(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() + 4);
    for &b in bytes {
        match b {
            b'\r' => s.push_str("\\r"),
            b'\n' => s.push_str("\\n"),
            b'\\' => s.push_str("\\\\"),
            0x20..=0x7E => s.push(char::from(b)),
            _ => s.push_str(&format!("\\x{b:02X}")),
        }
    }
    s
}

/// The inverse of [`escape`]; also accepts `\t`. An escape it does not
/// know stays as written.
pub fn unescape(text: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(text.len());
    let mut i = 0;
    while let Some(&b) = text.get(i) {
        if b != b'\\' {
            out.push(b);
            i += 1;
            continue;
        }
        match text.get(i + 1) {
            Some(b'r') => out.push(b'\r'),
            Some(b'n') => out.push(b'\n'),
            Some(b't') => out.push(b'\t'),
            Some(b'\\') => out.push(b'\\'),
            Some(b'x') => {
                let hex = text
                    .get(i + 2..i + 4)
                    .and_then(|h| std::str::from_utf8(h).ok())
                    .and_then(|h| u8::from_str_radix(h, 16).ok());
                if let Some(v) = hex {
                    out.push(v);
                    i += 4;
                    continue;
                }
                out.extend_from_slice(b"\\x");
            }
            Some(&other) => {
                out.push(b'\\');
                out.push(other);
            }
            None => out.push(b'\\'),
        }
        i += 2;
    }
    out
}

/// A JSON string literal.
pub fn json_str(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if u32::from(c) < 0x20 => out.push_str(&format!("\\u{:04x}", u32::from(c))),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// A decimal or `0x` hex integer, optionally negative: one optional `-`,
/// then digits only (no `+`, no second sign, no `_`, no spaces).
pub fn parse_int(s: &str) -> Option<i128> {
    let (neg, body) = match s.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, s),
    };
    let (radix, digits) = match body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        Some(hex) => (16, hex),
        None => (10, body),
    };
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    let v = i128::from_str_radix(digits, radix).ok()?;
    Some(if neg { -v } else { v })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escape_round_trips() {
        let raw = b"!99\\212\x01\r\n";
        assert_eq!(escape(raw), "!99\\\\212\\x01\\r\\n");
        assert_eq!(unescape(escape(raw).as_bytes()), raw);
    }

    #[test]
    fn integers() {
        assert_eq!(parse_int("0x1F"), Some(31));
        assert_eq!(parse_int("-25500"), Some(-25500));
        assert_eq!(parse_int("x"), None);
        for bad in [
            "--5000", "1__0", "1_0", "+5", "", "-", "0x", "5 ", "1e3", "0x-1",
        ] {
            assert_eq!(parse_int(bad), None, "{bad:?}");
        }
    }
}
