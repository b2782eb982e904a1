//! The STM32 boards' code under QEMU 10's `b-l475e-iot01a` (STM32L475,
//! the USART design of the STM32G0 boards, the same embassy tasks): the
//! firmware `b-l475e-iot01a` with the simulated controller behind it, as
//! `tools/gateway.sh --board b-l475e-iot01a` runs it, in one boot:
//!
//! 1. recorded commands (the read-only ones for station 99 in
//!    `fixtures/frames.txt`) pass through the bridge unchanged: the host
//!    gets exactly what the simulator answers each;
//! 2. pymodbus runs a PLC's sequence on the Modbus RTU port (servo, home,
//!    a numeric move, PNOW compared with the simulator's 212H, 100
//!    positions through the table window, read back, the controller
//!    holding exactly them);
//! 3. `iai table write --bridge` writes 2,000 records of 8 axes as one
//!    26DH, which the bridge splits, confirms and reads back (`verified`);
//!    208H then counts exactly 2,000 positions defined.
//!
//! Then, each in a short boot of its own: the embassy example (the core's
//! async `Client` and `Transfer` in an embassy task) against the
//! simulator; and the watchdog, which QEMU 10 does not model on this
//! board (its IWDG is an unimplemented device: a stalled loop is not
//! reset there). What is checked instead is what the firmware writes to
//! it (QEMU's `-d unimp` log): the start sequence, feeds while the loop
//! runs, none once it stalls.
//!
//! Needs QEMU 10's `qemu-system-arm` (tools/setup.sh installs it), the
//! `thumbv7em-none-eabihf` target and pymodbus (tools/setup.sh's venv).

#[path = "../fixtures/fixture_file.rs"]
mod fixture_file;
mod gateway_proc;
mod plc_gateway;

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use gateway_proc::{csv_of, err, text, Gateway, SERIAL};
use host_tests::bridge::SimThread;
use host_tests::qemu::{
    build_example, build_firmware, build_firmware_with, iai_binary, target_dir, Board, QemuSession,
    FIRMWARE_PROFILE,
};
use host_tests::table::table;
use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_simulator::Simulator;
use plc_gateway::{pymodbus_python, pymodbus_sequence};

const BOARD: Board = Board::BL475eIot01a;
const STATION: Station = Station(0x99);

/// The recorded commands to station 99 that change nothing in the
/// controller (test call, queries), so that the bridge's simulator and a
/// fresh one answer them alike.
fn recorded_queries() -> Vec<(String, Vec<u8>)> {
    const READ_ONLY: [&str; 6] = ["200", "208", "209", "212", "215", "216"];
    fixture_file::load()
        .into_iter()
        .filter(|f| f.dir == "host>controller")
        .filter(|f| {
            let mut e = f.envelope.split_whitespace();
            e.next() == Some("command")
                && e.next() == Some("station=99")
                && e.next()
                    .and_then(|c| c.strip_prefix("code="))
                    .is_some_and(|c| READ_ONLY.contains(&c))
                && !f.envelope.ends_with("sc=@@")
        })
        .map(|f| (f.name, f.frame))
        .collect()
}

/// The bytes up to and including the next LF from `reader`.
fn read_frame(reader: &mut impl BufRead) -> Vec<u8> {
    let mut frame = Vec::new();
    reader.read_until(b'\n', &mut frame).expect("a reply");
    frame
}

