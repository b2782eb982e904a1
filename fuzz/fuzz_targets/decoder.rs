//! The push decoder on arbitrary bytes in arbitrary chunks.
//!
//! Input layout: byte 0 picks the bypass policy (bits 0-1) and the buffer
//! capacity (bits 2-3: 2,051 / 16 / 100); byte 1 gives the number of chunk
//! lengths k (0-15); the next k bytes are chunk lengths (each + 1, the last
//! chunk takes the rest); everything after that is the byte stream.
//!
//! Two decoders run side by side on the same stream: one fed in those
//! chunks through `decode` (called until `Partial`, including with the
//! empty rest of a chunk), the other fed byte by byte through `push` and
//! drained with `decode(&[])` after each byte. Every event of one is
//! compared with the next event of the other as it comes, so no event is
//! stored. Each runs in lockstep with a `ReferenceDecoder` (test-support:
//! the decoder without its short cuts) fed the same calls.
//!
//! Checked:
//! - no panic; both decoders give the same events, the same stats and the
//!   same `pending()` at the end (the events do not depend on the chunking);
//! - each gives, call for call, what the reference gives: bytes consumed,
//!   event, stats, `pending()`, `failed_envelope()`, `last_frame()`;
//! - `decode` consumes at most its input; `Partial` only with all of it
//!   consumed; an event with `consumed == 0` only while bytes are held
//!   (`pending() > 0` before the call: bytes of a failed text frame being
//!   decoded again);
//! - the accounting holds after *every* call, not only at the end: frame
//!   bytes returned + `stats().discarded_bytes` + `pending()` = bytes
//!   consumed so far (pending includes the bytes waiting to be decoded
//!   again); hence the events are at most as many as the input bytes;
//! - every frame returned passes `Frame::new_checked` under the decoder's
//!   policy, with a correct checksum (or an `@@` the policy allows), fits
//!   the capacity, and is what `last_frame()` shows; `FrameTooLong` names
//!   the capacity; `stats()` count the frames and errors seen;
//! - every frame goes through `decode_any` and the field visitor (see
//!   `common/mod.rs`);
//! - `decoder::FrameSkipper` (a frame passed over without a buffer): every
//!   frame the decoder returns but a 216H reply (whose counted text the
//!   skipper does not know), skipped from its envelope on, gives
//!   `Partial` for each byte and `End { checksum_ok: true }` at its LF;
//!   the whole stream scanned with the skipper alone (`skip_scan`) ends
//!   frames only at an LF, `checksum_ok` agreeing with the decoder's check
//!   (`skipped_frame`).
#![no_main]

#[path = "common/mod.rs"]
mod common;

use iai_protocol_b::catalogue::text_span;
use iai_protocol_b::checksum::{BypassPolicy, Checksum, ChecksumField};
use iai_protocol_b::decoder::{
    Event, FrameDecoder, FrameSkipper, Skipped, Status, DEFAULT_CAPACITY,
};
use iai_protocol_b::error::Error;
use iai_protocol_b::frame::{Frame, Header, ENVELOPE_LEN};
use libfuzzer_sys::fuzz_target;
use test_support::reference_decoder::{Reference, ReferenceDecoder};

/// The decoder's answer in the reference's terms.
fn as_reference(status: &Status<Event<'_>>) -> Reference {
    match status {
        Status::Partial => Reference::Partial,
        Status::Complete(Event::Frame(f)) => Reference::Frame(f.as_bytes().to_vec()),
        Status::Complete(Event::Error(e)) => Reference::Error(*e),
    }
}

/// Everything a caller can see of a decoder and its reference is the same.
fn same_as_reference<const N: usize>(dec: &FrameDecoder<N>, reference: &ReferenceDecoder) {
    assert_eq!(
        dec.stats(),
        reference.stats(),
        "stats differ from the reference"
    );
    assert_eq!(
        dec.pending(),
        reference.pending(),
        "pending differs from the reference"
    );
    assert_eq!(dec.failed_envelope(), reference.failed_envelope());
    assert_eq!(
        dec.last_frame().map(|f| f.as_bytes()),
        reference.last_frame()
    );
}

/// The byte-by-byte decoder, producing one event at a time.
struct ByByte<'s, const N: usize> {
    dec: FrameDecoder<N>,
    reference: ReferenceDecoder,
    rest: &'s [u8],
    /// The last call gave an event: drain with `decode(&[])` first.
    draining: bool,
}

