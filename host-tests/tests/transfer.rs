//! End to end: full-size position tables written through the transfer
//! engine into the simulated controller, with and without faults.

use host_tests::link::{line_to, run_fed, run_transfer, LinkRun};
use host_tests::table::table;
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::transfer::{
    packed_len, Guarantee, RecordBuffer, RecordSource, Transfer, TransferConfig, Verify,
};
use iai_protocol_b::{error::Failure, profile::Profile};
use iai_simulator::{Faults, Simulator};

const ST: Station = Station(0x99);

/// A TTA's table writes.
const TTA: TransferConfig = TransferConfig::new(Profile::TTA);

/// Runs `t` against `sim` on a line of its own (at `baud`, 0: no wire time).
fn run_line<I: RecordSource, const N: usize>(
    t: &mut Transfer<I, N>,
    sim: &mut Simulator,
    resumes: u32,
    baud: u32,
) -> LinkRun {
    run_transfer(t, &mut line_to(sim), sim, resumes, baud, 0)
}

fn assert_table_equal(sim: &Simulator, source: impl Iterator<Item = PositionRecord>) {
    let mut expected = std::collections::BTreeMap::new();
    for r in source {
        expected.insert(r.number, r);
    }
    assert_eq!(sim.table.len(), expected.len());
    assert!(
        sim.table == expected,
        "simulator table differs from the source"
    );
}

/// The TTA's fastest line: the virtual time is the wire time.
const BAUD: u32 = 115_200;

#[test]
fn full_table_20000_records_8_axes_no_faults() {
    let mut sim = Simulator::tta(ST);
    let mut t: Transfer<_> = Transfer::new(TTA, table(20_000, 8, 11));
    let run = run_line(&mut t, &mut sim, 0, BAUD);
    let stats = t.stats();
    assert_eq!(run.result, Ok(Guarantee::Verified));
    assert_eq!(stats.records_confirmed, 20_000);
    assert_eq!(stats.records_verified, 20_000);
    assert_eq!(stats.retries, 0);
    assert_eq!(stats.rewrites, 0);
    assert_table_equal(&sim, table(20_000, 8, 11));
    // 24 records of 82 bytes fit a 2,051-byte frame (14 + 24 x 82 = 1,982);
    // the late-reply guard makes some frames shorter.
    assert!(stats.frames_confirmed >= 20_000 / 24);
    println!(
        "20000x8 clean, full verification at {BAUD} baud: {} s of wire time, {} frames \
         ({} shortened by the guard), {} bytes up, {} down",
        run.virtual_ms / 1000,
        stats.frames_confirmed,
        stats.guarded_frames,
        run.bytes_to_controller,
        run.bytes_to_host
    );
}

#[test]
fn full_table_20000_records_1_axis_no_faults() {
    let mut sim = Simulator::tta(ST);
    let mut t: Transfer<_> = Transfer::new(TTA, table(20_000, 1, 12));
    assert_eq!(
        run_line(&mut t, &mut sim, 0, BAUD).result,
        Ok(Guarantee::Verified)
    );
    assert_eq!(t.stats().records_confirmed, 20_000);
    assert_eq!(t.stats().records_verified, 20_000);
    assert_table_equal(&sim, table(20_000, 1, 12));
}

#[test]
fn each_policy_says_what_it_proves_and_after_fault_costs_nothing_on_a_clean_line() {
    for (verify, guarantee) in [
        (Verify::Off, Guarantee::Unverified),
        (Verify::AfterFault, Guarantee::FaultsVerified),
        (Verify::Full, Guarantee::Verified),
    ] {
        let mut sim = Simulator::tta(ST);
        let cfg = TTA.with_verify(verify);
        let mut t: Transfer<_> = Transfer::new(cfg, table(500, 8, 19));
        let run = run_line(&mut t, &mut sim, 0, BAUD);
        assert_eq!(run.result, Ok(guarantee));
        let queries = t.stats().verify_queries;
        match verify {
            Verify::Full => assert!(queries >= 500 / 24),
            _ => assert_eq!(queries, 0, "{verify:?} reads nothing back on a clean line"),
        }
        assert_table_equal(&sim, table(500, 8, 19));
        println!("{verify:?}: {} ms of wire time", run.virtual_ms);
    }
}

/// The fault mix of issue 4: 1 byte in 10,000 corrupted each way, every
/// 50th reply dropped, error replies on random chunks, noise, late replies.
fn faulty() -> Faults {
    Faults {
        flip_bit_in: 1.0 / 10_000.0,
        flip_bit_out: 1.0 / 10_000.0,
        drop_every_nth_reply: Some(50),
        error_reply: 0.01,
        garbage_before_reply: 0.02,
        late_every_nth_reply: Some((37, 3_500)),
        ..Faults::default()
    }
}

