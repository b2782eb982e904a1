//! Modbus TCP on the Ethernet build end to end, with third-party Modbus
//! clients: the gateway (`tools/gateway.sh --ethernet`'s binary) runs the
//! `lm3s6965-eth` firmware under QEMU with the simulated controller
//! behind it, QEMU's user network forwarding `modbus-tcp 127.0.0.1:PORT`
//! to the firmware's port 502, and
//!
//! 1. **pymodbus** (Modbus TCP framer, `host-tests/plc/pymodbus_plc.py
//!    --tcp`): servo on, home, wait for HEND, a numeric move to
//!    25.500 mm, wait for PEND, read PNOW, compared with the simulator's
//!    212H asked by the real `iai` tool on the protocol-B port;
//! 2. **mbpoll** (`-m tcp`, one process per request,
//!    `plc_gateway::mbpoll`): servo on (off first if the PLC before left
//!    it on), home, wait for HEND, a numeric move to 12.000 mm, wait for
//!    PEND, read PNOW, compared with the simulator's 212H; then 500
//!    positions of 8 axes written through the table window, a whole
//!    window per call, each write waited for through CMDST, read back
//!    through it equal, and `iai table read` of them on the protocol-B
//!    port equal too;
//! 3. a raw socket: transaction IDs echoed on two requests sent back to
//!    back, an ADU with a protocol ID other than 0 dropped unanswered
//!    (the connection goes on), a length field out of range closes the
//!    connection; two clients are served at once.
//!
//! pymodbus comes from the venv `tools/setup.sh` makes (`.venv`), mbpoll
//! from the Debian package it installs. A client that is absent is
//! skipped with its reason printed; the test fails if both are.

mod plc_gateway;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::Command;
use std::time::{Duration, Instant};

use host_tests::qemu::{build_ethernet_firmware, workspace_root};
use plc_gateway::{on_path, pymodbus_python, run_within, Gateway};

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

/// MBAP framing as the firmware serves it, on raw sockets.
fn raw_framing(addr: &str, pnow: i32) {
    let connect = || {
        let c = TcpStream::connect(addr).expect("connect to Modbus TCP");
        c.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        c
    };
    let pnow_words = (pnow as u32).to_be_bytes();
    let answer = |tid: u16| {
        let mut v = tid.to_be_bytes().to_vec();
        v.extend([0, 0, 0, 7, 1, 4, 4]);
        v.extend(pnow_words);
        v
    };
    let mut a = connect();
    let mut b = connect();
    // Two requests back to back: answered in order, their IDs echoed.
    let mut two = read_inputs(0x1234, 0, PNOW, 2);
    two.extend(read_inputs(0xABCD, 0, PNOW, 2));
    a.write_all(&two).unwrap();
    let got = read_n(&mut a, 26);
    assert_eq!(got[..13], answer(0x1234), "first answer {got:02X?}");
    assert_eq!(got[13..], answer(0xABCD), "second answer {got:02X?}");
    // The second client is served meanwhile.
    b.write_all(&read_inputs(7, 0, PNOW, 2)).unwrap();
    assert_eq!(read_n(&mut b, 13), answer(7));
    // Protocol ID 1: not Modbus, dropped; the next request is answered.
    let mut mixed = read_inputs(0x0101, 1, PNOW, 2);
    mixed.extend(read_inputs(0x0202, 0, PNOW, 2));
    a.write_all(&mixed).unwrap();
    assert_eq!(read_n(&mut a, 13), answer(0x0202), "after a protocol ID 1");
    // A length field of 1: the stream cannot be followed, the connection
    // is closed (reset) without an answer.
    a.write_all(&[0, 9, 0, 0, 0, 1, 1]).unwrap();
    let mut rest = Vec::new();
    let closed = match a.read_to_end(&mut rest) {
        Ok(_) => rest.is_empty(),
        Err(e) => matches!(
            e.kind(),
            std::io::ErrorKind::ConnectionReset | std::io::ErrorKind::ConnectionAborted
        ),
    };
    assert!(closed, "a length of 1 answered {rest:02X?}");
    // The other client is still served.
    b.write_all(&read_inputs(8, 0, PNOW, 2)).unwrap();
    assert_eq!(read_n(&mut b, 13), answer(8));
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
    let mut gw = Gateway::start(&elf, true);
    let booted = t0.elapsed();

    let mut pnow = None;
    if let Ok(py) = &python {
        let t = Instant::now();
        let out = run_within(
            Command::new(py)
                .arg(workspace_root().join("host-tests/plc/pymodbus_plc.py"))
                .args(["--tcp", "127.0.0.1", gw.modbus_port()]),
            Duration::from_secs(40),
        );
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        println!("pymodbus ({:.1} s):\n{stdout}", t.elapsed().as_secs_f64());
        assert!(
            out.status.success(),
            "pymodbus: {}\n{stdout}\n{}\ngateway:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr),
            gw.log()
        );
        assert!(stdout.lines().any(|l| l == "pnow 25500"), "{stdout}");
        assert_eq!(gw.axis1_position(&iai), 25_500, "the simulator's 212H");
        pnow = Some(25_500);
    }

    if mbpoll.is_ok() {
        use plc_gateway::mbpoll::{plc_sequence, Link};
        let records: Vec<_> = host_tests::table::table(500, 8, 7).collect();
        let link = Link::tcp(&gw.modbus);
        pnow = Some(plc_sequence(&mut gw, &iai, link, &records));
    }

    let pnow = i32::try_from(pnow.expect("pymodbus or mbpoll ran")).expect("PNOW");
    raw_framing(&gw.modbus, pnow);

    let status = gw.stop();
    let log = gw.log();
    assert!(status.success(), "{status}\n{log}");
    println!(
        "{log}\nboot {:.1} s, all {:.1} s",
        booted.as_secs_f64(),
        t0.elapsed().as_secs_f64()
    );
}