impl<'s, const N: usize> ByByte<'s, N> {
    /// Hands the next event to `f`; `false` once the stream is used up and
    /// drained.
    fn next(&mut self, f: impl FnOnce(Event<'_>)) -> bool {
        loop {
            // What the last call left, before the next (its event borrowed
            // the decoder).
            same_as_reference(&self.dec, &self.reference);
            if self.draining {
                let (used, want) = self.reference.decode(&[]);
                let d = self.dec.decode(&[]);
                assert_eq!((d.consumed, used), (0, 0));
                assert_eq!(
                    as_reference(&d.status),
                    want,
                    "push differs from the reference"
                );
                if let Status::Complete(e) = d.status {
                    f(e);
                    return true;
                }
                self.draining = false;
                continue;
            }
            let Some((&b, rest)) = self.rest.split_first() else {
                return false;
            };
            self.rest = rest;
            let want = self.reference.push(b);
            let e = self.dec.push(b);
            assert_eq!(as_reference(&e), want, "push differs from the reference");
            if let Status::Complete(e) = e {
                self.draining = true;
                f(e);
                return true;
            }
        }
    }
}

/// Checks one frame the decoder returned.
fn check_frame<const N: usize>(f: &Frame<'_>, policy: BypassPolicy) {
    let bytes = f.as_bytes();
    assert!(bytes.len() <= N);
    let g = Frame::new_checked(bytes, policy).expect("decoder returned an invalid frame");
    assert_eq!(g, *f);
    let sc_at = bytes.len() - 4;
    match f.checksum() {
        ChecksumField::Sum(s) => assert_eq!(s, Checksum::of(&bytes[..sc_at])),
        ChecksumField::Bypass => assert!(policy.allows(f.header())),
    }
    // Skipped instead of decoded, the frame ends with a right checksum.
    if !counted_text(bytes) {
        let env: &[u8; ENVELOPE_LEN] = bytes[..ENVELOPE_LEN].try_into().expect("envelope");
        let mut sk = FrameSkipper::new(f.header(), env, policy);
        let (last, body) = bytes[ENVELOPE_LEN..]
            .split_last()
            .expect("a frame ends with LF");
        for &b in body {
            assert_eq!(
                sk.push(b),
                Status::Partial,
                "the skipper broke a valid frame"
            );
        }
        assert_eq!(
            sk.push(*last),
            Status::Complete(Skipped::End { checksum_ok: true }),
            "the skipper refused a valid frame"
        );
    }
    let _ = common::decode_and_visit(f);
}

/// Whether the frame `bytes` (header through LF) has a text field the
/// skipper does not know: a counted one (216H replies).
fn counted_text(bytes: &[u8]) -> bool {
    let header = Header::from_byte(bytes[0]).expect("a header byte");
    let id = bytes.get(3..6);
    let test_call = id == Some(&b"200"[..]);
    text_span(header, bytes).is_some() && !test_call
}

/// A frame the skipper ended with `checksum_ok` (but one with a counted
/// text, which the skipper does not know): compared with the frame check
/// the decoder runs (`Frame::new_checked`, `frame::validate`), which
/// checks the checksum last: `checksum_ok` is exactly whether it accepts
/// the frame, whenever it accepts it or refuses it for its checksum (a
/// wrong sum, a refused `@@`, a non-hex SC: nothing else was wrong).
fn skipped_frame(bytes: &[u8], checksum_ok: bool, policy: BypassPolicy) {
    if counted_text(bytes) {
        return;
    }
    let sc_at = bytes.len().saturating_sub(4);
    let verdict = match Frame::new_checked(bytes, policy) {
        Ok(_) => Some(true),
        Err(Error::ChecksumMismatch { .. } | Error::ChecksumBypassRejected) => Some(false),
        Err(Error::InvalidHexDigit { offset, .. }) if offset >= sc_at && sc_at >= 6 => Some(false),
        // Something else than the checksum is wrong: the skipper does not
        // look at it.
        Err(_) => None,
    };
    if let Some(accepted) = verdict {
        assert_eq!(
            checksum_ok,
            accepted,
            "the skipper and the decoder disagree on {:?}",
            String::from_utf8_lossy(bytes)
        );
    }
}

/// `FrameSkipper` over the stream: at each header byte, the envelope is
/// read, then the skipper runs to `End` or `Broken` (a header byte that
/// broke it starts the next frame).
fn skip_scan(policy: BypassPolicy, stream: &[u8]) {
    let is_header = |b: u8| Header::from_byte(b).is_some();
    let mut i = 0;
    'hunt: while i < stream.len() {
        if !is_header(stream[i]) {
            i += 1;
            continue;
        }
        let start = i;
        let Some(env) = stream.get(start..start + ENVELOPE_LEN) else {
            return;
        };
        if let Some(p) = env[1..]
            .iter()
            .position(|&b| is_header(b) || b == b'\r' || b == b'\n')
        {
            i = start + 1 + p;
            continue;
        }
        let header = Header::from_byte(env[0]).expect("a header byte");
        let env: &[u8; ENVELOPE_LEN] = env.try_into().expect("envelope");
        let mut sk = FrameSkipper::new(header, env, policy);
        i = start + ENVELOPE_LEN;
        while i < stream.len() {
            let b = stream[i];
            i += 1;
            match sk.push(b) {
                Status::Partial => {}
                Status::Complete(Skipped::End { checksum_ok }) => {
                    assert_eq!(b, b'\n');
                    skipped_frame(&stream[start..i], checksum_ok, policy);
                    continue 'hunt;
                }
                Status::Complete(Skipped::Broken) => {
                    if is_header(b) {
                        i -= 1;
                    }
                    continue 'hunt;
                }
            }
        }
    }
}

