//! The gateway process and the third-party clients around it, for the
//! end-to-end tests of its Modbus fronts (`qemu_modbus.rs` on the serial
//! build's RTU port, `qemu_modbus_tcp.rs` on the Ethernet build's Modbus
//! TCP port). Each test uses its part.
#![allow(dead_code)]

pub mod mbpoll;

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

use host_tests::qemu::workspace_root;
use iai_protocol_b::position::PositionRecord;

/// Whether `tool` is on the PATH.
pub fn on_path(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The venv's python if it has pymodbus, else why not.
pub fn pymodbus_python() -> Result<PathBuf, String> {
    let py = workspace_root().join(".venv/bin/python");
    if !py.is_file() {
        return Err(format!("{} is absent", py.display()));
    }
    let ok = Command::new(&py)
        .args(["-c", "import pymodbus"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        Ok(py)
    } else {
        Err(format!("{} has no pymodbus", py.display()))
    }
}

/// Runs `cmd` to its end, killed after `limit`.
pub fn run_within(cmd: &mut Command, limit: Duration) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let pipe = |p: Option<Box<dyn Read + Send>>| {
        let mut p = p.expect("piped");
        std::thread::spawn(move || {
            let mut v = Vec::new();
            let _ = p.read_to_end(&mut v);
            v
        })
    };
    let out = pipe(child.stdout.take().map(|p| Box::new(p) as _));
    let err = pipe(child.stderr.take().map(|p| Box::new(p) as _));
    let end = Instant::now() + limit;
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if Instant::now() > end {
            let _ = child.kill();
            break child.wait().expect("wait");
        }
        // Short: an mbpoll call takes about 30 ms (20 of them its own
        // sleep after connecting), and a PLC sequence makes hundreds.
        std::thread::sleep(Duration::from_millis(2));
    };
    Output {
        status,
        stdout: out.join().unwrap_or_default(),
        stderr: err.join().unwrap_or_default(),
    }
}

/// The gateway process (`tools/gateway.sh`'s binary), on the serial build
/// or with `--ethernet`; stopped (SIGTERM, then SIGKILL) when dropped.
pub struct Gateway {
    child: Child,
    /// The protocol-B port, `127.0.0.1:PORT`.
    pub protocol_b: String,
    /// The Modbus port (RTU frames over TCP, or Modbus TCP), `127.0.0.1:PORT`.
    pub modbus: String,
    stderr: Receiver<String>,
    log: Vec<String>,
}

impl Gateway {
    /// Starts it on `elf` and waits for its two ready lines: `protocol-b`
    /// and `modbus-rtu`, or with `ethernet` `protocol-b-tcp` and
    /// `modbus-tcp`.
    pub fn start(elf: &Path, ethernet: bool) -> Gateway {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gateway"))
            .args(ethernet.then_some("--ethernet"))
            .arg("--elf")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start the gateway");
        let lines = |pipe: Box<dyn Read + Send>| {
            let (tx, rx) = channel();
            std::thread::spawn(move || {
                for l in BufReader::new(pipe).lines() {
                    let Ok(l) = l else { break };
                    if tx.send(l).is_err() {
                        break;
                    }
                }
            });
            rx
        };
        let stdout = lines(Box::new(child.stdout.take().expect("stdout")));
        let stderr = lines(Box::new(child.stderr.take().expect("stderr")));
        let mut gw = Gateway {
            child,
            protocol_b: String::new(),
            modbus: String::new(),
            stderr,
            log: Vec::new(),
        };
        let next = |what: &str, gw: &mut Gateway| {
            let l = stdout.recv_timeout(Duration::from_secs(60));
            let l = l.unwrap_or_else(|_| panic!("no {what} line; stderr:\n{}", gw.log()));
            l.strip_prefix(what)
                .and_then(|a| a.strip_prefix(' '))
                .filter(|a| a.starts_with("127.0.0.1:"))
                .unwrap_or_else(|| panic!("{l:?} where {what} was due"))
                .to_owned()
        };
        let (host, plc) = if ethernet {
            ("protocol-b-tcp", "modbus-tcp")
        } else {
            ("protocol-b", "modbus-rtu")
        };
        gw.protocol_b = next(host, &mut gw);
        gw.modbus = next(plc, &mut gw);
        gw
    }

    pub fn modbus_port(&self) -> &str {
        self.modbus.trim_start_matches("127.0.0.1:")
    }

    pub fn log(&mut self) -> String {
        while let Ok(l) = self.stderr.try_recv() {
            self.log.push(l);
        }
        self.log.join("\n")
    }

    /// The simulator's current position of axis 1, from its 212H reply
    /// through the bridge (asked by `iai` on the protocol-B port).
    pub fn axis1_position(&mut self, iai: &Path) -> i64 {
        let out = run_within(
            Command::new(iai).args([
                "send",
                "212",
                "query_axis_pattern=1",
                "--tcp",
                &self.protocol_b,
            ]),
            Duration::from_secs(30),
        );
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success(), "iai send 212: {text}\n{}", self.log());
        text.lines()
            .find_map(|l| l.trim().strip_prefix("axes[0].current_position = "))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no position in:\n{text}"))
    }

    /// Positions `first`..`first + count` as `iai table read` prints them
    /// (CSV of 8 axes), read on the protocol-B port.
    pub fn table_csv(&mut self, iai: &Path, first: u16, count: usize) -> Vec<u8> {
        let out = run_within(
            Command::new(iai).args([
                "table",
                "read",
                "--first",
                &first.to_string(),
                "--count",
                &count.to_string(),
                "--tcp",
                &self.protocol_b,
            ]),
            Duration::from_secs(60),
        );
        assert!(
            out.status.success(),
            "iai table read: {}\n{}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr),
            self.log()
        );
        out.stdout
    }

    /// SIGTERM, then the exit status.
    pub fn stop(&mut self) -> std::process::ExitStatus {
        signal(self.child.id(), "TERM");
        let end = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some(status) = self.child.try_wait().expect("wait") {
                return status;
            }
            assert!(Instant::now() < end, "the gateway did not stop");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            signal(self.child.id(), "TERM");
            std::thread::sleep(Duration::from_secs(2));
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// Sends SIGname to our own child `pid`.
pub fn signal(pid: u32, name: &str) {
    let _ = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(pid.to_string())
        .status();
}

/// `records` as `iai table read` prints them (8 axes).
pub fn csv_of(records: &[PositionRecord]) -> Vec<u8> {
    let mut csv = Vec::new();
    iai_cli::csvtable::write_header(&mut csv, 8).unwrap();
    for r in records {
        iai_cli::csvtable::write_row(&mut csv, r, 8).unwrap();
    }
    csv
}
