//! Fault scenarios for the bridge library in the virtual-time host model
//! (they used to be QEMU runs of tens of seconds each): thousands of seeds,
//! each a different mix of controller faults (flipped bits in its replies,
//! lost bytes, dropped, late and `&` replies, noise), and host-side
//! corruption.
//!
//! Checked for every seed:
//! * a 26DH ends, after at most a few whole re-sends by the host, with the
//!   `#` reply carrying the full count, and the controller's table equals
//!   the source (nothing lost, skipped or reordered);
//! * every `&` the bridge sends on the way is one of its own 26DH codes;
//! * a host 26DH with one flipped bit is answered `&` B01 (or B04 when the
//!   flip made it look longer than it is), never `#`;
//! * a pass-through reply is always a valid frame from the controller's
//!   station with the command's ID (or `&`), or nothing;
//! * the bridge never broke the [`Poll`] contract (no stale waits) and no
//!   upstream byte overran the ring.
//!
//! The scenario count and the time taken are printed.

use std::time::Instant;

use firmware_example::codes;
use firmware_example::serial::FlowControl;
use host_tests::bridge::model::{self, ModelConfig};
use host_tests::bridge::{check_table, command_26dh, reply_26dh};
use host_tests::sim::{Faults, Rng, Simulator};
use host_tests::table::table;
use iai_protocol_b::axis::AxisPattern;
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::message::{AxisStatusQuery, Message};

/// Seeds per test function (four functions run in parallel).
const SEEDS: u64 = 600;

/// A fault mix drawn from `seed`.
///
/// No bit flips on the way into the controller: protocol B's checksum is a
/// sum, so two flips in one chunk that change it by opposite amounts (one
/// bit set, the same bit cleared elsewhere) pass it, and the controller
/// writes a wrong record while the bridge reports success (seed 227 of an
/// earlier version of this suite did exactly that). Only reading the table
/// back can catch it; that is the transfer engine's verification, not the
/// bridge's. Lost bytes shift the frame and are caught.
fn faults(seed: u64) -> Faults {
    let mut r = Rng::new(seed ^ 0x5EED);
    let p = |r: &mut Rng, max: f64| (r.below(1_000) as f64 / 1_000.0) * max;
    Faults {
        flip_bit_in: 0.0,
        drop_byte_in: p(&mut r, 1e-4),
        flip_bit_out: p(&mut r, 3e-3),
        drop_every_nth_reply: r.chance(0.5).then(|| 3 + r.below(10) as u32),
        late_every_nth_reply: r
            .chance(0.3)
            .then(|| (2 + r.below(8) as u32, 100 + r.below(5_000) as u32)),
        error_reply: p(&mut r, 0.15),
        garbage_before_reply: p(&mut r, 0.2),
    }
}

fn config(seed: u64) -> ModelConfig {
    let baud = [9_600, 38_400, 115_200][(seed % 3) as usize];
    let flow = if seed % 4 == 3 {
        FlowControl::RtsCts
    } else {
        FlowControl::XonXoff
    };
    ModelConfig::new(baud, flow)
}

/// One 26DH under faults, re-sent whole after each `&` (at most 6 sends).
fn stream_under_faults(seed: u64) {
    let cfg = config(seed);
    let station = cfg.bridge.controller_station;
    let n = 20 + (seed % 40) as u32;
    let records: Vec<_> = table(n, 1 + (seed % 8) as u8, seed as u32).collect();
    let cmd = command_26dh(station, &records);
    let mut sim = Simulator::tta(station).with_faults(faults(seed), seed);
    sim.response_delay_ms = (seed % 50) as u32;
    let mut bridge = model::bridge(&cfg.bridge);
    let want = reply_26dh(station, n as u16);
    for send in 1..=6 {
        let r = model::run(&cfg, &mut bridge, &mut sim, &[&cmd]);
        assert_eq!(r.overruns, 0, "seed {seed}");
        assert_eq!(r.stale_waits, 0, "seed {seed}");
        let reply = r.replies[0]
            .clone()
            .unwrap_or_else(|| panic!("seed {seed}: no reply to send {send}"));
        if reply == want {
            check_table(&sim.table, &records).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
            return;
        }
        let f = Frame::new_checked(&reply, Default::default())
            .unwrap_or_else(|e| panic!("seed {seed}: invalid reply {reply:?}: {e}"));
        assert_eq!(f.header(), Header::Error, "seed {seed}: {reply:?}");
        assert!(
            [codes::CONTROLLER_TIMEOUT, codes::CONTROLLER_ERROR].contains(&f.code()),
            "seed {seed}: unexpected code {:03X}",
            f.code()
        );
    }
    panic!("seed {seed}: no `#` after 6 sends ({:?})", sim.stats());
}

