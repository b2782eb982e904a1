//! Demo: the bridge firmware under QEMU writes a position table (by
//! default 20,000 records x 8 axes, one 26DH command of 1,640,014 bytes)
//! to the controller simulator, in controller-sized confirmed commands.
//!
//! The host writes at a line rate (`--baud`, default 115,200, 8N1) and
//! honours the bridge's XON/XOFF, as a PC's serial port does: QEMU models
//! neither, so without this the run would prove nothing about overruns.
//! Afterwards it asks the bridge's status query for its counters, ends the
//! run with the quit sequence and prints the figures: the effective rate
//! against the line rate, the XOFF pauses, the overruns the bridge counted
//! and the firmware's measured stack peak. It asserts no timing.
//!
//! Run through `./tools/demo.sh`. Options: `--records N` (1..=20000),
//! `--baud B`, `--processing-ms MS` (the controller's time per command,
//! default 100), `--board lm3s6965|mps2-an386|b-l475e-iot01a`, `--faults SEED` (controller
//! faults: flipped bits both ways, dropped and `&` replies, records stored
//! altered; the host sends the command again after an `&`, up to
//! [`MAX_SENDS`] times), `--elf PATH`,
//! `--timeout SECS` (whole run, default 600). Exit code 0 only if the
//! simulator's table equals the source and QEMU exited cleanly.

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use firmware_example::config::Config;
use host_tests::bridge::{
    check_table, command_26dh, reply_26dh, status_query, HostLink, SimThread, Throughput,
};
use host_tests::qemu::{build_firmware, test_config, Board, QemuSession, READY_MARKER};
use host_tests::table::table;
use iai_protocol_b::line::LineConfig;
use iai_simulator::{Faults, Simulator};

/// Sends of the 26DH before the demo gives up (a host's own retries).
const MAX_SENDS: u32 = 8;

struct Options {
    records: u16,
    processing_ms: u32,
    baud: u32,
    board: Board,
    faults: Option<u64>,
    elf: Option<PathBuf>,
    timeout: Duration,
}

fn parse_args() -> Result<Options, String> {
    let mut o = Options {
        records: 20_000,
        processing_ms: 100,
        baud: 115_200,
        board: Board::Lm3s6965,
        faults: None,
        elf: None,
        timeout: Duration::from_secs(600),
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
            "--processing-ms" => {
                o.processing_ms = value()?
                    .parse()
                    .map_err(|_| "--processing-ms takes milliseconds".to_owned())?;
            }
            "--baud" => {
                o.baud = value()?
                    .parse()
                    .ok()
                    .filter(|b| firmware_example::config::BAUD_RATES.contains(b))
                    .ok_or("--baud takes 9600, 19200, 38400, 57600 or 115200")?;
            }
            "--board" => {
                let v = value()?;
                o.board = Board::named(&v)
                    .ok_or(format!("--board takes {}, not {v:?}", Board::names()))?;
            }
            "--faults" => {
                o.faults = Some(
                    value()?
                        .parse()
                        .map_err(|_| "--faults takes a seed (a number)".to_owned())?,
                )
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
                return Err("usage: demo [--records N] [--baud B] [--processing-ms MS] [--board NAME] [--faults SEED] [--elf PATH] [--timeout SECS]".to_owned())
            }
            other => return Err(format!("unknown argument {other:?} (try --help)")),
        }
    }
    Ok(o)
}

