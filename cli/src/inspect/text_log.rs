//! Text logs: one frame per line, an optional direction prefix (`> `,
//! `< `, `TX `, `RX `, `TX: `, `RX: `), surrounding blanks, and the escapes
//! of [`crate::text::unescape`]. The unescaped bytes go to an
//! [`Inspector`], each line closed on its own.

use super::inspector::Inspector;
use super::item::Origin;

/// Splits a text-log line into its direction and frame text.
pub fn split_prefix(line: &[u8]) -> (Option<&'static str>, &[u8]) {
    for (p, dir) in PREFIXES {
        if let Some(rest) = line.strip_prefix(p) {
            return (Some(dir), rest);
        }
    }
    (None, line)
}

/// The direction prefixes of a text-log line, with the direction each gives.
const PREFIXES: [(&[u8], &str); 6] = [
    (b"> ", "tx"),
    (b"< ", "rx"),
    (b"TX ", "tx"),
    (b"RX ", "rx"),
    (b"TX: ", "tx"),
    (b"RX: ", "rx"),
];

/// A text log read as a stream: one frame per line, optional direction
/// prefix and surrounding blanks, escapes as in [`crate::text::unescape`]. Nothing but
/// a few bytes of the current line is held, whatever the line's length.
#[derive(Default)]
pub(super) struct TextLog {
    line: usize,
    /// Still reading the line's leading blanks and direction prefix.
    head: Option<Vec<u8>>,
    /// Blanks seen but not yet known to be inside the line.
    blanks: Vec<u8>,
    /// An escape sequence in progress.
    esc: Vec<u8>,
    /// Last two unescaped bytes of this line, and whether there were any.
    last: [u8; 2],
    any: bool,
    out: Vec<u8>,
}

impl TextLog {
    fn emit(&mut self, b: u8) {
        self.out.push(b);
        self.last = [self.last[1], b];
        self.any = true;
    }

    fn unescaped(&mut self, c: u8) {
        match self.esc.len() {
            0 if c == b'\\' => self.esc.push(c),
            0 => self.emit(c),
            1 => {
                self.esc.clear();
                match c {
                    b'r' => self.emit(b'\r'),
                    b'n' => self.emit(b'\n'),
                    b't' => self.emit(b'\t'),
                    b'\\' => self.emit(b'\\'),
                    b'x' => self.esc.extend_from_slice(b"\\x"),
                    other => {
                        self.emit(b'\\');
                        self.emit(other);
                    }
                }
            }
            2 => self.esc.push(c),
            _ => {
                self.esc.push(c);
                let hex = std::str::from_utf8(self.esc.get(2..4).unwrap_or(&[]))
                    .ok()
                    .and_then(|h| u8::from_str_radix(h, 16).ok());
                let esc = std::mem::take(&mut self.esc);
                match hex {
                    Some(v) => self.emit(v),
                    None => self.literal(&esc),
                }
            }
        }
    }

    /// An escape that is not one: `\x` as written, the rest read again.
    fn literal(&mut self, esc: &[u8]) {
        self.emit(b'\\');
        self.emit(b'x');
        for &c in esc.get(2..).unwrap_or(&[]) {
            self.unescaped(c);
        }
    }

    fn content(&mut self, c: u8) {
        if matches!(c, b' ' | b'\t' | b'\r') {
            self.blanks.push(c);
            return;
        }
        for b in std::mem::take(&mut self.blanks) {
            self.unescaped(b);
        }
        self.unescaped(c);
    }

    fn start_content(&mut self, ins: &mut Inspector, dir: Option<&'static str>, replay: &[u8]) {
        self.flush(ins);
        ins.set_origin(Origin {
            line: Some(self.line),
            dir,
        });
        for &c in replay {
            self.content(c);
        }
    }

    fn flush(&mut self, ins: &mut Inspector) {
        if !self.out.is_empty() {
            ins.feed(&self.out);
            self.out.clear();
        }
    }

    fn end_line(&mut self, ins: &mut Inspector) {
        if let Some(head) = self.head.take() {
            if !head.is_empty() {
                self.start_content(ins, None, &head);
            }
        }
        self.blanks.clear();
        let esc = std::mem::take(&mut self.esc);
        match esc.len() {
            0 => {}
            1 => self.emit(b'\\'),
            _ => self.literal(&esc),
        }
        if self.any && self.last != *b"\r\n" {
            self.emit(b'\r');
            self.emit(b'\n');
        }
        self.flush(ins);
        if self.any {
            ins.end_line();
        }
        self.any = false;
        self.last = [0; 2];
    }

    pub(super) fn feed(&mut self, chunk: &[u8], ins: &mut Inspector) {
        for &c in chunk {
            if self.line == 0 {
                self.line = 1;
                self.head = Some(Vec::new());
            }
            if c == b'\n' {
                self.end_line(ins);
                self.line += 1;
                self.head = Some(Vec::new());
                continue;
            }
            let Some(head) = self.head.as_mut() else {
                self.content(c);
                continue;
            };
            if head.is_empty() && matches!(c, b' ' | b'\t' | b'\r') {
                continue;
            }
            head.push(c);
            if let Some((_, dir)) = PREFIXES.iter().find(|(p, _)| *p == head.as_slice()) {
                self.head = None;
                self.start_content(ins, Some(dir), &[]);
            } else if !PREFIXES.iter().any(|(p, _)| p.starts_with(head)) {
                let replay = std::mem::take(head);
                self.head = None;
                self.start_content(ins, None, &replay);
            }
        }
        self.flush(ins);
    }

    pub(super) fn finish(&mut self, ins: &mut Inspector) {
        if self.line > 0 {
            self.end_line(ins);
        }
    }
}
