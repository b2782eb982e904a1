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

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

use host_tests::qemu::{build_firmware, Board};
use host_tests::table::table;

/// The gateway process; stopped (SIGTERM, then SIGKILL) when dropped.
struct Gateway {
    child: Child,
    addr: String,
    stderr: Receiver<String>,
    log: Vec<String>,
}

impl Gateway {
    fn start(elf: &Path) -> Gateway {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gateway"))
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
            addr: String::new(),
            stderr,
            log: Vec::new(),
        };
        let first = stdout.recv_timeout(Duration::from_secs(60));
        gw.drain_log();
        let first = first.unwrap_or_else(|_| panic!("no ready line; stderr:\n{}", gw.log()));
        gw.addr = first
            .strip_prefix("protocol-b ")
            .filter(|a| a.starts_with("127.0.0.1:"))
            .unwrap_or_else(|| panic!("first line {first:?}"))
            .to_owned();
        // Then the Modbus RTU port (lm3s6965 has one), and nothing more.
        let second = stdout.recv_timeout(Duration::from_secs(5));
        gw.drain_log();
        let second = second.unwrap_or_else(|_| panic!("no modbus-rtu line; stderr:\n{}", gw.log()));
        assert!(
            second.starts_with("modbus-rtu 127.0.0.1:"),
            "second line {second:?}"
        );
        assert!(stdout.recv_timeout(Duration::from_millis(200)).is_err());
        gw
    }

    fn drain_log(&mut self) {
        while let Ok(l) = self.stderr.try_recv() {
            self.log.push(l);
        }
    }

    fn log(&mut self) -> String {
        self.drain_log();
        self.log.join("\n")
    }

    /// Waits (at most 10 s) for a log line containing `pat`.
    fn wait_for(&mut self, pat: &str) {
        let end = Instant::now() + Duration::from_secs(10);
        while !self.log.iter().any(|l| l.contains(pat)) {
            let left = end.saturating_duration_since(Instant::now());
            match self.stderr.recv_timeout(left) {
                Ok(l) => self.log.push(l),
                Err(_) => panic!("no log line with {pat:?} in:\n{}", self.log.join("\n")),
            }
        }
    }

    /// The pid of the QEMU it started, from its log.
    fn qemu_pid(&mut self) -> u32 {
        let log = self.log();
        log.split("(QEMU pid ")
            .nth(1)
            .and_then(|s| s.split(')').next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no QEMU pid in:\n{log}"))
    }

    fn iai(&mut self, iai: &Path, args: &[&str]) -> Output {
        let out = Command::new(iai)
            .args(args)
            .args(["--tcp", &self.addr])
            .stdin(Stdio::null())
            .output()
            .expect("run iai");
        assert!(
            out.status.success(),
            "iai {args:?}: {}\n{}\ngateway:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr),
            self.log()
        );
        out
    }

    fn connect(&self) -> TcpStream {
        let c = TcpStream::connect(&self.addr).expect("connect");
        c.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        c
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

/// Whether `pid` is a running (not reaped) qemu-system-arm.
fn qemu_running(pid: u32) -> bool {
    std::fs::read(format!("/proc/{pid}/cmdline"))
        .is_ok_and(|c| String::from_utf8_lossy(&c).contains("qemu-system-arm"))
}

#[test]
fn iai_through_the_gateway_sends_writes_and_reads_a_table() {
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf);
    let qemu = gw.qemu_pid();
    assert!(qemu_running(qemu));

    // An axis status query, typed.
    let out = gw.iai(&iai, &["send", "212", "query_axis_pattern=1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("212H Axis Status Query"), "{text}");
    assert!(text.contains("axis_pattern = 0x01"), "{text}");
    assert!(text.contains("axes[0].current_position = 0"), "{text}");

    // One client at a time: a second connection is closed unanswered.
    let mut first = gw.connect();
    let peer = first.local_addr().unwrap();
    gw.wait_for(&format!("{peer} connected"));
    let mut second = gw.connect();
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
    let mut csv = Vec::new();
    iai_cli::csvtable::write_header(&mut csv, 8).unwrap();
    for r in table(200, 8, 77) {
        iai_cli::csvtable::write_row(&mut csv, &r, 8).unwrap();
    }
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
