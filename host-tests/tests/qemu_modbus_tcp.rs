//! Modbus TCP on the Ethernet build end to end, with third-party Modbus
//! clients: the gateway (`tools/gateway.sh --ethernet`'s binary) runs the
//! `lm3s6965-eth` firmware under QEMU with the simulated controller
//! behind it, QEMU's user network forwarding `modbus-tcp 127.0.0.1:PORT`
//! to the firmware's port 502, and
//!
//! 1. **pymodbus** (Modbus TCP framer, `host-tests/plc/pymodbus_plc.py
//!    --tcp`): servo on, home, wait for HEND, a numeric move to
//!    25.500 mm, wait for PEND, read PNOW, compared with the simulator's
//!    212H asked by the real `iai` tool on the protocol-B port; then 500
//!    positions of 8 axes written through the table window (2200H) and
//!    read back through it (21F0H, 2200H), equal, and `iai table read
//!    --all` on the protocol-B port finds exactly those 500 in the
//!    controller (the times of the write, the read-back and iai's read are
//!    printed);
//! 2. **mbpoll** (`-m tcp`, one process per request,
//!    `plc_gateway::mbpoll`): servo on (off first if the PLC before left
//!    it on), home, wait for HEND, a numeric move to 12.000 mm, wait for
//!    PEND, read PNOW, compared with the simulator's 212H; then 500 other
//!    positions of 8 axes written through the table window, a whole
//!    window per call, each write waited for through CMDST, read back
//!    through it equal, and `iai table read --all` finds exactly those;
//! 3. raw sockets: four clients at once, each with two requests sent back
//!    to back before any answer is read, each answered in order with its
//!    transaction IDs; a fifth connection meanwhile is reset (by the
//!    firmware's stack: QEMU's user network closes it), and once one of
//!    the four has left a new client is served; an ADU with a protocol ID
//!    other than 0 dropped unanswered (the connection goes on), a length
//!    field out of range closes the connection while the others are still
//!    served;
//! 4. raw sockets, the standard (`plc_gateway::standard`): functions 15
//!    and 16 whose byte count is not the quantity's (03), Read Device
//!    Identification with the simulator's 201H version, unsupported
//!    functions (01) whatever the MBAP length, unit 255 as the gateway;
//!    four clients that close (FIN) or reset (RST) their connection in
//!    the middle of a request free their sockets at once: a new client is
//!    served within seconds, not after the 60 s idle time;
//! 5. the README's **worked example** ("Worked example: Modbus TCP"), run
//!    by bash as written, with mbpoll.
//!
//! pymodbus comes from the venv `tools/setup.sh` makes (`.venv`), mbpoll
//! from the Debian package it installs. A client that is absent is
//! skipped with its reason printed; the test fails if both are.

mod gateway_proc;
mod plc_gateway;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use gateway_proc::{Gateway, ETHERNET};
use host_tests::qemu::build_ethernet_firmware;
use host_tests::table::table;
use iai_protocol_b::position::PositionRecord;
use plc_gateway::standard::{standard_cases, worked_example, Raw};
use plc_gateway::{on_path, pymodbus_python, pymodbus_sequence, PYMODBUS_MOVE_TO};

/// Positions pymodbus writes and reads back through the table window.
const POSITIONS: u32 = 500;
/// Modbus TCP clients the firmware must serve at once (the issue's
/// figure; the firmware's `net::modbus::CLIENTS`, checked here from the
/// outside: one fewer fails to connect the last, one more answers the
/// connection that must be reset).
const CLIENTS: usize = 4;

const PNOW: u16 = 0x9000;
/// A Modbus TCP request: `tid`, protocol `proto`, unit 1, function 04,
/// `count` registers from `addr`.
fn read_inputs(tid: u16, proto: u16, addr: u16, count: u16) -> Vec<u8> {
    let mut v = tid.to_be_bytes().to_vec();
    v.extend(proto.to_be_bytes());
    v.extend([0, 6, 1, 4]);
    v.extend(addr.to_be_bytes());
    v.extend(count.to_be_bytes());
    v
}

