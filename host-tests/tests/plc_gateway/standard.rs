//! What both Modbus fronts must do alike, checked from the outside on the
//! gateway process (`crate::gateway_proc`) under QEMU:
//!
//! - [`worked_example`]: the README's worked example of a front (its `sh`
//!   block under the heading given), run in bash exactly as written but
//!   for the port and the pty's path, with mbpoll counted by a wrapper
//!   put first on PATH; what it prints is checked;
//! - [`Raw`]: requests as bytes on a raw socket (RTU frames through the
//!   serial build's relay, MBAP ADUs on the Ethernet build's port 502),
//!   and [`standard_cases`], the requests whose answers issue 27 fixed:
//!   functions 15 and 16 whose byte count disagrees with the quantity
//!   (03), Read Device Identification (43/14) with the simulator's 201H
//!   version, unsupported functions (01), unit 255.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use firmware_example::modbus::ident::FIRMWARE;
use firmware_example::modbus::rtu::crc16;
use host_tests::qemu::workspace_root;

use super::run_within;

/// The lines of the fenced `sh` block after the line `heading` of the
/// README.
fn readme_block(heading: &str) -> String {
    let readme = std::fs::read_to_string(workspace_root().join("README.md")).expect("README.md");
    let mut lines = readme.lines().skip_while(|l| l.trim_end() != heading);
    assert!(lines.next().is_some(), "no {heading:?} in README.md");
    let block: Vec<&str> = lines
        .skip_while(|l| l.trim_end() != "```sh")
        .skip(1)
        .take_while(|l| l.trim_end() != "```")
        .collect();
    assert!(!block.is_empty(), "no sh block after {heading:?}");
    block.join("\n") + "\n"
}

/// What a worked example did.
pub struct Worked {
    /// What it printed.
    pub stdout: String,
    /// mbpoll calls.
    pub calls: usize,
    /// Wall time, s.
    pub secs: f64,
}

/// The README's block under `heading`, each `(from, to)` of `subst`
/// replaced, run by `bash -euo pipefail` in `dir` (at most 120 s); it
/// must succeed and print `PNOW 25500`, `stopped N` with N between,
/// the window as written and `PNOW 12000`.
pub fn worked_example(heading: &str, subst: &[(&str, &str)], dir: &Path) -> Worked {
    let mut script = readme_block(heading);
    for (from, to) in subst {
        assert!(script.contains(from), "{heading}: no {from:?} in its block");
        script = script.replace(from, to);
    }
    // mbpoll counted: a wrapper first on PATH.
    let real = String::from_utf8(
        Command::new("sh")
            .args(["-c", "command -v mbpoll"])
            .output()
            .expect("sh")
            .stdout,
    )
    .expect("a path");
    let bin = dir.join("counting-bin");
    std::fs::create_dir_all(&bin).unwrap();
    let calls = dir.join("mbpoll-calls");
    let _ = std::fs::remove_file(&calls);
    let wrapper = bin.join("mbpoll");
    std::fs::write(
        &wrapper,
        format!(
            "#!/bin/sh\necho >> '{}'\nexec '{}' \"$@\"\n",
            calls.display(),
            real.trim()
        ),
    )
    .unwrap();
    Command::new("chmod")
        .arg("+x")
        .arg(&wrapper)
        .status()
        .unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let t0 = Instant::now();
    let out = run_within(
        Command::new("bash")
            .args(["-euo", "pipefail", "-c", &script])
            .current_dir(dir)
            .env("PATH", path),
        Duration::from_secs(120),
    );
    let secs = t0.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        out.status.success(),
        "{heading}: {}\n{stdout}\n{stderr}",
        out.status
    );
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 4, "{heading} printed:\n{stdout}");
    assert_eq!(lines[0], "PNOW 25500");
    let stopped: i64 = lines[1]
        .strip_prefix("stopped ")
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{heading}: {:?}", lines[1]));
    assert!(0 < stopped && stopped < 25_500, "stopped at {stopped}");
    let mut window = "window 900 3 30 30 200 0 12000 65535 40036".to_owned();
    window.push_str(&" 0".repeat(12));
    window.push_str(" 901 ");
    assert_eq!(lines[2], window);
    assert_eq!(lines[3], "PNOW 12000");
    let calls = std::fs::read_to_string(&calls)
        .unwrap_or_default()
        .lines()
        .count();
    println!("{heading}: {calls} mbpoll calls, {secs:.1} s; the stop caught the move at {stopped}");
    Worked {
        stdout,
        calls,
        secs,
    }
}

/// A raw client of one front.
pub enum Raw {
    /// RTU frames through the serial build's relay (bytes on the wire as
    /// a serial master sends them).
    Rtu(TcpStream),
    /// MBAP ADUs on the Ethernet build's Modbus TCP port.
    Tcp(TcpStream),
}

impl Raw {
    /// A connection to `addr` (`127.0.0.1:PORT`).
    pub fn rtu(addr: &str) -> Raw {
        Raw::Rtu(connect(addr))
    }

    /// A Modbus TCP connection to `addr`.
    pub fn tcp(addr: &str) -> Raw {
        Raw::Tcp(connect(addr))
    }

