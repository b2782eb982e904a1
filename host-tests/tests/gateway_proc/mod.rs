//! The gateway (`tools/gateway.sh`'s binary) as a process, for the
//! end-to-end tests that drive it with real clients (`iai_bridge.rs`,
//! `readme_try_it.rs`, `qemu_gateway.rs`, `qemu_ethernet.rs`, and through
//! `plc_gateway` the Modbus tests): started, its ready lines read, its
//! log kept, `iai` run against it, stopped.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

/// The ready lines of the serial build with its Modbus RTU port.
pub const SERIAL: [&str; 2] = ["protocol-b", "modbus-rtu"];
/// The ready lines of the Ethernet build.
pub const ETHERNET: [&str; 3] = ["protocol-b-tcp", "modbus-tcp", "http"];

/// The gateway; SIGTERM (then SIGKILL) when dropped.
pub struct Gateway {
    child: Child,
    /// Where its protocol-B side listens (the first ready line),
    /// `127.0.0.1:PORT`.
    pub addr: String,
    /// Its Modbus side (the second ready line, if one was due), or empty.
    pub modbus: String,
    /// Its web page (the third ready line, if one was due), or empty.
    pub http: String,
    stderr: Receiver<String>,
    log: Vec<String>,
}

/// Sends SIGname to our own child `pid`.
pub fn signal(pid: u32, name: &str) {
    let _ = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(pid.to_string())
        .status();
}

impl Gateway {
    /// Starts the gateway on the bridge firmware `elf`, with `args` after
    /// `--elf`, and waits for its ready lines, `ready` in that order (each
    /// `NAME 127.0.0.1:PORT`, the first within 90 s); then checks that it
    /// prints nothing else on stdout.
    pub fn start<S: AsRef<std::ffi::OsStr>>(elf: &Path, args: &[S], ready: &[&str]) -> Gateway {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gateway"))
            .arg("--elf")
            .arg(elf)
            .args(args)
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
            modbus: String::new(),
            http: String::new(),
            stderr,
            log: Vec::new(),
        };
        let mut addrs = Vec::new();
        for (i, name) in ready.iter().enumerate() {
            let wait = Duration::from_secs(if i == 0 { 90 } else { 5 });
            let l = stdout.recv_timeout(wait);
            let l = l.unwrap_or_else(|_| panic!("no {name} line; stderr:\n{}", gw.log()));
            let addr = l
                .strip_prefix(name)
                .and_then(|a| a.strip_prefix(' '))
                .filter(|a| {
                    a.strip_prefix("127.0.0.1:")
                        .is_some_and(|p| p.parse::<u16>().is_ok())
                })
                .unwrap_or_else(|| panic!("{l:?} where {name} was due"));
            addrs.push(addr.to_owned());
        }
        let more = stdout.recv_timeout(Duration::from_millis(200));
        assert!(more.is_err(), "more on stdout: {more:?}");
        let mut addrs = addrs.into_iter();
        gw.addr = addrs.next().unwrap_or_default();
        gw.modbus = addrs.next().unwrap_or_default();
        gw.http = addrs.next().unwrap_or_default();
        gw
    }

    /// The Modbus side's port number.
    pub fn modbus_port(&self) -> &str {
        self.modbus.trim_start_matches("127.0.0.1:")
    }

    /// Its log (stderr) so far.
    pub fn log(&mut self) -> String {
        while let Ok(l) = self.stderr.try_recv() {
            self.log.push(l);
        }
        self.log.join("\n")
    }

    /// Waits (at most 10 s) for a log line containing `pat`.
    pub fn wait_for(&mut self, pat: &str) {
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
    pub fn qemu_pid(&mut self) -> u32 {
        let log = self.log();
        log.split("(QEMU pid ")
            .nth(1)
            .and_then(|s| s.split(')').next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no QEMU pid in:\n{log}"))
    }

    /// `iai ARGS` in the directory `dir`, which must succeed.
    pub fn run<S: AsRef<std::ffi::OsStr> + std::fmt::Debug>(
        &mut self,
        iai: &Path,
        args: &[S],
        dir: &Path,
    ) -> Output {
        let out = Command::new(iai)
            .args(args)
            .current_dir(dir)
            .stdin(Stdio::null())
            .output()
            .expect("run iai");
        assert!(
            out.status.success(),
            "iai {args:?}: {}\n{}\n{}\ngateway:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
            self.log()
        );
        out
    }

    /// `iai ARGS --tcp ADDR` on its protocol-B side, which must succeed.
    pub fn iai(&mut self, iai: &Path, args: &[&str]) -> Output {
        let addr = self.addr.clone();
        let mut all: Vec<&str> = args.to_vec();
        all.extend(["--tcp", &addr]);
        self.run(iai, &all, Path::new("."))
    }

    /// SIGTERM, then the exit status (within 10 s).
    pub fn stop(&mut self) -> ExitStatus {
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
            for _ in 0..100 {
                if let Ok(Some(_)) = self.child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

/// The table `host_tests::table::table(records, 8, seed)` as a CSV of 8
/// axes, as `iai table write` takes it and `iai table read` prints it.
pub fn csv_of(records: u32, seed: u32) -> Vec<u8> {
    let mut csv = Vec::new();
    iai_cli::csvtable::write_header(&mut csv, 8).unwrap();
    for r in host_tests::table::table(records, 8, seed) {
        iai_cli::csvtable::write_row(&mut csv, &r, 8).unwrap();
    }
    csv
}

/// What `o` printed on stdout.
pub fn text(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// What `o` printed on stderr.
pub fn err(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