#[test]
fn full_table_8_axes_with_faults() {
    let mut sim = Simulator::tta(ST).with_faults(faulty(), 0xFA17);
    let mut t: Transfer<_> = Transfer::new(TTA, table(20_000, 8, 13));
    // Error replies stop the transfer (they are not resent blindly): the
    // caller decides to go on, here always.
    let run = run_line(&mut t, &mut sim, 200, BAUD);
    let stats = t.stats();
    let s = sim.stats();
    println!(
        "20000x8 faults: {stats:?}\nsimulator: {s:?}\nvirtual time {} s",
        run.virtual_ms / 1000
    );
    assert_eq!(run.result, Ok(Guarantee::Verified));
    assert_eq!(stats.records_confirmed, 20_000);
    assert!(stats.retries > 0 && stats.timeouts > 0 && stats.error_replies > 0);
    assert!(s.broken_frames > 0, "bit flips must have hit some commands");
    assert_table_equal(&sim, table(20_000, 8, 13));
}

#[test]
fn full_table_1_axis_with_faults() {
    let mut sim = Simulator::tta(ST).with_faults(faulty(), 0xBEEF);
    let mut t: Transfer<_> = Transfer::new(TTA, table(20_000, 1, 14));
    assert_eq!(
        run_line(&mut t, &mut sim, 200, BAUD).result,
        Ok(Guarantee::Verified)
    );
    let stats = t.stats();
    assert_eq!(stats.records_confirmed, 20_000);
    assert!(stats.retries > 0);
    assert_table_equal(&sim, table(20_000, 1, 14));
}

#[test]
fn xsel_2003_limit_splits_at_1023_bytes_with_245h() {
    let mut sim = Simulator::xsel_2003(ST);
    let cfg = TransferConfig::new(Profile::XSEL_2003);
    assert_eq!((cfg.stream, cfg.max_frame), (PositionStream::CHANGE, 1023));
    let mut t: Transfer<_, 1023> = Transfer::new(
        cfg,
        table(2_000, 8, 15).map(|mut r| {
            r.number %= 0x1000;
            r
        }),
    );
    assert!(run_line(&mut t, &mut sim, 0, 0).result.is_ok());
    let stats = t.stats();
    assert_eq!(stats.records_confirmed, 2_000);
    assert_eq!(sim.stats().oversize_frames, 0);
    assert!(stats.frames_confirmed >= 2_000 / 12);
}

#[test]
fn a_dead_controller_fails_after_three_tries_and_resume_continues_exactly() {
    let mut sim = Simulator::tta(ST).with_faults(
        Faults {
            drop_every_nth_reply: Some(1),
            ..Faults::default()
        },
        3,
    );
    let mut t: Transfer<_> = Transfer::new(TTA, table(100, 4, 16));
    let mut line = line_to(&sim);
    let first = run_transfer(&mut t, &mut line, &mut sim, 0, 0, 0);
    assert_eq!(first.result, Err(Failure::Timeout { sends: 3 }));
    assert_eq!(t.stats().frames_sent, 3);
    // The line just opened fences first; no echo by 3,000: a second fence
    // (its echo may have been lost); none by 6,000 either: the controller
    // may not answer 200H, so the line waits out the past and the second
    // fence's own late reply (sent at 3,000: until 3,000 + 3,000 + 3,000
    // + 1), then three sends, 3 s each.
    assert_eq!(line.stats().fences_failed, 2);
    assert_eq!(first.virtual_ms, 9_001 + 9_000);
    assert_eq!(t.progress(), (0, Some(100)));
    // The controller comes back: resuming sends the same frame again, on
    // the same line (after a fence: the three sends' replies were owed).
    sim.faults = Faults::default();
    let second = run_transfer(&mut t, &mut line, &mut sim, 1, 0, first.virtual_ms);
    assert!(second.result.is_ok());
    assert_eq!(t.stats().records_confirmed, 100);
    assert_eq!(line.stats().fences, 3);
    assert_table_equal(&sim, table(100, 4, 16));
}

#[test]
fn persistent_error_replies_fail_with_the_code() {
    let mut sim = Simulator::tta(ST).with_faults(
        Faults {
            error_reply: 1.0,
            ..Faults::default()
        },
        4,
    );
    let mut t: Transfer<_> = Transfer::new(TTA, table(10, 2, 17));
    let r = run_line(&mut t, &mut sim, 0, 0);
    assert_eq!(
        r.result,
        Err(Failure::Controller {
            code: iai_simulator::INJECTED_ERROR_CODE,
            detail: None,
        })
    );
    // Not resent: the spec asks for appropriate action, not repetition.
    assert_eq!(t.stats().error_replies, 1);
    assert_eq!(t.stats().frames_sent, 1);
}

