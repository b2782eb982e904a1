//! The word-at-a-time hex paths (`iai_protocol_b::hex`) against the
//! per-byte reference paths, on arbitrary bytes.
//!
//! Input: any bytes. Every 8-byte window (at every offset) is decoded as 8,
//! 4 and 2 digits and compared with `decode_bytewise`; every 4-byte window
//! is taken as a `u32` value, encoded as 8, 4 and 2 digits and compared with
//! `encode_bytewise` (and the returned sums with `sum_bytewise`, the
//! digits decoded back); the checksum of every suffix, from three starting
//! values, is compared with `sum_bytewise` (both `sum` and `sum_words`).
//! `Batch` decodes every window as 2+2+4 digits: valid exactly when all
//! eight bytes are digits, values and sum as the per-byte path.
#![no_main]

use iai_protocol_b::hex;
use libfuzzer_sys::fuzz_target;

fn decode_window(d: &[u8; 8]) {
    let reference = hex::decode_bytewise(d);
    let mut b = hex::Batch::new();
    let x = b.decode2(d[..2].try_into().unwrap());
    let y = b.decode2(d[2..4].try_into().unwrap());
    let z = b.decode4(d[4..].try_into().unwrap());
    assert_eq!(b.is_valid(), reference.is_ok());
    assert_eq!(b.sum(), d.iter().map(|&c| u32::from(c)).sum::<u32>());
    if let Ok(v) = reference {
        assert_eq!(u64::from(x) << 24 | u64::from(y) << 16 | u64::from(z), v);
    }
    assert_eq!(hex::decode8(d), reference.ok().map(|v| v as u32), "{d:?}");
    assert_eq!(hex::first_invalid(d), reference.err());
    for half in [&d[..4], &d[4..]] {
        let four: &[u8; 4] = half.try_into().unwrap();
        assert_eq!(
            hex::decode4(four),
            hex::decode_bytewise(half).ok().map(|v| v as u16)
        );
    }
    let two: &[u8; 2] = d[..2].try_into().unwrap();
    assert_eq!(
        hex::decode2(two),
        hex::decode_bytewise(two).ok().map(|v| v as u8)
    );
}

fn encode_value(v: u32) {
    let sum = |d: &[u8]| u32::from(d.iter().fold(0u8, |s, &b| s.wrapping_add(b)));
    let mut reference = [0u8; 8];
    assert!(hex::encode_bytewise(u64::from(v), &mut reference));
    let mut out = [0u8; 8];
    let s = hex::put8(v, &mut out);
    assert_eq!(out, reference);
    assert_eq!(s & 0xFF, sum(&out));
    assert_eq!(hex::encode8(v), reference);
    assert_eq!(hex::decode8(&out), Some(v));
    let mut out4 = [0u8; 4];
    let s = hex::put4(v as u16, &mut out4);
    assert_eq!(out4[..], reference[4..]);
    assert_eq!(s & 0xFF, sum(&out4));
    assert_eq!(hex::decode4(&out4), Some(v as u16));
    let mut out2 = [0u8; 2];
    let s = hex::put2(v as u8, &mut out2);
    assert_eq!(out2[..], reference[6..]);
    assert_eq!(s & 0xFF, sum(&out2));
    assert_eq!(hex::decode2(&out2), Some(v as u8));
}

fuzz_target!(|data: &[u8]| {
    for w in data.windows(8) {
        decode_window(w.try_into().unwrap());
    }
    for w in data.windows(4) {
        encode_value(u32::from_le_bytes(w.try_into().unwrap()));
    }
    for start in 0..data.len().min(64) {
        let s = &data[start..];
        for acc in [0u8, 0x80, 0xFF] {
            assert_eq!(hex::sum(acc, s), hex::sum_bytewise(acc, s));
            assert_eq!(hex::sum_words(acc, s), hex::sum_bytewise(acc, s));
        }
    }
});
