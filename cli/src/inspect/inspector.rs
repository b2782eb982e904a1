//! The incremental inspector: bytes in, listing entries out.
//!
//! The bytes go through the core's [`FrameDecoder`] (every `@@` accepted,
//! so the listing can say where it was used), then
//! [`decode_any`](iai_protocol_b::message::decode_any) and the field
//! visitor. Commands that carry a position stream (244H, 245H, 26DH,
//! 290H, 291H) are diverted to the [`PositionStreamDecoder`] instead, so a
//! 1.6 MB 26DH is summarised without ever being held in memory whole; one
//! that fits the frame decoder's buffer is listed field by field as well.
//!
//! After a failed 200H or 216H the frame decoder decodes that frame's
//! bytes again from its first header byte (its text may hide whole
//! frames): each byte is given with `decode` and everything it produces is
//! taken until it answers `Partial`, and [`Held`] places each frame and
//! error at its offset. Where the capture (or a text log's line) ends
//! inside a frame, that frame is listed as cut short and its bytes are
//! decoded again the same way, so the frames its text swallowed are
//! listed too.

use iai_protocol_b::checksum::{BypassPolicy, ChecksumField};
use iai_protocol_b::decoder::{Event, FrameDecoder, Status, DEFAULT_CAPACITY};
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::{PositionStreamDecoder, StreamEvent};

use super::held::Held;
use super::item::{frame_item, Item, Origin, StreamItem, What};
use crate::fields::record_tree;

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
    /// The bytes given to the frame decoder and not listed yet (it holds
    /// the last `pending()` of them).
    held: Held,
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

