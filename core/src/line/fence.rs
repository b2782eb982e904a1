//! The fence: a 200H Test Call whose ten characters no earlier command on
//! the line carried. The controller sends the same ten characters back
//! (2003 p. 15; the TTA's page is lost and the same layout is
//! **inferred**), and it answers its commands in order (an
//! **assumption**: half duplex, one command at a time), so once the echo
//! is in, every reply to a command sent before the fence has arrived or
//! never will.
//!
//! The text is ten upper-case hex digits: six of a nonce (the line's seed,
//! stirred with whatever varies: see [`Fence::stir`]) and four of a
//! sequence number. Hex keeps it free of header bytes, CR, LF, XON and
//! XOFF. An echo settles the fence only if its text is exactly the text of
//! the fence in flight, kept with its bytes.

use crate::catalogue;
use crate::checksum::ChecksumMode;
use crate::frame::{emit_frame, Header, Station, ENVELOPE_LEN};
use crate::hex;

/// Fences sent in a row without an echo before the line takes it that the
/// controller does not answer 200H and waits out what it owes instead. A
/// fence lost to the line costs its timeout; the next, with a new text,
/// settles the first's late echo too (order).
pub(crate) const FENCE_TRIES: u8 = 2;

/// Bytes of a fence command: header, station, ID, ten characters, SC, CR LF.
pub(crate) const FENCE_LEN: usize = 20;

/// The fence of a line: the one in flight, and the text of the next.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) struct Fence {
    /// The nonce: 24 bits of the seed, stirred.
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

    /// Mixes `entropy` into the nonce of the fences still to come (the
    /// fence in flight keeps its text): a tick of when something outside
    /// happened, a chip's unique ID, a boot counter.
    pub(crate) fn stir(&mut self, entropy: u32) {
        // A multiply-xorshift round: every input bit reaches every nonce bit.
        let x = (self.nonce ^ entropy.rotate_left(8)).wrapping_mul(0x9E37_79B1);
        self.nonce = (x ^ (x >> 15)) & 0x00FF_FFFF;
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

    /// Whether `body` (a 200H reply's) is the echo of the fence in flight:
    /// exactly its text.
    pub(crate) fn is_echo(&self, body: &[u8]) -> bool {
        self.len == FENCE_LEN && self.frame.get(ENVELOPE_LEN..ENVELOPE_LEN + 10) == Some(body)
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
        assert!(!f.is_echo(b"1234560001"));
    }

    #[test]
    fn stirring_changes_the_next_fence_not_the_one_in_flight() {
        let mut f = Fence::new(0x12_3456);
        f.next(Station(0x99), ChecksumMode::Compute);
        f.stir(0x0000_0001);
        assert!(f.is_echo(b"1234560001"));
        let next = f.next(Station(0x99), ChecksumMode::Compute);
        assert_ne!(&next[6..12], b"123456");
        // Two stirs with different entropy give different nonces.
        let (mut a, mut b) = (Fence::new(7), Fence::new(7));
        a.stir(1);
        b.stir(2);
        assert_ne!(a.nonce, b.nonce);
    }
}
