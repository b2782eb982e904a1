//! Where a transfer takes its records from.

use crate::axis::{AxisPattern, PerAxis, MAX_AXES};
use crate::position::PositionRecord;

/// What a [`RecordSource`] has to offer.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pull {
    /// The next record.
    Record(PositionRecord),
    /// No record yet; ask again later.
    Pending,
    /// No more records.
    End,
}

/// Where a transfer takes its records from. Every
/// `Iterator<Item = PositionRecord>` is one (never pending); a
/// [`RecordBuffer`] is one that fills as records arrive.
pub trait RecordSource {
    /// The next record, if ready.
    fn pull(&mut self) -> Pull;
    /// Records in all, if known.
    fn total(&self) -> Option<u32> {
        None
    }
}

impl<I: Iterator<Item = PositionRecord>> RecordSource for I {
    fn pull(&mut self) -> Pull {
        self.next().map_or(Pull::End, Pull::Record)
    }
    fn total(&self) -> Option<u32> {
        let (lo, hi) = self.size_hint();
        if Some(lo) == hi {
            u32::try_from(lo).ok()
        } else {
            None
        }
    }
}

/// Bytes a record takes in a [`RecordBuffer`] with `axes` coordinates:
/// number, pattern, count, acceleration, deceleration, speed and extended
/// byte (11), then 4 per coordinate. An 8-axis record takes 43 bytes, about
/// half its 82 on the wire; a 1-axis record 15.
pub const fn packed_len(axes: usize) -> usize {
    RECORD_HEAD + 4 * axes
}

const RECORD_HEAD: usize = 11;

/// A FIFO of records that a producer fills as they arrive (for example
/// from a [`PositionStreamDecoder`](crate::table::PositionStreamDecoder))
/// and a [`Transfer`](super::Transfer) drains, packed into `BYTES` bytes:
/// a record takes [`packed_len`] of its axes, so the same buffer holds
/// three times as many 1-axis records as 8-axis ones. It is pending while
/// empty, until [`RecordBuffer::finish`].
///
/// Written by hand rather than a `heapless::Deque<PositionRecord, Q>`
/// (48 bytes a record whatever its axes): the bridge holds a whole chunk
/// of the host's records here while the chunk before is written and read
/// back, on 8 KiB of RAM.
#[derive(Debug, Clone)]
pub struct RecordBuffer<const BYTES: usize> {
    ring: [u8; BYTES],
    /// Index of the oldest record's first byte.
    head: usize,
    /// Bytes in use.
    used: usize,
    /// Records in the buffer.
    records: usize,
    finished: bool,
}

impl<const BYTES: usize> Default for RecordBuffer<BYTES> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const BYTES: usize> RecordBuffer<BYTES> {
    /// An empty buffer.
    pub const fn new() -> Self {
        RecordBuffer {
            ring: [0; BYTES],
            head: 0,
            used: 0,
            records: 0,
            finished: false,
        }
    }

    /// Appends a record; gives it back if it does not fit.
    pub fn push(&mut self, rec: PositionRecord) -> core::result::Result<(), PositionRecord> {
        let n = rec.positions.len();
        if !self.fits(n) {
            return Err(rec);
        }
        let [n0, n1] = rec.number.to_le_bytes();
        let [a0, a1] = rec.acceleration.to_le_bytes();
        let [d0, d1] = rec.deceleration.to_le_bytes();
        let [s0, s1] = rec.speed.to_le_bytes();
        let head = [
            n0,
            n1,
            rec.axes.bits(),
            n as u8,
            a0,
            a1,
            d0,
            d1,
            s0,
            s1,
            rec.extended,
        ];
        let bytes = head
            .into_iter()
            .chain(rec.positions.iter().flat_map(|p| p.to_le_bytes()));
        for (at, b) in (self.head + self.used..).zip(bytes) {
            if let Some(slot) = self.ring.get_mut(at % BYTES.max(1)) {
                *slot = b;
            }
        }
        self.used += packed_len(n);
        self.records += 1;
        Ok(())
    }

    /// Whether a record of `axes` coordinates fits now.
    pub const fn fits(&self, axes: usize) -> bool {
        axes <= MAX_AXES && BYTES - self.used >= packed_len(axes)
    }

