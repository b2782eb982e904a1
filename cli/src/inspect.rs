//! `iai inspect`: a capture (raw bytes or a text log) as a listing of
//! frames and errors, each at its byte offset.
//!
//! The bytes go through the core's [`FrameDecoder`] (every `@@` accepted,
//! so the listing can say where it was used), then [`decode_any`] and the
//! field visitor. Commands that carry a position stream (244H, 245H, 26DH,
//! 290H, 291H) are diverted to the [`PositionStreamDecoder`] instead, so a
//! 1.6 MB 26DH is summarised without ever being held in memory whole; one
//! that fits the frame decoder's buffer is listed field by field as well.

use std::io::{BufRead, Read, Write};

use iai_protocol_b::catalogue;
use iai_protocol_b::checksum::{BypassPolicy, ChecksumField};
use iai_protocol_b::decoder::{Event, FrameDecoder, DEFAULT_CAPACITY};
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::message::{decode_any, AnyMessage};
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::stream::{PositionStreamDecoder, StreamEvent};

use super::fields::{json_object, record_tree, text_lines, tree, Node};
use super::text::{escape, json_str};

/// Where a byte came from in a text log: line number and direction prefix.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Origin {
    /// 1-based line of a text log (`None` for raw captures).
    pub line: Option<usize>,
    /// `"tx"` for `> ` / `TX ` lines, `"rx"` for `< ` / `RX ` lines.
    pub dir: Option<&'static str>,
}

/// A frame that decoded (envelope and checksum valid).
#[derive(Debug, Clone)]
pub struct FrameItem {
    /// Header kind.
    pub header: Header,
    /// Station code.
    pub station: u8,
    /// Message ID or error code.
    pub code: u16,
    /// The checksum field carried.
    pub checksum: ChecksumField,
    /// The typed message's Rust name and fields, or why it did not decode.
    pub decoded: Result<(String, Vec<Node>), String>,
}

/// A position-stream command, summarised.
#[derive(Debug, Clone)]
pub struct StreamItem {
    /// The stream's kind.
    pub kind: PositionStream,
    /// Station code.
    pub station: u8,
    /// Start number (0 where the message has none).
    pub start: u16,
    /// Records announced.
    pub count: u16,
    /// Records read.
    pub records: u16,
    /// First record read.
    pub first: Option<Vec<Node>>,
    /// Last record read.
    pub last: Option<Vec<Node>>,
    /// The checksum field carried.
    pub checksum: ChecksumField,
}

/// What one entry of the listing is.
#[derive(Debug, Clone)]
pub enum What {
    /// A checked frame.
    Frame(FrameItem),
    /// A position stream too long for the frame decoder.
    Stream(StreamItem),
    /// A broken frame or stray bytes: error kind, message and the first
    /// bytes involved.
    Error {
        /// Error kind (`Noise` for bytes outside any frame).
        kind: String,
        /// Human-readable text.
        message: String,
        /// The first bytes involved (at most 64).
        bytes: Vec<u8>,
    },
}

/// One entry of the listing.
#[derive(Debug, Clone)]
pub struct Item {
    /// Byte offset in the capture (in a text log: in the unescaped bytes).
    pub offset: u64,
    /// Length in bytes.
    pub len: u64,
    /// Where in a text log it started.
    pub origin: Origin,
    /// What it is.
    pub what: What,
}

impl Item {
    /// Whether this entry is an error: a broken frame, noise, or a frame
    /// whose body does not decode as its message.
    pub fn is_error(&self) -> bool {
        match &self.what {
            What::Error { .. } => true,
            What::Frame(f) => f.decoded.is_err(),
            What::Stream(_) => false,
        }
    }
}

const SAMPLE: usize = 64;

struct StreamState {
    dec: PositionStreamDecoder,
    start: u64,
    origin: Origin,
    /// The frame's bytes while they fit the frame decoder's buffer.
    copy: Vec<u8>,
    len: u64,
    tail: [u8; 4],
    item: Option<StreamItem>,
}

/// The incremental inspector: feed bytes, collect items.
pub struct Inspector {
    dec: Box<FrameDecoder<DEFAULT_CAPACITY>>,
    offset: u64,
    origin: Origin,
    frame_start: (u64, Origin),
    cur: Vec<u8>,
    noise: Option<(u64, Origin, Vec<u8>, u64)>,
    env: Vec<u8>,
    env_start: (u64, Origin),
    stream: Option<Box<StreamState>>,
    skip: Option<Item>,
    items: Vec<Item>,
}

