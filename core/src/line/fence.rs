//! The fence: a 200H Test Call whose ten characters no earlier command on
//! the line carried. The controller sends the same ten characters back
//! (2003 p. 15; the TTA's page is lost and the same layout is
//! **inferred**), and it answers its commands in order (an
//! **assumption**: half duplex, one command at a time), so once the echo
//! is in, every reply to a command sent before the fence has arrived or
//! never will.
//!
//! The text is ten upper-case hex digits: six from the line's seed (so
//! that two runs on one line do not share texts) and four of a sequence
//! number. Hex keeps it free of header bytes, CR, LF, XON and XOFF.

use crate::catalogue;
use crate::checksum::ChecksumMode;
use crate::frame::{emit_frame, Header, Station};
use crate::hex;

/// Bytes of a fence command: header, station, ID, ten characters, SC, CR LF.
pub(crate) const FENCE_LEN: usize = 20;

/// The fence of a line: the one in flight, and the text of the next.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Fence {
    /// Six hex digits of the seed.
    nonce: u32,
    /// Sequence number of the fence in flight (or the last one).
    pub(crate) seq: u16,
    frame: [u8; FENCE_LEN],
    len: usize,
}

impl Fence {
    pub(crate) const fn new(seed: u32) -> Self {
        Fence {
            nonce: seed & 0x00FF_FFFF,
            seq: 0,
            frame: [0; FENCE_LEN],
            len: 0,
        }
    }

    /// The ten characters of fence `seq`.
    fn text(&self, seq: u16) -> [u8; 10] {
        let nonce = hex::encode8(self.nonce);
        let seq = hex::encode4(seq);
        let mut t = [0u8; 10];
        for (slot, &d) in t.iter_mut().zip(nonce.iter().skip(2).chain(seq.iter())) {
            *slot = d;
        }
        t
    }

    /// Builds the next fence for `station` and returns its bytes.
    pub(crate) fn next(&mut self, station: Station, checksum: ChecksumMode) -> &[u8] {
        self.seq = self.seq.wrapping_add(1);
        let text = self.text(self.seq);
        self.len = emit_frame(
            &mut self.frame,
            Header::Command,
            station,
            catalogue::TEST_CALL.id,
            checksum,
            |w| w.put(&text),
        )
        .unwrap_or(0);
        self.bytes()
    }

    /// The fence in flight.
    pub(crate) fn bytes(&self) -> &[u8] {
        self.frame.get(..self.len).unwrap_or(&[])
    }

    /// Whether `body` (a 200H reply's) is the echo of the fence in flight.
    pub(crate) fn is_echo(&self, body: &[u8]) -> bool {
        body == self.text(self.seq)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fence_is_a_test_call_with_a_text_of_its_own() {
        let mut f = Fence::new(0x12_3456);
        assert_eq!(
            f.next(Station(0x99), ChecksumMode::Compute),
            b"!9920012345600011B\r\n"
        );
        assert!(f.is_echo(b"1234560001"));
        assert!(!f.is_echo(b"1234560000"));
        // The next fence carries the next sequence number.
        assert_eq!(
            &f.next(Station(0x99), ChecksumMode::Compute)[6..16],
            b"1234560002"
        );
    }
}
