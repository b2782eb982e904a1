//! `iai bridge status` and `iai table write --bridge` without QEMU: a
//! fake bridge that answers the status query with a reply recorded from
//! the bridge firmware (and 26DH as the bridge does), and the simulator,
//! which is no bridge. The firmware itself under QEMU is tested in
//! `host-tests/tests/iai_bridge.rs`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::io::{Read, Write};
use std::net::TcpListener;

use common::{csv_table, iai, stderr, stdout, temp, Sim};

/// The bridge's status reply, recorded under QEMU (gateway, lm3s6965).
const RECORDED: &[u8] = include_bytes!("fixtures/bridge-status.bin");

fn sc(b: &[u8]) -> String {
    format!(
        "{:02X}",
        b.iter().map(|&x| u32::from(x)).sum::<u32>() & 0xFF
    )
}

fn frame(body: &str) -> Vec<u8> {
    format!("{body}{}\r\n", sc(body.as_bytes())).into_bytes()
}

/// What the fake bridge does with a 26DH.
#[derive(Clone, Copy)]
enum Answer {
    /// `#` with the count of records.
    Count,
    /// `&` B07 every time.
    Overrun,
}

/// A fake bridge on a local port: its status reply is the recorded one;
/// 200H is echoed as station 99; a 26DH (of any size) is answered as
/// `answer` says, each frame sending XOFF then XON first. Returns the
/// address and a log of the IDs it received.
fn fake_bridge(answer: Answer) -> (String, std::sync::mpsc::Receiver<String>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for c in l.incoming() {
            let Ok(mut c) = c else { return };
            let tx = tx.clone();
            std::thread::spawn(move || {
                let mut buf = [0u8; 65536];
                let mut pending: Vec<u8> = Vec::new();
                loop {
                    let n = match c.read(&mut buf) {
                        Ok(0) | Err(_) => return,
                        Ok(n) => n,
                    };
                    pending.extend_from_slice(&buf[..n]);
                    while let Some(end) = pending.windows(2).position(|w| w == b"\r\n") {
                        let f: Vec<u8> = pending.drain(..end + 2).collect();
                        if f.len() < 10 || f[0] != b'!' {
                            continue;
                        }
                        let id = String::from_utf8_lossy(&f[3..6]).to_string();
                        let _ = tx.send(id.clone());
                        let reply = match id.as_str() {
                            "B00" => RECORDED.to_vec(),
                            "200" => {
                                frame(&format!("#99200{}", String::from_utf8_lossy(&f[6..16])))
                            }
                            "26D" => {
                                // Flow control as the bridge sends it, taken out by iai.
                                let _ = c.write_all(&[0x13]);
                                let _ = c.write_all(&[0x11]);
                                match answer {
                                    Answer::Count => frame(&format!(
                                        "#9926D{}",
                                        String::from_utf8_lossy(&f[6..10])
                                    )),
                                    Answer::Overrun => frame("&99B07"),
                                }
                            }
                            _ => continue,
                        };
                        let _ = c.write_all(&reply);
                    }
                }
            });
        }
    });
    (addr, rx)
}