impl Default for Inspector {
    fn default() -> Self {
        Self::new()
    }
}

fn error_kind(e: &iai_protocol_b::Error) -> String {
    let d = format!("{e:?}");
    d.split([' ', '{', '(']).next().unwrap_or("").to_string()
}

fn sample(bytes: &[u8]) -> Vec<u8> {
    bytes.iter().take(SAMPLE).copied().collect()
}

impl Inspector {
    /// A fresh inspector at offset 0.
    pub fn new() -> Self {
        Inspector {
            dec: Box::new(FrameDecoder::with_policy(BypassPolicy::Accept)),
            offset: 0,
            origin: Origin::default(),
            frame_start: (0, Origin::default()),
            cur: Vec::new(),
            noise: None,
            env: Vec::new(),
            env_start: (0, Origin::default()),
            stream: None,
            skip: None,
            items: Vec::new(),
        }
    }

    /// Sets the origin of the bytes fed next.
    pub fn set_origin(&mut self, origin: Origin) {
        self.origin = origin;
    }

    /// Entries completed so far (taken out).
    pub fn take_items(&mut self) -> Vec<Item> {
        std::mem::take(&mut self.items)
    }

    /// Feeds bytes.
    pub fn feed(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.byte(b);
            self.offset += 1;
        }
    }

    /// Ends the capture: whatever is still open is reported as cut short.
    pub fn finish(&mut self) {
        self.close("the end of the capture");
    }

    /// Ends a line of a text log, which holds one frame: whatever is
    /// still open is reported as cut short, and the next line starts
    /// afresh (a frame that swallowed the line's end, such as a 200H whose
    /// fixed-width text ran past it, cannot take the next line's frame
    /// with it).
    pub fn end_line(&mut self) {
        self.close("the end of its line");
    }

    fn close(&mut self, by: &str) {
        if let Some(st) = self.stream.take() {
            let records = st.item.as_ref().map_or(0, |i| i.records);
            self.items.push(Item {
                offset: st.start,
                len: st.len,
                origin: st.origin,
                what: What::Error {
                    kind: "Truncated".into(),
                    message: format!(
                        "position stream cut short by {by} after {} bytes ({records} records read)",
                        st.len
                    ),
                    bytes: sample(&st.copy),
                },
            });
        }
        if let Some(item) = self.skip.take() {
            self.items.push(item);
        }
        let env = std::mem::take(&mut self.env);
        let at = self.env_start.0;
        for (i, b) in env.into_iter().enumerate() {
            self.feed_dec(b, at + i as u64);
        }
        let pending = self.dec.pending();
        if pending > 0 {
            self.items.push(Item {
                offset: self.frame_start.0,
                len: pending as u64,
                origin: self.frame_start.1,
                what: What::Error {
                    kind: "Truncated".into(),
                    message: format!("frame cut short by {by} after {pending} bytes"),
                    bytes: sample(&self.cur),
                },
            });
            self.dec.reset();
        }
        self.flush_noise();
    }

    fn byte(&mut self, b: u8) {
        let off = self.offset;
        let is_header = Header::from_byte(b).is_some();
        if self.stream.is_some() {
            self.stream_byte(b, is_header);
            return;
        }
        if let Some(item) = self.skip.as_mut() {
            if !is_header {
                // The rest of the broken frame, through its LF.
                item.len += 1;
                if b == b'\n' {
                    let item = self.skip.take();
                    self.items.extend(item);
                }
                return;
            }
            let item = self.skip.take();
            self.items.extend(item);
        }
        if !self.env.is_empty() {
            if is_header {
                self.flush_env();
                self.start_or_feed(b, off);
                return;
            }
            self.env.push(b);
            if self.env.len() == 6 {
                self.check_env();
            }
            return;
        }
        self.start_or_feed(b, off);
    }

    fn start_or_feed(&mut self, b: u8, off: u64) {
        if b == b'!' && self.dec.pending() == 0 {
            self.flush_noise();
            self.env.push(b);
            self.env_start = (off, self.origin);
        } else {
            self.feed_dec(b, off);
        }
    }

    fn flush_env(&mut self) {
        let env = std::mem::take(&mut self.env);
        let at = self.env_start.0;
        let origin = self.origin;
        self.origin = self.env_start.1;
        for (i, b) in env.into_iter().enumerate() {
            self.feed_dec(b, at + i as u64);
        }
        self.origin = origin;
    }

    /// Six bytes of a command are known: divert a position stream.
    fn check_env(&mut self) {
        let id = std::str::from_utf8(self.env.get(3..6).unwrap_or(&[]))
            .ok()
            .and_then(|s| u16::from_str_radix(s, 16).ok());
        let Some(_kind) = id.and_then(|id| PositionStream::find(Header::Command, id)) else {
            self.flush_env();
            return;
        };
        let env = std::mem::take(&mut self.env);
        let mut st = Box::new(StreamState {
            dec: PositionStreamDecoder::new(BypassPolicy::Accept),
            start: self.env_start.0,
            origin: self.env_start.1,
            copy: Vec::new(),
            len: 0,
            tail: [0; 4],
            item: None,
        });
        for b in env {
            st.push_copy(b);
            if let StreamEvent::Error { .. } = st.dec.decode(&[b]).event {
                // An envelope the stream decoder refuses: let the frame
                // decoder report it.
                self.env = std::mem::take(&mut st.copy);
                self.flush_env();
                return;
            }
        }
        self.stream = Some(st);
    }

    fn stream_byte(&mut self, b: u8, is_header: bool) {
        let Some(mut st) = self.stream.take() else {
            return;
        };
        let r = st.dec.decode(&[b]);
        let (used, ev) = (r.consumed, r.event);
        if used > 0 {
            st.push_copy(b);
        }
        match ev {
            StreamEvent::NeedMore => self.stream = Some(st),
            StreamEvent::Start {
                kind,
                station,
                start,
                count,
            } => {
                st.item = Some(StreamItem {
                    kind,
                    station: station.0,
                    start,
                    count,
                    records: 0,
                    first: None,
                    last: None,
                    checksum: ChecksumField::Bypass,
                });
                self.stream = Some(st);
            }
            StreamEvent::Record(rec) => {
                if let Some(item) = st.item.as_mut() {
                    let t = record_tree(item.kind.layout, &rec);
                    if item.first.is_none() {
                        item.first = Some(t);
                    } else {
                        item.last = Some(t);
                    }
                    item.records += 1;
                }
                self.stream = Some(st);
            }
            StreamEvent::End { .. } => self.end_stream(*st),
            StreamEvent::Error { error, records_ok } => {
                let consumed_header = used > 0 && is_header;
                let len = if consumed_header { st.len - 1 } else { st.len };
                let item = Item {
                    offset: st.start,
                    len,
                    origin: st.origin,
                    what: What::Error {
                        kind: error_kind(&error),
                        message: format!(
                            "position stream {:03X}H broken at frame offset {}: {error} ({records_ok} records read)",
                            st.item.as_ref().map_or(0, |i| i.kind.id),
                            st.dec.offset()
                        ),
                        bytes: sample(&st.copy),
                    },
                };
                if used == 0 || consumed_header {
                    // The byte belongs to what follows.
                    self.items.push(item);
                    self.byte(b);
                } else {
                    self.skip = Some(item);
                }
            }
        }
    }

    fn end_stream(&mut self, st: StreamState) {
        let sc = &st.tail[..2];
        let checksum = if sc == b"@@" {
            ChecksumField::Bypass
        } else {
            let v = std::str::from_utf8(sc)
                .ok()
                .and_then(|s| u8::from_str_radix(s, 16).ok());
            ChecksumField::Sum(v.unwrap_or(0))
        };
        // Small enough for the frame decoder: list it field by field.
        if st.copy.len() as u64 == st.len && st.copy.len() <= DEFAULT_CAPACITY {
            if let Ok(frame) = Frame::new_checked(&st.copy, BypassPolicy::Accept) {
                self.items.push(Item {
                    offset: st.start,
                    len: st.len,
                    origin: st.origin,
                    what: What::Frame(frame_item(&frame)),
                });
                return;
            }
        }
        let Some(mut item) = st.item else { return };
        item.checksum = checksum;
        self.items.push(Item {
            offset: st.start,
            len: st.len,
            origin: st.origin,
            what: What::Stream(item),
        });
    }

    fn noise_byte(&mut self, b: u8, off: u64) {
        match self.noise.as_mut() {
            Some((_, _, bytes, len)) => {
                if bytes.len() < SAMPLE {
                    bytes.push(b);
                }
                *len += 1;
            }
            None => self.noise = Some((off, self.origin, vec![b], 1)),
        }
    }

    fn flush_noise(&mut self) {
        if let Some((offset, origin, bytes, len)) = self.noise.take() {
            self.items.push(Item {
                offset,
                len,
                origin,
                what: What::Error {
                    kind: "Noise".into(),
                    message: format!("{len} byte(s) outside any frame"),
                    bytes,
                },
            });
        }
    }

    fn feed_dec(&mut self, b: u8, off: u64) {
        let before = self.dec.pending();
        let origin = self.origin;
        let (item, started) = match self.dec.push(b) {
            Event::NeedMore => {
                if before == 0 && self.dec.pending() == 0 {
                    self.noise_byte(b, off);
                    return;
                }
                (None, before == 0)
            }
            Event::Frame(f) => {
                let item = Item {
                    offset: self.frame_start.0,
                    len: f.len() as u64,
                    origin: self.frame_start.1,
                    what: What::Frame(frame_item(&f)),
                };
                (Some(item), false)
            }
            Event::Error(e) => {
                let start = if before > 0 { self.frame_start.0 } else { off };
                let new_frame = self.dec.pending() == 1;
                let end = if new_frame { off } else { off + 1 };
                let mut bytes = self.cur.clone();
                if !new_frame {
                    bytes.push(b);
                }
                let item = Item {
                    offset: start,
                    len: end - start,
                    origin: self.frame_start.1,
                    what: What::Error {
                        kind: error_kind(&e),
                        message: e.to_string(),
                        bytes: sample(&bytes),
                    },
                };
                if matches!(e, iai_protocol_b::Error::FrameTooLong { .. }) && b != b'\n' {
                    // The frame goes on past the decoder's buffer: the
                    // bytes up to its LF (or the next header) belong to
                    // this one error, not to noise.
                    self.flush_noise();
                    self.skip = Some(item);
                    self.cur.clear();
                    return;
                }
                (Some(item), new_frame)
            }
        };
        if item.is_some() || started {
            self.flush_noise();
        }
        self.items.extend(item);
        if started {
            self.frame_start = (off, origin);
            self.cur.clear();
            if b == b'!' && before > 0 {
                // Cut off by a new command: it may be a position stream.
                self.dec.reset();
                self.start_or_feed(b, off);
                return;
            }
        }
        if self.dec.pending() > 0 && self.cur.len() < SAMPLE {
            self.cur.push(b);
        }
    }
}

