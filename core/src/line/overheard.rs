//! Frames the line hears while no engine can keep them (an owner holds its
//! reply in its buffer, or no engine runs): each is checked as it passes,
//! its SC summed by a [`FrameSkipper`], its first bytes kept (enough for a
//! fence's echo) and its bytes fingerprinted, so that the line can still
//! place it (a late reply, a copy, an echo) without a buffer for it.

use super::receiver::{fingerprint_more, FINGERPRINT_START};
use crate::checksum::BypassPolicy;
use crate::decoder::{FrameSkipper, Skipped, Status};
use crate::error::Error;
use crate::frame::{read_envelope, Header, Station, ENVELOPE_LEN, TRAILER_LEN};

/// Bytes of a frame kept: a fence's echo (20) and any frame as short.
pub(crate) const KEPT: usize = 24;

/// A frame heard in passing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Passed<'a> {
    /// A frame whose SC checked: its envelope, its body if it was short
    /// enough to keep, and the fingerprint of its bytes.
    Whole {
        header: Header,
        station: Station,
        code: u16,
        body: Option<&'a [u8]>,
        print: u32,
    },
    /// A broken frame, with its envelope if it could be read.
    Broken(Option<(Header, Station, u16)>, Error),
}

/// The decoder of frames heard in passing.
#[derive(Debug, Clone)]
pub(crate) struct Overheard {
    kept: [u8; KEPT],
    /// Bytes of the frame so far.
    len: usize,
    envelope: Option<(Header, Station, u16)>,
    skipper: Option<FrameSkipper>,
    print: u32,
}

impl Overheard {
    pub(crate) const fn new() -> Self {
        Overheard {
            kept: [0; KEPT],
            len: 0,
            envelope: None,
            skipper: None,
            print: FINGERPRINT_START,
        }
    }

    fn restart(&mut self) {
        self.len = 0;
        self.envelope = None;
        self.skipper = None;
        self.print = FINGERPRINT_START;
    }

    fn keep(&mut self, b: u8) {
        self.keep_all(core::slice::from_ref(&b));
    }

    /// [`Overheard::keep`] for each of `bytes`.
    fn keep_all(&mut self, bytes: &[u8]) {
        if let Some(room) = self.kept.get_mut(self.len..) {
            let n = room.len().min(bytes.len());
            if let (Some(dst), Some(src)) = (room.get_mut(..n), bytes.get(..n)) {
                dst.copy_from_slice(src);
            }
        }
        self.len = self.len.saturating_add(bytes.len());
        self.print = fingerprint_more(self.print, bytes);
    }

    /// Decodes `input` up to the first frame that ends (whole or broken);
    /// returns the bytes used. A frame's body goes through a run at a time
    /// ([`FrameSkipper::skip_run`]), the rest a byte at a time.
    pub(crate) fn decode(&mut self, input: &[u8]) -> (usize, Status<Passed<'_>>) {
        let mut i = 0;
        while let Some(&b) = input.get(i) {
            if let Some(skipper) = self.skipper.as_mut() {
                let rest = input.get(i..).unwrap_or(&[]);
                let n = skipper.skip_run(rest);
                if n > 0 {
                    self.keep_all(rest.get(..n).unwrap_or(&[]));
                    i += n;
                    continue;
                }
            }
            i += 1;
            match self.step(b) {
                Step::More => {}
                Step::Broken(env, e, again) => {
                    self.restart();
                    if again {
                        self.keep(b);
                    }
                    return (i, Status::Complete(Passed::Broken(env, e)));
                }
                Step::Whole => {
                    let (used, len) = (i, self.len);
                    let Some((header, station, code)) = self.envelope else {
                        self.restart();
                        let e = Error::BodyTooShort { offset: len };
                        return (used, Status::Complete(Passed::Broken(None, e)));
                    };
                    let print = self.print;
                    self.restart();
                    let body_end = len.saturating_sub(TRAILER_LEN);
                    let body = (len <= KEPT)
                        .then(|| self.kept.get(ENVELOPE_LEN..body_end))
                        .flatten();
                    return (
                        used,
                        Status::Complete(Passed::Whole {
                            header,
                            station,
                            code,
                            body,
                            print,
                        }),
                    );
                }
            }
        }
        (input.len(), Status::Partial)
    }

