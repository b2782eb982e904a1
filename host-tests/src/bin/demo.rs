//! Demo: the bridge firmware on QEMU `lm3s6965evb` writes a 20,000-record,
//! 8-axis position table (one 26DH command of 1,640,014 bytes) to the
//! controller simulator, in controller-sized confirmed commands.
//!
//! Run through `./tools/demo.sh` (it installs QEMU and the targets, builds
//! the firmware in release). Options: `--records N` (1..=20000),
//! `--elf PATH` (default: build the release firmware), `--timeout SECS`
//! (whole-transfer limit, default 300). Exit code 0 only if the simulator's
//! table equals the source and QEMU exited cleanly.

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::thread;
use std::time::{Duration, Instant};

use host_tests::bridge::{check_table, command_26dh, read_frame, reply_26dh, send, SimThread};
use host_tests::qemu::{build_firmware, Board, QemuSession};
use host_tests::sim::Simulator;
use host_tests::table::table;
use iai_protocol_b::frame::Station;

const STATION: Station = Station(0x99);

struct Options {
    records: u16,
    elf: Option<PathBuf>,
    timeout: Duration,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options {
        records: 20_000,
        elf: None,
        timeout: Duration::from_secs(300),
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--records" => {
                o.records = value()?
                    .parse()
                    .ok()
                    .filter(|n| (1..=20_000).contains(n))
                    .ok_or("--records takes 1..=20000")?;
            }
            "--elf" => o.elf = Some(PathBuf::from(value()?)),
            "--timeout" => {
                o.timeout = Duration::from_secs(
                    value()?
                        .parse()
                        .map_err(|_| "--timeout takes seconds".to_owned())?,
                );
            }
            "-h" | "--help" => {
                return Err("usage: demo [--records N] [--elf PATH] [--timeout SECS]".to_owned())
            }
            other => return Err(format!("unknown argument {other:?} (try --help)")),
        }
    }
    Ok(o)
}

/// A text progress bar on stderr: records the controller has written.
fn progress_bar(done: usize, total: usize, started: Instant) {
    const WIDTH: usize = 40;
    let filled = (done * WIDTH).checked_div(total).unwrap_or(WIDTH);
    let secs = started.elapsed().as_secs_f64();
    let rate = if secs > 0.0 { done as f64 / secs } else { 0.0 };
    eprint!(
        "\r[{}{}] {:>3}% {:>6} / {} records  {:>6.0} rec/s  {:>5.1} s",
        "#".repeat(filled),
        "-".repeat(WIDTH - filled),
        (done * 100).checked_div(total).unwrap_or(100),
        done,
        total,
        rate,
        secs
    );
    let _ = io::stderr().flush();
}

fn run() -> Result<(), String> {
    let o = parse_args()?;
    let elf = match o.elf {
        Some(p) => p,
        None => build_firmware(Board::Lm3s6965).map_err(|e| format!("building firmware: {e}"))?,
    };
    let records: Vec<_> = table(u32::from(o.records), 8, 2024).collect();
    let command = command_26dh(STATION, &records);
    eprintln!(
        "demo: {} records x 8 axes = one 26DH command of {} bytes",
        records.len(),
        command.len()
    );

    let mut qemu = QemuSession::start(Board::Lm3s6965, &elf, Duration::from_secs(15))
        .map_err(|e| format!("starting QEMU: {e}"))?;
    eprintln!(
        "demo: QEMU {} (pid {}) up; simulator on the downstream",
        Board::Lm3s6965,
        qemu.pid()
    );
    qemu.upstream
        .set_write_timeout(Some(Duration::from_secs(30)))
        .map_err(|e| e.to_string())?;
    let sim = SimThread::spawn_with(
        Simulator::tta(STATION),
        qemu.downstream
            .try_clone()
            .map_err(|e| format!("downstream socket: {e}"))?,
        true,
    );

    // Send on a thread (the sockets and QEMU buffer most of the command, so
    // the bar follows the records the controller has written instead).
    let started = Instant::now();
    let mut writer = qemu
        .upstream
        .try_clone()
        .map_err(|e| format!("upstream socket: {e}"))?;
    let sender = {
        let command = command.clone();
        thread::spawn(move || send(&mut writer, &command, |_| {}))
    };
    // The reply comes only at the end; wait for it while drawing.
    let mut reader = qemu
        .upstream
        .try_clone()
        .map_err(|e| format!("upstream socket: {e}"))?;
    let deadline = started + o.timeout;
    let reply = loop {
        progress_bar(sim.records() as usize, records.len(), started);
        if let Some(f) =
            read_frame(&mut reader, Duration::from_millis(100)).map_err(|e| e.to_string())?
        {
            break Some(f);
        }
        if Instant::now() >= deadline {
            break None;
        }
    };
    progress_bar(sim.records() as usize, records.len(), started);
    eprintln!();
    let elapsed = started.elapsed();
    match sender.join() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(format!("sending the command: {e}")),
        Err(_) => return Err("sender thread panicked".to_owned()),
    }
    let reply = reply.ok_or_else(|| format!("no reply from the bridge within {:?}", o.timeout))?;
    let want = reply_26dh(STATION, o.records);
    if reply != want {
        return Err(format!(
            "bridge answered {:?}, expected {:?}",
            String::from_utf8_lossy(&reply),
            String::from_utf8_lossy(&want)
        ));
    }

    qemu.quit().map_err(|e| format!("sending quit: {e}"))?;
    let outcome = qemu
        .wait(Duration::from_secs(10))
        .map_err(|e| format!("waiting for QEMU: {e}"))?;
    if !outcome.success() {
        return Err(format!(
            "firmware exited with {:?}\n{}",
            outcome.code, outcome.stdout
        ));
    }
    let sim = sim.join().map_err(|e| e.to_string())?;
    check_table(&sim.table, &records).map_err(|e| format!("table check failed: {e}"))?;
    let s = sim.stats();
    let firmware = outcome
        .stdout
        .lines()
        .find(|l| l.contains("BridgeStats"))
        .unwrap_or("(no firmware stats)")
        .trim_start_matches("firmware-example: ");
    let retries = firmware
        .split("retries: ")
        .nth(1)
        .and_then(|r| r.split(',').next())
        .unwrap_or("?");

    println!("demo: OK — the simulator's table equals the source");
    println!("  records          {}", records.len());
    println!(
        "  host -> bridge   {} bytes (one 26DH), reply {:?}",
        command.len(),
        String::from_utf8_lossy(&reply).trim_end()
    );
    println!(
        "  bridge -> ctrl   {} bytes in {} 26DH commands, {} bytes of replies",
        s.bytes_in, s.commands, s.bytes_out
    );
    println!("  retries          {retries}");
    println!(
        "  time             {:.1} s ({:.1} kB/s upstream)",
        elapsed.as_secs_f64(),
        command.len() as f64 / elapsed.as_secs_f64() / 1000.0
    );
    println!("  firmware         {firmware}");
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("\ndemo: FAILED: {e}");
            ExitCode::FAILURE
        }
    }
}