impl StreamState {
    fn push_copy(&mut self, b: u8) {
        self.len += 1;
        self.tail = [self.tail[1], self.tail[2], self.tail[3], b];
        if self.copy.len() <= DEFAULT_CAPACITY {
            self.copy.push(b);
        }
    }
}

/// The listing entry of a checked frame.
pub fn frame_item(f: &Frame<'_>) -> FrameItem {
    let decoded = decode_any(f).map_err(|e| e.to_string()).map(|d| {
        let name = match &d.message {
            AnyMessage::Command(c) => variant_name(&format!("{c:?}")),
            AnyMessage::Response(r) => variant_name(&format!("{r:?}")),
            AnyMessage::Error(_) => "ErrorResponse".to_string(),
        };
        (name, tree(&d.message))
    });
    FrameItem {
        header: f.header(),
        station: f.station().0,
        code: f.code(),
        checksum: f.checksum(),
        decoded,
    }
}

fn variant_name(debug: &str) -> String {
    debug
        .split(['(', ' ', '{'])
        .next()
        .unwrap_or("")
        .to_string()
}

fn kind_name(h: Header) -> &'static str {
    match h {
        Header::Command => "command",
        Header::Response => "response",
        Header::Error => "error",
    }
}

fn checksum_text(c: ChecksumField) -> (&'static str, String) {
    match c {
        ChecksumField::Sum(v) => ("ok", format!("{v:02X}")),
        ChecksumField::Bypass => ("bypass", "@@".into()),
    }
}

