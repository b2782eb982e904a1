//! End-to-end checks of the bridge firmware on QEMU `lm3s6965evb`: a host
//! client on the upstream socket, the controller simulator on the
//! downstream socket (its own thread, real time).
//!
//! The host writes at the configured line rate and honours XON/XOFF
//! ([`HostLink`]); nothing here asserts timing.
//!
//! 1. one 26DH of 300 records x 8 axes (25 KB) at 38,400 baud is split into
//!    controller-sized commands; the host gets one `#` reply with the
//!    total and the simulator's table equals the source;
//! 2. 212H and 216H pass through, and so does a controller `&` reply: the
//!    host gets exactly the simulator's reply; a malformed upstream command
//!    is not forwarded and gets no reply; an upstream 26DH with a wrong
//!    checksum gets `&` B01;
//! 3. a configuration block (read-only policy, other stations) in flash:
//!    the status query reports it, a 26DH is refused with `&` B06 and never
//!    reaches the controller, a query passes.
//!
//! Fault scenarios (bit flips, dropped, late and `&` replies) run in the
//! host model instead, thousands of them (`bridge_faults.rs`).
//! Every run ends with the quit sequence and checks QEMU's exit code.
//! Needs `qemu-system-arm` and the `thumbv7m-none-eabi` rustup target.

use std::time::{Duration, Instant};

use firmware_example::config::{Config, Policy};
use firmware_example::status;
use host_tests::bridge::{
    check_table, codes, command_26dh, error_reply, reply_26dh, HostLink, SimThread,
};
use host_tests::qemu::{build_firmware, test_config, Board, QemuSession, READY_MARKER};
use host_tests::table::table;
use iai_protocol_b::axis::AxisPattern;
use iai_protocol_b::checksum::ChecksumMode;
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::message::{AxisStatusQuery, ErrorDetailQuery, Message};
use iai_simulator::{Simulator, UNSUPPORTED_ERROR_CODE};

const STATION: Station = Station(0x99);

/// Boot the bridge on lm3s6965evb with `cfg` in flash and `sim` on the
/// downstream; the host link paced to the configured upstream rate, with
/// XON/XOFF.
fn start_with(sim: Simulator, cfg: &Config) -> (QemuSession, SimThread, HostLink) {
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let qemu = QemuSession::start_configured(
        Board::Lm3s6965,
        &elf,
        Duration::from_secs(10),
        Some(READY_MARKER),
        &[],
        Some(cfg),
    )
    .expect("start QEMU");
    let down = qemu.downstream.try_clone().expect("clone downstream");
    let sim = SimThread::spawn(sim, down, Some(cfg.downstream_baud));
    let link = HostLink::new(&qemu.upstream, Some(cfg.upstream_baud), true).expect("host link");
    (qemu, sim, link)
}

/// [`start_with`] the test configuration at 38,400 baud (see the first
/// test for why not faster).
fn start(sim: Simulator) -> (QemuSession, SimThread, HostLink) {
    start_with(sim, &slow_config())
}

fn slow_config() -> Config {
    Config {
        upstream_baud: 38_400,
        downstream_baud: 38_400,
        ..test_config()
    }
}

/// Quit, check the exit code, get the simulator back; returns the
/// firmware's semihosting output too.
fn finish(mut qemu: QemuSession, sim: SimThread) -> (Simulator, String) {
    qemu.quit().expect("send quit sequence");
    let outcome = qemu.wait(Duration::from_secs(10)).expect("QEMU exits");
    assert!(
        outcome.success(),
        "firmware did not exit cleanly: {outcome:#?}"
    );
    let sim = sim.join().expect("simulator");
    (sim, outcome.stdout)
}

