//! Instructions per wire byte of the core's hex paths, and per received
//! byte of the firmware's line paths, on three Cortex-M cores, counted
//! under QEMU with `-icount shift=5,sleep=off`.
//!
//! Builds `firmware-example`'s `icount_bench` program (see
//! `firmware-example/src/bench.rs` and `src/bench_line.rs`) for each board
//! into its own target directory (`target/icount`, so the bridge ELF other
//! tests use stays as it is), runs it and prints one line per figure:
//!
//! ```text
//! icount <board> <workload> <what> <N.NN> instr/byte
//! ```
//!
//! for the boards `mps2-an386` (Cortex-M4F), `lm3s6965evb` (Cortex-M3) and
//! `microbit` (Cortex-M0, if this QEMU has it). The hex paths, per byte of
//! 26DH frames (workloads `26dh-8axis` and `26dh-1axis`): `encode`
//! (`PositionStreamEncoder::read` in 64-byte chunks), `encode-frame` (the
//! same, the whole frame in one `read`), `decode`
//! (`PositionStreamDecoder::decode`, a record per event), `decode-records`
//! (`PositionStreamDecoder::decode_records`, records straight into the
//! caller's array), `push` (the frame decoder, byte by byte) and
//! `checksum`. The line paths, per byte the bridge read: workload `bridge`
//! (`212h-8axis` and `21fh-window`, a host's command and the controller's
//! reply relayed; `listen`, replies heard with no command on the line) and
//! workload `gateway` (`poll-round`, the Modbus gateway's polls). Lines
//! starting `icount:` are context, not figures. Figures, not assertions:
//! the exit code is 0 when every board ran and checked its round trips,
//! whatever the numbers.

use std::collections::BTreeMap;
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use host_tests::qemu::{target_dir, workspace_root};

/// A QEMU machine the bench runs on.
struct Board {
    machine: &'static str,
    target: &'static str,
    /// Extra rustc arguments for the final link.
    link_args: &'static [&'static str],
}

const BOARDS: [Board; 3] = [
    Board {
        machine: "mps2-an386",
        target: "thumbv7em-none-eabihf",
        link_args: &[],
    },
    Board {
        machine: "lm3s6965evb",
        target: "thumbv7m-none-eabi",
        link_args: &[],
    },
    // The nRF51822 has 16 KiB of RAM, not the 64 KiB of the shared
    // memory.x: the stack starts at its top.
    Board {
        machine: "microbit",
        target: "thumbv6m-none-eabi",
        link_args: &["-C", "link-arg=--defsym=_stack_start=0x20004000"],
    },
];

/// The figures of a hex-path workload, in order.
const HEX_FIGURES: &[&str] = &[
    "encode",
    "encode-frame",
    "decode",
    "decode-records",
    "push",
    "checksum",
];

/// Every workload and its figures, in the order printed.
const WORKLOADS: [(&str, &[&str]); 4] = [
    ("26dh-8axis", HEX_FIGURES),
    ("26dh-1axis", HEX_FIGURES),
    ("bridge", &["212h-8axis", "21fh-window", "listen"]),
    ("gateway", &["poll-round"]),
];
const QEMU: &str = "qemu-system-arm";
const ICOUNT: &str = "shift=5,sleep=off";
const TIMEOUT: Duration = Duration::from_secs(120);

