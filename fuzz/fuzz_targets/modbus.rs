//! The Modbus gateway's frame handler on arbitrary bytes.
//!
//! Input layout: byte 0 picks the policy (bits 0-1: forward all,
//! read-only, an allow-list of 232H only) and how the rest is cut into
//! frames: the input is split at every 0xFE byte (each piece arrives as
//! one frame, then the line is silent). Between frames the bridge runs
//! the gateway's exchanges on a controller line that answers with the
//! same piece.
//!
//! Checked: no panic; every answer has a valid CRC, is for unit 1, and
//! follows a request to unit 1 (never a broadcast or another unit); no
//! answer is longer than 256 bytes.
#![no_main]

use firmware_example::bridge::{Bridge, NoPort};
use firmware_example::config::{AllowList, Config, Policy, Source};
use firmware_example::modbus::{rtu, Gateway};
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
    for piece in rest.split(|&b| b == 0xFE) {
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