#[test]
fn an_invalid_record_stops_before_anything_is_sent_for_it() {
    // 2-axis records are 34 bytes: 59 fit a 2,051-byte frame (14 + 59 x 34).
    let mut bad: Vec<_> = table(100, 2, 18).collect();
    bad[70].positions.pop(); // 2 axes in the pattern, 1 coordinate
    let mut sim = Simulator::tta(ST);
    let mut t: Transfer<_> = Transfer::new(TTA, bad.clone().into_iter());
    let r = run_line(&mut t, &mut sim, 0, 0);
    match r.result {
        Err(Failure::InvalidRecord {
            index: 70,
            error:
                iai_protocol_b::error::Error::CountMismatch {
                    expected: 2,
                    found: 1,
                },
        }) => {}
        other => panic!("{other:?}"),
    }
    // The first frame (records 0..59) went out and was confirmed; the frame
    // holding the bad record was never sent.
    assert_eq!(t.stats().records_confirmed, 59);
    assert_eq!(t.stats().frames_sent, 1);
    assert_table_equal(&sim, bad.into_iter().take(59));
}

#[test]
fn records_arriving_a_few_at_a_time_through_a_queue_lose_nothing() {
    // As in the bridge: records come from the upstream UART in bursts; the
    // engine waits (NeedRecords) rather than sending short frames.
    let mut sim = Simulator::tta(ST).with_faults(faulty(), 77);
    let mut t: Transfer<RecordBuffer<{ 32 * packed_len(3) }>> =
        Transfer::new(TTA, RecordBuffer::new()).with_total(3_000);
    let mut src = table(3_000, 3, 21);
    let mut line = line_to(&sim);
    let r = run_fed(&mut t, &mut line, &mut sim, 50, 0, 0, |q| {
        for _ in 0..5 {
            if !q.fits(3) || q.is_finished() {
                break;
            }
            match src.next() {
                Some(rec) => q.push(rec).unwrap(),
                None => q.finish(),
            }
        }
    });
    assert!(r.result.is_ok());
    assert_eq!(t.stats().records_confirmed, 3_000);
    assert_table_equal(&sim, table(3_000, 3, 21));
}

#[test]
fn the_simulator_answers_what_it_models_and_refuses_the_rest() {
    // Every catalogue command gets its own normal response, or an `&` with
    // the simulator's "not modelled" code: never a made-up normal response
    // (which fields it models is the simulator's own unit tests' business).
    use iai_protocol_b::catalogue;
    use iai_protocol_b::checksum::BypassPolicy;
    use iai_protocol_b::frame::Frame;
    use iai_protocol_b::message::{decode_any, AnyMessage, Command};
    let mut sim = Simulator::tta(ST);
    let (mut answered, mut refused) = (0, 0);
    for (i, id) in catalogue::ALL.iter().map(|m| m.id).enumerate() {
        let cmd = Command::default_for(id).unwrap();
        let mut buf = [0u8; 64];
        let n = cmd.emit(ST, &mut buf).unwrap();
        let now = i as u32 * 100;
        sim.receive(&buf[..n], now);
        let reply = sim.take_output(now + 50);
        let frame = Frame::new_checked(&reply, BypassPolicy::Reject).unwrap();
        match decode_any(&frame).unwrap().message {
            AnyMessage::Response(r) => {
                assert_eq!(r.id(), id);
                answered += 1;
            }
            AnyMessage::Error(e) => {
                assert_eq!(e.code, iai_simulator::NOT_MODELLED_CODE, "{id:03X}H");
                refused += 1;
            }
            other => panic!("{id:03X}H answered with {other:?}"),
        }
    }
    assert!(
        answered > 0 && refused > 0,
        "{answered} answered, {refused} refused"
    );
}

#[test]
fn a_range_write_ending_at_the_top_of_its_start_field_completes() {
    // Found by the `transfer` fuzz target: 244H with start FFE and two
    // records used to fail building a third, empty frame with start 1000.
    let mut sim = Simulator::tta(ST);
    let cfg = TransferConfig {
        stream: PositionStream::RANGE,
        start: 0xFFE,
        ..TTA
    };
    let recs: Vec<_> = table(2, 1, 40).collect();
    let mut t: Transfer<_> = Transfer::new(cfg, recs.clone().into_iter());
    assert!(run_line(&mut t, &mut sim, 0, 0).result.is_ok());
    assert_eq!(t.stats().records_confirmed, 2);
    assert_eq!(
        sim.table.keys().copied().collect::<Vec<_>>(),
        vec![0xFFE, 0xFFF]
    );
    // One record more cannot be numbered: refused, after the two that fit.
    let mut sim = Simulator::tta(ST);
    let mut t: Transfer<_> = Transfer::new(cfg, table(3, 1, 41));
    let r = run_line(&mut t, &mut sim, 0, 0);
    assert!(
        matches!(
            r.result,
            Err(Failure::Protocol(_)) | Err(Failure::InvalidRecord { .. })
        ),
        "{:?}",
        r.result
    );
}
