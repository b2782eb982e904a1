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
//! 2. **mbpoll** (`-m tcp`): reads PNOW and DSS1 (servo on, homed, at
//!    rest);
//! 3. a raw socket: transaction IDs echoed on two requests sent back to
//!    back, an ADU with a protocol ID other than 0 dropped unanswered
//!    (the connection goes on), a length field out of range closes the
//!    connection; two clients are served at once.
//!
//! pymodbus comes from the venv `tools/setup.sh` makes (`.venv`), mbpoll
//! from the Debian package it installs. A client that is absent is
//! skipped with its reason printed; the test fails if both are.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

use host_tests::qemu::{build_ethernet_firmware, workspace_root};

const PNOW: u16 = 0x9000;
const DSS1: u16 = 0x9005;
const SV: u16 = 1 << 12;
const HEND: u16 = 1 << 4;
const PEND: u16 = 1 << 3;

/// Builds the `iai` binary in this test's profile; its path.
fn iai_binary() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .to_path_buf();
    let profile = match dir.file_name().and_then(|n| n.to_str()) {
        Some("debug") => "dev".to_owned(),
        Some(other) => other.to_owned(),
        None => panic!("no profile directory in {}", exe.display()),
    };
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(workspace_root())
        .args(["build", "--quiet", "-p", "iai-cli", "--bin", "iai"])
        .arg("--profile")
        .arg(&profile)
        .stdin(Stdio::null())
        .output()
        .expect("run cargo");
    assert!(
        out.status.success(),
        "building iai failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    dir.join("iai")
}

/// Whether `tool` is on the PATH.
fn on_path(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The venv's python if it has pymodbus, else why not.
fn pymodbus_python() -> Result<PathBuf, String> {
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
fn run_within(cmd: &mut Command, limit: Duration) -> Output {
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
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        status,
        stdout: out.join().unwrap_or_default(),
        stderr: err.join().unwrap_or_default(),
    }
}

/// The gateway process with `--ethernet`; stopped (SIGTERM, then SIGKILL)
/// when dropped.
struct Gateway {
    child: Child,
    protocol_b: String,
    modbus: String,
    stderr: Receiver<String>,
    log: Vec<String>,
}

impl Gateway {
    fn start(elf: &Path) -> Gateway {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gateway"))
            .arg("--ethernet")
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
        gw.protocol_b = next("protocol-b-tcp", &mut gw);
        gw.modbus = next("modbus-tcp", &mut gw);
        gw
    }

    fn modbus_port(&self) -> &str {
        self.modbus.trim_start_matches("127.0.0.1:")
    }

    fn log(&mut self) -> String {
        while let Ok(l) = self.stderr.try_recv() {
            self.log.push(l);
        }
        self.log.join("\n")
    }

    /// The simulator's current position of axis 1, from its 212H reply
    /// through the bridge over TCP (asked by `iai`).
    fn axis1_position(&mut self, iai: &Path) -> i64 {
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

    /// SIGTERM, then the exit status.
    fn stop(&mut self) -> std::process::ExitStatus {
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
fn signal(pid: u32, name: &str) {
    let _ = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(pid.to_string())
        .status();
}

/// mbpoll over Modbus TCP: `count` values from `addr` of data type `kind`
/// (`3:hex`, `3:int`), unit 1, PDU addresses, once.
fn mbpoll_read(port: &str, kind: &str, addr: u16, count: usize) -> Vec<i64> {
    let out = run_within(
        Command::new("mbpoll")
            .args([
                "-m", "tcp", "-p", port, "-a", "1", "-0", "-1", "-q", "-o", "1",
            ])
            .args(["-t", kind, "-B", "-r", &addr.to_string()])
            .args(["-c", &count.to_string(), "127.0.0.1"]),
        Duration::from_secs(10),
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "mbpoll {kind} {addr:04X}: {}\n{text}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let values: Vec<i64> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix('['))
        .filter_map(|l| l.split_once("]:"))
        .map(|(_, v)| {
            let v = v.trim();
            match v.strip_prefix("0x") {
                Some(h) => i64::from_str_radix(h, 16),
                None => v.parse(),
            }
            .unwrap_or_else(|_| panic!("mbpoll value {v:?} in:\n{text}"))
        })
        .collect();
    assert_eq!(values.len(), count, "mbpoll read {addr:04X}:\n{text}");
    values
}

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
    let iai = iai_binary();
    let mut gw = Gateway::start(&elf);
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
        let port = gw.modbus_port().to_owned();
        let read = mbpoll_read(&port, "3:int", PNOW, 1)[0];
        let sim = gw.axis1_position(&iai);
        assert_eq!(
            read, sim,
            "PNOW read by mbpoll against the simulator's 212H"
        );
        if let Some(p) = pnow {
            assert_eq!(read, p);
        }
        let dss1 = mbpoll_read(&port, "3:hex", DSS1, 1)[0];
        let dss1 = u16::try_from(dss1).expect("a 16-bit register");
        if pnow.is_some() {
            // pymodbus left the axis servo on, homed and at rest.
            assert_eq!(
                dss1 & (SV | HEND | PEND),
                SV | HEND | PEND,
                "DSS1 {dss1:04X}"
            );
        }
        println!("mbpoll -m tcp: PNOW {read}, DSS1 {dss1:04X}");
        pnow = Some(read);
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
