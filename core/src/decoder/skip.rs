//! A frame passed over without a buffer: its bytes are summed as they go
//! by, and its end says whether its checksum (or an `@@` the policy
//! allows) was right. For a frame that is not kept anyway: a bridge reads
//! a refused command (a 26DH may be 1.6 MB) to its end before it answers,
//! and skips commands for other stations.

use super::Status;
use crate::catalogue::text_span;
use crate::checksum::BypassPolicy;
use crate::error::Error;
use crate::frame::{Header, ENVELOPE_LEN};
use crate::hex;

/// How a skipped frame ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Skipped {
    /// The frame ended with CR LF: whether its checksum was right.
    End {
        /// The SC matched the bytes it covers, or was an `@@` the policy
        /// allows.
        checksum_ok: bool,
    },
    /// The frame broke at this byte (a header byte outside a text field,
    /// or CR without LF): the byte may start the next frame.
    Broken,
}

/// Skips one frame, summing its checksum (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameSkipper {
    header: Header,
    policy: BypassPolicy,
    /// Sum of every byte so far, the last two included.
    sum: u8,
    /// The last two bytes (the SC once CR comes).
    tail: [u8; 2],
    len: usize,
    /// The text field's span, when the envelope says it has one.
    text: Option<(usize, usize)>,
    cr: bool,
}

impl FrameSkipper {
    /// Begins skipping the frame whose envelope (its first
    /// [`ENVELOPE_LEN`] bytes, already read) is `envelope`. A text field
    /// is recognised when the envelope locates it (200H); a 216H reply's
    /// counted text is not.
    pub fn new(header: Header, envelope: &[u8; ENVELOPE_LEN], policy: BypassPolicy) -> Self {
        FrameSkipper {
            header,
            policy,
            sum: envelope.iter().fold(0u8, |s, &b| s.wrapping_add(b)),
            tail: [envelope[4], envelope[5]],
            len: ENVELOPE_LEN,
            text: text_span(header, envelope),
            cr: false,
        }
    }

    /// After [`Skipped::End`] with a bad checksum: what was wrong with it.
    pub fn checksum_error(&self) -> Error {
        let [h, l] = self.tail;
        let covered = self.sum.wrapping_sub(h).wrapping_sub(l);
        match hex::decode2(&[h, l]) {
            _ if h == b'@' && l == b'@' => Error::ChecksumBypassRejected,
            Some(received) => Error::ChecksumMismatch {
                computed: covered,
                received,
            },
            None => Error::InvalidHexDigit {
                offset: self.len.saturating_sub(2),
                byte: if hex::decode2(&[h, h]).is_some() {
                    l
                } else {
                    h
                },
            },
        }
    }

    /// Takes the leading bytes of `bytes` that only continue the frame's
    /// body (no header byte, CR or LF, and no text field left to cross),
    /// as [`FrameSkipper::push`] would one by one with [`Status::Partial`]
    /// for each, but summed a word at a time; returns how many it took
    /// (0: push the next byte).
    pub fn skip_run(&mut self, bytes: &[u8]) -> usize {
        let text_left = self.text.is_some_and(|(_, end)| self.len < end);
        if self.cr || text_left {
            return 0;
        }
        let n = bytes.iter().position(|&b| !super::plain(b));
        let run = bytes.get(..n.unwrap_or(bytes.len())).unwrap_or(&[]);
        self.sum = hex::sum(self.sum, run);
        self.tail = match *run {
            [] => self.tail,
            [b] => [self.tail[1], b],
            [.., a, b] => [a, b],
        };
        self.len = self.len.saturating_add(run.len());
        run.len()
    }

