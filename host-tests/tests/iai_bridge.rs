//! `iai` and the bridge firmware end to end: the gateway
//! (`tools/gateway.sh`'s binary: the bridge under QEMU `lm3s6965evb`, the
//! simulator behind it, its host side on a TCP port) and the real `iai`
//! tool as a user runs it.
//!
//! 1. `iai bridge status` decodes the bridge's status reply;
//! 2. `iai probe` finds the bridge and the controller behind it;
//! 3. `iai table write --bridge` sends 600 records x 8 axes as one 26DH
//!    (about 49 KB, the bridge splits it into 2,051-byte commands and
//!    reads each back) and reports the bridge's `#`; `iai table read` gives
//!    the same CSV back; the bridge's counters show the message;
//! 4. `--bridge --replace` leaves exactly the new file's records.
//!
//! The `iai` binary is built here with cargo (a no-op when the test
//! command built it), in this test's profile, as `qemu_gateway.rs` does.
//! Nothing asserts timing. Needs `qemu-system-arm` and the
//! `thumbv7m-none-eabi` rustup target.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::Duration;

use host_tests::qemu::{build_firmware, workspace_root, Board};
use host_tests::table::table;

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
        .args([
            "build",
            "--quiet",
            "-p",
            "iai-cli",
            "--bin",
            "iai",
            "--profile",
        ])
        .arg(&profile)
        .stdin(Stdio::null())
        .output()
        .expect("run cargo");
    assert!(
        out.status.success(),
        "building iai failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let iai = dir.join("iai");
    assert!(iai.is_file(), "{} missing", iai.display());
    iai
}

/// The gateway; SIGTERM (then SIGKILL) when dropped.
struct Gateway {
    child: Child,
    addr: String,
    log: Receiver<String>,
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
        let log = lines(Box::new(child.stderr.take().expect("stderr")));
        let first = stdout
            .recv_timeout(Duration::from_secs(60))
            .unwrap_or_else(|_| {
                panic!(
                    "no ready line: {}",
                    log.try_iter().collect::<Vec<_>>().join("\n")
                )
            });
        let addr = first
            .strip_prefix("protocol-b ")
            .unwrap_or_else(|| panic!("first line {first:?}"))
            .to_owned();
        Gateway { child, addr, log }
    }

    /// `iai ARGS --tcp ADDR`, which must succeed.
    fn iai(&self, iai: &Path, args: &[&str]) -> Output {
        let out = Command::new(iai)
            .args(args)
            .args(["--tcp", &self.addr])
            .stdin(Stdio::null())
            .output()
            .expect("run iai");
        assert!(
            out.status.success(),
            "iai {args:?}: {}\n{}\n{}\ngateway:\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
            self.log.try_iter().collect::<Vec<_>>().join("\n")
        );
        out
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.child.id().to_string())
            .status();
        for _ in 0..100 {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn text(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn err(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The value of `name = N` in `iai bridge status`'s listing.
fn counter(listing: &str, name: &str) -> u64 {
    let pat = format!("  {name} = ");
    listing
        .lines()
        .find_map(|l| l.strip_prefix(&pat))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in:\n{listing}"))
}

fn csv_of(records: u32, seed: u32) -> Vec<u8> {
    let mut csv = Vec::new();
    iai_cli::csvtable::write_header(&mut csv, 8).unwrap();
    for r in table(records, 8, seed) {
        iai_cli::csvtable::write_row(&mut csv, &r, 8).unwrap();
    }
    csv
}

#[test]
fn iai_sends_whole_tables_through_the_bridge_and_reads_its_status() {
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = iai_binary();
    let gw = Gateway::start(&elf);

    // 1. The status, decoded.
    let status = text(&gw.iai(&iai, &["bridge", "status"]));
    assert!(status.starts_with("bridge at station BB:"), "{status}");
    assert!(
        status.contains("controller_station = 153 -> 99"),
        "{status}"
    );
    assert!(status.contains("flow_control = 1 -> XON/XOFF"), "{status}");
    assert!(status.contains("policy = 0 -> forward all"), "{status}");
    let (ok_before, records_before) = (counter(&status, "streams_ok"), counter(&status, "records"));

    // 2. probe: the bridge, and station 99 behind it.
    let probe = text(&gw.iai(&iai, &["probe", "--timeout", "1000"]));
    assert!(
        probe.contains("bridge BB: a bridge answers its status query: controller station 99"),
        "{probe}"
    );
    assert!(probe.contains("station 99: ANSWERED"), "{probe}");

    // 3. 600 records x 8 axes as one 26DH, far past a controller's 2,051 bytes.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let csv = csv_of(600, 91);
    let path = dir.join(format!("bridge-{}.csv", std::process::id()));
    std::fs::write(&path, &csv).unwrap();
    let file = path.to_str().expect("UTF-8 path");
    let out = gw.iai(&iai, &["table", "write", file, "--bridge"]);
    assert!(
        text(&out).starts_with(
            "verified by the bridge: the controller holds all 600 records (1 26DH message(s) of "
        ),
        "{}\n{}",
        text(&out),
        err(&out)
    );
    assert!(
        err(&out).contains("the bridge answered # with 600"),
        "{}",
        err(&out)
    );
    let back = gw.iai(&iai, &["table", "read", "--first", "1", "--count", "600"]);
    assert!(back.stdout == csv, "read back:\n{}", text(&back));
    let status = text(&gw.iai(&iai, &["bridge", "status"]));
    assert!(counter(&status, "streams_ok") > ok_before, "{status}");
    assert!(
        counter(&status, "records") >= records_before + 600,
        "{status}"
    );
    assert_eq!(counter(&status, "streams_failed"), 0, "{status}");

    // 4. --replace through the bridge: the table becomes the new file's.
    let csv = csv_of(100, 92);
    let small = dir.join(format!("bridge-small-{}.csv", std::process::id()));
    std::fs::write(&small, &csv).unwrap();
    let out = gw.iai(
        &iai,
        &[
            "table",
            "write",
            small.to_str().unwrap(),
            "--bridge",
            "--replace",
        ],
    );
    assert!(
        text(&out).contains(
            "replaced: the controller's table defines exactly these 100 positions (208H: 100)"
        ),
        "{}\n{}",
        text(&out),
        err(&out)
    );
    let back = gw.iai(&iai, &["table", "read", "--all"]);
    assert!(back.stdout == csv, "read back:\n{}", text(&back));
    let _ = std::fs::remove_file(&path);
    let _ = std::fs::remove_file(&small);
}