    /// The byte `k` places after the oldest record's first.
    fn byte(&self, k: usize) -> u8 {
        self.ring
            .get((self.head + k) % BYTES.max(1))
            .copied()
            .unwrap_or(0)
    }

    /// Removes the oldest record.
    fn pop(&mut self) -> Option<PositionRecord> {
        if self.records == 0 {
            return None;
        }
        let u16_at = |k| u16::from_le_bytes([self.byte(k), self.byte(k + 1)]);
        let n = usize::from(self.byte(3)).min(MAX_AXES);
        let mut positions = PerAxis::new();
        for i in 0..n {
            let k = RECORD_HEAD + 4 * i;
            let p = [
                self.byte(k),
                self.byte(k + 1),
                self.byte(k + 2),
                self.byte(k + 3),
            ];
            // At most MAX_AXES: always fits.
            let _ = positions.push(i32::from_le_bytes(p));
        }
        let rec = PositionRecord {
            number: u16_at(0),
            axes: AxisPattern::from_bits(self.byte(2)),
            acceleration: u16_at(4),
            deceleration: u16_at(6),
            speed: u16_at(8),
            positions,
            extended: self.byte(10),
        };
        let len = packed_len(n).min(self.used);
        self.head = (self.head + len) % BYTES.max(1);
        self.used -= len;
        self.records -= 1;
        Some(rec)
    }

    /// Empties the buffer for another transfer (not finished any more).
    pub fn clear(&mut self) {
        self.head = 0;
        self.used = 0;
        self.records = 0;
        self.finished = false;
    }
    /// No more records will come.
    pub fn finish(&mut self) {
        self.finished = true;
    }
    /// Whether [`RecordBuffer::finish`] was called.
    pub fn is_finished(&self) -> bool {
        self.finished
    }
    /// Records waiting.
    pub fn len(&self) -> usize {
        self.records
    }
    /// Whether no record is waiting.
    pub fn is_empty(&self) -> bool {
        self.records == 0
    }
    /// Bytes free.
    pub const fn free(&self) -> usize {
        BYTES - self.used
    }
}

impl<const BYTES: usize> RecordSource for RecordBuffer<BYTES> {
    fn pull(&mut self) -> Pull {
        match self.pop() {
            Some(r) => Pull::Record(r),
            None if self.finished => Pull::End,
            None => Pull::Pending,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(number: u16, axes: &[(u8, i32)]) -> PositionRecord {
        PositionRecord::new(number, 30, 31, 100, axes).unwrap()
    }

    #[test]
    fn records_come_out_as_they_went_in_across_the_wrap() {
        // Room for two 8-axis records (43 bytes each) and a bit.
        let mut q: RecordBuffer<100> = RecordBuffer::new();
        let eight: [(u8, i32); 8] =
            core::array::from_fn(|i| (i as u8 + 1, -(i as i32) * 1_000_001));
        let mut expect = heapless::Deque::<PositionRecord, 8>::new();
        for n in 0..40u16 {
            let r = if n % 3 == 0 {
                rec(n, &eight)
            } else {
                rec(n, &[(2, i32::MAX), (7, i32::MIN)])
            };
            while !q.fits(r.positions.len()) {
                let want = expect.pop_front().unwrap();
                assert_eq!(q.pull(), Pull::Record(want));
            }
            q.push(r.clone()).unwrap();
            expect.push_back(r).unwrap();
        }
        while let Some(want) = expect.pop_front() {
            assert_eq!(q.pull(), Pull::Record(want));
        }
        assert_eq!(q.pull(), Pull::Pending);
        q.finish();
        assert_eq!(q.pull(), Pull::End);
    }

    #[test]
    fn a_record_that_does_not_fit_is_given_back() {
        let mut q: RecordBuffer<{ packed_len(8) }> = RecordBuffer::new();
        let eight: [(u8, i32); 8] = core::array::from_fn(|i| (i as u8 + 1, 5));
        assert!(q.push(rec(1, &eight)).is_ok());
        assert_eq!(q.free(), 0);
        let one = rec(2, &[(1, 7)]);
        assert_eq!(q.push(one.clone()), Err(one));
        assert_eq!(q.len(), 1);
        let mut none: RecordBuffer<0> = RecordBuffer::new();
        assert!(none.push(rec(3, &[(1, 7)])).is_err());
        assert_eq!(none.pull(), Pull::Pending);
    }
}