fn check<const N: usize>(policy: BypassPolicy, cuts: &[u8], stream: &[u8]) {
    skip_scan(policy, stream);
    let mut dec = FrameDecoder::<N>::with_policy(policy);
    let mut reference = ReferenceDecoder::new(N, policy);
    let mut other = ByByte::<N> {
        dec: FrameDecoder::with_policy(policy),
        reference: ReferenceDecoder::new(N, policy),
        rest: stream,
        draining: false,
    };
    let mut cuts = cuts.iter();
    let mut rest = stream;
    let mut consumed_total = 0usize;
    let mut in_frames = 0usize;
    let (mut frames, mut errors) = (0u32, 0u32);
    loop {
        let n = cuts
            .next()
            .map_or(rest.len(), |&c| usize::from(c) + 1)
            .min(rest.len());
        let mut chunk = &rest[..n];
        rest = &rest[n..];
        loop {
            // What the last call left, before the next.
            same_as_reference(&dec, &reference);
            let held = dec.pending();
            let (used, want) = reference.decode(chunk);
            let d = dec.decode(chunk);
            assert_eq!(d.consumed, used, "consumed differs from the reference");
            assert_eq!(
                as_reference(&d.status),
                want,
                "decode differs from the reference"
            );
            assert!(d.consumed <= chunk.len());
            consumed_total += d.consumed;
            chunk = &chunk[d.consumed..];
            let k = match d.status {
                Status::Partial => {
                    assert!(chunk.is_empty(), "Partial with input left");
                    None
                }
                Status::Complete(ev) => {
                    assert!(d.consumed > 0 || held > 0, "an event from nothing: {ev:?}");
                    let mut k = None;
                    let ran = other.next(|theirs| match (&ev, &theirs) {
                        (Event::Frame(a), Event::Frame(b)) => {
                            assert_eq!(a.as_bytes(), b.as_bytes(), "events depend on the chunking");
                            check_frame::<N>(a, policy);
                            in_frames += a.len();
                            frames += 1;
                            k = Some(Some(a.len()));
                        }
                        (Event::Error(a), Event::Error(b)) => {
                            assert_eq!(a, b, "events depend on the chunking");
                            if let Error::FrameTooLong { limit } = a {
                                assert_eq!(*limit, N);
                            }
                            errors += 1;
                            k = Some(None);
                        }
                        (a, b) => panic!("events depend on the chunking: {a:?} / {b:?}"),
                    });
                    assert!(ran, "the byte-by-byte decoder ran dry");
                    k
                }
            };
            if let Some(Some(len)) = k {
                let last = dec.last_frame().expect("last_frame after a frame");
                assert_eq!(last.len(), len);
            }
            let s = dec.stats();
            assert_eq!((s.frames, s.errors), (frames, errors));
            assert_eq!(
                in_frames + s.discarded_bytes as usize + dec.pending(),
                consumed_total,
                "bytes unaccounted for"
            );
            if k.is_none() {
                break;
            }
        }
        if rest.is_empty() {
            break;
        }
    }
    assert_eq!(consumed_total, stream.len());
    assert!(
        !other.next(|e| panic!("the byte-by-byte decoder has more: {e:?}")),
        "the byte-by-byte decoder has more events"
    );
    same_as_reference(&dec, &reference);
    same_as_reference(&other.dec, &other.reference);
    assert_eq!(dec.stats(), other.dec.stats());
    assert_eq!(dec.pending(), other.dec.pending());
    assert!(frames as usize + errors as usize <= stream.len());
}

fuzz_target!(|data: &[u8]| {
    let Some((&config, rest)) = data.split_first() else {
        return;
    };
    let Some((&k, rest)) = rest.split_first() else {
        return;
    };
    let k = usize::from(k % 16).min(rest.len());
    let (cuts, stream) = rest.split_at(k);
    let policy = match config & 3 {
        0 => BypassPolicy::CommandsOnly,
        1 => BypassPolicy::Reject,
        _ => BypassPolicy::Accept,
    };
    match (config >> 2) & 3 {
        0 | 3 => check::<DEFAULT_CAPACITY>(policy, cuts, stream),
        1 => check::<16>(policy, cuts, stream),
        _ => check::<100>(policy, cuts, stream),
    }
});
