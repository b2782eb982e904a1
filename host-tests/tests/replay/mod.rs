//! Replaying a byte stream through the push decoder, shared by the decoder
//! and malformed-input tests.

use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::error::Error;

/// An event with the frame copied out of the decoder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Out {
    Frame(Vec<u8>),
    Error(Error),
}

/// Feeds `input` in the given chunk lengths (the last chunk takes the rest)
/// through `decode`, collecting every event, then drains what the decoder
/// still has to decode again. Checks the `consumed` contract: an event
/// consumes input unless it comes from bytes being decoded again.
pub fn decode_chunks<const N: usize>(
    dec: &mut FrameDecoder<N>,
    input: &[u8],
    cuts: &[usize],
) -> Vec<Out> {
    let mut out = Vec::new();
    let mut rest = input;
    let mut cuts = cuts.iter();
    while !rest.is_empty() {
        let n = cuts.next().copied().unwrap_or(rest.len()).min(rest.len());
        let mut chunk = &rest[..n];
        rest = &rest[n..];
        loop {
            let d = dec.decode(chunk);
            assert!(d.consumed <= chunk.len());
            match d.status {
                Status::Partial => {
                    assert_eq!(d.consumed, chunk.len(), "Partial before the chunk ended");
                    break;
                }
                Status::Complete(Event::Frame(f)) => out.push(Out::Frame(f.as_bytes().to_vec())),
                Status::Complete(Event::Error(e)) => out.push(Out::Error(e)),
            }
            chunk = &chunk[d.consumed..];
        }
    }
    out.extend(drain(dec));
    out
}

/// The events still held by `dec` (frames a failed text frame had
/// swallowed), with no new input.
pub fn drain<const N: usize>(dec: &mut FrameDecoder<N>) -> Vec<Out> {
    let mut out = Vec::new();
    loop {
        let d = dec.decode(&[]);
        assert_eq!(d.consumed, 0);
        match d.status {
            Status::Partial => return out,
            Status::Complete(Event::Frame(f)) => out.push(Out::Frame(f.as_bytes().to_vec())),
            Status::Complete(Event::Error(e)) => out.push(Out::Error(e)),
        }
    }
}

/// Feeds `input` one byte at a time through `push`, draining after each.
pub fn push_bytes<const N: usize>(dec: &mut FrameDecoder<N>, input: &[u8]) -> Vec<Out> {
    let mut out = Vec::new();
    for &b in input {
        match dec.push(b) {
            Status::Partial => {}
            Status::Complete(Event::Frame(f)) => out.push(Out::Frame(f.as_bytes().to_vec())),
            Status::Complete(Event::Error(e)) => out.push(Out::Error(e)),
        }
        out.extend(drain(dec));
    }
    out
}
