//! The third-party clients around the gateway process
//! ([`crate::gateway_proc`]), for the end-to-end tests of its Modbus
//! fronts (`qemu_modbus.rs` on the serial build's RTU port,
//! `qemu_modbus_tcp.rs` on the Ethernet build's Modbus TCP port). Each
//! test uses its part.
#![allow(dead_code)]

pub mod mbpoll;
pub mod standard;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::gateway_proc::Gateway;
use host_tests::qemu::workspace_root;
use iai_protocol_b::position::PositionRecord;

/// Registers of one record in the table window (PWREC, 2200H).
pub const RECORD_WORDS: usize = 21;

/// A record as its 21 window registers: number, axis pattern,
/// acceleration, deceleration, speed, axes 1 to 8 (high word first).
pub fn record_words(r: &PositionRecord) -> Vec<u16> {
    let mut w = vec![
        r.number,
        u16::from(r.axes.bits()),
        r.acceleration,
        r.deceleration,
        r.speed,
    ];
    let mut at = r.positions.iter();
    for axis in 0..8 {
        let v = if r.axes.bits() & (1 << axis) != 0 {
            at.next().copied().unwrap_or(0)
        } else {
            0
        };
        let v = v as u32;
        w.extend([(v >> 16) as u16, v as u16]);
    }
    assert_eq!(w.len(), RECORD_WORDS);
    w
}

/// Writes `records` as `pymodbus_plc.py`'s TABLE file: one record a line,
/// its window registers in decimal.
pub fn write_table_file(path: &Path, records: &[PositionRecord]) {
    let text: String = records
        .iter()
        .map(|r| {
            let w: Vec<String> = record_words(r).iter().map(u16::to_string).collect();
            w.join(" ") + "\n"
        })
        .collect();
    std::fs::write(path, text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

/// The seconds `pymodbus_plc.py` printed on its line `time LABEL...: S s`
/// (the table write's and read-back's).
pub fn plc_seconds(stdout: &str, label: &str) -> Option<f64> {
    stdout
        .lines()
        .filter_map(|l| l.strip_prefix("time "))
        .filter(|l| l.starts_with(label))
        .find_map(|l| l.rsplit_once(": "))
        .and_then(|(_, v)| v.strip_suffix(" s"))
        .and_then(|v| v.parse().ok())
}

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

/// Where `pymodbus_plc.py`'s numeric move goes, 0.001 mm.
pub const PYMODBUS_MOVE_TO: i64 = 25_500;

/// pymodbus's PLC sequence (`host-tests/plc/pymodbus_plc.py`, RTU framing
/// over TCP or with `tcp` Modbus TCP) against `gw`: servo on, home, HEND,
/// the numeric move, PEND, PNOW; `records` written through the table
/// window and read back equal. Then, with the real `iai` on the
/// protocol-B port: the simulator's 212H at PNOW, and the controller
/// holding exactly `records`. Prints the times.
pub fn pymodbus_sequence(
    gw: &mut Gateway,
    python: &Path,
    iai: &Path,
    records: &[PositionRecord],
    tcp: bool,
) {
    let framing = if tcp { "Modbus TCP" } else { "RTU" };
    let file = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!(
        "pymodbus-{}-{}.txt",
        if tcp { "tcp" } else { "rtu" },
        std::process::id()
    ));
    write_table_file(&file, records);
    let t = Instant::now();
    let out = run_within(
        Command::new(python)
            .arg(workspace_root().join("host-tests/plc/pymodbus_plc.py"))
            .args(tcp.then_some("--tcp"))
            .args(["127.0.0.1", gw.modbus_port()])
            .arg(&file),
        Duration::from_secs(180),
    );
    let _ = std::fs::remove_file(&file);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    println!(
        "pymodbus, {framing} ({:.1} s):\n{stdout}",
        t.elapsed().as_secs_f64()
    );
    assert!(
        out.status.success(),
        "pymodbus: {}\n{stdout}\n{}\ngateway:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr),
        gw.log()
    );
    let pnow = format!("pnow {PYMODBUS_MOVE_TO}");
    assert!(stdout.lines().any(|l| l == pnow), "{stdout}");
    let n = records.len();
    assert!(
        stdout
            .lines()
            .any(|l| l == format!("table {n} written, read back equal")),
        "{stdout}"
    );
    assert_eq!(
        gw.axis1_position(iai),
        PYMODBUS_MOVE_TO,
        "the simulator's 212H"
    );
    // The controller holds exactly what the PLC wrote: the real iai tool
    // reads it back on the protocol-B port.
    let iai_read = gw.assert_controller_holds(iai, records);
    let written = plc_seconds(&stdout, "table write").expect("the write's time");
    let read_back = plc_seconds(&stdout, "table read back").expect("the read-back's time");
    println!(
        "{framing} table window: {n} positions x 8 axes written in {written:.1} s, read back \
         equal in {read_back:.1} s (pymodbus); iai table read --all on the protocol-B port: \
         the same {n}, {iai_read:.1} s"
    );
}

/// The PLC tests' questions to the gateway, asked with the real `iai`
/// tool on its protocol-B side.
impl Gateway {
    /// The simulator's current position of axis 1, from its 212H reply
    /// through the bridge (asked by `iai` on the protocol-B port).
    pub fn axis1_position(&mut self, iai: &Path) -> i64 {
        let out = run_within(
            Command::new(iai).args(["send", "212", "query_axis_pattern=1", "--tcp", &self.addr]),
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

    /// Checks with the real `iai` tool on the protocol-B port that the
    /// controller's table is exactly `records` (`iai table read --all`:
    /// the positions 208H counts, compared with the records' CSV); the
    /// seconds the read took.
    pub fn assert_controller_holds(&mut self, iai: &Path, records: &[PositionRecord]) -> f64 {
        let mut sorted: Vec<&PositionRecord> = records.iter().collect();
        sorted.sort_by_key(|r| r.number);
        let axes = iai_cli::csvtable::axes_used(sorted.iter().copied());
        let mut csv = Vec::new();
        iai_cli::csvtable::write_header(&mut csv, axes).unwrap();
        for r in sorted {
            iai_cli::csvtable::write_row(&mut csv, r, axes).unwrap();
        }
        let t = Instant::now();
        let out = run_within(
            Command::new(iai).args(["table", "read", "--all", "--tcp", &self.addr]),
            Duration::from_secs(60),
        );
        let took = t.elapsed().as_secs_f64();
        assert!(
            out.status.success(),
            "iai table read: {}\n{}\ngateway:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr),
            self.log()
        );
        assert!(
            out.stdout == csv,
            "iai table read --all after the PLC's writes:\n{}",
            String::from_utf8_lossy(&out.stdout)
        );
        took
    }
}
