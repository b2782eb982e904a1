//! A form's body (`application/x-www-form-urlencoded`) byte by byte, as it
//! arrives: `key=value` pairs between `&`, `+` for a space, `%XX` for a
//! byte. Keys and values are kept decoded in bounded buffers; one longer
//! is an error, not a cut value.

use heapless::Vec;

/// Bytes of a key at most.
pub const KEY_MAX: usize = 32;
/// Bytes of a value at most (decoded): the longest setting's text.
pub const VALUE_MAX: usize = 256;

/// Why a body is not a form this gateway takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FormError {
    /// A key longer than [`KEY_MAX`].
    KeyTooLong,
    /// A value longer than [`VALUE_MAX`].
    ValueTooLong,
    /// `%` not followed by two hex digits.
    BadEscape,
}

impl FormError {
    /// What it means, in a few words.
    pub const fn reason(self) -> &'static str {
        match self {
            FormError::KeyTooLong => "a field name is too long",
            FormError::ValueTooLong => "a field's value is too long (256 characters at most)",
            FormError::BadEscape => "a % not followed by two hex digits",
        }
    }
}

/// What [`FormParser::push`] and [`FormParser::end`] hand out: at the end
/// of a pair, the pair `(key, value)` or why it is not one.
pub type Pair<'a> = Option<Result<(&'a [u8], &'a [u8]), FormError>>;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Escape {
    None,
    First,
    Second(u8),
}

/// The pair being read.
#[derive(Debug, Clone)]
pub struct FormParser {
    key: Vec<u8, KEY_MAX>,
    value: Vec<u8, VALUE_MAX>,
    in_value: bool,
    escape: Escape,
    error: Option<FormError>,
    /// The pair in the buffers was handed out: cleared at the next byte.
    handed: bool,
}

impl Default for FormParser {
    fn default() -> Self {
        Self::new()
    }
}

impl FormParser {
    /// Nothing read yet.
    pub const fn new() -> Self {
        FormParser {
            key: Vec::new(),
            value: Vec::new(),
            in_value: false,
            escape: Escape::None,
            error: None,
            handed: false,
        }
    }

    /// Back to nothing read.
    pub fn clear(&mut self) {
        self.key.clear();
        self.value.clear();
        self.in_value = false;
        self.escape = Escape::None;
        self.error = None;
        self.handed = false;
    }

    fn clear_handed(&mut self) {
        if self.handed {
            self.key.clear();
            self.value.clear();
            self.handed = false;
        }
    }

    /// Takes `byte`; at the `&` that ends a pair, the pair (or why it is
    /// not one).
    pub fn push(&mut self, byte: u8) -> Pair<'_> {
        self.clear_handed();
        if byte == b'&' {
            return self.end();
        }
        let decoded = match (self.escape, byte) {
            (Escape::None, b'%') => {
                self.escape = Escape::First;
                return None;
            }
            (Escape::None, b'+') => b' ',
            (Escape::None, b'=') if !self.in_value => {
                self.in_value = true;
                return None;
            }
            (Escape::None, b) => b,
            (Escape::First, b) => {
                match hex_digit(b) {
                    Some(h) => self.escape = Escape::Second(h),
                    None => self.fail(FormError::BadEscape),
                }
                return None;
            }
            (Escape::Second(h), b) => {
                self.escape = Escape::None;
                match hex_digit(b) {
                    Some(l) => h << 4 | l,
                    None => {
                        self.fail(FormError::BadEscape);
                        return None;
                    }
                }
            }
        };
        let full = if self.in_value {
            self.value.push(decoded).is_err()
        } else {
            self.key.push(decoded).is_err()
        };
        if full {
            self.fail(if self.in_value {
                FormError::ValueTooLong
            } else {
                FormError::KeyTooLong
            });
        }
        None
    }

    /// The body ended: its last pair, if any.
    pub fn end(&mut self) -> Pair<'_> {
        self.clear_handed();
        let error = self.error.take().or(match self.escape {
            Escape::None => None,
            _ => Some(FormError::BadEscape),
        });
        let was_empty = self.key.is_empty() && !self.in_value;
        self.in_value = false;
        self.escape = Escape::None;
        if let Some(e) = error {
            self.key.clear();
            self.value.clear();
            return Some(Err(e));
        }
        if was_empty {
            self.value.clear();
            return None;
        }
        // The caller reads the pair before the next byte comes; it is
        // cleared then.
        self.handed = true;
        Some(Ok((&self.key, &self.value)))
    }

    fn fail(&mut self, e: FormError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
    }
}

fn hex_digit(b: u8) -> Option<u8> {
    (b as char).to_digit(16).map(|d| d as u8)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::String;
    use std::vec::Vec as StdVec;

    fn pairs(body: &[u8]) -> StdVec<Result<(String, String), FormError>> {
        let mut p = FormParser::new();
        let mut out = StdVec::new();
        let mut take = |r: Pair<'_>| {
            if let Some(r) = r {
                out.push(r.map(|(k, v)| {
                    (
                        String::from_utf8_lossy(k).into_owned(),
                        String::from_utf8_lossy(v).into_owned(),
                    )
                }));
            }
        };
        for &b in body {
            take(p.push(b));
        }
        take(p.end());
        out
    }

    #[test]
    fn a_browser_s_form_body_decodes_pair_by_pair() {
        let got = pairs(b"modbus.unit=5&bridge.allow=212%2C215-217&password=a+b%26c%3D&empty=");
        assert_eq!(
            got,
            [
                Ok(("modbus.unit".into(), "5".into())),
                Ok(("bridge.allow".into(), "212,215-217".into())),
                Ok(("password".into(), "a b&c=".into())),
                Ok(("empty".into(), "".into())),
            ]
        );
        assert_eq!(pairs(b""), []);
        assert_eq!(
            pairs(b"a=1&&b=2"),
            [Ok(("a".into(), "1".into())), Ok(("b".into(), "2".into()))]
        );
    }

    #[test]
    fn what_does_not_fit_is_an_error_not_a_cut_value() {
        assert_eq!(pairs(b"a=%G1"), [Err(FormError::BadEscape)]);
        assert_eq!(pairs(b"a=%4"), [Err(FormError::BadEscape)]);
        let mut long = StdVec::from(&b"k="[..]);
        long.extend(core::iter::repeat_n(b'x', VALUE_MAX + 1));
        long.extend_from_slice(b"&b=2");
        assert_eq!(
            pairs(&long),
            [Err(FormError::ValueTooLong), Ok(("b".into(), "2".into()))]
        );
        let key = [b'k'; KEY_MAX + 1];
        assert_eq!(pairs(&key), [Err(FormError::KeyTooLong)]);
    }
}