#[test]
fn bridge_status_decodes_the_recorded_reply() {
    let (addr, _) = fake_bridge(Answer::Count);
    let out = iai(&["bridge", "status", "--tcp", &addr]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stdout(&out);
    assert!(text.starts_with("bridge at station BB:"), "{text}");
    for want in [
        "controller_station = 153 -> 99",
        "flow_control = 1 -> XON/XOFF",
        "policy = 0 -> forward all",
        "records = 200",
        "last_error = 0 -> none",
    ] {
        assert!(text.contains(want), "{want}: {text}");
    }
    let out = iai(&["bridge", "status", "--tcp", &addr, "--json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    assert_eq!(v["type"], "bridge_status");
    assert_eq!(v["fields"]["upstream_baud"], 115_200);
    assert_eq!(v["meanings"]["policy"], "forward all");
}

/// A 26DH larger than a controller takes (2,051 bytes) goes out whole;
/// the bridge's `#` is reported with what it means, its `&` too, and an
/// `&` worth resending is resent up to --retries.
#[test]
fn a_whole_table_goes_to_the_bridge_as_one_26dh() {
    let (addr, ids) = fake_bridge(Answer::Count);
    let path = temp("bridge-whole.csv", csv_table(300, 8, 61).as_bytes());
    let p = path.to_str().unwrap();
    let out = iai(&["table", "write", p, "--tcp", &addr, "--bridge"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stdout(&out).starts_with(
            "verified by the bridge: the controller holds all 300 records (1 26DH message(s)"
        ),
        "{}",
        stdout(&out)
    );
    let e = stderr(&out);
    assert!(
        e.contains("bridge at station BB: controller station 99"),
        "{e}"
    );
    assert!(e.contains("the bridge answered # with 300: the controller holds all 300 records of the message, each read back by the bridge and compared"), "{e}");
    let seen: Vec<String> = ids.try_iter().collect();
    assert_eq!(
        seen,
        ["200", "B00", "200", "200", "26D"],
        "fence (what was on the line before is unknown), status, fence, test call, one 26DH"
    );
    // An & worth resending is resent; the last one is the verdict.
    let (addr, ids) = fake_bridge(Answer::Overrun);
    let out = iai(&[
        "table",
        "write",
        p,
        "--tcp",
        &addr,
        "--bridge",
        "--retries",
        "1",
        "--timeout",
        "300",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let e = stderr(&out);
    assert!(e.contains("sending the message again (2 of 2)"), "{e}");
    assert!(e.contains("& B07 (bridge: bytes of the host's 26DH were lost on the way in): an & cannot say how far the write went"), "{e}");
    assert!(
        e.contains("send the table again (position writes are idempotent)"),
        "{e}"
    );
    assert_eq!(ids.try_iter().filter(|i| i == "26D").count(), 2);
    // The station the bridge names must be the one given.
    let (addr, _) = fake_bridge(Answer::Count);
    let out = iai(&[
        "table",
        "write",
        p,
        "--tcp",
        &addr,
        "--bridge",
        "--station",
        "12",
    ]);
    assert!(
        stderr(&out).contains("forwards to controller station 99, not 12: give --station 99"),
        "{}",
        stderr(&out)
    );
    // --bridge is a TTA message, and no resume.
    let out = iai(&[
        "table",
        "write",
        p,
        "--tcp",
        &addr,
        "--bridge",
        "--profile",
        "xsel2003",
    ]);
    assert!(
        stderr(&out).contains("--bridge sends the table as one 26DH"),
        "{}",
        stderr(&out)
    );
    let out = iai(&["table", "write", p, "--tcp", &addr, "--bridge", "--resume"]);
    assert_eq!(out.status.code(), Some(2));
}

fn no_bridge_on(line: &[&str], sim: Sim) {
    let path = temp(
        &format!("no-bridge-{}.csv", line[0].trim_start_matches('-')),
        csv_table(5, 2, 3).as_bytes(),
    );
    let mut args = vec![
        "table",
        "write",
        path.to_str().unwrap(),
        "--bridge",
        "--timeout",
        "200",
        "--retries",
        "0",
    ];
    args.extend_from_slice(line);
    let out = iai(&args);
    assert_eq!(out.status.code(), Some(1));
    let e = stderr(&out);
    assert!(
        e.contains("no bridge answered its status query (B00H to station BB, 1 send(s))"),
        "{e}"
    );
    assert!(e.contains("hint: nothing came back at all"), "{e}");
    let mut args = vec!["bridge", "status", "--timeout", "200", "--retries", "0"];
    args.extend_from_slice(line);
    let out = iai(&args);
    assert_eq!(out.status.code(), Some(1));
    let log = sim.stop();
    assert!(
        !log.contains("26DH"),
        "a 26DH reached the controller: {log}"
    );
}

#[test]
fn without_a_bridge_nothing_is_written_tcp() {
    let sim = Sim::tcp(&[]);
    let at = sim.at.clone();
    no_bridge_on(&["--tcp", &at], sim);
}

#[cfg(unix)]
#[test]
fn without_a_bridge_nothing_is_written_pty() {
    let sim = Sim::start(&["--pty"]);
    let at = sim.at.clone();
    no_bridge_on(&["--port", &at, "--baud", "115200"], sim);
}