/// One entry as a JSON object on one line.
pub fn json_line(item: &Item) -> String {
    let mut parts = vec![
        format!("\"offset\":{}", item.offset),
        format!("\"len\":{}", item.len),
    ];
    if let Some(line) = item.origin.line {
        parts.push(format!("\"line\":{line}"));
    }
    if let Some(dir) = item.origin.dir {
        parts.push(format!("\"dir\":{}", json_str(dir)));
    }
    let head = match &item.what {
        What::Frame(f) => {
            let (status, sc) = checksum_text(f.checksum);
            let mut p = vec![
                "\"type\":\"frame\"".to_string(),
                format!("\"kind\":\"{}\"", kind_name(f.header)),
                format!("\"station\":\"{:02X}\"", f.station),
            ];
            if f.header == Header::Error {
                p.push(format!("\"code\":\"{:03X}\"", f.code));
            } else {
                p.push(format!("\"id\":\"{:03X}\"", f.code));
                if let Some(n) = catalogue::lookup(f.code).map(|m| m.name) {
                    p.push(format!("\"name\":{}", json_str(n)));
                }
            }
            p.push(format!("\"checksum\":\"{status}\",\"sc\":\"{sc}\""));
            match &f.decoded {
                Ok((ty, fields)) => {
                    p.push(format!("\"message\":{}", json_str(ty)));
                    p.push(format!("\"fields\":{}", json_object(fields)));
                }
                Err(e) => p.push(format!("\"decode_error\":{}", json_str(e))),
            }
            p
        }
        What::Stream(s) => {
            let (status, sc) = checksum_text(s.checksum);
            let mut p = vec![
                "\"type\":\"stream\"".to_string(),
                "\"kind\":\"command\"".to_string(),
                format!("\"station\":\"{:02X}\"", s.station),
                format!("\"id\":\"{:03X}\"", s.kind.id),
            ];
            if let Some(n) = catalogue::lookup(s.kind.id).map(|m| m.name) {
                p.push(format!("\"name\":{}", json_str(n)));
            }
            p.push(format!("\"checksum\":\"{status}\",\"sc\":\"{sc}\""));
            p.push(format!(
                "\"start\":{},\"count\":{},\"records\":{}",
                s.start, s.count, s.records
            ));
            if let Some(first) = &s.first {
                p.push(format!("\"first\":{}", json_object(first)));
            }
            if let Some(last) = &s.last {
                p.push(format!("\"last\":{}", json_object(last)));
            }
            p
        }
        What::Error {
            kind,
            message,
            bytes,
        } => vec![
            "\"type\":\"error\"".to_string(),
            format!("\"error\":{}", json_str(kind)),
            format!("\"message\":{}", json_str(message)),
            format!("\"bytes\":{}", json_str(&escape(bytes))),
        ],
    };
    let mut all = head;
    all.extend(parts);
    format!("{{{}}}", all.join(","))
}

