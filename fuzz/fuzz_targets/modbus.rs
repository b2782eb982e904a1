//! The Modbus gateway's frame handler on arbitrary bytes.
//!
//! Input layout: byte 0 picks the policy (bits 0-1: forward all,
//! read-only, an allow-list of 232H only) and how the rest is cut into
//! frames: the input is split at every 0xFE byte (each piece arrives as
//! one frame, then the line is silent). Bit 2: the harness appends each
//! piece's CRC, so that the fuzzer reaches every function past the CRC
//! check (15 and 16 with any byte count, 43/14, unknown functions). Bit
//! 3: each piece is a Modbus TCP request instead (unit and PDU, behind an
//! MBAP header the harness builds). Between frames the bridge runs the
//! gateway's exchanges on a controller line that answers with the same
//! piece.
//!
//! Checked: no panic; every RTU answer has a valid CRC, is for unit 1,
//! and follows a request to unit 1 (never a broadcast or another unit);
//! every TCP answer echoes the transaction ID, has protocol 0 and the
//! length of what follows, and carries the request's unit, 1 or 255; an
//! exception answer's function is the request's with bit 7 and its code
//! 1, 2, 3 or 6; no answer is longer than 256 bytes (260 on TCP).
#![no_main]

use firmware_example::bridge::{Bridge, NoPort};
use firmware_example::config::{AllowList, Config, Policy, Source};
use firmware_example::modbus::{rtu, tcp, Gateway};
use libfuzzer_sys::fuzz_target;
use test_support::VecPort;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let policy = match mode & 0b11 {
        0 => Policy::ForwardAll,
        1 => Policy::ReadOnly,
        _ => Policy::Allow(AllowList::of(&[0x232])),
    };
    let cfg = Config {
        policy,
        ..Config::DEFAULT
    };
    let mut gw = Gateway::new(cfg.modbus, cfg.policy);
    let mut bridge = Bridge::new(cfg, Source::Default, 1);
    let mut mb = VecPort::default();
    let mut down = VecPort::default();
    let mut ms = 0u32;
    let with_crc = mode & 0b100 != 0;
    let over_tcp = mode & 0b1000 != 0;
    for (k, piece) in rest.split(|&b| b == 0xFE).enumerate() {
        if over_tcp {
            let tid = k as u16;
            let mut adu = tid.to_be_bytes().to_vec();
            adu.extend([0, 0]);
            adu.extend((piece.len() as u16).to_be_bytes());
            adu.extend(piece);
            let mut resp = tcp::Response::new();
            gw.serve_tcp(&adu, &mut resp, ms);
            if !resp.is_empty() {
                assert!(resp.len() <= tcp::MAX_ADU);
                assert_eq!(resp[..4], [(tid >> 8) as u8, tid as u8, 0, 0], "IDs echoed");
                let len = usize::from(u16::from_be_bytes([resp[4], resp[5]]));
                assert_eq!(len, resp.len() - 6, "MBAP length");
                assert!(
                    matches!(piece.first(), Some(1 | 0xFF)),
                    "answered unit 1 or 255 only"
                );
                assert_eq!(resp.get(6), piece.first(), "the request's unit");
                check_pdu(&resp[7..], piece.get(1).copied());
            }
            continue;
        }
        let mut piece = piece.to_vec();
        if with_crc {
            let crc = rtu::crc16(&piece);
            piece.extend(crc.to_le_bytes());
        }
        let piece = &piece[..];
        mb.input.extend_from_slice(piece);
        let us = ms.wrapping_mul(1_000);
        gw.serve(&mut mb, ms, us).unwrap();
        // The silence after the piece.
        ms = ms.wrapping_add(5);
        gw.serve(&mut mb, ms, ms.wrapping_mul(1_000)).unwrap();
        let answer = std::mem::take(&mut mb.output);
        if !answer.is_empty() {
            assert!(answer.len() <= rtu::MAX_FRAME);
            assert_eq!(rtu::crc16(&answer), 0, "answer CRC");
            assert_eq!(answer[0], 1, "answer for unit 1");
            assert_eq!(piece.first(), Some(&1), "answered a request to unit 1 only");
            check_pdu(&answer[1..answer.len() - 2], piece.get(1).copied());
        }
        // The controller answers the gateway's exchanges with the piece.
        down.input.extend_from_slice(piece);
        for _ in 0..8 {
            let _ = bridge.poll_with(&mut NoPort, &mut down, &mut gw, ms);
            ms = ms.wrapping_add(500);
        }
        down.output.clear();
    }
});

/// An answer's PDU: the request's function, or its exception with a code
/// the gateway gives.
fn check_pdu(pdu: &[u8], function: Option<u8>) {
    let f = pdu.first().copied();
    assert!(
        f == function || f == function.map(|f| f | 0x80),
        "function {f:?} for {function:?}"
    );
    if f.is_some_and(|f| f & 0x80 != 0) {
        assert_eq!(pdu.len(), 2, "an exception is its function and code");
        assert!(matches!(pdu[1], 1 | 2 | 3 | 6), "exception code {}", pdu[1]);
    }
}