#[test]
fn the_l475_passes_recorded_frames_runs_a_plc_and_writes_2000_records_as_one_26dh() {
    let python = pymodbus_python().expect("pymodbus (tools/setup.sh installs it)");
    let elf = build_firmware(BOARD).expect("build b-l475e-iot01a firmware");
    let iai = iai_binary().expect("the iai binary");
    let started = Instant::now();
    let mut gw = Gateway::start(&elf, &["--board", BOARD.bin()], &SERIAL);

    // 1. Recorded frames through the bridge, each reply the simulator's.
    let queries = recorded_queries();
    assert!(queries.len() >= 8, "{} recorded queries", queries.len());
    let mut oracle = Simulator::tta(STATION);
    oracle.refuse = true;
    let mut host = TcpStream::connect(&gw.addr).expect("connect");
    host.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut replies = BufReader::new(host.try_clone().unwrap());
    for (name, frame) in &queries {
        oracle.receive(frame, 0);
        let want = oracle.take_output(1_000);
        host.write_all(frame).unwrap();
        let got = read_frame(&mut replies);
        assert_eq!(
            String::from_utf8_lossy(&got),
            String::from_utf8_lossy(&want),
            "{name}"
        );
    }
    drop(replies);
    drop(host);
    eprintln!("{} recorded frames passed through unchanged", queries.len());

    // 2. A PLC's sequence on the Modbus RTU port.
    let records: Vec<PositionRecord> = table(100, 8, 475).collect();
    pymodbus_sequence(&mut gw, &python, &iai, &records, false);

    // 3. 2,000 records of 8 axes as one 26DH (about 164 KB).
    let csv = csv_of(2_000, 2026);
    let path =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("l475-{}.csv", std::process::id()));
    std::fs::write(&path, &csv).unwrap();
    let t = Instant::now();
    // QEMU's model of this USART hands the firmware its next received byte
    // only when QEMU's main loop next runs (about once a millisecond while
    // the host side is quiet), so this board takes the table in at about a
    // tenth of the line rate, slower than iai's default answer timeout
    // allows for.
    let out = gw.iai(
        &iai,
        &[
            "table",
            "write",
            path.to_str().unwrap(),
            "--bridge",
            "--timeout",
            "240000",
        ],
    );
    let took = t.elapsed().as_secs_f64();
    let _ = std::fs::remove_file(&path);
    assert!(
        text(&out).starts_with(
            "verified by the bridge: the controller holds all 2000 records (1 26DH message(s) of "
        ),
        "{}\n{}",
        text(&out),
        err(&out)
    );
    assert!(
        err(&out).contains("the bridge answered # with 2000"),
        "{}",
        err(&out)
    );
    let count = text(&gw.iai(&iai, &["send", "208"]));
    assert!(
        count.contains("number_of_effective_positions = 0x7D0 (2000)"),
        "208H: {count}"
    );
    eprintln!("2,000 records x 8 axes as one 26DH, verified, in {took:.1} s");

    let status = gw.stop();
    let log = gw.log();
    assert!(status.success(), "{status}\n{log}");
    eprintln!(
        "b-l475e-iot01a, one boot: {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// Record `n` of the example's table (see `examples/embassy_client.rs`).
fn example_record(n: u16) -> PositionRecord {
    let mut positions = PerAxis::new();
    positions.push(i32::from(n) * 1_000).unwrap();
    positions.push(-i32::from(n) * 500).unwrap();
    PositionRecord {
        number: n,
        axes: AxisPattern::first(2),
        acceleration: 30,
        deceleration: 30,
        speed: 100,
        positions,
        extended: 0,
    }
}

#[test]
fn the_embassy_example_runs_the_cores_async_client_and_transfer() {
    let elf = build_example(BOARD, "embassy_client").expect("build the embassy example");
    let qemu = QemuSession::start_with_marker(
        BOARD,
        &elf,
        Duration::from_secs(20),
        Some("embassy client: up"),
    )
    .expect("start QEMU");
    let sim = SimThread::spawn(
        Simulator::tta(STATION),
        qemu.downstream.try_clone().expect("controller side"),
        Some(115_200),
    );
    let outcome = qemu
        .wait(Duration::from_secs(60))
        .expect("the example ends");
    assert!(outcome.success(), "{outcome:#?}");
    assert!(
        outcome
            .stdout
            .contains("embassy client: 212H axes 2 position 0 position 0\n"),
        "{}",
        outcome.stdout
    );
    assert!(
        outcome
            .stdout
            .contains("embassy client: table verified, records 100,"),
        "{}",
        outcome.stdout
    );
    let sim = sim.join().expect("simulator");
    let want: Vec<PositionRecord> = (1..=100).map(example_record).collect();
    let held: Vec<PositionRecord> = sim.table.values().cloned().collect();
    assert!(held == want, "the controller's table: {held:?}");
    print!("{}", outcome.stdout);
}

/// The firmware's writes to the IWDG (QEMU's `-d unimp` log lines for
/// it), as `(offset, value)`.
fn iwdg_writes(log: &str) -> Vec<(u32, u32)> {
    log.lines()
        .filter_map(|l| l.strip_prefix("IWDG: unimplemented device write (size 4, offset "))
        .filter_map(|l| {
            let (offset, rest) = l.split_once(", value ")?;
            let value = rest.strip_suffix(')')?;
            let hex = |s: &str| u32::from_str_radix(s.trim_start_matches("0x"), 16).ok();
            Some((hex(offset)?, hex(value)?))
        })
        .collect()
}

/// Boots `elf` for `run` with QEMU logging unimplemented devices; the
/// IWDG writes and the firmware's output.
fn boot_logging_unimp(
    elf: &std::path::Path,
    name: &str,
    run: Duration,
) -> (Vec<(u32, u32)>, String) {
    let log = target_dir().join(format!("iwdg-{name}-{}.log", std::process::id()));
    let args = ["-d", "unimp", "-D", log.to_str().unwrap()];
    let mut qemu = QemuSession::start_with_args(
        BOARD,
        elf,
        Duration::from_secs(20),
        Some("bridge up"),
        &args,
    )
    .expect("start QEMU");
    std::thread::sleep(run);
    let stdout = if name == "running" {
        qemu.quit().expect("quit");
        let out = qemu.wait(Duration::from_secs(10)).expect("exit");
        assert!(out.success(), "{out:#?}");
        out.stdout
    } else {
        let out = qemu.stdout_so_far();
        drop(qemu);
        out
    };
    let writes = iwdg_writes(&std::fs::read_to_string(&log).unwrap_or_default());
    let _ = std::fs::remove_file(&log);
    (writes, stdout)
}

#[test]
fn the_l475_starts_its_watchdog_feeds_it_and_stops_feeding_a_stalled_loop() {
    // KR, PR, RLR: start, unlock, /64, 1,000 counts of 2 ms; then a reload.
    let start = [
        (0x0, 0xCCCC),
        (0x0, 0x5555),
        (0x4, 0x4),
        (0x8, 1_000),
        (0x0, 0xAAAA),
    ];
    let elf = build_firmware(BOARD).expect("build b-l475e-iot01a firmware");
    let (writes, _) = boot_logging_unimp(&elf, "running", Duration::from_millis(1_500));
    assert_eq!(writes.get(..5), Some(&start[..]), "{writes:?}");
    let feeds = writes
        .iter()
        .skip(5)
        .filter(|w| **w == (0x0, 0xAAAA))
        .count();
    assert!(feeds > 100, "{feeds} feeds in 1.5 s");

    let dir = target_dir().join("stall");
    let stalled = build_firmware_with(BOARD, FIRMWARE_PROFILE, &["stall"], Some(&dir))
        .expect("build with the stall feature");
    let (writes, stdout) = boot_logging_unimp(&stalled, "stalled", Duration::from_millis(1_500));
    assert_eq!(writes, start, "after the stall: {writes:?}");
    assert!(
        stdout.contains("firmware-example: stalling the loop"),
        "{stdout}"
    );
    // QEMU 10 does not model the IWDG: no reset follows, and none is
    // claimed.
    assert_eq!(stdout.matches("bridge up").count(), 1, "{stdout}");
    eprintln!(
        "b-l475e-iot01a: {feeds} feeds in 1.5 s; stalled: none after the start sequence \
         (QEMU 10 leaves the IWDG unimplemented, so no reset follows)"
    );
}
