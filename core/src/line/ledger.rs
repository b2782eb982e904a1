//! The ledger: the replies that may still arrive on a line, and until when.
//!
//! Two kinds of entry, because two kinds of fault put them there:
//! - **owed** replies: a send whose reply was not taken (a timeout, a
//!   resend, an abandoned command, or the past before the line was
//!   opened). Their content is unknown, so each could answer any command.
//!   A controller answers in order, so a fence clears them ([`super`]).
//! - **copies**: every reply seen from the station may be repeated within
//!   the line's duplicate window (an echoing converter), and a copy may
//!   come after later replies, so only time clears them. Each is kept with
//!   the values its content commits to ([`Span`]): a copy can pass only
//!   for a command that accepts those values.

use crate::clock::{later, passed};

/// A message ID that matches every command: the entry of an `&` reply
/// (which names no ID) or of a reply whose envelope could not be read.
/// IDs are three hex digits, so it never clashes with one.
pub(crate) const ANY_ID: u16 = 0xFFFF;

/// A range of values (a record count, the position numbers of a reply's
/// records, a fence's sequence number): what a reply carries, or what a
/// command accepts in its reply. Empty when `lo > hi`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Span {
    pub(crate) lo: u16,
    pub(crate) hi: u16,
}

impl Span {
    /// Every value: a command that accepts any reply of its ID.
    pub(crate) const ANY: Span = Span {
        lo: 0,
        hi: u16::MAX,
    };
    /// No value: a reply whose content is unknown, or that carries nothing
    /// that tells it apart (an empty read-back reply). It passes for every
    /// command of its ID.
    pub(crate) const UNKNOWN: Span = Span { lo: 1, hi: 0 };

    /// The one value `v`.
    pub(crate) const fn one(v: u16) -> Span {
        Span { lo: v, hi: v }
    }

    /// This span grown to hold `v` (from no value, `v` alone): the
    /// positions of a reply, record by record.
    pub(crate) const fn holding(self, v: u16) -> Span {
        if self.lo > self.hi {
            return Span::one(v);
        }
        Span {
            lo: if v < self.lo { v } else { self.lo },
            hi: if v > self.hi { v } else { self.hi },
        }
    }

    /// Whether the two could describe the same reply: either is unknown,
    /// or they share a value.
    pub(crate) const fn meets(self, other: Span) -> bool {
        self.lo > self.hi || other.lo > other.hi || (self.lo <= other.hi && other.lo <= self.hi)
    }

    /// The smallest span holding both (unknown if either is).
    pub(crate) const fn union(self, other: Span) -> Span {
        if self.lo > self.hi || other.lo > other.hi {
            return Span::UNKNOWN;
        }
        Span {
            lo: if self.lo < other.lo {
                self.lo
            } else {
                other.lo
            },
            hi: if self.hi > other.hi {
                self.hi
            } else {
                other.hi
            },
        }
    }

    /// Whether a reply carrying these values could be accepted by a command
    /// that accepts `accepts`.
    pub(crate) const fn within(self, accepts: Span) -> bool {
        self.lo > self.hi || (accepts.lo <= self.lo && self.hi <= accepts.hi)
    }
}

/// Copies remembered at once; a further one merges the two copies of one
/// ID that would be forgotten soonest (never forgotten early, kept a
/// little more broadly), or with no two of one ID the last slot becomes a
/// copy of anything.
const COPIES: usize = 16;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Copy {
    id: u16,
    /// What the copy carries; for merged copies, the range all their
    /// values lie in.
    values: Span,
    /// The highest first value and the lowest last value of the copies
    /// merged here (`values` for one copy): a command can take one of them
    /// only if it accepts a span reaching from at most the one to at least
    /// the other. Merging copies of windows read in order (low positions)
    /// thus keeps the windows ahead clear.
    inner: Span,
    /// The first tick at which it can no longer arrive.
    until: u32,
}

impl Copy {
    /// Whether one of the copies here could pass for the reply to a
    /// command that accepts `accepts`.
    const fn passes(&self, accepts: Span) -> bool {
        let unknown = self.values.lo > self.values.hi;
        unknown || (accepts.lo <= self.inner.lo && self.inner.hi <= accepts.hi)
    }

    /// These copies and those of `other` (same ID) in one entry.
    fn merge(self, other: Copy) -> Copy {
        let values = self.values.union(other.values);
        let known = values.lo <= values.hi;
        Copy {
            id: self.id,
            values,
            inner: if known {
                Span {
                    lo: self.inner.lo.max(other.inner.lo),
                    hi: self.inner.hi.min(other.inner.hi),
                }
            } else {
                Span::UNKNOWN
            },
            until: later(self.until, other.until),
        }
    }
}

