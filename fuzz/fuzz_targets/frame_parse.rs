//! One frame: `Frame::new_checked` under every bypass policy, then
//! `decode_any` with the field visitor (every field fits its wire format,
//! the fields account for every body byte). A message that decodes is
//! emitted again through its `Command` / `Response` / `ErrorResponse`; the
//! emission must be the input in normal form (hex digits upper case, real
//! checksum, `&` for error headers) and must decode to the same value.
//!
//! Also: for a single complete frame (the input starts with a header byte
//! and its first CR LF is its end), `Frame::new_checked` and the
//! `FrameDecoder` agree on whether it is valid.
#![no_main]

#[path = "common/mod.rs"]
mod common;

use iai_protocol_b::catalogue::{self, text_span};
use iai_protocol_b::checksum::{BypassPolicy, Checksum, ChecksumField};
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::message::*;
use libfuzzer_sys::fuzz_target;

/// The input up to SC with hex digits upper-cased outside the text field.
fn normalised(f: &Frame<'_>) -> Vec<u8> {
    let bytes = f.as_bytes();
    let text = text_span(f.header(), bytes);
    let mut out: Vec<u8> = bytes[..bytes.len() - 4]
        .iter()
        .enumerate()
        .map(|(i, &b)| match text {
            Some((s, e)) if i >= s && i < e => b,
            _ => b.to_ascii_uppercase(),
        })
        .collect();
    out[0] = f.header().byte();
    out
}

fn emit(msg: &AnyMessage<'_>, f: &Frame<'_>, buf: &mut [u8]) -> usize {
    let station = f.station();
    match msg {
        AnyMessage::Command(m) => m.emit(station, buf),
        AnyMessage::Response(m) => m.emit(station, buf),
        AnyMessage::Error(m) => m.emit(station, buf),
    }
    .expect("a decoded message must emit")
}

fn round_trip(f: &Frame<'_>) {
    let Some(msg) = common::decode_and_visit(f) else {
        return;
    };
    // The typed layer and the catalogue agree on the ID.
    match &msg {
        AnyMessage::Command(c) => {
            assert_eq!(c.id(), f.code());
            let info = catalogue::lookup(c.id()).expect("a command outside the catalogue");
            assert_eq!(info, c.info());
            assert_eq!(info.id, c.id());
            assert!(!info.name.is_empty());
        }
        AnyMessage::Response(r) => {
            assert_eq!(r.id(), f.code());
            let info = catalogue::lookup(r.id()).expect("a response outside the catalogue");
            assert_eq!(info, r.info());
            assert!(info.has_normal_response());
        }
        AnyMessage::Error(e) => assert_eq!(e.code, f.code()),
    }
    let mut buf = vec![0u8; f.len() + 16];
    let n = emit(&msg, f, &mut buf);
    let emitted = &buf[..n];
    assert_eq!(
        String::from_utf8_lossy(&emitted[..n - 4]),
        String::from_utf8_lossy(&normalised(f)),
        "emission is not the normal form of {msg:?}"
    );
    let again =
        Frame::new_checked(emitted, BypassPolicy::Reject).expect("emitted frame must be valid");
    assert_eq!(again.station(), f.station());
    let back = common::decode_and_visit(&again).expect("emitted frame must decode");
    assert_eq!(back, msg);
    // Emitting into a buffer one byte short fails cleanly.
    let mut short = vec![0u8; n - 1];
    let short_res = match &msg {
        AnyMessage::Command(m) => m.emit(f.station(), &mut short),
        AnyMessage::Response(m) => m.emit(f.station(), &mut short),
        AnyMessage::Error(m) => m.emit(f.station(), &mut short),
    };
    assert!(short_res.is_err(), "emission into a short buffer succeeded");
}

/// The decoder's verdict on `data` as one frame: `Ok` iff the whole input
/// came out as exactly one frame.
fn decoder_verdict(data: &[u8], policy: BypassPolicy) -> Result<(), String> {
    let mut dec = FrameDecoder::<4096>::with_policy(policy);
    let d = dec.decode(data);
    match d.status {
        Status::Complete(Event::Frame(f)) => {
            assert_eq!(d.consumed, data.len(), "a frame before the first CR LF");
            assert_eq!(f.as_bytes(), data);
            Ok(())
        }
        Status::Complete(Event::Error(e)) => Err(format!("{e:?}")),
        Status::Partial => Err("Partial".into()),
    }
}

fuzz_target!(|data: &[u8]| {
    let single_frame = data
        .first()
        .is_some_and(|&b| Header::from_byte(b).is_some())
        && data.len() <= 4096
        && data.windows(2).position(|w| w == b"\r\n") == Some(data.len().saturating_sub(2));
    for policy in [
        BypassPolicy::Reject,
        BypassPolicy::CommandsOnly,
        BypassPolicy::Accept,
    ] {
        let checked = Frame::new_checked(data, policy);
        if single_frame {
            let from_decoder = decoder_verdict(data, policy);
            assert_eq!(
                checked.is_ok(),
                from_decoder.is_ok(),
                "new_checked {checked:?} / decoder {from_decoder:?} under {policy:?}"
            );
        }
        let Ok(f) = checked else {
            continue;
        };
        assert_eq!(f.as_bytes(), data);
        assert!(f.len() >= 10);
        let sc_at = data.len() - 4;
        match f.checksum() {
            ChecksumField::Sum(s) => assert_eq!(s, Checksum::of(&data[..sc_at])),
            ChecksumField::Bypass => assert!(policy.allows(f.header())),
        }
        let _ = (f.body(), f.reader(), f.message_id(), f.error_code());
        round_trip(&f);
    }
});