/// A text progress bar on stderr: records the controller has written.
fn progress_bar(done: usize, total: usize, started: Instant) {
    const WIDTH: usize = 40;
    // Records written again after a re-send count once.
    let done = done.min(total);
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

fn field(fields: &[(&'static str, u64)], name: &str) -> u64 {
    fields
        .iter()
        .find(|(n, _)| *n == name)
        .map_or(0, |(_, v)| *v)
}

fn run() -> Result<(), String> {
    let o = parse_args()?;
    let board = o.board;
    let elf = match o.elf {
        Some(p) => p,
        None => build_firmware(board).map_err(|e| format!("building firmware: {e}"))?,
    };
    let cfg = Config {
        upstream_baud: o.baud,
        downstream_baud: o.baud,
        ..test_config()
    };
    let station = cfg.controller_station;
    let records: Vec<_> = table(u32::from(o.records), 8, 2024).collect();
    let command = command_26dh(station, &records);
    eprintln!(
        "demo: {} records x 8 axes = one 26DH command of {} bytes, host paced to {} baud with XON/XOFF",
        records.len(),
        command.len(),
        o.baud
    );

    let qemu = QemuSession::start_configured(
        board,
        &elf,
        Duration::from_secs(15),
        Some(READY_MARKER),
        &[],
        Some(&cfg),
    )
    .map_err(|e| format!("starting QEMU: {e}"))?;
    eprintln!(
        "demo: QEMU {board} (pid {}) up; simulator on the downstream{}",
        qemu.pid(),
        o.faults
            .map(|s| format!(" with faults (seed {s})"))
            .unwrap_or_default()
    );
    let mut sim = Simulator::tta(station);
    sim.response_delay_ms = o.processing_ms;
    if let Some(seed) = o.faults {
        sim = sim.with_faults(
            // Rates a resend gets through: a 2 KB read-back reply is
            // broken one time in five at 1e-4 flipped bits per byte.
            Faults {
                flip_bit_out: 1e-4,
                flip_bit_in: 1e-5,
                drop_every_nth_reply: Some(25),
                error_reply: 0.005,
                garbage_before_reply: 0.05,
                swap_record: 0.02,
                ..Faults::default()
            },
            seed,
        );
    }
    let sim = SimThread::spawn(
        sim,
        qemu.downstream
            .try_clone()
            .map_err(|e| format!("downstream socket: {e}"))?,
        Some(o.baud),
    );
    let link = Arc::new(
        HostLink::new(&qemu.upstream, Some(o.baud), true)
            .map_err(|e| format!("upstream socket: {e}"))?,
    );

    // Send on a thread while the bar follows the records written; after an
    // `&` reply send the whole command again (position writes are
    // idempotent).
    let started = Instant::now();
    let deadline = started + o.timeout;
    let mut sends = 0;
    let reply = loop {
        sends += 1;
        let sender = {
            let link = Arc::clone(&link);
            let command = command.clone();
            thread::spawn(move || link.send(&command, |_| {}))
        };
        let reply = loop {
            progress_bar(sim.records() as usize, records.len(), started);
            if let Some(f) = link
                .read_frame(Duration::from_millis(200))
                .map_err(|e| e.to_string())?
            {
                break Some(f);
            }
            if Instant::now() >= deadline {
                break None;
            }
        };
        match sender.join() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(format!("sending the command: {e}")),
            Err(_) => return Err("sender thread panicked".to_owned()),
        }
        match reply {
            Some(r) if r.first() == Some(&b'&') && sends < MAX_SENDS => {
                eprintln!(
                    "\ndemo: the bridge answered {:?}; sending the command again",
                    String::from_utf8_lossy(&r).trim_end()
                );
            }
            other => break other,
        }
    };
    progress_bar(sim.records() as usize, records.len(), started);
    eprintln!();
    let elapsed = started.elapsed();
    let reply = reply.ok_or_else(|| format!("no reply from the bridge within {:?}", o.timeout))?;
    let want = reply_26dh(station, o.records);
    if reply != want {
        return Err(format!(
            "bridge answered {:?}, expected {:?}",
            String::from_utf8_lossy(&reply),
            String::from_utf8_lossy(&want)
        ));
    }
    let fields = status_query(&link, cfg.bridge_station, Duration::from_secs(5))?;
    let link_stats = link.stats();

    let mut qemu = qemu;
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
    let stack = outcome
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("firmware-example: stack peak "))
        .and_then(|l| l.split_whitespace().next())
        .unwrap_or("?")
        .to_owned();

    let line_rate = f64::from(o.baud) / 10.0;
    let secs = elapsed.as_secs_f64();
    let upstream = command.len() as f64 * f64::from(sends);
    println!("demo: OK, the simulator's table equals the source");
    println!("  board            {board}");
    println!("  records          {}", records.len());
    println!(
        "  host -> bridge   {} bytes (one 26DH, sent {sends} time(s)), reply {:?}",
        command.len(),
        String::from_utf8_lossy(&reply).trim_end()
    );
    println!(
        "  bridge -> ctrl   {} bytes in {} commands (26DH chunks and their 21FH read-backs), {} bytes of replies",
        s.bytes_in, s.commands, s.bytes_out
    );
    println!(
        "  rate             {:.0} B/s effective against a line rate of {line_rate:.0} B/s ({} baud): {:.0}%",
        upstream / secs,
        o.baud,
        upstream / secs * 100.0 / line_rate
    );
    println!(
        "  XOFF pauses      {} ({:.1} s stopped)",
        link_stats.xoffs,
        link_stats.paused.as_secs_f64()
    );
    println!(
        "  overruns         {} (upstream, counted by the bridge), {} downstream",
        field(&fields, "upstream_overruns"),
        field(&fields, "downstream_overruns")
    );
    println!(
        "  chunks           {} sent, {} retries, {} timeouts, {} & replies",
        field(&fields, "chunks_sent"),
        field(&fields, "retries"),
        field(&fields, "chunk_timeouts"),
        field(&fields, "chunk_error_replies")
    );
    println!("  time             {secs:.1} s");
    let throughput = Throughput {
        baud: o.baud,
        host_bytes: upstream as u64,
        seconds: secs,
        // The demo's own limit: QEMU hands the bridge's transmissions to
        // the simulator at emulator speed, and only the simulator's
        // replies are paced to the line rate, so only they take line time.
        downstream_bytes: s.bytes_out,
        commands: s.commands,
        per_command_ms: o.processing_ms + LineConfig::new(station).turnaround_ms,
    };
    // The demo's host honours XON/XOFF (the default configuration).
    println!("{}", throughput.line("xon-xoff"));
    println!("  stack peak       {stack} bytes");
    println!("stack {} {stack}", board.bin());
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
