//! Where a transfer takes its records from.

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
/// [`RecordQueue`] is one that fills as records arrive.
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

/// A bounded FIFO of records that a producer fills as they arrive (for
/// example from a [`PositionStreamDecoder`](crate::stream::PositionStreamDecoder))
/// and a [`Transfer`](super::Transfer) drains. It is pending while empty, until
/// [`RecordQueue::finish`].
#[derive(Debug, Clone, Default)]
pub struct RecordQueue<const Q: usize> {
    items: heapless::Deque<PositionRecord, Q>,
    finished: bool,
}

impl<const Q: usize> RecordQueue<Q> {
    /// An empty queue.
    pub const fn new() -> Self {
        RecordQueue {
            items: heapless::Deque::new(),
            finished: false,
        }
    }
    /// Appends a record; gives it back if the queue is full.
    pub fn push(&mut self, rec: PositionRecord) -> core::result::Result<(), PositionRecord> {
        self.items.push_back(rec)
    }
    /// No more records will come.
    pub fn finish(&mut self) {
        self.finished = true;
    }
    /// Whether [`RecordQueue::finish`] was called.
    pub fn is_finished(&self) -> bool {
        self.finished
    }
    /// Records waiting.
    pub fn len(&self) -> usize {
        self.items.len()
    }
    /// Whether no record is waiting.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
    /// Whether another record would not fit.
    pub fn is_full(&self) -> bool {
        self.items.is_full()
    }
}

impl<const Q: usize> RecordSource for RecordQueue<Q> {
    fn pull(&mut self) -> Pull {
        match self.items.pop_front() {
            Some(r) => Pull::Record(r),
            None if self.finished => Pull::End,
            None => Pull::Pending,
        }
    }
}
