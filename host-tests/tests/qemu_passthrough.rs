//! Both boards under QEMU: the firmware builds and links for each, boots,
//! bridges a command and its reply (checked, not a raw byte pump: see
//! `qemu_bridge.rs` for the protocol behaviour), and the quit sequence ends
//! the run with exit code 0.
//!
//! Needs `qemu-system-arm` and the `thumbv7m-none-eabi` /
//! `thumbv7em-none-eabihf` rustup targets.

use std::time::{Duration, Instant};

use host_tests::bridge::{HostLink, SimThread};
use host_tests::qemu::{build_firmware, Board, QemuSession};
use iai_protocol_b::axis::AxisPattern;
use iai_protocol_b::frame::Station;
use iai_protocol_b::message::{AxisStatusQuery, Message};
use iai_simulator::Simulator;

const STATION: Station = Station(0x99);

/// Boot the bridge on `board`, pass a 212H through to the simulator and
/// back, quit, check the exit code.
fn bridges_a_query_and_quits(board: Board) {
    let started = Instant::now();
    let elf = build_firmware(board).unwrap_or_else(|e| panic!("build {board} firmware: {e}"));
    let mut qemu = QemuSession::start(board, &elf, Duration::from_secs(10)).expect("start QEMU");
    let sim = SimThread::spawn(
        Simulator::tta(STATION),
        qemu.downstream.try_clone().expect("clone downstream"),
        Some(115_200),
    );

    let mut buf = [0u8; 32];
    let n = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(2),
    }
    .emit(STATION, &mut buf)
    .expect("212H");
    let mut oracle = Simulator::tta(STATION);
    oracle.receive(&buf[..n], 0);
    let want = oracle.take_output(1_000);
    let link = HostLink::new(&qemu.upstream, Some(115_200), true).expect("host link");
    let got = link
        .exchange(&buf[..n], Duration::from_secs(5))
        .expect("exchange")
        .expect("a reply through the bridge");
    assert_eq!(got, want);

    qemu.quit().expect("send quit sequence");
    let outcome = qemu.wait(Duration::from_secs(5)).expect("QEMU exits");
    assert!(
        outcome.success(),
        "firmware did not exit cleanly: {outcome:#?}"
    );
    assert!(
        outcome
            .stdout
            .contains(&format!("bridge up on {}", board.machine())),
        "missing banner: {outcome:#?}"
    );
    let sim = sim.join().expect("simulator");
    // The bridge's opening fence (a 200H), then the host's 212H.
    assert_eq!(sim.stats().commands, 2);
    eprintln!("{board}: bridged and quit in {:?}", started.elapsed());
}

#[test]
fn lm3s6965_bridges_a_query_and_quits() {
    bridges_a_query_and_quits(Board::Lm3s6965);
}

#[test]
fn mps2_an386_bridges_a_query_and_quits() {
    bridges_a_query_and_quits(Board::Mps2An386);
}

#[test]
fn mps2_an386_firmware_builds_and_links() {
    let elf = build_firmware(Board::Mps2An386).expect("build mps2-an386 firmware");
    let bytes = std::fs::read(&elf).expect("read ELF");
    assert!(
        bytes.starts_with(b"\x7fELF"),
        "{} is not an ELF file",
        elf.display()
    );
    // e_machine (offset 18, little-endian) must be EM_ARM (40).
    assert_eq!(
        u16::from_le_bytes([bytes[18], bytes[19]]),
        40,
        "not an ARM ELF"
    );
}

/// The watchdog resets a board whose loop stalls, on each board whose
/// watchdog QEMU models (not the STM32L475's: see `qemu_stm32.rs`): a
/// build with the `stall` feature stops feeding it after start, and the
/// firmware boots again.
#[test]
fn the_watchdog_resets_a_stalled_loop() {
    for board in Board::ALL.into_iter().filter(|b| b.watchdog_modelled()) {
        let dir = host_tests::qemu::target_dir().join("stall");
        let elf = host_tests::qemu::build_firmware_with(
            board,
            host_tests::qemu::FIRMWARE_PROFILE,
            &["stall"],
            Some(&dir),
        )
        .unwrap_or_else(|e| panic!("build {board} with the stall feature: {e}"));
        let qemu = QemuSession::start(board, &elf, Duration::from_secs(10)).expect("start QEMU");
        // Up to two watchdog periods of 2 s, plus margin for a slow host.
        let deadline = Instant::now() + Duration::from_secs(30);
        let boots = loop {
            let out = qemu.stdout_so_far();
            let boots = out.matches("bridge up").count();
            if boots >= 2 || Instant::now() >= deadline {
                break boots;
            }
            std::thread::sleep(Duration::from_millis(100));
        };
        assert!(boots >= 2, "{board}: no reset after the loop stalled");
        eprintln!("{board}: reset by the watchdog");
    }
}
