//! Read-back windows, planned one way for both readers of position tables
//! ([`crate::readback`] and the verification of [`crate::transfer`]): how
//! many positions a query asks for, halved after a timeout (a long reply
//! is more likely hit by noise) and doubled back after each answer, never
//! more than a reply can carry ([`PositionStream::window`]).

use crate::checksum::ChecksumMode;
use crate::error::Result;
use crate::field::Writer;
use crate::frame::{emit_envelope, emit_trailer, Header, Station};
use crate::position::PositionStream;

/// Bytes of the longest read-back query (21FH: envelope, head, count, SC,
/// CR LF = 18; 22DH adds two).
pub(crate) const QUERY_LEN: usize = 24;

/// The window size in force.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Windows {
    full: u16,
    limit: u16,
}

impl Windows {
    /// Windows of at most `full` positions (at least one).
    pub(crate) const fn new(full: u16) -> Self {
        let full = if full == 0 { 1 } else { full };
        Windows { full, limit: full }
    }

    /// Positions to ask for when `left` remain to be read (at least one).
    pub(crate) fn span(&self, left: u32) -> u16 {
        // Not `clamp`: its check of the bounds' order would stay linked.
        left.min(u32::from(self.limit)).max(1) as u16
    }

    /// A query of `asked` positions timed out: half as many (at least
    /// one), from now on.
    pub(crate) fn shrink(&mut self, asked: u16) -> u16 {
        let half = (asked / 2).max(1);
        self.limit = half;
        half
    }

    /// A window was answered: half as many more next time ([`grown`]).
    pub(crate) fn grow(&mut self) {
        self.limit = grown(self.limit, self.full);
    }
}

/// A window limit after an answer: half as many more, at least one, at
/// most `max`. Halved after a timeout and grown back by halves, a size
/// settles where most replies get through a noisy line (doubling went
/// straight back to sizes that broke), and comes back in two answers
/// after a lost reply.
pub(crate) const fn grown(limit: u16, max: u16) -> u16 {
    let step = if limit / 2 > 1 { limit / 2 } else { 1 };
    let next = limit.saturating_add(step);
    if next < max {
        next
    } else {
        max
    }
}

/// Writes the query of `stream` for `asked` positions from `head` into
/// `out`; returns its length.
pub(crate) fn write_query(
    stream: PositionStream,
    station: Station,
    checksum: ChecksumMode,
    head: u16,
    asked: u16,
    out: &mut [u8],
) -> Result<usize> {
    let mut w = Writer::new(out);
    emit_envelope(&mut w, Header::Command, station, stream.id)?;
    stream.write_query(&mut w, head, asked)?;
    emit_trailer(&mut w, checksum)?;
    Ok(w.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_halves_after_a_timeout_and_grows_back_by_halves() {
        let mut w = Windows::new(24);
        assert_eq!(w.span(1_000), 24);
        assert_eq!(w.span(5), 5);
        assert_eq!(w.shrink(24), 12);
        assert_eq!(w.shrink(12), 6);
        assert_eq!(w.shrink(1), 1);
        assert_eq!(w.span(1_000), 1);
        for want in [2, 3, 4, 6, 9, 13, 19, 24, 24] {
            w.grow();
            assert_eq!(w.span(1_000), want);
        }
    }

    #[test]
    fn a_21fh_query_asks_its_window() {
        let mut buf = [0u8; QUERY_LEN];
        let q = PositionStream::QUERY_2_RESPONSE;
        let n = write_query(q, Station(0x99), ChecksumMode::Compute, 1, 24, &mut buf).unwrap();
        assert_eq!(&buf[..n], b"!9921F00010018C6\r\n");
    }
}
