//! Line diagnostics: `iai ports`, `iai probe`, `--timeout`/`--retries`,
//! the hint a failure gives (our own frames echoed, bytes that are not
//! protocol B, another station, nothing at all) and warnings for options
//! that do not apply to the link; against the simulator over TCP and a
//! pty, and against fake lines.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::io::{Read, Write};
use std::net::TcpListener;
use std::time::{Duration, Instant};

use common::{iai, stderr, stdout, Sim};

/// What a fake line does with what it receives.
#[derive(Clone, Copy)]
enum Fake {
    /// Sends every byte back.
    Echo,
    /// Answers every byte with a byte that is no protocol B.
    Garbage,
    /// Answers every command as station 12 would, whatever its station.
    Station12,
    /// Says nothing.
    Silent,
}

fn sc(b: &[u8]) -> String {
    format!(
        "{:02X}",
        b.iter().map(|&x| u32::from(x)).sum::<u32>() & 0xFF
    )
}

/// A fake line on a local port; its address.
fn fake(mode: Fake) -> String {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        for c in l.incoming() {
            let Ok(mut c) = c else { return };
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                let mut pending = Vec::new();
                loop {
                    let n = match c.read(&mut buf) {
                        Ok(0) | Err(_) => return,
                        Ok(n) => n,
                    };
                    let got = &buf[..n];
                    let _ = match mode {
                        Fake::Echo => c.write_all(got),
                        Fake::Garbage => c.write_all(
                            &got.iter()
                                .map(|x| x.wrapping_mul(37) | 0x80)
                                .collect::<Vec<_>>(),
                        ),
                        Fake::Silent => Ok(()),
                        Fake::Station12 => {
                            pending.extend_from_slice(got);
                            while let Some(end) = pending.windows(2).position(|w| w == b"\r\n") {
                                let frame: Vec<u8> = pending.drain(..end + 2).collect();
                                if frame.first() == Some(&b'!') && frame.len() >= 10 {
                                    let mut body = b"#12".to_vec();
                                    body.extend_from_slice(&frame[3..frame.len() - 4]);
                                    let s = sc(&body);
                                    body.extend_from_slice(s.as_bytes());
                                    body.extend_from_slice(b"\r\n");
                                    let _ = c.write_all(&body);
                                }
                            }
                            Ok(())
                        }
                    };
                }
            });
        }
    });
    addr
}

/// `iai ARGS` in a thread (the failing ones wait out their timeouts).
fn spawn(args: Vec<String>) -> std::thread::JoinHandle<std::process::Output> {
    std::thread::spawn(move || {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        iai(&a)
    })
}

fn send_args(at: &str, extra: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = ["send", "212", "query_axis_pattern=1", "--tcp", at]
        .iter()
        .map(|s| s.to_string())
        .collect();
    v.extend(extra.iter().map(|s| s.to_string()));
    v
}

/// A failure names the likely cause: each fake line gives its own hint,
/// in text and in JSON; --timeout and --retries are what the line waits
/// and sends.
#[test]
fn a_failure_names_the_likely_cause() {
    let quick = ["--timeout", "200", "--retries", "0"];
    let cases = [
        (Fake::Echo, "our own frames came back"),
        (Fake::Garbage, "are not protocol B"),
        (Fake::Station12, "not 99: wrong --station? Try --station 12"),
        (Fake::Silent, "nothing came back at all"),
    ];
    let runs: Vec<_> = cases
        .iter()
        .map(|(mode, _)| spawn(send_args(&fake(*mode), &quick)))
        .collect();
    let silent = fake(Fake::Silent);
    let retried = spawn(send_args(
        &silent,
        &["--timeout", "200", "--retries", "1", "--json"],
    ));
    let table = spawn(
        [
            "table",
            "read",
            "--first",
            "1",
            "--count",
            "5",
            "--tcp",
            &silent,
            "--timeout",
            "200",
            "--retries",
            "0",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect(),
    );
    for ((_, want), run) in cases.iter().zip(runs) {
        let out = run.join().unwrap();
        assert_eq!(out.status.code(), Some(1));
        let e = stderr(&out);
        assert!(e.contains("after 1 send(s), 200 ms each"), "{e}");
        let hint = e
            .split("hint: ")
            .nth(1)
            .unwrap_or_else(|| panic!("no hint: {e}"));
        assert!(hint.contains(want), "{want}: {e}");
    }
    let out = retried.join().unwrap();
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    assert_eq!(v["failure"], "timeout");
    assert_eq!(v["sends"], 2);
    assert!(
        v["hint"].as_str().unwrap().contains("nothing came back"),
        "{v}"
    );
    let out = table.join().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("did not answer (1 send(s), 200 ms each)")
            && stderr(&out).contains("hint: nothing came back at all"),
        "{}",
        stderr(&out)
    );
}