/// What the ledger holds.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Ledger {
    copies: heapless::Vec<Copy, COPIES>,
    /// The first tick at which no owed reply can arrive any more.
    owed: Option<u32>,
    /// How far ahead of the tick it was set any hold lies (see [`passed`]).
    horizon: u32,
}

impl Ledger {
    pub(crate) const fn new(horizon: u32) -> Self {
        Ledger {
            copies: heapless::Vec::new(),
            owed: None,
            horizon,
        }
    }

    pub(crate) fn set_horizon(&mut self, horizon: u32) {
        self.horizon = self.horizon.max(horizon);
    }

    fn over(&self, now: u32, until: u32) -> bool {
        passed(now, until, self.horizon)
    }

    /// Drops what can no longer arrive.
    pub(crate) fn prune(&mut self, now: u32) {
        let h = self.horizon;
        self.copies.retain(|c| !passed(now, c.until, h));
        if self.owed.is_some_and(|u| self.over(now, u)) {
            self.owed = None;
        }
    }

    /// Replies owed until `until` (exclusive).
    pub(crate) fn owe(&mut self, until: u32, now: u32) {
        self.prune(now);
        self.owed = Some(match self.owed {
            Some(u) => later(u, until),
            None => until,
        });
    }

    /// When owed replies stop being possible, if any still are.
    pub(crate) fn owed(&self, now: u32) -> Option<u32> {
        self.owed.filter(|&u| !self.over(now, u))
    }

    /// A fence was answered: every reply owed before it has come or never
    /// will.
    pub(crate) fn settle_owed(&mut self) {
        self.owed = None;
    }

    /// A reply of `id` carrying `values` arrived: a copy of it may come
    /// until `until` (exclusive).
    pub(crate) fn copy(&mut self, id: u16, values: Span, until: u32, now: u32) {
        self.prune(now);
        let new = Copy {
            id,
            values,
            inner: values,
            until,
        };
        if let Some(c) = self
            .copies
            .iter_mut()
            .find(|c| c.id == id && c.values == values && c.inner == values)
        {
            c.until = later(c.until, until);
            return;
        }
        let Err(new) = self.copies.push(new) else {
            return;
        };
        // Full: merge the two copies of one ID, the new one among them,
        // whose entry would end soonest (a window read long ago, a count
        // written long ago: far from what is asked next), so that none is
        // forgotten early and the values asked next stay clear.
        let h = self.horizon;
        let end = |c: &Copy| c.until.wrapping_sub(now).min(h);
        let mut best: Option<(usize, Option<usize>, u32)> = None;
        for (i, a) in self.copies.iter().enumerate() {
            if a.id == id {
                let cost = end(a).max(end(&new));
                if best.is_none_or(|(_, _, c)| cost < c) {
                    best = Some((i, None, cost));
                }
            }
            for (j, b) in self.copies.iter().enumerate().skip(i + 1) {
                if a.id == b.id {
                    let cost = end(a).max(end(b));
                    if best.is_none_or(|(_, _, c)| cost < c) {
                        best = Some((i, Some(j), cost));
                    }
                }
            }
        }
        match best {
            Some((i, None, _)) => {
                if let Some(a) = self.copies.get_mut(i) {
                    *a = a.merge(new);
                }
            }
            Some((i, Some(j), _)) => {
                // `j` takes the new copy once `i` holds both.
                let b = self.copies.get(j).copied();
                if let (Some(a), Some(b)) = (self.copies.get_mut(i), b) {
                    *a = a.merge(b);
                }
                if let Some(slot) = self.copies.get_mut(j) {
                    *slot = new;
                }
            }
            None => {
                if let Some(last) = self.copies.last_mut() {
                    *last = Copy {
                        id: ANY_ID,
                        values: Span::UNKNOWN,
                        inner: Span::UNKNOWN,
                        until: later(last.until, until),
                    };
                }
            }
        }
    }

    /// Whether a copy of a reply `id` carrying `values` is expected at
    /// `now` (an `&`, whose `id` is [`ANY_ID`], only by an `&`'s copy).
    pub(crate) fn expects(&self, id: u16, values: Span, now: u32) -> bool {
        self.copies.iter().any(|c| {
            (c.id == id || c.id == ANY_ID) && c.values.meets(values) && !self.over(now, c.until)
        })
    }

