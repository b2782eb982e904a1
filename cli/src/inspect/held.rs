//! A copy of the bytes the frame decoder holds, with their offsets and
//! origins, so that whatever it reports can be placed in the capture.
//!
//! The core's [`FrameDecoder`](iai_protocol_b::decoder::FrameDecoder)
//! holds the last [`pending`](iai_protocol_b::decoder::FrameDecoder::pending)
//! bytes it was given, in order: a frame in progress and, after a failed
//! 200H or 216H, the bytes of that frame it decodes again from its first
//! header byte on. It reports a frame or an error once those bytes are
//! accounted for: whatever lies between the last report and what it still
//! holds is the reported frame (its last `len` bytes) or the failed frame
//! (from its header byte), and noise before either.

use std::collections::VecDeque;

use iai_protocol_b::frame::Header;

use super::item::Origin;

/// The bytes given to the frame decoder and not yet placed in the listing.
#[derive(Debug, Default)]
pub(super) struct Held {
    /// Offset of the first byte.
    start: u64,
    bytes: VecDeque<u8>,
    /// Where the origin changes, ascending: `(offset, origin)`, the first
    /// at `start` or before it.
    origins: VecDeque<(u64, Origin)>,
}

impl Held {
    /// Offset just past the last byte.
    pub(super) fn end(&self) -> u64 {
        self.start + self.bytes.len() as u64
    }

    /// Appends the byte at `off`, which follows the held ones (the frame
    /// decoder is given the capture's bytes in order, and is idle, holding
    /// nothing, whenever bytes bypass it).
    pub(super) fn push(&mut self, b: u8, off: u64, origin: Origin) {
        if self.bytes.is_empty() {
            self.start = off;
            self.origins.clear();
        }
        if self.origins.back().map(|o| o.1) != Some(origin) {
            self.origins.push_back((off, origin));
        }
        self.bytes.push_back(b);
    }

    /// Where the byte at `off` came from.
    pub(super) fn origin_at(&self, off: u64) -> Origin {
        self.origins
            .iter()
            .rev()
            .find(|(at, _)| *at <= off)
            .map(|(_, o)| *o)
            .unwrap_or_default()
    }

    /// The held bytes in `[from, to)`, at most `max` of them.
    pub(super) fn sample(&self, from: u64, to: u64, max: usize) -> Vec<u8> {
        let skip = from.saturating_sub(self.start) as usize;
        let n = to.saturating_sub(from.max(self.start)) as usize;
        self.bytes
            .iter()
            .skip(skip)
            .take(n.min(max))
            .copied()
            .collect()
    }

    /// Offset of the first header byte at or after `from`.
    pub(super) fn first_header(&self, from: u64) -> Option<u64> {
        let skip = from.saturating_sub(self.start) as usize;
        let at = self
            .bytes
            .iter()
            .skip(skip)
            .position(|&b| Header::from_byte(b).is_some())?;
        Some(self.start.max(from) + at as u64)
    }

    /// Takes out the first byte, with its offset and origin.
    pub(super) fn pop(&mut self) -> Option<(u8, u64, Origin)> {
        let b = self.bytes.pop_front()?;
        let off = self.start;
        let origin = self.origin_at(off);
        self.start += 1;
        while self.origins.get(1).is_some_and(|(at, _)| *at <= self.start) {
            self.origins.pop_front();
        }
        Some((b, off, origin))
    }

    /// Takes out the first byte if it lies before `off`.
    pub(super) fn pop_before(&mut self, off: u64) -> Option<(u8, u64, Origin)> {
        if self.start < off {
            self.pop()
        } else {
            None
        }
    }

    /// Drops the bytes before `off`.
    pub(super) fn drop_to(&mut self, off: u64) {
        while self.pop_before(off).is_some() {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_origins_and_headers() {
        let line = |n| Origin {
            line: Some(n),
            dir: None,
        };
        let mut h = Held::default();
        for (i, &b) in b"ab#cd".iter().enumerate() {
            h.push(b, 10 + i as u64, line(1 + i / 3));
        }
        assert_eq!(h.end(), 15);
        assert_eq!(h.first_header(10), Some(12));
        assert_eq!(h.first_header(13), None);
        assert_eq!(h.sample(11, 14, 2), b"b#");
        assert_eq!(h.origin_at(12), line(1));
        assert_eq!(h.origin_at(13), line(2));
        h.drop_to(12);
        assert_eq!(h.pop(), Some((b'#', 12, line(1))));
        assert_eq!(h.pop(), Some((b'c', 13, line(2))));
        assert_eq!(h.origin_at(14), line(2));
        h.drop_to(20);
        assert_eq!(h.end(), 15);
        // Empty, it starts again wherever the next byte is.
        h.push(b'x', 40, line(9));
        assert_eq!((h.end(), h.origin_at(40)), (41, line(9)));
    }
}