#[test]
fn a_large_26dh_is_split_confirmed_and_answered_once() {
    let started = Instant::now();
    let records: Vec<_> = table(300, 8, 7).collect();
    // A controller that takes 100 ms per chunk: the bridge has to stop the
    // host (XOFF) while it waits.
    let mut controller = Simulator::tta(STATION);
    controller.response_delay_ms = 100;
    // 38,400 baud: QEMU and this host are not real time; when the machine
    // is busy, QEMU may pause for milliseconds and then take in all the
    // host wrote meanwhile, as no UART would. The slower line leaves the
    // ring's margin (80 bytes) 20 ms of such pauses.
    let (qemu, sim, link) = start(controller);

    // Position writes are idempotent: after `&` B07 (bytes lost, see
    // above) the host sends the command again, as documented.
    let command = command_26dh(STATION, &records);
    let mut sends = 0;
    let reply = loop {
        sends += 1;
        let reply = link
            .exchange(&command, Duration::from_secs(60))
            .expect("exchange")
            .expect("a reply to the 26DH");
        if reply != error_reply(STATION, codes::UPSTREAM_OVERRUN) || sends == 3 {
            break reply;
        }
        eprintln!("send {sends}: the bridge lost bytes (B07); sending again");
    };
    assert_eq!(
        reply,
        reply_26dh(STATION, 300),
        "got {:?}",
        String::from_utf8_lossy(&reply)
    );
    // Exactly one reply: nothing else follows.
    assert_eq!(
        link.read_frame(Duration::from_millis(300)).expect("read"),
        None
    );

    let (sim, stdout) = finish(qemu, sim);
    check_table(&sim.table, &records).unwrap_or_else(|e| panic!("{e}"));
    let stats = sim.stats();
    // 24 records of 8 axes fit one 2,051-byte command: at least 13 26DH
    // chunks (a few more: the transfer never gives two frames in a row the
    // same count, so that a late reply cannot confirm the wrong one), each
    // read back with one 21FH before the bridge takes more from the host.
    assert!(
        (2 * 13..=2 * 16 * sends).contains(&stats.commands),
        "{stats:?}"
    );
    assert!(stdout.contains("streams_ok: 1"), "firmware stats: {stdout}");
    eprintln!(
        "300 x 8 axes ({} bytes upstream, {sends} send(s), {} bytes to the controller), {} XOFF pauses, in {:?}",
        command.len(),
        stats.bytes_in,
        link.stats().xoffs,
        started.elapsed()
    );
}

#[test]
fn pass_through_rejections_and_upstream_checksum_errors() {
    let started = Instant::now();
    let (qemu, sim, link) = start(Simulator::tta(STATION));
    // A second simulator in the same state says what the reply must be.
    let mut oracle = Simulator::tta(STATION);
    let mut expect = |cmd: &[u8]| {
        oracle.receive(cmd, 0);
        oracle.take_output(1_000)
    };

    // 3. Pass-through: 212H, 216H, and a command the controller answers
    // with `&`.
    let mut buf = [0u8; 64];
    let n = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(3),
    }
    .emit(STATION, &mut buf)
    .expect("212H");
    let q212 = buf[..n].to_vec();
    let n = ErrorDetailQuery {
        type_1: 1,
        type_2: 2,
        record_number: 0,
    }
    .emit(STATION, &mut buf)
    .expect("216H");
    let q216 = buf[..n].to_vec();
    let n = emit_frame(
        &mut buf,
        Header::Command,
        STATION,
        0x2FF,
        ChecksumMode::Compute,
        |_| Ok(()),
    )
    .expect("2FFH");
    let unsupported = buf[..n].to_vec();
    for cmd in [&q212, &q216, &unsupported] {
        let want = expect(cmd);
        let got = link
            .exchange(cmd, Duration::from_secs(5))
            .expect("exchange")
            .unwrap_or_else(|| panic!("no reply to {:?}", String::from_utf8_lossy(cmd)));
        assert_eq!(
            got,
            want,
            "{:?} -> {:?}",
            String::from_utf8_lossy(cmd),
            String::from_utf8_lossy(&got)
        );
    }
    assert_eq!(
        expect(&unsupported),
        error_reply(STATION, UNSUPPORTED_ERROR_CODE)
    );

    // 4. Malformed upstream commands: a wrong checksum, a non-hex digit, a
    // frame cut by the next header, noise. None is forwarded, none answered.
    let mut bad_sum = q212.clone();
    let sc = bad_sum.len() - 4;
    bad_sum[sc] = if bad_sum[sc] == b'0' { b'1' } else { b'0' };
    let mut bad_digit = q216.clone();
    bad_digit[7] = b'G';
    for cmd in [&bad_sum[..], &bad_digit[..], b"!9921", b"noise\r\n"] {
        link.send(cmd, |_| {}).expect("send");
    }
    // A cut frame is followed by a header; make it a valid command, which
    // must still be answered (the bridge resynchronises).
    let want = expect(&q212);
    let got = link
        .exchange(&q212, Duration::from_secs(5))
        .expect("exchange")
        .expect("reply after the malformed commands");
    assert_eq!(got, want);
    assert_eq!(
        link.read_frame(Duration::from_millis(500)).expect("read"),
        None,
        "a malformed command was answered"
    );

    // 5. A 26DH whose checksum is wrong: `&` B01 at its end.
    let records: Vec<_> = table(100, 8, 3).collect();
    let mut cmd = command_26dh(STATION, &records);
    let sc = cmd.len() - 4;
    cmd[sc] = if cmd[sc] == b'0' { b'1' } else { b'0' };
    let got = link
        .exchange(&cmd, Duration::from_secs(10))
        .expect("exchange")
        .expect("reply to the broken 26DH");
    assert_eq!(
        got,
        error_reply(STATION, codes::UPSTREAM_FRAME),
        "{:?}",
        String::from_utf8_lossy(&got)
    );
    // The host sends it again, correct this time: `#` with the count.
    let cmd = command_26dh(STATION, &records);
    let got = link
        .exchange(&cmd, Duration::from_secs(10))
        .expect("exchange")
        .expect("reply to the 26DH");
    assert_eq!(got, reply_26dh(STATION, 100));

    // 6. Noise from the host with XOFF (0x13) in it and no XON: the
    // bridge's transmitter is held at most the configured time
    // (`Config::xoff_hold_ms`, 5 s), then answers again.
    link.write_raw(b"\x01\x13z\x13\r\n").expect("noise");
    let held = Instant::now();
    let query = status_query(test_config().bridge_station);
    link.exchange(&query, Duration::from_secs(20))
        .expect("exchange")
        .expect("the status after the XOFF noise");
    let held = held.elapsed();
    // The reply waited for the XOFF to be let go (its counter is in the
    // next reply: the first was made before).
    assert!(held >= Duration::from_secs(4), "held only {held:?}");
    let got = link
        .exchange(&query, Duration::from_secs(5))
        .expect("exchange")
        .expect("the next status");
    let frame = Frame::new_checked(&got, Default::default()).expect("a valid frame");
    let fields = status::parse(frame.body()).expect("status fields");
    let released = fields
        .iter()
        .find(|(n, _)| *n == "xoff_released")
        .expect("field")
        .1;
    assert_eq!(released, 1, "the XOFF was let go once");
    eprintln!("status after XOFF noise: {held:?}");

    let (sim, stdout) = finish(qemu, sim);
    let stats = sim.stats();
    // Forwarded: 212H, 216H, 2FFH, 212H; then the 26DH chunks: those of
    // the broken one sent before its end, and at least 5 of the good one.
    assert_eq!(stats.broken_frames, 0, "a malformed command got through");
    assert!(stats.commands >= 4 + 5, "{stats:?}");
    check_table(&sim.table, &records).unwrap_or_else(|e| panic!("{e}"));
    assert!(stdout.contains("rejected: 3"), "firmware stats: {stdout}");
    eprintln!("pass-through checks took {:?}", started.elapsed());
}