    /// The first tick, from `now`, at which no copy could pass for the
    /// reply to a command `id` accepting `accepts`. With `errors_only`,
    /// only copies that could pass as an error reply count (see
    /// [`super::Claim::Tentative`]).
    pub(crate) fn clear_at(&self, id: u16, accepts: Span, errors_only: bool, now: u32) -> u32 {
        let mut at = now;
        for c in &self.copies {
            let id_ok = c.id == ANY_ID || (!errors_only && c.id == id);
            if id_ok && c.passes(accepts) && !self.over(now, c.until) {
                at = later(at, c.until);
            }
        }
        at
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_copy_passes_only_for_commands_that_accept_its_values() {
        let mut l = Ledger::new(10_000);
        // A 26DH reply reporting 24 records, seen at 100, copies until 3,101.
        l.copy(0x26D, Span::one(24), 3_101, 100);
        assert_eq!(l.clear_at(0x26D, Span::one(24), false, 200), 3_101);
        assert_eq!(l.clear_at(0x26D, Span::one(23), false, 200), 200);
        assert_eq!(l.clear_at(0x21F, Span::ANY, false, 200), 200);
        // A read-back reply with positions 1..=24: a window 1..=30 could
        // take it, a window 25..=48 could not.
        l.copy(0x21F, Span { lo: 1, hi: 24 }, 3_200, 200);
        assert_eq!(l.clear_at(0x21F, Span { lo: 1, hi: 30 }, false, 300), 3_200);
        assert_eq!(l.clear_at(0x21F, Span { lo: 25, hi: 48 }, false, 300), 300);
        // An empty one passes for any window.
        l.copy(0x21F, Span::UNKNOWN, 3_300, 300);
        assert_eq!(
            l.clear_at(0x21F, Span { lo: 25, hi: 48 }, false, 300),
            3_300
        );
        assert_eq!(
            l.clear_at(0x21F, Span { lo: 25, hi: 48 }, false, 3_300),
            3_300
        );
        assert_eq!(
            l.clear_at(0x21F, Span { lo: 25, hi: 48 }, false, 3_301),
            3_301
        );
    }

    #[test]
    fn an_error_copy_passes_for_every_command_even_tentative_ones() {
        let mut l = Ledger::new(10_000);
        l.copy(0x21F, Span::UNKNOWN, 500, 0);
        assert_eq!(l.clear_at(0x21F, Span::ANY, true, 10), 10);
        l.copy(ANY_ID, Span::UNKNOWN, 600, 0);
        assert_eq!(l.clear_at(0x212, Span::ANY, true, 10), 600);
        assert_eq!(l.clear_at(0x26D, Span::one(3), false, 10), 600);
    }

    #[test]
    fn a_full_ledger_forgets_nothing_early() {
        let mut l = Ledger::new(100_000);
        for i in 0..40u16 {
            l.copy(0x26D, Span::one(i), 1_000 + u32::from(i), 0);
        }
        // Every count is still guarded until its own time, or later.
        for i in 0..40u16 {
            assert!(l.clear_at(0x26D, Span::one(i), false, 1) >= 1_000 + u32::from(i));
        }
    }

    /// Forty read-back windows' replies on a full ledger: every window
    /// read stays guarded until its copy's time or later, while a window
    /// not read yet, another ID, and a window shifted by half of one over
    /// the windows read last are clear at once.
    #[test]
    fn a_full_ledger_merges_the_copies_that_end_soonest() {
        let window = |w: u16| Span {
            lo: 1 + 24 * w,
            hi: 24 * (w + 1),
        };
        let mut l = Ledger::new(100_000);
        for w in 0..40u16 {
            l.copy(0x21F, window(w), 8_000 + u32::from(w), u32::from(w));
        }
        for w in 0..40u16 {
            assert!(l.clear_at(0x21F, window(w), false, 40) >= 8_000 + u32::from(w));
            // A confirmation that asks one more position is guarded too.
            let wider = Span {
                lo: window(w).lo.saturating_sub(1).max(1),
                hi: window(w).hi,
            };
            assert!(l.clear_at(0x21F, wider, false, 40) >= 8_000 + u32::from(w));
        }
        assert_eq!(l.clear_at(0x21F, window(40), false, 40), 40);
        assert_eq!(l.clear_at(0x212, Span::ANY, false, 40), 40);
        for w in 30..39u16 {
            let shifted = Span {
                lo: window(w).lo + 12,
                hi: window(w).hi + 12,
            };
            assert_eq!(l.clear_at(0x21F, shifted, false, 40), 40, "window {w}");
        }
    }

    #[test]
    fn owed_replies_end_at_their_horizon_or_a_fence() {
        let mut l = Ledger::new(10_000);
        l.owe(6_000, 0);
        l.owe(5_000, 10);
        assert_eq!(l.owed(5_999), Some(6_000));
        assert_eq!(l.owed(6_000), None);
        l.owe(9_000, 6_100);
        l.settle_owed();
        assert_eq!(l.owed(6_200), None);
    }
}
