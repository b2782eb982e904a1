//! The Modbus TCP sockets against a second smoltcp interface over an
//! in-memory wire, in simulated time ([`crate::net::testkit`]): four
//! clients answered in order, the fifth connection reset, the idle close,
//! a bad length, a client that vanishes.

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
fn four_clients_are_answered_in_order_a_fifth_is_reset_a_silent_one_closed() {
    assert_eq!(CLIENTS, 4);
    let mut rig = rig();
    rig.gateway.regs.cache.axes[0].current_position = 12_000;
    rig.run(10, 1);
    for n in 0..CLIENTS {
        rig.connect(n, MODBUS_PORT, 40_000 + n as u16);
    }
    rig.run(20, 1);
    for n in 0..CLIENTS {
        assert!(
            rig.client(n).may_send(),
            "client {n}: {}",
            rig.client(n).state()
        );
    }
    // All four at once, each with three requests back to back: every
    // client gets its own answers, in its order, their IDs echoed.
    let tid = |n: usize, k: u16| (n as u16 + 1) << 8 | k;
    for n in 0..CLIENTS {
        let three: Vec<u8> = (1..=3).flat_map(|k| read_pnow(tid(n, k))).collect();
        rig.client(n).send_slice(&three).unwrap();
    }
    rig.run(20, 1);
    for n in 0..CLIENTS {
        let want: Vec<u8> = (1..=3).flat_map(|k| pnow_12000(tid(n, k))).collect();
        assert_eq!(rig.received(n), want, "client {n}");
    }
    // A fifth connection while all four are taken is reset by the stack;
    // the four are still served.
    rig.connect(CLIENTS, MODBUS_PORT, 40_010);
    rig.run(20, 1);
    assert!(
        !rig.client(CLIENTS).is_open(),
        "{}",
        rig.client(CLIENTS).state()
    );
    for n in 0..CLIENTS {
        rig.client(n).send_slice(&read_pnow(tid(n, 4))).unwrap();
    }
    rig.run(20, 1);
    for n in 0..CLIENTS {
        assert_eq!(rig.received(n), pnow_12000(tid(n, 4)), "client {n}");
    }
    // Client 1 keeps asking every 10 s; the others say nothing more.
    for k in 0..6u16 {
        rig.run(10_000, 5);
        rig.client(1).send_slice(&read_pnow(100 + k)).unwrap();
        rig.run(20, 1);
        assert_eq!(rig.received(1), pnow_12000(100 + k));
    }
    // 60 s after their last request, the silent ones were closed: they
    // read our FIN.
    for n in [0, 2, 3] {
        assert!(
            !rig.client(n).may_recv(),
            "client {n}: {}",
            rig.client(n).state()
        );
    }
    assert!(rig.client(1).may_recv(), "{}", rig.client(1).state());
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.connections, 4);
    assert_eq!(stats.requests, 4 * 4 + 6);
    assert_eq!(stats.idle_closed, 3);
    // Their sockets listen again: the client reset before is served now,
    // and so is a new one.
    for n in [0, 2, 3] {
        rig.client(n).close();
    }
    rig.run(3_000, 5);
    for n in [0, 2, 3] {
        rig.client(n).abort();
    }
    rig.client(CLIENTS).abort();
    rig.run(10, 1);
    rig.connect(CLIENTS, MODBUS_PORT, 40_011);
    rig.connect(0, MODBUS_PORT, 40_012);
    rig.run(20, 1);
    rig.client(CLIENTS).send_slice(&read_pnow(77)).unwrap();
    rig.client(0).send_slice(&read_pnow(78)).unwrap();
    rig.run(20, 1);
    assert_eq!(rig.received(CLIENTS), pnow_12000(77));
    assert_eq!(rig.received(0), pnow_12000(78));
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.connections, 6);
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
    // All four sockets taken: clients 0 and 1 ask, 2 and 3 are connected.
    for n in 0..CLIENTS {
        rig.connect(n, MODBUS_PORT, 40_000 + n as u16);
    }
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
    // Half way, all four sockets are still taken: a fifth client is reset
    // by the stack.
    rig.run_until(silence / 2, 1, |r| {
        ask(r);
        false
    });
    assert!(matches!(
        rig.net.modbus().unwrap().slot(0),
        Some(Slot::Open { .. })
    ));
    rig.connect(CLIENTS, MODBUS_PORT, 40_010);
    rig.run(20, 1);
    assert!(
        !rig.client(CLIENTS).is_open(),
        "{}",
        rig.client(CLIENTS).state()
    );
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
    assert_eq!(stats.connections, 4);
    // Client 1 had every answer; a new client takes the freed socket.
    rig.run(50, 1);
    let want: Vec<u8> = (3..=asked).flat_map(pnow_12000).collect();
    assert!(asked >= 5);
    assert_eq!(rig.received(1), want);
    rig.client(CLIENTS).abort();
    rig.run(10, 1);
    rig.connect(CLIENTS, MODBUS_PORT, 40_011);
    rig.run(20, 1);
    rig.client(CLIENTS).send_slice(&read_pnow(99)).unwrap();
    rig.run(50, 1);
    assert_eq!(rig.received(CLIENTS), pnow_12000(99));
}

#[test]
fn a_client_that_closes_or_resets_mid_request_frees_its_socket_at_once() {
    let mut rig = rig();
    rig.gateway.regs.cache.axes[0].current_position = 12_000;
    rig.run(10, 1);
    for n in 0..CLIENTS {
        rig.connect(n, MODBUS_PORT, 40_000 + n as u16);
    }
    rig.run(20, 1);
    // Client 0: a whole request and half of the next, then FIN; clients 1
    // and 2: half a request, then FIN; client 3: half a request, then RST.
    let mut first = read_pnow(1);
    first.extend(&read_pnow(2)[..7]);
    rig.client(0).send_slice(&first).unwrap();
    for n in 1..CLIENTS {
        let half = read_pnow(n as u16 + 10);
        rig.client(n).send_slice(&half[..7]).unwrap();
    }
    rig.run(10, 1);
    let t0 = rig.now;
    for n in 0..3 {
        rig.client(n).close();
    }
    rig.client(3).abort();
    // Every socket is let go within a few rounds, not after the idle time.
    let freed = rig.run_until(1_000, 1, |r| {
        (0..CLIENTS).all(|n| !matches!(r.net.modbus().unwrap().slot(n), Some(Slot::Open { .. })))
    });
    let after = rig.now - t0;
    std::eprintln!("four clients closed or reset mid-request: their sockets let go in {after} ms");
    assert!(freed, "still held {after} ms after their FIN or RST");
    // Client 0 got the answer to its whole request, then our FIN.
    rig.run(50, 1);
    assert_eq!(rig.received(0), pnow_12000(1));
    assert!(!rig.client(0).may_recv(), "{}", rig.client(0).state());
    // A new client is served at once.
    rig.client(CLIENTS).abort();
    rig.connect(CLIENTS, MODBUS_PORT, 40_020);
    rig.send_when_connected(CLIENTS, &read_pnow(99), 100);
    rig.run(20, 1);
    assert_eq!(rig.received(CLIENTS), pnow_12000(99));
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!((stats.requests, stats.idle_closed), (2, 0));
}