/// Reads exactly `n` bytes from `c` (its read timeout set).
fn read_n(c: &mut TcpStream, n: usize) -> Vec<u8> {
    let mut buf = vec![0u8; n];
    c.read_exact(&mut buf).expect("an answer");
    buf
}

/// Whether `c` was closed or reset by the other end, without a byte:
/// what a connection the firmware refused or dropped reads.
fn closed_unanswered(c: &mut TcpStream) -> Result<(), String> {
    let mut rest = Vec::new();
    match c.read_to_end(&mut rest) {
        Ok(_) if rest.is_empty() => Ok(()),
        Ok(_) => Err(format!("answered {rest:02X?}")),
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::ConnectionReset | std::io::ErrorKind::ConnectionAborted
            ) =>
        {
            Ok(())
        }
        Err(e) => Err(format!("still open ({e}), received {rest:02X?}")),
    }
}

/// MBAP framing and the clients as the firmware serves them, on raw
/// sockets.
fn raw_framing(addr: &str, pnow: i32) {
    let connect = || {
        let c = TcpStream::connect(addr).expect("connect to Modbus TCP");
        c.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        c.set_nodelay(true).unwrap();
        c
    };
    let pnow_words = (pnow as u32).to_be_bytes();
    let answer = |tid: u16| {
        let mut v = tid.to_be_bytes().to_vec();
        v.extend([0, 0, 0, 7, 1, 4, 4]);
        v.extend(pnow_words);
        v
    };
    // Four clients, each answered once it is connected (QEMU's user
    // network takes one connection at a time to the firmware), so that
    // all four hold a socket of the firmware.
    let mut clients: Vec<TcpStream> = (0..CLIENTS)
        .map(|n| {
            let mut c = connect();
            let tid = 0x100 * (n as u16 + 1);
            c.write_all(&read_inputs(tid, 0, PNOW, 2)).unwrap();
            assert_eq!(read_n(&mut c, 13), answer(tid), "client {n} connected");
            c
        })
        .collect();
    // All four at once: two requests back to back on each, sent before
    // any answer is read; each client gets its own, in order.
    let t = Instant::now();
    for (n, c) in clients.iter_mut().enumerate() {
        let base = 0x100 * (n as u16 + 1);
        let mut two = read_inputs(base + 1, 0, PNOW, 2);
        two.extend(read_inputs(base + 2, 0, PNOW, 2));
        c.write_all(&two).unwrap();
    }
    for (n, c) in clients.iter_mut().enumerate() {
        let base = 0x100 * (n as u16 + 1);
        let got = read_n(c, 26);
        assert_eq!(got[..13], answer(base + 1), "client {n} first {got:02X?}");
        assert_eq!(got[13..], answer(base + 2), "client {n} second {got:02X?}");
    }
    let at_once = t.elapsed();
    // A fifth while the four are connected: the firmware's stack resets
    // it, QEMU closes our side; no answer.
    let mut fifth = connect();
    // The request may find the connection already gone.
    let _ = fifth.write_all(&read_inputs(0x0500, 0, PNOW, 2));
    if let Err(why) = closed_unanswered(&mut fifth) {
        panic!("a fifth connection while four are served: {why}");
    }
    // The four are still served.
    for (n, c) in clients.iter_mut().enumerate() {
        let tid = 0x100 * (n as u16 + 1) + 3;
        c.write_all(&read_inputs(tid, 0, PNOW, 2)).unwrap();
        assert_eq!(read_n(c, 13), answer(tid), "client {n} after the fifth");
    }
    // One leaves: its socket listens again and a new client is served
    // (tried again while the firmware is still closing the old one).
    drop(clients.pop());
    let end = Instant::now() + Duration::from_secs(10);
    let (mut again, tries) = (1..)
        .find_map(|k| {
            let mut c = connect();
            c.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
            let asked = c.write_all(&read_inputs(0x0600, 0, PNOW, 2)).is_ok();
            let mut got = [0u8; 13];
            if asked && c.read_exact(&mut got).is_ok() {
                assert_eq!(got.to_vec(), answer(0x0600), "the client after one left");
                return Some((c, k));
            }
            assert!(
                Instant::now() < end,
                "no client served after one of four left"
            );
            std::thread::sleep(Duration::from_millis(200));
            None
        })
        .expect("served");
    again
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    println!(
        "raw sockets: {CLIENTS} clients at once, 2 requests each answered in order in \
         {:.0} ms; connection {} meanwhile reset; a new client served after one left \
         (attempt {tries})",
        at_once.as_secs_f64() * 1000.0,
        CLIENTS + 1
    );
    let mut a = clients.remove(0);
    let b = &mut clients[0];
    // Protocol ID 1: not Modbus, dropped; the next request is answered.
    let mut mixed = read_inputs(0x0101, 1, PNOW, 2);
    mixed.extend(read_inputs(0x0202, 0, PNOW, 2));
    a.write_all(&mixed).unwrap();
    assert_eq!(read_n(&mut a, 13), answer(0x0202), "after a protocol ID 1");
    // A length field of 1: the stream cannot be followed, the connection
    // is closed (reset) without an answer.
    a.write_all(&[0, 9, 0, 0, 0, 1, 1]).unwrap();
    if let Err(why) = closed_unanswered(&mut a) {
        panic!("a length of 1: {why}");
    }
    // The others are still served.
    b.write_all(&read_inputs(8, 0, PNOW, 2)).unwrap();
    assert_eq!(read_n(b, 13), answer(8));
    again.write_all(&read_inputs(9, 0, PNOW, 2)).unwrap();
    assert_eq!(read_n(&mut again, 13), answer(9));
}