fn main() -> ExitCode {
    let machines = match Command::new(QEMU).args(["-machine", "help"]).output() {
        Ok(out) => String::from_utf8_lossy(&out.stdout).into_owned(),
        Err(e) => {
            eprintln!("icount: running {QEMU}: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut ok = true;
    for board in &BOARDS {
        let listed = machines
            .lines()
            .any(|l| l.split_whitespace().next() == Some(board.machine));
        if !listed {
            println!(
                "icount: {} skipped: this QEMU has no such machine",
                board.machine
            );
            continue;
        }
        if let Err(e) = measure(board) {
            eprintln!("icount: {}: {e}", board.machine);
            ok = false;
        }
    }
    println!("icount: -icount {ICOUNT}; instructions, not cycles");
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

fn measure(board: &Board) -> io::Result<()> {
    let elf = build(board)?;
    let out = run(board, &elf)?;
    let report = Report::parse(&out)?;
    let per_tick = report.instructions_per_tick();
    for (workload, expected) in WORKLOADS {
        let figures = report
            .workloads
            .iter()
            .find_map(|(w, f)| (w == workload).then_some(f))
            .ok_or_else(|| io::Error::other(format!("no {workload} figures in:\n{out}")))?;
        for &what in expected {
            let &(ticks, bytes) = figures.get(what).ok_or_else(|| {
                io::Error::other(format!("no {workload} {what} figure in:\n{out}"))
            })?;
            let per_byte = ticks as f64 * per_tick / bytes.max(1) as f64;
            println!(
                "icount {} {workload} {what} {per_byte:.2} instr/byte",
                board.machine
            );
        }
    }
    println!(
        "icount: {} is a {}, {:.4} instructions per SysTick tick",
        board.machine, report.core, per_tick,
    );
    Ok(())
}

/// Builds the bench program for `board`; the ELF path.
fn build(board: &Board) -> io::Result<PathBuf> {
    let dir = target_dir().join("icount");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let status = Command::new(&cargo)
        .current_dir(workspace_root())
        .args(["rustc", "--quiet", "-p", "firmware-example", "--release"])
        .args(["--no-default-features", "--features", "icount-bench"])
        .args(["--bin", "icount_bench", "--target", board.target])
        .arg("--target-dir")
        .arg(&dir)
        .arg("--")
        .args(board.link_args)
        .stdin(Stdio::null())
        .status()?;
    if !status.success() {
        return Err(io::Error::other(format!(
            "building icount_bench for {} failed with {status}",
            board.target
        )));
    }
    Ok(dir.join(board.target).join("release").join("icount_bench"))
}

/// Runs the ELF under QEMU; its semihosting output. Kills only its own
/// QEMU process, and only on a timeout.
fn run(board: &Board, elf: &Path) -> io::Result<String> {
    let mut child = Command::new(QEMU)
        .args(["-machine", board.machine])
        .args(["-nographic", "-monitor", "none", "-serial", "null"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", ICOUNT])
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()?;
    let mut stdout = child.stdout.take();
    let reader = thread::spawn(move || {
        let mut s = String::new();
        if let Some(out) = stdout.as_mut() {
            let _ = out.read_to_string(&mut s);
        }
        s
    });
    let deadline = Instant::now() + TIMEOUT;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                format!("{QEMU} did not finish within {TIMEOUT:?}"),
            ));
        }
        thread::sleep(Duration::from_millis(20));
    };
    let out = reader.join().unwrap_or_default();
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut err);
    }
    if !status.success() || !out.lines().any(|l| l == "bench ok") {
        return Err(io::Error::other(format!(
            "the bench failed ({status}):\n{out}{err}"
        )));
    }
    Ok(out)
}

/// One workload's figures: name -> (ticks, bytes).
type Figures = BTreeMap<String, (u64, u64)>;

/// What the bench printed.
struct Report {
    core: String,
    calibration: (u64, u64),
    /// Workload -> figure -> (ticks, bytes), in the order printed.
    workloads: Vec<(String, Figures)>,
}

impl Report {
    fn parse(out: &str) -> io::Result<Report> {
        let bad = |l: &str| io::Error::other(format!("unexpected bench line {l:?}"));
        let mut report = Report {
            core: String::from("unknown core"),
            calibration: (0, 0),
            workloads: Vec::new(),
        };
        for line in out.lines() {
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.as_slice() {
                ["bench", "core", name, _cpuid] => report.core = (*name).to_owned(),
                ["bench", "calibration", i, t] => {
                    report.calibration = (
                        i.parse().map_err(|_| bad(line))?,
                        t.parse().map_err(|_| bad(line))?,
                    );
                }
                ["bench", workload, what, ticks, bytes] => {
                    let figure = (
                        ticks.parse().map_err(|_| bad(line))?,
                        bytes.parse().map_err(|_| bad(line))?,
                    );
                    match report.workloads.iter_mut().find(|(w, _)| w == workload) {
                        Some((_, f)) => {
                            f.insert((*what).to_owned(), figure);
                        }
                        None => report.workloads.push((
                            (*workload).to_owned(),
                            BTreeMap::from([((*what).to_owned(), figure)]),
                        )),
                    }
                }
                _ => {}
            }
        }
        if report.calibration.1 == 0 {
            return Err(io::Error::other(format!("no calibration in:\n{out}")));
        }
        Ok(report)
    }

    fn instructions_per_tick(&self) -> f64 {
        self.calibration.0 as f64 / self.calibration.1 as f64
    }
}