fn error_kind(e: &iai_protocol_b::error::Error) -> String {
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
            held: Held::default(),
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
            self.byte(b, self.offset);
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
        loop {
            if let Some(st) = self.stream.take() {
                let records = st.item.as_ref().map_or(0, |i| i.records);
                self.push_item(Item {
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
                self.push_item(item);
            }
            self.flush_env();
            if !self.cut_held_frame(by) {
                break;
            }
        }
        self.flush_noise();
    }

    /// The frame decoder holds the start of a frame that `by` cut short:
    /// lists it as cut short, up to its first header byte after its start,
    /// and decodes the bytes from there again, as the decoder does itself
    /// with a 200H or 216H that fails (text can hide whole frames; a frame
    /// without text holds no header byte after its start). `false` if the
    /// decoder held nothing.
    fn cut_held_frame(&mut self, by: &str) -> bool {
        let pending = self.dec.pending() as u64;
        if pending == 0 {
            return false;
        }
        let start = self.held.end().saturating_sub(pending);
        self.noise_to(start);
        let again = self.held.first_header(start + 1);
        let end = again.unwrap_or(self.held.end());
        let mut message = format!("frame cut short by {by} after {pending} bytes");
        if let Some(at) = again {
            message.push_str(&format!(", decoded again from offset {at}"));
        }
        let item = Item {
            offset: start,
            len: end - start,
            origin: self.held.origin_at(start),
            what: What::Error {
                kind: "Truncated".into(),
                message,
                bytes: self.held.sample(start, end, SAMPLE),
            },
        };
        self.push_item(item);
        self.dec.reset();
        self.held.drop_to(end);
        let origin = self.origin;
        let mut rest = std::mem::take(&mut self.held);
        while let Some((b, off, from)) = rest.pop() {
            self.origin = from;
            self.byte(b, off);
        }
        self.origin = origin;
        true
    }

    fn byte(&mut self, b: u8, off: u64) {
        let is_header = Header::from_byte(b).is_some();
        if self.stream.is_some() {
            self.stream_byte(b, off, is_header);
            return;
        }
        if let Some(item) = self.skip.as_mut() {
            if !is_header {
                // The rest of the broken frame, through its LF.
                item.len += 1;
                if b == b'\n' {
                    if let Some(item) = self.skip.take() {
                        self.push_item(item);
                    }
                }
                return;
            }
            if let Some(item) = self.skip.take() {
                self.push_item(item);
            }
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
            if let Status::Complete(StreamEvent::Error { .. }) = st.dec.decode(&[b]).status {
                // An envelope the stream decoder refuses: let the frame
                // decoder report it.
                self.env = std::mem::take(&mut st.copy);
                self.flush_env();
                return;
            }
        }
        self.stream = Some(st);
    }

    fn stream_byte(&mut self, b: u8, off: u64, is_header: bool) {
        let Some(mut st) = self.stream.take() else {
            return;
        };
        let r = st.dec.decode(&[b]);
        let (used, ev) = (r.consumed, r.status);
        if used > 0 {
            st.push_copy(b);
        }
        let Status::Complete(ev) = ev else {
            self.stream = Some(st);
            return;
        };
        match ev {
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
                    self.push_item(item);
                    self.byte(b, off);
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
                self.push_item(Item {
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
        self.push_item(Item {
            offset: st.start,
            len: st.len,
            origin: st.origin,
            what: What::Stream(item),
        });
    }

    /// Lists `item`, after the noise before it.
    fn push_item(&mut self, item: Item) {
        self.flush_noise();
        self.items.push(item);
    }

    fn noise_byte(&mut self, b: u8, off: u64, origin: Origin) {
        if let Some((start, _, _, len)) = &self.noise {
            if start + len != off {
                self.flush_noise();
            }
        }
        match self.noise.as_mut() {
            Some((_, _, bytes, len)) => {
                if bytes.len() < SAMPLE {
                    bytes.push(b);
                }
                *len += 1;
            }
            None => self.noise = Some((off, origin, vec![b], 1)),
        }
    }

    /// The held bytes before `off` are noise the frame decoder dropped.
    fn noise_to(&mut self, off: u64) {
        while let Some((b, at, origin)) = self.held.pop_before(off) {
            self.noise_byte(b, at, origin);
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

    /// Gives one byte to the frame decoder and lists everything it
    /// produces until it needs more: after a failed 200H or 216H one byte
    /// can bring several frames, decoded again from that frame's bytes.
    fn feed_dec(&mut self, b: u8, off: u64) {
        self.held.push(b, off, self.origin);
        let byte = [b];
        let mut input: &[u8] = &byte;
        loop {
            let d = self.dec.decode(input);
            input = input.get(d.consumed..).unwrap_or(&[]);
            let event = match d.status {
                Status::Partial => None,
                Status::Complete(Event::Frame(f)) => Some(Ok((f.len() as u64, frame_item(&f)))),
                Status::Complete(Event::Error(e)) => Some(Err(e)),
            };
            // What the decoder still holds starts here; what it reported
            // ends here.
            let unused = input.len() as u64 + self.dec.pending() as u64;
            let holds = self.held.end().saturating_sub(unused);
            match event {
                None => {
                    self.noise_to(holds);
                    return;
                }
                Some(Ok((len, frame))) => {
                    let start = holds.saturating_sub(len);
                    self.noise_to(start);
                    let item = Item {
                        offset: start,
                        len,
                        origin: self.held.origin_at(start),
                        what: What::Frame(frame),
                    };
                    self.push_item(item);
                    self.held.drop_to(holds);
                }
                Some(Err(e)) => {
                    let start = self.held.first_header(0).filter(|&h| h < holds);
                    let start = start.unwrap_or(holds);
                    self.noise_to(start);
                    let item = Item {
                        offset: start,
                        len: holds - start,
                        origin: self.held.origin_at(start),
                        what: What::Error {
                            kind: error_kind(&e),
                            message: e.to_string(),
                            bytes: self.held.sample(start, holds, SAMPLE),
                        },
                    };
                    self.held.drop_to(holds);
                    let idle = input.is_empty() && self.dec.pending() == 0;
                    if idle
                        && matches!(e, iai_protocol_b::error::Error::FrameTooLong { .. })
                        && b != b'\n'
                    {
                        // The frame goes on past the decoder's buffer: the
                        // bytes up to its LF (or the next header) belong to
                        // this one error, not to noise.
                        self.flush_noise();
                        self.skip = Some(item);
                        return;
                    }
                    self.push_item(item);
                    if input.is_empty() && b == b'!' && holds == off && self.dec.pending() == 1 {
                        // Cut off by a new command: it may be a position stream.
                        self.dec.reset();
                        self.held.drop_to(off + 1);
                        self.start_or_feed(b, off);
                        return;
                    }
                }
            }
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
