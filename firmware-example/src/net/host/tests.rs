//! The protocol-B hosts against a second smoltcp interface in simulated
//! time ([`crate::net::testkit`]): a host that vanishes without FIN or RST
//! holds the bridge only until the stack's silence limit (idle) or the
//! stall limit (an answer waiting for it), a connection made meanwhile is
//! held and refused, one made just before the limit is served after it.

extern crate std;
use std::vec::Vec;

use iai_protocol_b::checksum::ChecksumMode;
use iai_protocol_b::frame::{emit_frame, Frame, Header};

use super::*;
use crate::config::Config;
use crate::net::config::Addressing;
use crate::net::testkit::{net_config, Rig, PB_PORT};

/// The bridge's own station.
const BRIDGE: Station = Config::DEFAULT.bridge_station;

/// The bridge's side with the bridge served each round; tick 10.
fn rig() -> Rig<'static> {
    let mut rig = Rig::new(net_config(Addressing::Static));
    rig.serve_bridge = true;
    rig.run(10, 1);
    rig
}

/// The bridge's status query.
fn status_query() -> Vec<u8> {
    let mut buf = [0u8; 32];
    let n = emit_frame(
        &mut buf,
        Header::Command,
        BRIDGE,
        codes::STATUS_QUERY,
        ChecksumMode::Compute,
        |_| Ok(()),
    )
    .unwrap();
    buf[..n].to_vec()
}

/// The frames in `bytes` (CR LF ended), as header, station and code.
fn frames(bytes: &[u8]) -> Vec<(Header, Station, u16)> {
    bytes
        .split_inclusive(|&b| b == b'\n')
        .map(|f| {
            let f = Frame::new_checked(f, Default::default())
                .unwrap_or_else(|e| panic!("{e:?}: {:?}", std::string::String::from_utf8_lossy(f)));
            (f.header(), f.station(), f.code())
        })
        .collect()
}

/// The status query's answer, alone.
fn is_status_answer(bytes: &[u8]) -> bool {
    frames(bytes) == [(Header::Response, BRIDGE, codes::STATUS_QUERY)]
}

/// Host on client socket 0, then unplugged; `in_flight`: right after its
/// status query reached the bridge, so that the answer never reaches it
/// (otherwise once all is answered and acknowledged). It holds the bridge
/// until `bound` ms after its last frame arrived, give or take a round:
/// a host that connects 5 s after it vanished is held for [`HOLD_MS`] and
/// refused; one that connects [`HOLD_MS`]/2 before the bound is held and
/// then served, its status query answered.
fn vanished_host(in_flight: bool, bound: u32) {
    let mut rig = rig();
    rig.connect(0, PB_PORT, 41_000);
    rig.run(20, 1);
    assert_eq!(rig.net.hosts().session(), Session::Host(0));
    rig.client(0).send_slice(&status_query()).unwrap();
    if in_flight {
        // The query goes in, the bridge answers into the socket; the
        // answer goes out in the next round, and is lost.
        rig.run(1, 1);
        assert!(rig.net.hosts().stats().hosts == 1 && rig.received(0).is_empty());
    } else {
        rig.run(50, 1);
        assert!(is_status_answer(&rig.received(0)));
    }
    let last = rig.vanish(0).expect("host frames arrived");
    assert!(
        rig.now - last <= 50,
        "last frame at {last}, now {}",
        rig.now
    );

    // 5 s later, a second host: held for HOLD_MS, then `&` B0B and closed;
    // its query is not answered.
    rig.run(5_000, 1);
    rig.connect(1, PB_PORT, 41_001);
    rig.send_when_connected(1, &status_query(), 100);
    let held = rig.now;
    let mut got = Vec::new();
    let refused = rig.run_until(3_000, 1, |r| {
        got.extend(r.received(1));
        !got.is_empty() && !r.client(1).may_recv()
    });
    assert!(refused, "no refusal and close: {got:?}");
    assert_eq!(frames(&got), [(Header::Error, BRIDGE, codes::HOST_BUSY)]);
    let refused_after = rig.now - held;
    assert!(
        (HOLD_MS..HOLD_MS + 50).contains(&refused_after),
        "refused {refused_after} ms after it connected"
    );
    assert_eq!(rig.net.hosts().session(), Session::Host(0));
    assert_eq!(rig.net.hosts().stats().refused, 1);
    rig.client(1).close();

    // Half the hold before the bound, a third host: held, then served
    // once the vanished one is let go.
    rig.run(last + bound - HOLD_MS / 2 - rig.now, 1);
    rig.connect(2, PB_PORT, 41_002);
    rig.send_when_connected(2, &status_query(), 100);
    let mut freed = None;
    let mut got = Vec::new();
    let served = rig.run_until(2 * HOLD_MS, 1, |r| {
        if freed.is_none() && r.net.hosts().session() != Session::Host(0) {
            freed = Some(r.now);
        }
        got.extend(r.received(2));
        got.ends_with(b"\r\n")
    });
    assert!(served, "not served: {got:?}");
    assert!(is_status_answer(&got), "{got:?}");
    let freed = freed.expect("the vanished host let go") - last;
    let answered = rig.now - last;
    std::eprintln!(
        "vanished host (answer in flight: {in_flight}): let go {freed} ms after its last \
         frame (bound {bound} ms), the next host answered at {answered} ms"
    );
    assert!(
        (bound..bound + 10).contains(&freed),
        "let go {freed} ms after its last frame, bound {bound} ms"
    );
    assert!(
        answered >= freed && answered < freed + 20,
        "answered at {answered} ms"
    );
    let stats = rig.net.hosts().stats();
    assert_eq!(stats.hosts, 2);
    assert_eq!(stats.refused, 1);
    assert_eq!(stats.stalled, u32::from(in_flight));
}

#[test]
fn an_idle_host_that_vanishes_is_let_go_after_the_silence_limit() {
    vanished_host(false, SILENCE_LIMIT_MS as u32);
}

#[test]
fn a_host_that_vanishes_with_an_answer_owed_is_let_go_after_the_stall_limit() {
    vanished_host(true, HOST_STALL_MS);
}
