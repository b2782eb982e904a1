//! End-to-end checks of the bridge firmware on QEMU `lm3s6965evb`: a host
//! client on the upstream socket, the controller simulator on the
//! downstream socket (its own thread, real time).
//!
//! 1. one 26DH of 2,000 records x 8 axes (164 KB) is split into 84
//!    controller-sized commands; the host gets one `#` reply with the
//!    total and the simulator's table equals the source;
//! 2. the same (800 records) with faults injected downstream (bit flips
//!    both ways, dropped replies, `&` replies, noise): the table still ends
//!    equal;
//! 3. 212H and 216H pass through, and so does a controller `&` reply: the
//!    host gets exactly the simulator's reply;
//! 4. a malformed upstream command is not forwarded and gets no reply;
//! 5. an upstream 26DH with a wrong checksum gets `&` B01.
//!
//! Every run ends with the quit sequence and checks QEMU's exit code.
//! Needs `qemu-system-arm` and the `thumbv7m-none-eabi` rustup target.

use std::time::{Duration, Instant};

use host_tests::bridge::{
    check_table, codes, command_26dh, error_reply, exchange, read_frame, reply_26dh, send,
    SimThread,
};
use host_tests::qemu::{build_firmware, Board, QemuSession};
use host_tests::sim::{Faults, Simulator, UNSUPPORTED_ERROR_CODE};
use host_tests::table::table;
use iai_protocol_b::axis::AxisPattern;
use iai_protocol_b::checksum::ChecksumMode;
use iai_protocol_b::frame::{emit_frame, Header, Station};
use iai_protocol_b::message::{AxisStatusQuery, ErrorDetailQuery, Message};
use iai_protocol_b::position::PositionRecord;

const STATION: Station = Station(0x99);

/// Boot the bridge on lm3s6965evb with `sim` on the downstream.
fn start(sim: Simulator) -> (QemuSession, SimThread) {
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let qemu =
        QemuSession::start(Board::Lm3s6965, &elf, Duration::from_secs(10)).expect("start QEMU");
    // Writes block while the bridge holds the line back (a chunk waiting
    // out three 3 s timeouts at worst).
    qemu.upstream
        .set_write_timeout(Some(Duration::from_secs(30)))
        .expect("write timeout");
    let down = qemu.downstream.try_clone().expect("clone downstream");
    let sim = SimThread::spawn(sim, down);
    (qemu, sim)
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

/// Send a 26DH of `records`, re-sending the whole command after an `&`
/// reply (position writes are idempotent) up to `attempts` times. Returns
/// the final reply and the number of sends.
fn write_table(
    qemu: &mut QemuSession,
    records: &[PositionRecord],
    attempts: u32,
) -> (Vec<u8>, u32) {
    let command = command_26dh(STATION, records);
    for attempt in 1..=attempts {
        let reply = exchange(
            &mut qemu.upstream,
            &command,
            Duration::from_secs(60),
            |_| {},
        )
        .expect("exchange")
        .unwrap_or_else(|| panic!("no reply to the 26DH (attempt {attempt})"));
        if reply.first() == Some(&b'#') || attempt == attempts {
            return (reply, attempt);
        }
        eprintln!(
            "attempt {attempt}: bridge answered {:?}; sending again",
            String::from_utf8_lossy(&reply)
        );
    }
    unreachable!()
}

#[test]
fn a_large_26dh_is_split_confirmed_and_answered_once() {
    let started = Instant::now();
    let records: Vec<_> = table(2_000, 8, 7).collect();
    let (mut qemu, sim) = start(Simulator::tta(STATION));

    let (reply, sends) = write_table(&mut qemu, &records, 1);
    assert_eq!(
        reply,
        reply_26dh(STATION, 2_000),
        "got {:?}",
        String::from_utf8_lossy(&reply)
    );
    assert_eq!(sends, 1);
    // Exactly one reply: nothing else follows.
    assert_eq!(
        read_frame(&mut qemu.upstream, Duration::from_millis(300)).expect("read"),
        None
    );

    let (sim, stdout) = finish(qemu, sim);
    check_table(&sim.table, &records).unwrap_or_else(|e| panic!("{e}"));
    let stats = sim.stats();
    // 24 records of 8 axes fit one 2,051-byte command: at least 84 writes
    // (more: no frame gets a count a reply still in flight could carry),
    // and the bridge reads every chunk back (21FH, 24 positions a query).
    assert!(stats.commands >= 84 + 84, "{stats:?}");
    assert_eq!(stats.records_written, 2_000);
    assert!(stdout.contains("streams_ok: 1"), "firmware stats: {stdout}");
    eprintln!(
        "2,000 x 8 axes ({} bytes upstream, {} bytes to the controller) in {:?}",
        command_26dh(STATION, &records).len(),
        stats.bytes_in,
        started.elapsed()
    );
}

#[test]
fn a_26dh_survives_downstream_faults() {
    let started = Instant::now();
    let records: Vec<_> = table(800, 8, 11).collect();
    let faults = Faults {
        flip_bit_in: 8e-6,
        flip_bit_out: 1e-4,
        drop_every_nth_reply: Some(30),
        garbage_before_reply: 0.1,
        ..Faults::default()
    };
    let (mut qemu, sim) = start(Simulator::tta(STATION).with_faults(faults, 5));

    let (reply, sends) = write_table(&mut qemu, &records, 4);
    assert_eq!(
        reply,
        reply_26dh(STATION, 800),
        "after {sends} sends: {:?}",
        String::from_utf8_lossy(&reply)
    );

    let (sim, stdout) = finish(qemu, sim);
    check_table(&sim.table, &records).unwrap_or_else(|e| panic!("{e}"));
    let stats = sim.stats();
    assert!(
        stats.dropped_replies + stats.injected_errors + stats.broken_frames > 0,
        "no fault was injected: {stats:?}"
    );
    eprintln!(
        "faults: {stats:?}\nfirmware: {}\n{sends} send(s), {:?}",
        stdout.trim(),
        started.elapsed()
    );
}

#[test]
fn pass_through_rejections_and_upstream_checksum_errors() {
    let started = Instant::now();
    let (mut qemu, sim) = start(Simulator::tta(STATION));
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
        let got = exchange(&mut qemu.upstream, cmd, Duration::from_secs(5), |_| {})
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
        send(&mut qemu.upstream, cmd, |_| {}).expect("send");
    }
    // A cut frame is followed by a header; make it a valid command, which
    // must still be answered (the bridge resynchronises).
    let want = expect(&q212);
    let got = exchange(&mut qemu.upstream, &q212, Duration::from_secs(5), |_| {})
        .expect("exchange")
        .expect("reply after the malformed commands");
    assert_eq!(got, want);
    assert_eq!(
        read_frame(&mut qemu.upstream, Duration::from_millis(500)).expect("read"),
        None,
        "a malformed command was answered"
    );

    // 5. A 26DH whose checksum is wrong: `&` B01 at its end.
    let records: Vec<_> = table(100, 8, 3).collect();
    let mut cmd = command_26dh(STATION, &records);
    let sc = cmd.len() - 4;
    cmd[sc] = if cmd[sc] == b'0' { b'1' } else { b'0' };
    let got = exchange(&mut qemu.upstream, &cmd, Duration::from_secs(10), |_| {})
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
    let got = exchange(&mut qemu.upstream, &cmd, Duration::from_secs(10), |_| {})
        .expect("exchange")
        .expect("reply to the 26DH");
    assert_eq!(got, reply_26dh(STATION, 100));

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
