//! The late-reply guard: which record counts a reply still in flight
//! could carry (see the module docs of [`crate::transfer`]).

use crate::clock::{later, reached};

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
    /// The count of the frame answered last (always avoided).
    pub(super) previous: u16,
}

impl Guard {
    pub(super) const fn new() -> Self {
        Guard {
            entries: heapless::Vec::new(),
            duplicates_seen: false,
            previous: 0,
        }
    }

    pub(super) fn prune(&mut self, now: u32) {
        self.entries.retain(|&(_, u, _)| !reached(now, u));
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
        self.previous = count;
    }

    /// Whether a frame of `n` records could be confirmed by a reply still
    /// in flight.
    pub(super) fn blocks(&self, n: u16, now: u32) -> bool {
        n == self.previous
            || self
                .entries
                .iter()
                .any(|&(c, u, dup)| c == n && !reached(now, u) && (!dup || self.duplicates_seen))
    }

    /// The earliest tick at which a blocked count frees up.
    pub(super) fn wake(&self, now: u32) -> u32 {
        self.entries
            .iter()
            .map(|&(_, u, _)| u)
            .min_by_key(|&u| u.wrapping_sub(now))
            .unwrap_or(now.wrapping_add(1))
    }
}
