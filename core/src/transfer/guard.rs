//! The late-reply guard: which record counts a reply still in flight
//! could carry (see the module docs of [`crate::transfer`]).

use crate::clock::{later, passed};

/// Counts held back by the late-reply guard at once.
const RECENT: usize = 32;

/// The record counts a reply still in flight could carry (see the module
/// docs on late and duplicated replies).
#[derive(Debug, Clone)]
pub(super) struct Guard {
    /// `(count, until, only a duplicate could carry it)`, one per count.
    pub(super) entries: heapless::Vec<(u16, u32, bool), RECENT>,
    /// A late or duplicated reply was seen on this line: from then on the
    /// counts of answered frames are guarded for the duplicate window too.
    pub(super) duplicates_seen: bool,
    /// How far ahead any `until` may lie (see [`passed`]).
    pub(super) horizon: u32,
    /// The count of the frame answered last, avoided even before the
    /// line showed a duplicate, until the tick beside it (its answer plus
    /// the duplicate window). It must expire: when the records left are
    /// exactly that count (one record after a frame of one), no other
    /// count is possible, and waiting out the window is what keeps an
    /// unannounced duplicate from confirming the last frame.
    pub(super) previous: (u16, u32),
}

impl Guard {
    pub(super) const fn new(horizon: u32) -> Self {
        Guard {
            entries: heapless::Vec::new(),
            duplicates_seen: false,
            horizon,
            previous: (0, 0),
        }
    }

    /// Whether `until` is over at `now`.
    fn over(&self, now: u32, until: u32) -> bool {
        passed(now, until, self.horizon)
    }

    pub(super) fn prune(&mut self, now: u32) {
        let h = self.horizon;
        self.entries.retain(|&(_, u, _)| !passed(now, u, h));
    }

    /// Sets the entry of `count` (merging with one that exists).
    pub(super) fn note(&mut self, count: u16, until: u32, dup_only: bool, now: u32) {
        self.prune(now);
        if let Some(e) = self.entries.iter_mut().find(|e| e.0 == count) {
            e.1 = later(e.1, until);
            e.2 &= dup_only;
        } else if self.entries.push((count, until, dup_only)).is_err() {
            // Full: keep the latest deadline in the last slot, so that no
            // count is forgotten early (one may be guarded longer).
            if let Some(last) = self.entries.last_mut() {
                last.1 = later(last.1, until);
                last.2 = false;
            }
        }
    }

    /// A frame of `count` records was sent: its reply may come until
    /// `until` (timeout plus late window).
    pub(super) fn sent(&mut self, count: u16, until: u32, now: u32) {
        self.note(count, until, false, now);
    }

    /// The frame of `count` records was answered after `sends` sends.
    /// Sent once, only a duplicate of the reply can still come (until
    /// `dup_until`); sent more often, the other sends' replies can too.
    pub(super) fn answered(&mut self, count: u16, sends: u8, dup_until: u32, now: u32) {
        if sends <= 1 {
            self.entries.retain(|e| e.0 != count);
        }
        self.note(count, dup_until, sends <= 1, now);
        self.previous = (count, dup_until);
    }

    /// Whether the rule on the previous count still holds at `now`.
    fn previous_blocks(&self, n: u16, now: u32) -> bool {
        n == self.previous.0 && !self.over(now, self.previous.1)
    }

    /// Whether a frame of `n` records could be confirmed by a reply still
    /// in flight.
    pub(super) fn blocks(&self, n: u16, now: u32) -> bool {
        self.previous_blocks(n, now)
            || self
                .entries
                .iter()
                .any(|&(c, u, dup)| c == n && !self.over(now, u) && (!dup || self.duplicates_seen))
    }

    /// The earliest tick, later than `now`, at which a blocked count
    /// frees up (every rule expires, so this is never a busy wait).
    pub(super) fn wake(&self, now: u32) -> u32 {
        let previous = (!self.over(now, self.previous.1)).then_some(self.previous.1);
        self.entries
            .iter()
            .map(|&(_, u, _)| u)
            .chain(previous)
            .filter(|&u| !self.over(now, u))
            .min_by_key(|&u| u.wrapping_sub(now))
            .unwrap_or(now.wrapping_add(1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_previous_count_is_avoided_for_the_duplicate_window_only() {
        let mut g = Guard::new(6_001);
        // A frame of one record answered at its first send, at 100 ms.
        g.sent(1, 6_100, 0);
        g.answered(1, 1, 3_100, 100);
        assert!(g.blocks(1, 200));
        assert!(!g.blocks(2, 200));
        // One record is left: the frame waits for the window, not forever.
        assert_eq!(g.wake(200), 3_100);
        assert!(!g.blocks(1, 3_100));
    }

    #[test]
    fn a_count_sent_twice_stays_guarded_for_its_late_window() {
        let mut g = Guard::new(6_001);
        g.sent(5, 6_000, 0);
        g.sent(5, 9_000, 3_000);
        g.answered(5, 2, 6_100, 3_100);
        // A duplicate was never seen, but the first send's reply may come.
        assert!(g.blocks(5, 7_000));
        assert_eq!(g.wake(7_000), 9_000);
        assert!(!g.blocks(5, 9_000));
    }

    #[test]
    fn wake_is_always_later_than_now() {
        let g = Guard::new(6_001);
        assert_eq!(g.wake(u32::MAX), 0);
        let mut g = Guard::new(6_001);
        g.answered(3, 1, 10, 5);
        assert_eq!(g.wake(20), 21);
    }
}
