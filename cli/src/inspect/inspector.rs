//! The incremental inspector: bytes in, listing entries out.
//!
//! The bytes go through the core's [`FrameDecoder`] (every `@@` accepted,
//! so the listing can say where it was used), then
//! [`decode_any`](iai_protocol_b::message::decode_any) and the field
//! visitor. Commands that carry a position stream (244H, 245H, 26DH,
//! 290H, 291H) are diverted to the [`PositionStreamDecoder`] instead, so a
//! 1.6 MB 26DH is summarised without ever being held in memory whole; one
//! that fits the frame decoder's buffer is listed field by field as well.

use iai_protocol_b::checksum::{BypassPolicy, ChecksumField};
use iai_protocol_b::decoder::{Event, FrameDecoder, DEFAULT_CAPACITY};
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::stream::{PositionStream, PositionStreamDecoder, StreamEvent};

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
            if let (_, StreamEvent::Error { .. }) = st.dec.decode(&[b]) {
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
        let (used, ev) = st.dec.decode(&[b]);
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