/// A 26DH with one bit flipped on the way in: `&` B01, never `#`.
fn corrupted_upstream(seed: u64) {
    let cfg = config(seed);
    let station = cfg.bridge.controller_station;
    let records: Vec<_> = table(30, 4, seed as u32).collect();
    let mut cmd = command_26dh(station, &records);
    let mut rng = Rng::new(seed);
    // Any byte after the envelope, before CR LF.
    let at = 6 + rng.below(cmd.len() as u64 - 8) as usize;
    cmd[at] ^= 1 << rng.below(7);
    let mut sim = Simulator::tta(station);
    let mut bridge = model::bridge(&cfg.bridge);
    let r = model::run(&cfg, &mut bridge, &mut sim, &[&cmd]);
    let reply = r.replies[0].clone();
    // A flip that turned a byte into a header or CR/LF cuts the frame:
    // then the bridge answers B01 at once, or nothing if the envelope
    // itself broke; a `#` would be a false success.
    match reply {
        Some(reply) => {
            let f = Frame::new_checked(&reply, Default::default())
                .unwrap_or_else(|e| panic!("seed {seed}: invalid reply {reply:?}: {e}"));
            // B01 at the broken byte or at the checksum; B04 when the flip
            // made the decoder expect more bytes than the host sent.
            assert_eq!(f.header(), Header::Error, "seed {seed}: {reply:?}");
            assert!(
                [codes::UPSTREAM_FRAME, codes::UPSTREAM_STALLED].contains(&f.code()),
                "seed {seed}: flip at {at}: {reply:?}"
            );
        }
        None => assert!(
            cmd[at..].iter().any(|b| b"!#&%\r\n".contains(b)),
            "seed {seed}: no reply"
        ),
    }
}

/// Pass-through under faults: a reply is the controller's, or nothing.
fn passthrough_under_faults(seed: u64) {
    let cfg = config(seed);
    let station = cfg.bridge.controller_station;
    let mut sim = Simulator::tta(station).with_faults(faults(seed), seed);
    let mut buf = [0u8; 32];
    let n = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(1 + (seed % 4) as u8),
    }
    .emit(station, &mut buf)
    .expect("212H");
    let cmd = buf[..n].to_vec();
    let mut bridge = model::bridge(&cfg.bridge);
    let cmds: Vec<&[u8]> = vec![&cmd; 5];
    let r = model::run(&cfg, &mut bridge, &mut sim, &cmds);
    assert_eq!(r.stale_waits, 0, "seed {seed}");
    for reply in r.replies.iter().flatten() {
        let f = Frame::new_checked(reply, Default::default())
            .unwrap_or_else(|e| panic!("seed {seed}: relayed a broken frame {reply:?}: {e}"));
        assert_eq!(f.station(), station, "seed {seed}");
        match f.header() {
            Header::Response => assert_eq!(f.code(), 0x212, "seed {seed}"),
            Header::Error => {}
            Header::Command => panic!("seed {seed}: relayed a command"),
        }
    }
}

fn suite(first: u64) {
    let started = Instant::now();
    for seed in first..first + SEEDS {
        stream_under_faults(seed);
        corrupted_upstream(seed);
        passthrough_under_faults(seed);
    }
    eprintln!(
        "seeds {first}..{}: {} scenarios (26DH under controller faults, corrupted host 26DH, \
         pass-through under faults) in {:?}",
        first + SEEDS,
        3 * SEEDS,
        started.elapsed()
    );
}

#[test]
fn fault_seeds_0() {
    suite(0);
}

#[test]
fn fault_seeds_1() {
    suite(SEEDS);
}

#[test]
fn fault_seeds_2() {
    suite(2 * SEEDS);
}

#[test]
fn fault_seeds_3() {
    suite(3 * SEEDS);
}