/// One entry as listing lines.
pub fn text_entry(item: &Item) -> Vec<String> {
    let mut at = format!("{:08}", item.offset);
    if let Some(line) = item.origin.line {
        at.push_str(&format!(" L{line}"));
    }
    if let Some(dir) = item.origin.dir {
        at.push_str(&format!(" {dir}"));
    }
    let mut out = Vec::new();
    match &item.what {
        What::Frame(f) => {
            let (status, sc) = checksum_text(f.checksum);
            let what = if f.header == Header::Error {
                format!("error code {:03X}", f.code)
            } else {
                format!(
                    "{:03X}H {}",
                    f.code,
                    catalogue::lookup(f.code)
                        .map(|m| m.name)
                        .unwrap_or("(unknown message)")
                )
            };
            out.push(format!(
                "{at}  {:<8} st {:02X}  {what}  [{} bytes, SC {sc} {status}]",
                kind_name(f.header),
                f.station,
                item.len
            ));
            match &f.decoded {
                Ok((_, fields)) => text_lines(fields, "", "    ", &mut out),
                Err(e) => out.push(format!("    (not decoded: {e})")),
            }
        }
        What::Stream(s) => {
            let (status, sc) = checksum_text(s.checksum);
            out.push(format!(
                "{at}  {:<8} st {:02X}  {:03X}H {}  [{} bytes, SC {sc} {status}]",
                "command",
                s.station,
                s.kind.id,
                catalogue::lookup(s.kind.id).map(|m| m.name).unwrap_or(""),
                item.len
            ));
            out.push(format!(
                "    position stream: start {}, {} records announced, {} read",
                s.start, s.count, s.records
            ));
            for (label, rec) in [("first", &s.first), ("last", &s.last)] {
                if let Some(rec) = rec {
                    out.push(format!("    {label} record:"));
                    text_lines(rec, "", "      ", &mut out);
                }
            }
        }
        What::Error {
            kind,
            message,
            bytes,
        } => {
            out.push(format!(
                "{at}  ERROR    {kind}: {message}  [{} bytes] \"{}\"",
                item.len,
                escape(bytes)
            ));
        }
    }
    out
}

