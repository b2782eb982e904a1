//! The gateway (`tools/gateway.sh`'s binary) end to end: the bridge
//! firmware under QEMU `lm3s6965evb` with the simulator behind it, and the
//! real `iai` tool on its TCP port as a user runs it.
//!
//! 1. the gateway prints `protocol-b 127.0.0.1:PORT` then
//!    `modbus-rtu 127.0.0.1:PORT` once it is ready;
//! 2. `iai send 212` gets the typed axis status;
//! 3. a second connection while one is open is closed at once; a client
//!    that sends noise, leaves the bridge stopped with an XOFF and
//!    disconnects in the middle of a 26DH leaves a line the next client
//!    uses as usual;
//! 4. `iai table write` of 200 records x 8 axes reports `verified`, and
//!    `iai table read` gives back the same CSV;
//! 5. SIGTERM stops the gateway (exit 0) and the QEMU it started.
//!
//! The `iai` binary is built here with cargo (a no-op when the test
//! command built it), in this test's profile. Nothing asserts timing.
//! Needs `qemu-system-arm` and the `thumbv7m-none-eabi` rustup target.

mod gateway_proc;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::time::Duration;

use gateway_proc::{csv_of, Gateway, SERIAL};
use host_tests::qemu::{build_firmware, Board};

/// A connection to the gateway's host side, reads timing out after 5 s.
fn connect(gw: &Gateway) -> TcpStream {
    let c = TcpStream::connect(&gw.addr).expect("connect");
    c.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    c
}

/// Whether `pid` is a running (not reaped) qemu-system-arm.
fn qemu_running(pid: u32) -> bool {
    std::fs::read(format!("/proc/{pid}/cmdline"))
        .is_ok_and(|c| String::from_utf8_lossy(&c).contains("qemu-system-arm"))
}

#[test]
fn iai_through_the_gateway_sends_writes_and_reads_a_table() {
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf, &[] as &[&str], &SERIAL);
    let qemu = gw.qemu_pid();
    assert!(qemu_running(qemu));

    // An axis status query, typed.
    let out = gw.iai(&iai, &["send", "212", "query_axis_pattern=1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("212H Axis Status Query"), "{text}");
    assert!(text.contains("axis_pattern = 0x01"), "{text}");
    assert!(text.contains("axes[0].current_position = 0"), "{text}");

    // One client at a time: a second connection is closed unanswered.
    let mut first = connect(&gw);
    let peer = first.local_addr().unwrap();
    gw.wait_for(&format!("{peer} connected"));
    let mut second = connect(&gw);
    let mut buf = [0u8; 16];
    assert_eq!(second.read(&mut buf).expect("closed, not timed out"), 0);
    // The first sends noise (with an XOFF, which stops the bridge's
    // transmitter) and leaves in the middle of a 26DH.
    let noise: Vec<u8> = (0..600u32).map(|i| (i * 37 % 251) as u8).collect();
    first.write_all(&noise).unwrap();
    first.write_all(&[0x13]).unwrap();
    first.write_all(b"!9926D0001000501000000000064").unwrap();
    drop(first);
    gw.wait_for(&format!("{peer} left (629 byte(s) in"));

    // A position table: written and verified, read back equal.
    let csv = csv_of(200, 77);
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("gateway-{}.csv", std::process::id()));
    std::fs::write(&path, &csv).unwrap();
    let file = path.to_str().expect("UTF-8 path");
    let out = gw.iai(&iai, &["table", "write", file]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("verified: the controller holds all 200 records"),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = gw.iai(&iai, &["table", "read", "--first", "1", "--count", "200"]);
    assert!(
        out.stdout == csv,
        "read back:\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let _ = std::fs::remove_file(&path);

    // SIGTERM: a clean stop, and no QEMU left.
    let status = gw.stop();
    let log = gw.log();
    assert!(status.success(), "{status}\n{log}");
    assert!(log.contains("stopped;"), "{log}");
    assert!(!log.contains("did not answer"), "{log}");
    assert!(!qemu_running(qemu), "QEMU {qemu} still runs\n{log}");
}