/// The status query as the host sends it.
fn status_query(station: Station) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = emit_frame(
        &mut buf,
        Header::Command,
        station,
        codes::STATUS_QUERY,
        ChecksumMode::Compute,
        |_| Ok(()),
    )
    .expect("B00");
    buf[..n].to_vec()
}

#[test]
fn configuration_block_policy_and_status_query() {
    let cfg = Config {
        controller_station: Station(0x05),
        bridge_station: Station(0xF0),
        policy: Policy::ReadOnly,
        ..slow_config()
    };
    let station = cfg.controller_station;
    let (qemu, sim, link) = start_with(Simulator::tta(station), &cfg);

    // A 26DH is a write: refused, answered B06, never forwarded.
    let records: Vec<_> = table(30, 8, 5).collect();
    let got = link
        .exchange(&command_26dh(station, &records), Duration::from_secs(10))
        .expect("exchange")
        .expect("a reply to the refused 26DH");
    assert_eq!(got, error_reply(station, codes::REFUSED));
    // A query passes.
    let mut buf = [0u8; 32];
    let n = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(2),
    }
    .emit(station, &mut buf)
    .expect("212H");
    let got = link
        .exchange(&buf[..n], Duration::from_secs(5))
        .expect("exchange")
        .expect("a reply to the 212H");
    assert_eq!(got.first(), Some(&b'#'));
    // The status query on the bridge's station reports all of it.
    let reply = link
        .exchange(&status_query(cfg.bridge_station), Duration::from_secs(5))
        .expect("exchange")
        .expect("a status reply");
    let frame = Frame::new_checked(&reply, Default::default()).expect("a valid frame");
    assert_eq!(frame.station(), cfg.bridge_station);
    let fields = status::parse(frame.body()).expect("status fields");
    let get = |name: &str| fields.iter().find(|(n, _)| *n == name).expect(name).1;
    assert_eq!(get("config_source"), 1);
    assert_eq!(get("controller_station"), 0x05);
    assert_eq!(get("policy"), 1);
    assert_eq!(get("upstream_baud"), 38_400);
    assert_eq!(get("refused"), 1);
    assert_eq!(get("forwarded"), 1);
    assert_eq!(get("last_error"), u64::from(codes::REFUSED));

    let (sim, _) = finish(qemu, sim);
    assert_eq!(
        sim.stats().commands,
        2,
        "only the bridge's opening fence and the 212H reached the controller"
    );
    assert!(sim.table.is_empty());
}