/// Resets `c` on drop (SO_LINGER 0: an RST instead of a FIN).
fn reset_on_drop(c: &TcpStream) {
    use std::os::fd::AsRawFd;
    let linger = libc::linger {
        l_onoff: 1,
        l_linger: 0,
    };
    // SAFETY: a valid socket and a linger struct of the size given.
    let r = unsafe {
        libc::setsockopt(
            c.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_LINGER,
            (&linger as *const libc::linger).cast(),
            std::mem::size_of::<libc::linger>() as libc::socklen_t,
        )
    };
    assert_eq!(r, 0, "SO_LINGER");
}

/// A new client on `addr`, tried again (every 100 ms, at most 10 s after
/// `t0`) until it is answered: it, the attempts, the seconds since `t0`.
fn served_after(addr: &str, t0: Instant, why: &str) -> (TcpStream, u32, f64) {
    for k in 1.. {
        let mut c = TcpStream::connect(addr).expect("connect to Modbus TCP");
        c.set_nodelay(true).unwrap();
        c.set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        let asked = c.write_all(&read_inputs(0x07FF, 0, PNOW, 2)).is_ok();
        let mut got = [0u8; 13];
        if asked && c.read_exact(&mut got).is_ok() {
            assert_eq!(got[..2], [0x07, 0xFF]);
            c.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
            return (c, k, t0.elapsed().as_secs_f64());
        }
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "no client served 10 s after {why}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    unreachable!()
}

/// Clients that hold a socket (each answered once) and then send half of
/// a request.
fn holding_half(addr: &str, n: usize, tid: u16) -> Vec<TcpStream> {
    (0..n)
        .map(|i| {
            let mut c = TcpStream::connect(addr).expect("connect to Modbus TCP");
            c.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
            c.set_nodelay(true).unwrap();
            let tid = tid + i as u16;
            c.write_all(&read_inputs(tid, 0, PNOW, 2)).unwrap();
            assert_eq!(read_n(&mut c, 13)[..2], tid.to_be_bytes(), "client {i}");
            c.write_all(&read_inputs(tid | 0x80, 0, PNOW, 2)[..7])
                .unwrap();
            c
        })
        .collect()
}

/// Four clients take the four sockets and send half of a request, then
/// close their side (FIN): a new client is served at once (before, their
/// sockets were held for the 60 s idle time while the partial requests
/// sat in the buffers, and no one was served). Then with that client and
/// three more holding the sockets, one resets (SO_LINGER 0) mid-request:
/// the next client is served at once too.
fn closed_mid_request(addr: &str) {
    let mut fin = holding_half(addr, CLIENTS, 0x700);
    std::thread::sleep(Duration::from_millis(200));
    let t0 = Instant::now();
    for c in &fin {
        c.shutdown(std::net::Shutdown::Write).unwrap();
    }
    let (first, tries, secs) = served_after(addr, t0, "four clients closed mid-request");
    // They read our close, without an answer to the half request.
    for (n, c) in fin.iter_mut().enumerate() {
        if let Err(why) = closed_unanswered(c) {
            panic!("client {n} after its FIN mid-request: {why}");
        }
    }
    println!(
        "four clients closed (FIN) mid-request: a new client served {secs:.2} s later (attempt {tries})"
    );
    let mut rst = holding_half(addr, CLIENTS - 1, 0x710);
    let last = rst.pop().expect("three");
    std::thread::sleep(Duration::from_millis(200));
    let t0 = Instant::now();
    reset_on_drop(&last);
    drop(last);
    let (_, tries, secs) = served_after(addr, t0, "a client reset mid-request");
    println!(
        "a client reset (RST) mid-request: the next served {secs:.2} s later (attempt {tries})"
    );
    drop((first, rst));
}

#[test]
fn pymodbus_and_mbpoll_over_modbus_tcp_on_the_ethernet_build() {
    let t0 = Instant::now();
    let python = pymodbus_python();
    let mbpoll = if on_path("mbpoll") {
        Ok(())
    } else {
        Err("mbpoll is not installed".to_owned())
    };
    if let Err(why) = &python {
        println!("SKIPPED the pymodbus part: {why} (tools/setup.sh installs it)");
    }
    if let Err(why) = &mbpoll {
        println!("SKIPPED the mbpoll part: {why} (tools/setup.sh installs it)");
    }
    assert!(
        python.is_ok() || mbpoll.is_ok(),
        "neither pymodbus nor mbpoll: run tools/setup.sh"
    );

    let elf = build_ethernet_firmware().expect("build the Ethernet firmware");
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf, &["--ethernet"], &ETHERNET);
    let booted = t0.elapsed();

    let mut pnow = None;
    if let Ok(py) = &python {
        let records: Vec<PositionRecord> = table(POSITIONS, 8, 2026).collect();
        pymodbus_sequence(&mut gw, py, &iai, &records, true);
        pnow = Some(PYMODBUS_MOVE_TO);
    }

    if mbpoll.is_ok() {
        use plc_gateway::mbpoll::{plc_sequence, Link};
        let records: Vec<_> = host_tests::table::table(500, 8, 7).collect();
        let link = Link::tcp(&gw.modbus);
        pnow = Some(plc_sequence(&mut gw, &iai, link, &records));
    }

    let pnow = i32::try_from(pnow.expect("pymodbus or mbpoll ran")).expect("PNOW");
    raw_framing(&gw.modbus, pnow);
    let revision = standard_cases(&mut Raw::tcp(&gw.modbus));
    println!("raw ADUs: FC 15/16 byte counts 03, unsupported 01, unit 255, 43/14 {revision:?}");
    closed_mid_request(&gw.modbus);

    if mbpoll.is_ok() {
        let port = gw.modbus_port().to_owned();
        let dir = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
        worked_example(
            "##### Worked example: Modbus TCP",
            &[("MBPORT", &port)],
            &dir,
        );
    }

    let status = gw.stop();
    let log = gw.log();
    assert!(status.success(), "{status}\n{log}");
    println!(
        "{log}\nboot {:.1} s, all {:.1} s",
        booted.as_secs_f64(),
        t0.elapsed().as_secs_f64()
    );
}