/// Input format of a capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Bytes as on the wire.
    Raw,
    /// One frame per line, escaped, optional direction prefix.
    Text,
}

/// Splits a text-log line into its direction and frame text.
pub fn split_prefix(line: &[u8]) -> (Option<&'static str>, &[u8]) {
    for (p, dir) in [
        (&b"> "[..], "tx"),
        (b"< ", "rx"),
        (b"TX ", "tx"),
        (b"RX ", "rx"),
        (b"TX: ", "tx"),
        (b"RX: ", "rx"),
    ] {
        if let Some(rest) = line.strip_prefix(p) {
            return (Some(dir), rest);
        }
    }
    (None, line)
}

/// Why inspecting stopped: the input could not be read, or the output
/// could not be written (a closed pipe, for one).
#[derive(Debug)]
pub enum InspectError {
    /// Reading the capture failed.
    Read(std::io::Error),
    /// Writing the listing failed.
    Write(std::io::Error),
}

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
struct TextLog {
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

    fn feed(&mut self, chunk: &[u8], ins: &mut Inspector) {
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

    fn finish(&mut self, ins: &mut Inspector) {
        if self.line > 0 {
            self.end_line(ins);
        }
    }
}

/// Inspects a whole capture, calling `emit` for each entry as it is found.
/// Returns (frames, errors). Memory stays the same whatever the size of
/// the capture or of its lines.
pub fn run(
    mut input: impl BufRead,
    format: Format,
    mut emit: impl FnMut(&Item) -> std::io::Result<()>,
) -> Result<(u64, u64), InspectError> {
    let mut ins = Inspector::new();
    let mut counts = (0u64, 0u64);
    let mut drain = |ins: &mut Inspector, counts: &mut (u64, u64)| -> Result<(), InspectError> {
        for item in ins.take_items() {
            if item.is_error() {
                counts.1 += 1;
            } else {
                counts.0 += 1;
            }
            emit(&item).map_err(InspectError::Write)?;
        }
        Ok(())
    };
    let mut text = TextLog::default();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = match input.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(InspectError::Read(e)),
        };
        if n == 0 {
            break;
        }
        let chunk = buf.get(..n).unwrap_or(&[]);
        match format {
            Format::Raw => ins.feed(chunk),
            Format::Text => text.feed(chunk, &mut ins),
        }
        drain(&mut ins, &mut counts)?;
    }
    text.finish(&mut ins);
    ins.finish();
    drain(&mut ins, &mut counts)?;
    Ok(counts)
}

/// Guesses the format from the first bytes: escaped `\r` or a direction
/// prefix means a text log; otherwise a CR byte means raw bytes; a file
/// without either is read as a text log (one frame per line).
pub fn guess_format(head: &[u8]) -> Format {
    let escaped = head.windows(2).any(|w| w == b"\\r");
    let prefixed = head
        .split(|b| *b == b'\n')
        .any(|l| split_prefix(l.trim_ascii_start()).0.is_some());
    if escaped || prefixed || !head.contains(&b'\r') {
        Format::Text
    } else {
        Format::Raw
    }
}

/// `iai inspect` with parsed options; returns the process exit code
/// (0, or 1 when the capture had errors).
pub fn command(
    path: &str,
    format: Option<Format>,
    json: bool,
    out: &mut impl Write,
) -> Result<i32, InspectError> {
    let reader: Box<dyn Read> = if path == "-" {
        Box::new(std::io::stdin().lock())
    } else {
        Box::new(std::fs::File::open(path).map_err(InspectError::Read)?)
    };
    let mut reader = std::io::BufReader::with_capacity(1 << 16, reader);
    let format = match format {
        Some(f) => f,
        None => guess_format(reader.fill_buf().map_err(InspectError::Read)?),
    };
    let (frames, errors) = run(reader, format, |item| {
        if json {
            writeln!(out, "{}", json_line(item))
        } else {
            for l in text_entry(item) {
                writeln!(out, "{l}")?;
            }
            Ok(())
        }
    })?;
    if !json {
        writeln!(out, "-- {frames} frame(s), {errors} error(s)").map_err(InspectError::Write)?;
    }
    out.flush().map_err(InspectError::Write)?;
    Ok(if errors > 0 { 1 } else { 0 })
}
