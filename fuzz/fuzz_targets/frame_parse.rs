//! One frame: `Frame::new_checked` under every bypass policy, then every
//! typed message's `parse`. A message that parses is emitted again; the
//! emission must be the input in normal form (hex digits upper case, real
//! checksum, `&` for error headers) and must parse to the same value.
#![no_main]

use iai_protocol_b::checksum::{BypassPolicy, Checksum, ChecksumField};
use iai_protocol_b::frame::Frame;
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

macro_rules! round_trip {
    ($f:expr, $ty:ident) => {{
        let f: &Frame<'_> = $f;
        if let Ok(msg) = $ty::parse(f) {
            let mut buf = vec![0u8; f.len() + 16];
            let n = msg
                .emit(f.station(), &mut buf)
                .expect("a parsed message must emit");
            let emitted = &buf[..n];
            assert_eq!(
                &emitted[..n - 4],
                &normalised(f)[..],
                "{}: emission is not the normal form",
                stringify!($ty)
            );
            let again = Frame::new_checked(emitted, BypassPolicy::Reject)
                .expect("emitted frame must be valid");
            assert_eq!(again.station(), f.station());
            let back = $ty::parse(&again).expect("emitted frame must parse");
            assert_eq!(back, msg);
        }
    }};
}

fuzz_target!(|data: &[u8]| {
    for policy in [
        BypassPolicy::Reject,
        BypassPolicy::CommandsOnly,
        BypassPolicy::Accept,
    ] {
        let Ok(f) = Frame::new_checked(data, policy) else {
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
        round_trip!(&f, TestCall);
        round_trip!(&f, TestCallResponse);
        round_trip!(&f, AxisStatusQuery);
        round_trip!(&f, AxisStatusResponse);
        round_trip!(&f, SystemStatusQuery);
        round_trip!(&f, SystemStatusResponse);
        round_trip!(&f, ErrorDetailQuery);
        round_trip!(&f, ErrorDetailResponse);
        round_trip!(&f, ChangePositionData2);
        round_trip!(&f, ChangePositionData2Response);
    }
});
