//! `iai simulate --connect`: the simulator dials a listening port (here a
//! listener of the test, standing in for QEMU's controller port), waits
//! for it to come up, serves that one connection and exits when it closes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{read_frame, temp};
use iai_protocol_b::frame::Frame;

/// A port nothing listens on right now (bound, then released).
fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Accepts one connection on `listener` within `limit`.
fn accept_within(listener: &TcpListener, limit: Duration) -> TcpStream {
    listener.set_nonblocking(true).unwrap();
    let end = Instant::now() + limit;
    loop {
        match listener.accept() {
            Ok((conn, _)) => {
                conn.set_nonblocking(false).unwrap();
                conn.set_read_timeout(Some(Duration::from_secs(10)))
                    .unwrap();
                return conn;
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                assert!(Instant::now() < end, "the simulator did not connect");
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(e) => panic!("accept: {e}"),
        }
    }
}

#[test]
fn the_simulator_connects_once_the_port_listens_serves_it_and_exits_when_it_closes() {
    let port = free_port();
    let dump = temp("connect-dump.csv", b"");
    std::fs::remove_file(&dump).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["simulate", "--connect", &format!("127.0.0.1:{port}")])
        .arg("--dump")
        .arg(&dump)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Nothing listens yet: the simulator keeps trying.
    std::thread::sleep(Duration::from_millis(400));
    assert!(child.try_wait().unwrap().is_none(), "it gave up at once");
    let listener = TcpListener::bind(("127.0.0.1", port)).unwrap();
    let mut conn = accept_within(&listener, Duration::from_secs(10));

    // An axis status query, then a position write.
    conn.write_all(b"!99212038B\r\n").unwrap();
    let reply = read_frame(&mut conn);
    let frame = Frame::new_checked(&reply, Default::default())
        .unwrap_or_else(|e| panic!("{e:?}: {}", String::from_utf8_lossy(&reply)));
    assert!(
        frame.as_bytes().starts_with(b"#9921203"),
        "{}",
        String::from_utf8_lossy(&reply)
    );
    conn.write_all(b"!9926D0001000501000000000064000005DC1C\r\n")
        .unwrap();
    let reply = read_frame(&mut conn);
    let frame = Frame::new_checked(&reply, Default::default()).unwrap();
    assert!(
        frame.as_bytes().starts_with(b"#9926D"),
        "{}",
        String::from_utf8_lossy(&reply)
    );

    // The connection's end ends the run; the table is dumped.
    drop(conn);
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    let first = stdout.lines().next().unwrap_or_default();
    assert_eq!(first, format!("connected tcp 127.0.0.1:{port}"));
    assert!(stdout.contains("2 command(s), 2 reply(ies)"), "{stdout}");
    let csv = std::fs::read_to_string(&dump).unwrap();
    assert_eq!(
        csv,
        "number,acceleration,deceleration,speed,axis1\n5,0.00,0.00,100,1.500\n"
    );
}

#[test]
fn the_simulator_gives_up_when_nothing_listens() {
    let port = free_port();
    let started = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["simulate", "--connect", &format!("127.0.0.1:{port}")])
        .args(["--connect-wait-ms", "300"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!(
            "--connect 127.0.0.1:{port}: nothing accepted a connection within 0.3 s"
        )),
        "{err}"
    );
    assert!(out.stdout.is_empty());
    // It kept trying rather than failing on the first refusal.
    assert!(started.elapsed() >= Duration::from_millis(300));
}

#[test]
fn connect_excludes_the_other_places() {
    for other in [&["--tcp", "127.0.0.1:0"][..], &["--pty"][..]] {
        let out = Command::new(env!("CARGO_BIN_EXE_iai"))
            .args(["simulate", "--connect", "127.0.0.1:1"])
            .args(other)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("cannot be used with"), "{err}");
    }
    // --connect-wait-ms belongs to --connect: refused before it listens.
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["simulate", "--tcp", "127.0.0.1:0", "--connect-wait-ms", "5"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let end = Instant::now() + Duration::from_secs(10);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() >= end {
            let _ = child.kill();
            let _ = child.wait();
            panic!("--tcp with --connect-wait-ms was accepted");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(status.code(), Some(2));
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    assert!(lines.next().is_none());
}