    /// `pdu` (unit first) as a request; the answer's unit and PDU, or
    /// `None` when none came within a second. RTU answers are checked for
    /// their CRC, TCP answers for the transaction ID and length.
    pub fn ask(&mut self, pdu: &[u8]) -> Option<Vec<u8>> {
        match self {
            Raw::Rtu(s) => {
                let mut frame = pdu.to_vec();
                frame.extend(crc16(pdu).to_le_bytes());
                s.write_all(&frame).unwrap();
                // The answer: bytes until 100 ms of silence.
                let mut got = Vec::new();
                let end = Instant::now() + Duration::from_secs(1);
                let mut buf = [0u8; 300];
                loop {
                    let quiet = if got.is_empty() { 1_000 } else { 100 };
                    s.set_read_timeout(Some(Duration::from_millis(quiet)))
                        .unwrap();
                    match s.read(&mut buf) {
                        Ok(0) => break,
                        Ok(n) => got.extend(&buf[..n]),
                        Err(_) => break,
                    }
                    if Instant::now() > end && !got.is_empty() {
                        break;
                    }
                }
                if got.is_empty() {
                    return None;
                }
                assert_eq!(crc16(&got), 0, "answer CRC: {got:02X?}");
                got.truncate(got.len() - 2);
                Some(got)
            }
            Raw::Tcp(s) => {
                let tid: u16 = 0x2700 | u16::from(pdu.get(1).copied().unwrap_or(0));
                let mut adu = tid.to_be_bytes().to_vec();
                adu.extend([0, 0]);
                adu.extend((pdu.len() as u16).to_be_bytes());
                adu.extend(pdu);
                s.write_all(&adu).unwrap();
                s.set_read_timeout(Some(Duration::from_secs(1))).unwrap();
                let mut head = [0u8; 6];
                if s.read_exact(&mut head).is_err() {
                    return None;
                }
                assert_eq!(
                    head[..4],
                    [(tid >> 8) as u8, tid as u8, 0, 0],
                    "{head:02X?}"
                );
                let mut rest = vec![0u8; usize::from(u16::from_be_bytes([head[4], head[5]]))];
                s.read_exact(&mut rest).expect("the rest of the ADU");
                Some(rest)
            }
        }
    }
}

fn connect(addr: &str) -> TcpStream {
    let s = TcpStream::connect(addr).expect("connect");
    s.set_nodelay(true).unwrap();
    s
}

/// The requests of issue 27's Modbus cases on `raw`, answered as the
/// standard says (and alike on both fronts: every answer here is the
/// same PDU on both): returns the device identification's revision.
pub fn standard_cases(raw: &mut Raw) -> String {
    let tcp = matches!(raw, Raw::Tcp(_));
    // FC 15, quantity 1 with a byte count of 2; FC 16, quantity 1 with 4
    // bytes: 03, nothing done.
    assert_eq!(
        raw.ask(&[1, 15, 0x01, 0x2C, 0, 1, 2, 1, 0]),
        Some(vec![1, 0x8F, 3])
    );
    assert_eq!(
        raw.ask(&[1, 16, 0x0D, 0x03, 0, 1, 4, 0, 9, 0, 9]),
        Some(vec![1, 0x90, 3])
    );
    // POSR of axis 1 is still what it was before (0 after a start, or
    // what a PLC left): the same write with its byte count right works.
    let posr = raw.ask(&[1, 3, 0x0D, 0x03, 0, 1]).expect("POSR");
    assert_eq!(
        raw.ask(&[1, 16, 0x0D, 0x03, 0, 1, 2, posr[3], posr[4]]),
        Some(vec![1, 16, 0x0D, 0x03, 0, 1])
    );
    // Unsupported: 01, whatever the length (11H Report Server ID is 2
    // bytes of PDU and unit, under rmodbus's smallest MBAP length).
    assert_eq!(raw.ask(&[1, 0x11]), Some(vec![1, 0x91, 1]));
    assert_eq!(raw.ask(&[1, 0x2B, 0x0D, 1, 0]), Some(vec![1, 0xAB, 1]));
    assert_eq!(
        raw.ask(&[1, 0x08, 0, 0, 0x12, 0x34]),
        Some(vec![1, 0x88, 1])
    );
    // Read Device Identification, basic, stream.
    let id = raw.ask(&[1, 0x2B, 0x0E, 1, 0]).expect("43/14 answered");
    assert_eq!(id[..8], [1, 0x2B, 0x0E, 1, 0x81, 0, 0, 3], "{id:02X?}");
    let mut objects = Vec::new();
    let mut at = 8;
    while at < id.len() {
        let (oid, len) = (id[at], usize::from(id[at + 1]));
        objects.push((
            oid,
            String::from_utf8(id[at + 2..at + 2 + len].to_vec()).unwrap(),
        ));
        at += 2 + len;
    }
    assert_eq!(objects.len(), 3, "{objects:?}");
    assert_eq!(objects[0], (0, "iai-protocol-b".to_owned()));
    assert_eq!(objects[1], (1, "protocol-B Modbus gateway".to_owned()));
    let revision = objects[2].1.clone();
    // The gateway has polled: the simulator's 201H is in it.
    assert_eq!(
        revision,
        format!("{FIRMWARE}; controller 0100 model 5A unit 01 2026-12-01")
    );
    // Unit 255: the gateway itself over TCP (the answer carries 255); no
    // unit of an RTU line.
    let at255 = raw.ask(&[0xFF, 3, 0x0D, 0x03, 0, 1]);
    if tcp {
        assert_eq!(at255, Some(vec![0xFF, 3, 2, posr[3], posr[4]]));
    } else {
        assert_eq!(at255, None);
    }
    revision
}