    /// One more byte of the frame: [`Status::Partial`] while it goes on.
    pub fn push(&mut self, b: u8) -> Status<Skipped> {
        let in_text = self
            .text
            .is_some_and(|(start, end)| self.len >= start && self.len < end);
        if self.cr {
            let [h, l] = self.tail;
            let covered = self.sum.wrapping_sub(h).wrapping_sub(l);
            let bypass = h == b'@' && l == b'@' && self.policy.allows(self.header);
            let sc_ok = bypass || hex::decode2(&[h, l]) == Some(covered);
            return Status::Complete(if b == b'\n' {
                Skipped::End { checksum_ok: sc_ok }
            } else {
                Skipped::Broken
            });
        }
        if !in_text && (Header::from_byte(b).is_some() || b == b'\n') {
            return Status::Complete(Skipped::Broken);
        }
        if !in_text && b == b'\r' {
            self.cr = true;
            return Status::Partial;
        }
        self.sum = self.sum.wrapping_add(b);
        self.tail = [self.tail[1], b];
        self.len = self.len.saturating_add(1);
        Status::Partial
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    fn skip(frame: &[u8], policy: BypassPolicy) -> Vec<Status<Skipped>> {
        let mut env = [0u8; ENVELOPE_LEN];
        env.copy_from_slice(&frame[..ENVELOPE_LEN]);
        let header = Header::from_byte(frame[0]).unwrap();
        let mut s = FrameSkipper::new(header, &env, policy);
        frame[ENVELOPE_LEN..].iter().map(|&b| s.push(b)).collect()
    }

    fn end(frame: &[u8], policy: BypassPolicy) -> Skipped {
        skip(frame, policy).last().unwrap().complete().unwrap()
    }

    #[test]
    fn a_skipped_frame_ends_with_its_checksum_checked() {
        // 25BH Software Reset, as sent: SC 3C.
        let ok = b"!9925B3C\r\n";
        assert_eq!(
            end(ok, BypassPolicy::Reject),
            Skipped::End { checksum_ok: true }
        );
        let bad = b"!9925B3D\r\n";
        assert_eq!(
            end(bad, BypassPolicy::Reject),
            Skipped::End { checksum_ok: false }
        );
        // `@@` where the policy allows it.
        let bypass = b"!9925B@@\r\n";
        assert_eq!(
            end(bypass, BypassPolicy::CommandsOnly),
            Skipped::End { checksum_ok: true }
        );
        assert_eq!(
            end(bypass, BypassPolicy::Reject),
            Skipped::End { checksum_ok: false }
        );
    }

    /// Skipping runs where it can ([`FrameSkipper::skip_run`]) and pushing
    /// the rest ends every frame as pushing every byte does, in the same
    /// state: a long body, a 200H whose text holds header bytes and CR LF,
    /// a wrong SC, a cut frame, a CR without LF.
    #[test]
    fn a_run_is_skipped_as_its_bytes_would_be_pushed() {
        let mut long = b"!9926D0002".to_vec();
        long.extend_from_slice(
            b"000103001E001E0064000186A0FFFF9C64000201000000000000000030392B\r\n",
        );
        let frames: [&[u8]; 6] = [
            &long,
            b"!99200!#&\r\n89AB5D\r\n",
            b"!9920900100555\r\n",
            b"#99212011500#992322C\r\n",
            b"#992120115000\rX",
            b"&99E3A000000\n",
        ];
        for frame in frames {
            for policy in [BypassPolicy::Reject, BypassPolicy::Accept] {
                let mut env = [0u8; ENVELOPE_LEN];
                env.copy_from_slice(&frame[..ENVELOPE_LEN]);
                let header = Header::from_byte(frame[0]).unwrap();
                let mut by_byte = FrameSkipper::new(header, &env, policy);
                let mut pushed = Vec::new();
                for &b in &frame[ENVELOPE_LEN..] {
                    pushed.push((by_byte.push(b), by_byte));
                }
                let mut runs = FrameSkipper::new(header, &env, policy);
                let mut got = Vec::new();
                let mut rest = &frame[ENVELOPE_LEN..];
                while let Some((&b, tail)) = rest.split_first() {
                    let n = runs.skip_run(rest);
                    for _ in 0..n {
                        got.push((Status::Partial, runs));
                    }
                    if n > 0 {
                        // The run's state is the last byte's.
                        let (_, at) = pushed[got.len() - 1];
                        assert_eq!(runs, at, "{frame:?}");
                        rest = &rest[n..];
                        continue;
                    }
                    got.push((runs.push(b), runs));
                    rest = tail;
                }
                let statuses = |v: &[(Status<Skipped>, FrameSkipper)]| {
                    v.iter().map(|(s, _)| *s).collect::<Vec<_>>()
                };
                assert_eq!(statuses(&got), statuses(&pushed), "{frame:?}");
                assert_eq!(got.last().map(|g| g.1), pushed.last().map(|p| p.1));
            }
        }
    }

    #[test]
    fn a_header_byte_breaks_it_except_in_a_200h_text() {
        assert_eq!(end(b"!99212!", BypassPolicy::Reject), Skipped::Broken);
        assert_eq!(end(b"!99212\rX", BypassPolicy::Reject), Skipped::Broken);
        // 200H with `!99212` inside its ten characters: text, not a frame.
        let t = b"!99200!9921201391A\r\n";
        assert!(skip(t, BypassPolicy::Reject)
            .iter()
            .all(|&e| e == Status::Partial
                || e == Status::Complete(Skipped::End { checksum_ok: true })));
        assert_eq!(
            end(t, BypassPolicy::Reject),
            Skipped::End { checksum_ok: true }
        );
    }
}
