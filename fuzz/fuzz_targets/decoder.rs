//! The push decoder on arbitrary bytes in arbitrary chunks.
//!
//! Input layout: byte 0 picks the bypass policy (bits 0-1) and the buffer
//! capacity (bits 2-3); byte 1 gives the number of chunk lengths k (0-15);
//! the next k bytes are chunk lengths (each + 1, the last chunk takes the
//! rest); everything after that is the byte stream.
//!
//! Checked: no panic; the events do not depend on the chunking (compared
//! with byte-by-byte `push`); every frame returned is valid on its own;
//! every input byte is in a frame, discarded or pending; every frame goes
//! through `decode_any` and the field visitor (see `common/mod.rs`).
#![no_main]

#[path = "common/mod.rs"]
mod common;

use iai_protocol_b::checksum::{BypassPolicy, Checksum, ChecksumField};
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::frame::Frame;
use iai_protocol_b::Error;
use libfuzzer_sys::fuzz_target;

#[derive(Debug, PartialEq)]
enum Out {
    Frame(Vec<u8>),
    Error(Error),
}

fn chunked<const N: usize>(
    policy: BypassPolicy,
    cuts: &[u8],
    stream: &[u8],
) -> (Vec<Out>, FrameDecoder<N>) {
    let mut dec = FrameDecoder::<N>::with_policy(policy);
    let mut out = Vec::new();
    let mut rest = stream;
    let mut cuts = cuts.iter();
    while !rest.is_empty() {
        let n = cuts
            .next()
            .map_or(rest.len(), |&c| c as usize + 1)
            .min(rest.len());
        let mut chunk = &rest[..n];
        rest = &rest[n..];
        // Bytes of a failed text frame decoded again come out with
        // `consumed` 0 (a few buffers' worth in a row at most); every other
        // event takes input.
        let mut replayed = 0;
        loop {
            let d = dec.decode(chunk);
            assert!(d.consumed <= chunk.len());
            match d.event {
                Event::NeedMore => {
                    assert_eq!(d.consumed, chunk.len());
                    break;
                }
                Event::Frame(f) => {
                    parse_all(&f);
                    out.push(Out::Frame(f.as_bytes().to_vec()))
                }
                Event::Error(e) => out.push(Out::Error(e)),
            }
            if d.consumed == 0 {
                replayed += 1;
                assert!(replayed <= 8 * (N + 1), "events without progress");
            } else {
                replayed = 0;
            }
            chunk = &chunk[d.consumed..];
        }
    }
    (out, dec)
}

fn parse_all(f: &Frame<'_>) {
    let _ = common::decode_and_visit(f);
}

fn check<const N: usize>(policy: BypassPolicy, cuts: &[u8], stream: &[u8]) {
    let (events, dec) = chunked::<N>(policy, cuts, stream);
    let mut by_byte = FrameDecoder::<N>::with_policy(policy);
    let mut pushed = Vec::new();
    for &b in stream {
        match by_byte.push(b) {
            Event::NeedMore => {}
            Event::Frame(f) => pushed.push(Out::Frame(f.as_bytes().to_vec())),
            Event::Error(e) => pushed.push(Out::Error(e)),
        }
        // Drain the bytes being decoded again, as `push` asks.
        loop {
            match by_byte.decode(&[]).event {
                Event::NeedMore => break,
                Event::Frame(f) => pushed.push(Out::Frame(f.as_bytes().to_vec())),
                Event::Error(e) => pushed.push(Out::Error(e)),
            }
        }
    }
    assert_eq!(events, pushed, "events depend on the chunking");
    assert_eq!(dec.stats(), by_byte.stats());

    let mut in_frames = 0usize;
    let mut frames = 0usize;
    for e in &events {
        match e {
            Out::Frame(bytes) => {
                frames += 1;
                in_frames += bytes.len();
                assert!(bytes.len() <= N);
                let f =
                    Frame::new_checked(bytes, policy).expect("decoder returned an invalid frame");
                let sc_at = bytes.len() - 4;
                match f.checksum() {
                    ChecksumField::Sum(s) => assert_eq!(s, Checksum::of(&bytes[..sc_at])),
                    ChecksumField::Bypass => assert!(policy.allows(f.header())),
                }
            }
            Out::Error(Error::FrameTooLong { limit }) => assert_eq!(*limit, N),
            Out::Error(_) => {}
        }
    }
    let s = dec.stats();
    assert_eq!(s.frames as usize, frames);
    assert_eq!(s.errors as usize, events.len() - frames);
    assert_eq!(
        in_frames + s.discarded_bytes as usize + dec.pending(),
        stream.len()
    );
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
        0 | 3 => check::<2051>(policy, cuts, stream),
        1 => check::<16>(policy, cuts, stream),
        _ => check::<100>(policy, cuts, stream),
    }
});
