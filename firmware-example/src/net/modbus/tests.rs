//! The Modbus TCP sockets against a second smoltcp interface over an
//! in-memory wire, in simulated time ([`crate::net::testkit`]): answers,
//! the idle close, the third connection, a client that vanishes.

extern crate std;
use std::vec::Vec;

use super::*;
use crate::net::config::Addressing;
use crate::net::testkit::{net_config, Rig};

fn rig() -> Rig<'static> {
    Rig::new(net_config(Addressing::Static))
}

/// Read input registers 9000H..9001H (PNOW of axis 1), transaction `tid`.
fn read_pnow(tid: u16) -> Vec<u8> {
    let mut v = tid.to_be_bytes().to_vec();
    v.extend_from_slice(&[0, 0, 0, 6, 1, 4, 0x90, 0, 0, 2]);
    v
}

/// The answer to [`read_pnow`] `tid` with PNOW 12,000 (2EE0H).
fn pnow_12000(tid: u16) -> Vec<u8> {
    let mut v = tid.to_be_bytes().to_vec();
    v.extend_from_slice(&[0, 0, 0, 7, 1, 4, 4, 0, 0, 0x2E, 0xE0]);
    v
}

#[test]
fn two_clients_are_answered_a_silent_one_is_closed_after_the_idle_time() {
    let mut rig = rig();
    rig.gateway.regs.cache.axes[0].current_position = 12_000;
    rig.run(10, 1);
    rig.connect(0, MODBUS_PORT, 40_000);
    rig.connect(1, MODBUS_PORT, 40_001);
    rig.run(20, 1);
    assert!(rig.client(0).may_send() && rig.client(1).may_send());
    // Two requests back to back on one connection, one on the other.
    let mut two = read_pnow(0x0A0B);
    two.extend(read_pnow(0x0C0D));
    rig.client(0).send_slice(&two).unwrap();
    rig.client(1).send_slice(&read_pnow(5)).unwrap();
    rig.run(20, 1);
    let answer = pnow_12000;
    let mut both = answer(0x0A0B);
    both.extend(answer(0x0C0D));
    assert_eq!(rig.received(0), both);
    assert_eq!(rig.received(1), answer(5));
    // A third connection while both are taken is reset by the stack.
    rig.connect(2, MODBUS_PORT, 40_002);
    rig.run(20, 1);
    assert!(!rig.client(2).is_open(), "{}", rig.client(2).state());
    // Client 1 keeps asking every 10 s; client 0 says nothing more.
    for k in 0..6u16 {
        rig.run(10_000, 5);
        rig.client(1).send_slice(&read_pnow(100 + k)).unwrap();
        rig.run(20, 1);
        assert_eq!(rig.received(1), answer(100 + k));
    }
    // 60 s after its last request, client 0 was closed: it reads our FIN.
    assert!(!rig.client(0).may_recv(), "{}", rig.client(0).state());
    assert!(rig.client(1).may_recv(), "{}", rig.client(1).state());
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.connections, 2);
    assert_eq!(stats.requests, 9);
    assert_eq!(stats.idle_closed, 1);
    // Its socket listens again: a new client is served.
    rig.client(0).close();
    rig.run(3_000, 5);
    rig.client(0).abort();
    rig.run(10, 1);
    rig.connect(0, MODBUS_PORT, 40_003);
    rig.run(20, 1);
    rig.client(0).send_slice(&read_pnow(77)).unwrap();
    rig.run(20, 1);
    assert_eq!(rig.received(0), answer(77));
}

#[test]
fn a_length_field_out_of_range_resets_the_connection() {
    let mut rig = rig();
    rig.run(10, 1);
    rig.connect(0, MODBUS_PORT, 40_000);
    rig.run(20, 1);
    // Protocol ID 1: dropped, the next request answered.
    let mut bad = read_pnow(1);
    bad[3] = 1;
    bad.extend(read_pnow(2));
    rig.client(0).send_slice(&bad).unwrap();
    rig.run(20, 1);
    let got = rig.received(0);
    assert_eq!(got[..2], [0, 2]);
    assert_eq!(got.len(), 13);
    // Length 255: the stream cannot be followed.
    rig.client(0)
        .send_slice(&[0, 3, 0, 0, 0, 255, 1, 4])
        .unwrap();
    rig.run(20, 1);
    assert!(!rig.client(0).is_open(), "{}", rig.client(0).state());
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.framing_reset, 1);
}

#[test]
fn a_client_that_vanishes_is_reset_after_the_silence_limit() {
    use crate::net::host::SILENCE_LIMIT_MS;
    let silence = SILENCE_LIMIT_MS as u32;
    let mut rig = rig();
    rig.gateway.regs.cache.axes[0].current_position = 12_000;
    rig.run(10, 1);
    rig.connect(0, MODBUS_PORT, 40_000);
    rig.connect(1, MODBUS_PORT, 40_001);
    rig.run(20, 1);
    rig.client(0).send_slice(&read_pnow(1)).unwrap();
    rig.client(1).send_slice(&read_pnow(2)).unwrap();
    rig.run(50, 1);
    assert_eq!(rig.received(0), pnow_12000(1));
    assert_eq!(rig.received(1), pnow_12000(2));
    // Client 0 is unplugged: no FIN, no RST, its frames lost both ways.
    let last = rig.vanish(0).expect("client 0's frames arrived");
    // Client 1 asks every 5 s and stays served throughout.
    let mut asked = 2u16;
    let mut ask = |r: &mut Rig<'static>| {
        if r.now.is_multiple_of(5_000) {
            asked += 1;
            r.client(1).send_slice(&read_pnow(asked)).unwrap();
        }
    };
    // Half way, both sockets are still taken: a third client is reset by
    // the stack.
    rig.run_until(silence / 2, 1, |r| {
        ask(r);
        false
    });
    assert!(matches!(
        rig.net.modbus().unwrap().slot(0),
        Some(Slot::Open { .. })
    ));
    rig.connect(2, MODBUS_PORT, 40_002);
    rig.run(20, 1);
    assert!(!rig.client(2).is_open(), "{}", rig.client(2).state());
    // The vanished client's socket is let go after the silence limit,
    // well before the idle time.
    let freed = rig.run_until(silence, 1, |r| {
        ask(r);
        !matches!(r.net.modbus().unwrap().slot(0), Some(Slot::Open { .. }))
    });
    assert!(
        freed,
        "still open {} ms after its last frame",
        rig.now - last
    );
    let after = rig.now - last;
    std::eprintln!(
        "vanished Modbus client let go {after} ms after its last frame (silence limit {silence} ms, idle time {IDLE_MS} ms)"
    );
    assert!(
        (silence..silence + 10).contains(&after),
        "let go {after} ms after its last frame"
    );
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.idle_closed, 0);
    assert_eq!(stats.connections, 2);
    // Client 1 had every answer; a new client takes the freed socket.
    rig.run(50, 1);
    let want: Vec<u8> = (3..=asked).flat_map(pnow_12000).collect();
    assert!(asked >= 5);
    assert_eq!(rig.received(1), want);
    rig.connect(2, MODBUS_PORT, 40_003);
    rig.run(20, 1);
    rig.client(2).send_slice(&read_pnow(99)).unwrap();
    rig.run(50, 1);
    assert_eq!(rig.received(2), pnow_12000(99));
}
