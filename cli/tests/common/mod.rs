//! Running `iai` as a user would, and `iai simulate` in the background.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::Duration;

use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::position::PositionRecord;

pub fn iai(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(args)
        .output()
        .expect("run iai")
}

pub fn iai_stdin(args: &[&str], input: &[u8]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run iai");
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(input).unwrap();
    drop(stdin);
    child.wait_with_output().unwrap()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8(o.stdout.clone()).unwrap()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn temp(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let p = dir.join(format!("cli-{}-{name}", std::process::id()));
    std::fs::write(&p, bytes).unwrap();
    p
}

/// A deterministic record: number `i + 1`, axes `1..=axes`, coordinates
/// over ±2 m, some axes left out when `sparse`.
pub fn record(i: u32, axes: u8, seed: u32) -> PositionRecord {
    sparse_record(i, axes, seed, false)
}

pub fn sparse_record(i: u32, axes: u8, seed: u32, sparse: bool) -> PositionRecord {
    let mut x = i.wrapping_mul(2_654_435_761) ^ seed.wrapping_mul(40_503) ^ 0x5bd1_e995;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x
    };
    let mut positions = PerAxis::new();
    let mut pattern = AxisPattern::NONE;
    for a in 1..=axes {
        let v = (next() % 4_000_001) as i32 - 2_000_000;
        // The last axis always, so that the table's width is `axes`.
        if sparse && a < axes && next() % 4 == 0 {
            continue;
        }
        pattern = pattern.with(a).unwrap();
        positions.push(v).unwrap();
    }
    PositionRecord {
        number: (i % 20_000) as u16 + 1,
        axes: pattern,
        acceleration: (next() % 200) as u16,
        deceleration: (next() % 200) as u16,
        speed: (next() % 2000) as u16,
        positions,
        extended: 0,
    }
}

/// The CSV of `n` sparse records over `axes` axes, in the normal form
/// `table read` prints.
pub fn csv_table(n: u32, axes: u8, seed: u32) -> String {
    let mut out = Vec::new();
    iai_cli::csvtable::write_header(&mut out, usize::from(axes)).unwrap();
    for i in 0..n {
        let r = sparse_record(i, axes, seed, true);
        iai_cli::csvtable::write_row(&mut out, &r, usize::from(axes)).unwrap();
    }
    String::from_utf8(out).unwrap()
}

/// Reads one frame (through LF) from a stream.
pub fn read_frame(conn: &mut impl Read) -> Vec<u8> {
    let mut reply = Vec::new();
    let mut b = [0u8; 1];
    while !reply.ends_with(b"\r\n") {
        let n = conn.read(&mut b).unwrap();
        assert!(n > 0, "connection closed");
        reply.push(b[0]);
    }
    reply
}

/// `iai simulate` running in the background; its stdout is drained.
pub struct Sim {
    child: Child,
    /// `127.0.0.1:PORT` or `/dev/pts/N`.
    pub at: String,
    lines: Receiver<String>,
    seen: Vec<String>,
}

impl Sim {
    pub fn start(args: &[&str]) -> Sim {
        let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
            .arg("simulate")
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("run iai simulate");
        let out = child.stdout.take().unwrap();
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines() {
                let Ok(l) = l else { break };
                if tx.send(l).is_err() {
                    break;
                }
            }
        });
        let first = rx
            .recv_timeout(Duration::from_secs(20))
            .expect("first line");
        let at = first
            .strip_prefix("listening tcp ")
            .or_else(|| first.strip_prefix("listening pty "))
            .unwrap_or_else(|| panic!("first line: {first}"))
            .to_string();
        Sim {
            child,
            at,
            lines: rx,
            seen: Vec::new(),
        }
    }

    pub fn tcp(extra: &[&str]) -> Sim {
        let mut args = vec!["--tcp", "127.0.0.1:0"];
        args.extend_from_slice(extra);
        Sim::start(&args)
    }

    pub fn connect(&self) -> std::net::TcpStream {
        let c = std::net::TcpStream::connect(&self.at).unwrap();
        c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        c
    }

    /// Waits (at most 10 s) for a line containing `pat`.
    pub fn wait_for(&mut self, pat: &str) {
        let end = std::time::Instant::now() + Duration::from_secs(10);
        while !self.seen.iter().any(|l| l.contains(pat)) {
            let left = end.saturating_duration_since(std::time::Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) => self.seen.push(l),
                Err(_) => panic!("no line with {pat:?} in:\n{}", self.seen.join("\n")),
            }
        }
    }

    /// SIGTERM, then everything it printed.
    pub fn stop(mut self) -> String {
        // SAFETY: signalling our own child.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        let status = self.child.wait().unwrap();
        assert!(status.success(), "simulate exited with {status}");
        let mut log = std::mem::take(&mut self.seen);
        while let Ok(l) = self.lines.recv_timeout(Duration::from_secs(5)) {
            log.push(l);
        }
        log.join("\n")
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