    fn step(&mut self, b: u8) -> Step {
        let header = Header::from_byte(b);
        if self.len == 0 {
            if header.is_some() {
                self.keep(b);
            }
            return Step::More;
        }
        if let Some(mut skipper) = self.skipper {
            let status = skipper.push(b);
            self.skipper = Some(skipper);
            if !matches!(status, Status::Complete(Skipped::Broken)) {
                self.keep(b);
            }
            let cut = Error::Truncated { len: self.len };
            return match status {
                Status::Partial => Step::More,
                Status::Complete(Skipped::End { checksum_ok: true }) => Step::Whole,
                Status::Complete(Skipped::End { checksum_ok: false }) => {
                    Step::Broken(self.envelope, skipper.checksum_error(), false)
                }
                Status::Complete(Skipped::Broken) => {
                    Step::Broken(self.envelope, cut, header.is_some())
                }
            };
        }
        // The envelope: header, station, ID.
        if header.is_some() || b == b'\r' || b == b'\n' {
            let cut = Error::Truncated { len: self.len };
            return Step::Broken(None, cut, header.is_some());
        }
        self.keep(b);
        if self.len == ENVELOPE_LEN {
            let mut env = [0u8; ENVELOPE_LEN];
            if let Some(src) = self.kept.get(..ENVELOPE_LEN) {
                env.copy_from_slice(src);
            }
            self.envelope = read_envelope(&env);
            match self.envelope {
                Some((h, _, _)) => {
                    self.skipper = Some(FrameSkipper::new(h, &env, BypassPolicy::Reject))
                }
                None => {
                    let e = Error::InvalidHeader {
                        byte: self.kept.first().copied().unwrap_or(0),
                    };
                    return Step::Broken(None, e, false);
                }
            }
        }
        Step::More
    }
}

/// What one byte did.
enum Step {
    More,
    Whole,
    /// Broken, with the envelope if read and why; `true` if the byte
    /// starts the next frame.
    Broken(Option<(Header, Station, u16)>, Error, bool),
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(mut input: &[u8]) -> std::vec::Vec<std::string::String> {
        extern crate std;
        let mut d = Overheard::new();
        let mut out = std::vec::Vec::new();
        while !input.is_empty() {
            let (used, status) = d.decode(input);
            input = &input[used..];
            match status {
                Status::Complete(Passed::Whole { code, body, .. }) => out.push(std::format!(
                    "{code:03X} {:?}",
                    body.map(|b| std::string::String::from_utf8_lossy(b).into_owned())
                )),
                Status::Complete(Passed::Broken(env, _)) => {
                    out.push(std::format!("broken {:03X}", env.map_or(0, |e| e.2)))
                }
                Status::Partial => {}
            }
        }
        out
    }

    extern crate std;

    #[test]
    fn short_frames_keep_their_body_long_ones_their_envelope() {
        // A fence's echo, then a 212H reply for axis 1 (28 bytes).
        let echo = b"#9920012345600011D\r\n";
        let status = b"#99212011500000000001388A5\r\n";
        let mut wire = echo.to_vec();
        wire.extend_from_slice(status);
        let got = all(&wire);
        assert_eq!(got[0], "200 Some(\"1234560001\")");
        assert_eq!(got[1], "212 None");
    }

    /// What a stream of frames gives, fed in pieces of `piece` bytes: each
    /// frame's bytes used, envelope, body and fingerprint, or why broken.
    fn pieces(input: &[u8], piece: usize) -> std::vec::Vec<std::string::String> {
        let mut d = Overheard::new();
        let mut out = std::vec::Vec::new();
        let mut used = 0;
        for chunk in input.chunks(piece) {
            let mut rest = chunk;
            while !rest.is_empty() {
                let (n, status) = d.decode(rest);
                rest = &rest[n..];
                used += n;
                if let Status::Complete(p) = status {
                    out.push(std::format!("{used} {p:?}"));
                }
            }
        }
        out
    }

    /// A 26DH's body goes by a run at a time, the rest a byte at a time:
    /// whole, byte by byte or in pieces, the same frames, bodies and
    /// fingerprints, at the same bytes.
    #[test]
    fn the_same_frames_however_the_bytes_come() {
        let mut wire = b"noise!9926D0002".to_vec();
        wire.extend_from_slice(
            b"000103001E001E0064000186A0FFFF9C64000201000000000000000030392B\r\n",
        );
        // A fence's echo, a 200H with header bytes and CR LF in its text,
        // a wrong SC, a cut frame, a CR without LF, a 212H reply.
        wire.extend_from_slice(b"#9920012345600011D\r\n");
        wire.extend_from_slice(b"#99200!#&\r\n12345E4\r\n");
        wire.extend_from_slice(b"#992322D\r\n#99212#992120115\rX");
        wire.extend_from_slice(b"#99212011500000000001388A5\r\n");
        let whole = pieces(&wire, wire.len());
        assert_eq!(whole.len(), 7, "{whole:?}");
        for piece in [1, 2, 3, 7, 16, 64] {
            assert_eq!(pieces(&wire, piece), whole, "in pieces of {piece}");
        }
    }

    #[test]
    fn a_bad_checksum_or_a_cut_frame_is_broken_by_its_envelope() {
        assert_eq!(all(b"#992322D\r\n"), ["broken 232"]);
        // Cut by the next frame's header, which then decodes.
        assert_eq!(all(b"#99212#992322C\r\n"), ["broken 212", "232 Some(\"\")"]);
    }
}