/// Over a pty: a controller at another station answers nothing; the hint
/// says so and `probe` finds it once given the station.
#[cfg(unix)]
#[test]
fn over_a_pty_the_station_is_found() {
    let sim = Sim::start(&["--pty", "--quiet", "--station", "12"]);
    let at = sim.at.clone();
    let t0 = Instant::now();
    let out = iai(&[
        "send",
        "212",
        "query_axis_pattern=1",
        "--port",
        &at,
        "--baud",
        "115200",
        "--timeout",
        "150",
        "--retries",
        "0",
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("hint: nothing came back at all"),
        "{}",
        stderr(&out)
    );
    assert!(t0.elapsed() < Duration::from_secs(10));
    let out = iai(&[
        "probe",
        "--port",
        &at,
        "--baud",
        "9600,115200",
        "--timeout",
        "150",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    assert!(
        stdout(&out).contains("not found: nothing answered"),
        "{}",
        stdout(&out)
    );
    let out = iai(&[
        "probe",
        "--port",
        &at,
        "--station",
        "99,12",
        "--timeout",
        "300",
    ]);
    assert!(out.status.success(), "{}", stdout(&out));
    let text = stdout(&out);
    assert!(text.contains("9600 baud, station 12: ANSWERED"), "{text}");
    assert!(
        text.contains("found: a controller answers; use --baud 9600 --station 12"),
        "{text}"
    );
    // A pty ignores framing; the options reach the port without a warning.
    let out = iai(&[
        "send",
        "212",
        "query_axis_pattern=1",
        "--port",
        &at,
        "--station",
        "12",
        "--parity",
        "even",
        "--stop-bits",
        "2",
        "--data-bits",
        "8",
        "--flow",
        "xonxoff",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(!stderr(&out).contains("warning"), "{}", stderr(&out));
    sim.stop();
}

#[test]
fn probe_over_tcp_follows_the_stations_replies_show() {
    let sim = Sim::tcp(&["--quiet"]);
    let out = iai(&["probe", "--tcp", &sim.at, "--json"]);
    assert!(out.status.success(), "{}", stdout(&out));
    let lines: Vec<serde_json::Value> = stdout(&out)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // The bridge's status query first: the simulator is no bridge.
    assert_eq!(lines[0]["type"], "bridge");
    assert_eq!(lines[0]["result"], "silent");
    let lines: Vec<serde_json::Value> = lines.into_iter().skip(1).collect();
    assert_eq!(lines[0]["station"], "99");
    assert_eq!(lines[0]["result"], "answered");
    assert_eq!(lines[1]["result"], "silent");
    assert_eq!(lines.last().unwrap()["found"][0]["station"], "99");
    sim.stop();
    // A line where station 12 answers whatever is asked: 99 and 00 show
    // replies from 12, which is tried next and answers.
    let out = iai(&["probe", "--tcp", &fake(Fake::Station12), "--timeout", "200"]);
    assert!(out.status.success(), "{}", stdout(&out));
    let text = stdout(&out);
    assert!(
        text.contains("tcp, station 99: replies from station 12"),
        "{text}"
    );
    assert!(text.contains("tcp, station 12: ANSWERED"), "{text}");
    assert!(text.contains("use --station 12"), "{text}");
    let out = iai(&["probe", "--tcp", &fake(Fake::Echo), "--timeout", "200"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stdout(&out).contains("not found: our own frames came back"),
        "{}",
        stdout(&out)
    );
    let out = iai(&["probe", "--tcp", &fake(Fake::Garbage), "--timeout", "200"]);
    assert!(
        stdout(&out).contains("not found: only bytes that are not protocol B"),
        "{}",
        stdout(&out)
    );
}

#[test]
fn serial_options_with_tcp_are_warned_about() {
    let sim = Sim::tcp(&["--quiet"]);
    let out = iai(&[
        "send",
        "212",
        "query_axis_pattern=1",
        "--tcp",
        &sim.at,
        "--parity",
        "even",
        "--baud",
        "9600",
        "--flow",
        "rtscts",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let e = stderr(&out);
    assert!(
        e.contains("warning: --baud applies to a serial port (--port); ignored with --tcp"),
        "{e}"
    );
    assert!(
        e.contains("warning: --parity applies to a serial port"),
        "{e}"
    );
    assert!(
        e.contains("warning: --flow rtscts needs a serial port's modem lines"),
        "{e}"
    );
    assert!(!e.contains("--stop-bits"), "{e}");
    sim.stop();
}

#[test]
fn ports_lists_what_the_system_has() {
    let out = iai(&["ports", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    for l in stdout(&out).lines() {
        let v: serde_json::Value = serde_json::from_str(l).unwrap();
        assert!(v["port"].is_string() && v["kind"].is_string(), "{v}");
    }
    let text = iai(&["ports"]);
    assert!(text.status.success());
    assert_eq!(stdout(&text).lines().count(), stdout(&out).lines().count());
    if stdout(&out).is_empty() {
        assert!(stderr(&text).contains("no serial ports found"));
    }
}
