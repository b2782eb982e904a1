//! The transfer engine, frame by frame: counts, confirmations, read-backs
//! and what may still arrive, against the scripted controller of
//! [`crate::testing`].

extern crate std;
use std::vec::Vec;

use super::*;
use crate::engine::feed;
use crate::line::LineConfig;
use crate::message::{ChangePositionData2Response, EffectivePositionResponse2, Message, Repeated};
use crate::testing::{record, run, Controller, Fault, ST};

/// Room for four 8-axis records.
type Queue = RecordBuffer<{ 4 * packed_len(8) }>;

fn records(n: u16, axes: u8) -> Vec<PositionRecord> {
    (1..=n)
        .map(|i| {
            let coords: Vec<(u8, i32)> = (1..=axes).map(|a| (a, i32::from(i) * 10)).collect();
            PositionRecord::new(i, 30, 30, 100, &coords).unwrap()
        })
        .collect()
}

const TTA: TransferConfig = TransferConfig::new(Profile::TTA);

/// A line whose past is known, as after its first fence.
fn line() -> Line {
    Line::known(LineConfig::new(ST))
}

/// A line that repeats frames up to 3 s after them.
fn repeating() -> Line {
    Line::known(LineConfig::new(ST).with_duplicate_window(3_000))
}

/// `#9926D` + count: the reply to a 26DH.
fn reply_26dh(count: u16) -> Vec<u8> {
    let r = ChangePositionData2Response {
        number_of_changed_positions: count,
    };
    let mut buf = [0u8; 16];
    let n = r.emit(ST, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// `#9921F` + the records: a read-back reply.
fn reply_21fh(stored: &[PositionRecord]) -> Vec<u8> {
    let r = EffectivePositionResponse2 {
        records: Repeated::from_slice(stored),
    };
    let mut buf = [0u8; 512];
    let n = r.emit(ST, &mut buf).unwrap();
    buf[..n].to_vec()
}

type Iter = std::vec::IntoIter<PositionRecord>;

/// Every event of `bytes` fed at `now`.
fn events(t: &mut Transfer<Iter>, l: &mut Line, mut bytes: &[u8], now: u32) -> Vec<Heard> {
    let mut out = Vec::new();
    loop {
        let r = t.received(l, bytes, now);
        bytes = &bytes[r.consumed..];
        match r.status {
            Status::Partial => return out,
            Status::Complete(h) => out.push(h),
        }
    }
}

fn transmitted(t: &mut Transfer<Iter>, l: &mut Line, now: u32) -> Vec<u8> {
    match t.poll(l, now) {
        Step::Transmit(b) => b.to_vec(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_reply_with_another_count_never_confirms_and_a_reply_before_the_send_is_stale() {
    let mut l = line();
    let mut t = Transfer::<_>::new(TTA.with_verify(Verify::Off), records(3, 2).into_iter());
    let frame = transmitted(&mut t, &mut l, 0);
    assert_eq!(&frame[..10], b"!9926D0003");
    // Before `sent`: not a reply to this frame, and nothing explains it.
    assert_eq!(events(&mut t, &mut l, &reply_26dh(3), 0), [Heard::Unplaced]);
    t.sent(&mut l, 5);
    assert_eq!(
        events(&mut t, &mut l, &reply_26dh(2), 10),
        [Heard::Mismatch]
    );
    assert!(matches!(t.poll(&mut l, 10), Step::WaitUntil(3_005)));
    assert_eq!(events(&mut t, &mut l, &reply_26dh(3), 10), [Heard::Answer]);
    assert_eq!(t.poll(&mut l, 20), Step::Done(Ok(Guarantee::Unverified)));
    assert_eq!(t.stats().records_confirmed, 3);
    assert_eq!(t.stats().count_mismatches, 1);
}

/// Runs a queue-fed transfer of `recs` (Verify::Off) to its end, answering
/// every chunk: what it sent.
fn run_queued(
    t: &mut Transfer<Queue>,
    l: &mut Line,
    recs: &[PositionRecord],
    mut now: u32,
) -> (Vec<Vec<u8>>, Result<Guarantee, Failure>) {
    let mut rest = recs.iter().peekable();
    let mut sent = Vec::new();
    loop {
        while let Some(r) = rest.next_if(|r| t.source_mut().fits(r.positions.len())) {
            t.source_mut().push(r.clone()).unwrap();
        }
        if rest.peek().is_none() {
            t.source_mut().finish();
        }
        match t.poll(l, now) {
            Step::Transmit(b) => {
                let n = u16::from_str_radix(std::str::from_utf8(&b[6..10]).unwrap(), 16).unwrap();
                sent.push(b.to_vec());
                t.sent(l, now);
                feed(t, l, &reply_26dh(n), now + 1);
            }
            Step::WaitUntil(d) => now = d,
            Step::Idle => now += 1,
            Step::Done(r) => return (sent, r),
        }
    }
}

#[test]
fn a_restarted_transfer_runs_as_a_new_one() {
    let first = TTA.with_verify(Verify::Off);
    let second = TransferConfig {
        max_records: 5,
        ..TTA.with_verify(Verify::Off)
    };
    let recs = records(17, 3);
    let mut fresh = Transfer::<_>::new(second, Queue::new()).with_total(17);
    let expected = run_queued(&mut fresh, &mut line(), &recs, 1_000);

    // A transfer left half way (a chunk sent, never answered, records
    // queued), its buffer then used to decode something else.
    let mut l = line();
    let mut t = Transfer::<_>::new(first, Queue::new());
    for r in &recs[..4] {
        t.source_mut().push(r.clone()).unwrap();
    }
    t.source_mut().finish();
    assert!(matches!(t.poll(&mut l, 0), Step::Transmit(_)));
    t.sent(&mut l, 0);
    let _ = t.idle_decoder().decode(b"!9921201??");
    t.source_mut().clear();
    t.restart(second);
    t.set_total(17);
    assert_eq!(t.progress(), (0, Some(17)));
    assert_eq!(t.stats(), TransferStats::default());
    // The unanswered chunk is the line's to remember: the restarted
    // transfer's first frame is fenced; on a line without that past it runs
    // as the fresh one did.
    t.source_mut().push(recs[0].clone()).unwrap();
    t.source_mut().finish();
    match t.poll(&mut l, 1_000) {
        Step::Transmit(b) => assert!(b.starts_with(b"!99200"), "a fence first"),
        other => panic!("{other:?}"),
    }
    assert_eq!(l.stats().fences, 1);
    let mut fresh_line = line();
    let mut again = Transfer::<_>::new(second, Queue::new()).with_total(17);
    assert_eq!(
        run_queued(&mut again, &mut fresh_line, &recs, 1_000),
        expected
    );
    assert_eq!(expected.1, Ok(Guarantee::Unverified));
}

#[test]
fn on_a_direct_line_frames_are_full_and_on_a_repeating_one_no_count_repeats_within_its_window() {
    // 8-axis records: 24 fit a frame.
    let counts = |l: &mut Line| {
        let mut t = Transfer::<_>::new(TTA.with_verify(Verify::Off), records(96, 8).into_iter());
        let mut out = Vec::new();
        let mut now = 0;
        loop {
            match t.poll(l, now) {
                Step::Transmit(b) => {
                    let n =
                        u16::from_str_radix(std::str::from_utf8(&b[6..10]).unwrap(), 16).unwrap();
                    out.push((now, n));
                    t.sent(l, now);
                    feed(&mut t, l, &reply_26dh(n), now + 200);
                    now += 200;
                }
                Step::WaitUntil(d) => now = d,
                Step::Done(_) => return out,
                Step::Idle => unreachable!(),
            }
        }
    };
    let direct = counts(&mut line());
    assert_eq!(
        direct.iter().map(|c| c.1).collect::<Vec<_>>(),
        [24, 24, 24, 24]
    );
    let repeating = counts(&mut repeating());
    for (i, &(t, n)) in repeating.iter().enumerate() {
        for &(u, m) in &repeating[..i] {
            assert!(
                n != m || t > u + 200 + 3_000,
                "count {n} at {t} could be confirmed by a copy of the reply at {}",
                u + 200
            );
        }
    }
    assert_eq!(repeating.iter().map(|c| u32::from(c.1)).sum::<u32>(), 96);
}

#[test]
fn a_frame_that_reads_back_different_is_rewritten() {
    let recs = records(2, 1);
    let mut ctl = Controller::new();
    // The first write stores position 2 altered; the rewrite lands.
    ctl.alter.insert(0, (2, 999));
    let mut t = Transfer::<_>::new(TTA, recs.clone().into_iter());
    let r = run(&mut t, &mut line(), &mut ctl, 0);
    assert_eq!(r.result, Ok(Guarantee::Verified));
    assert_eq!(t.stats().rewrites, 1);
    assert_eq!(t.stats().records_verified, 2);
    assert_eq!(ctl.count(b"!9926D"), 2);
    // The read-back asks the frame's two positions from 1, not a whole
    // 24-record window.
    assert!(ctl
        .received
        .iter()
        .any(|(_, c)| c.starts_with(b"!9921F00010002")));
    assert_eq!(ctl.table.values().cloned().collect::<Vec<_>>(), recs);
}

#[test]
fn a_frame_that_stays_different_fails_naming_its_records() {
    let recs = records(3, 1);
    let cfg = TransferConfig { rewrites: 1, ..TTA };
    let mut ctl = Controller::new();
    ctl.alter.insert(0, (2, 999));
    ctl.alter.insert(1, (2, 999));
    let mut t = Transfer::<_>::new(cfg, recs.into_iter());
    let r = run(&mut t, &mut line(), &mut ctl, 0);
    assert_eq!(
        r.result,
        Err(Failure::Mismatch {
            first_position: 2,
            records: 1
        })
    );
    assert_eq!(t.mismatched_positions().collect::<Vec<_>>(), [2]);
}

/// A frame resumed after a timeout was sent before the resume too: a late
/// reply to that send may still come. The line owes it, so the resumed
/// send is fenced and the late reply, arriving before the echo, confirms
/// nothing; and after a fault the frame is read back (fuzz finding F12).
#[test]
fn sends_before_a_resume_are_the_lines_to_settle() {
    let mut l = line();
    let mut cfg = LineConfig::new(ST);
    cfg.max_sends = 1;
    l.set_config(cfg);
    let mut ctl = Controller::new();
    // The first write's reply comes 3.5 s late: after its timeout.
    ctl.faults.insert(
        0,
        Fault {
            late_ms: 3_500,
            ..Fault::default()
        },
    );
    let mut t = Transfer::<_>::new(
        TTA.with_verify(Verify::AfterFault),
        records(2, 1).into_iter(),
    );
    let first = run(&mut t, &mut l, &mut ctl, 0);
    assert_eq!(first.result, Err(Failure::Timeout { sends: 1 }));
    t.resume(&mut l, first.now);
    let second = run(&mut t, &mut l, &mut ctl, first.now);
    assert_eq!(second.result, Ok(Guarantee::FaultsVerified));
    // Fence, then the write again, then (after the fault) its read-back.
    let kinds: Vec<&[u8]> = ctl.received.iter().map(|(_, c)| &c[..6]).collect();
    assert_eq!(kinds, [b"!9926D", b"!99200", b"!9926D", b"!9921F"]);
    assert_eq!(t.stats().frames_verified, 1);
    assert_eq!(l.stats().fences, 1);
}

/// Issue "one memory of the line", case 1: a table that writes the same
/// positions twice. A copy of the first chunk's read-back reply (30 ms
/// after it, inside the line's 3 s duplicate window) shows what the first
/// write stored; the second write of position 1 is stored with two digits
/// swapped. The copy must not verify the second chunk.
#[test]
fn a_copy_of_an_earlier_chunks_read_back_never_verifies_a_later_chunk() {
    // Chunk 1: position 1 = 111111; chunk 2: position 2, and position 1
    // again = 111111, stored as 1094151 (the SC does not change).
    let recs = std::vec![record(1, 111_111), record(2, 2_000), record(1, 111_111)];
    let cfg = TransferConfig {
        max_records: 2,
        ..TTA
    };
    let mut ctl = Controller::new();
    // Command 0 writes chunk 1 (position 1), command 1 reads it back:
    // its reply is copied 30 ms later. Write 1 (chunk 2) swaps position 1.
    ctl.faults.insert(
        1,
        Fault {
            copy_after_ms: Some(30),
            ..Fault::default()
        },
    );
    ctl.alter.insert(1, (1, 1_094_151));
    let mut l = repeating();
    let mut t = Transfer::<_>::new(cfg, recs.clone().into_iter());
    // Chunks of 1 then 2 records (the counts differ): force chunk 1 to
    // one record by its frame limit.
    t.frame_limit = 1;
    let r = run(&mut t, &mut l, &mut ctl, 0);
    let held = ctl.table.get(&1).map(|r| r.positions[0]);
    match r.result {
        Ok(Guarantee::Verified) => assert_eq!(held, Some(111_111), "a false success"),
        other => panic!("expected a verified write after the rewrite: {other:?}"),
    }
    assert!(t.stats().rewrites >= 1, "the swap was found and rewritten");
}

/// Case 1, the other way: the late reply to the first send of chunk 1's
/// read-back (after its resend) arrives 3.04 s after that send, while the
/// second chunk is being written. The line owes it, so the second chunk
/// is fenced and the late reply never answers its read-back.
#[test]
fn a_late_read_back_reply_never_verifies_a_later_chunk() {
    let recs = std::vec![record(1, 111_111), record(2, 2_000), record(1, 111_111)];
    let cfg = TransferConfig {
        max_records: 2,
        ..TTA
    };
    let mut ctl = Controller::new();
    ctl.faults.insert(
        1,
        Fault {
            late_ms: 3_040,
            ..Fault::default()
        },
    );
    ctl.alter.insert(1, (1, 1_094_151));
    let mut l = line();
    let mut t = Transfer::<_>::new(cfg, recs.into_iter());
    t.frame_limit = 1;
    let r = run(&mut t, &mut l, &mut ctl, 0);
    assert_eq!(r.result, Ok(Guarantee::Verified));
    assert_eq!(ctl.table.get(&1).map(|r| r.positions[0]), Some(111_111));
    assert!(l.stats().fences >= 1);
    assert!(t.stats().rewrites >= 1);
}

/// A read-back reply carries nothing that ties it to its query: after a
/// rewrite, a copy of the reply from before it would read as the new
/// state. On a line that repeats frames, the next read-back of the window
/// waits until no such copy can come.
#[test]
fn after_a_rewrite_a_copy_of_the_old_read_back_cannot_verify_the_frame() {
    let recs = records(2, 1);
    let mut altered = recs.clone();
    altered[1].positions[0] += 1;
    let old = reply_21fh(&altered);
    let mut l = repeating();
    let mut t = Transfer::<_>::new(TTA, recs.clone().into_iter());
    // Written, confirmed, read back different at 11.
    assert!(transmitted(&mut t, &mut l, 0).starts_with(b"!9926D"));
    t.sent(&mut l, 5);
    feed(&mut t, &mut l, &reply_26dh(2), 6);
    assert!(matches!(t.poll(&mut l, 6), Step::WaitUntil(8)));
    assert!(transmitted(&mut t, &mut l, 8).starts_with(b"!9921F"));
    t.sent(&mut l, 10);
    feed(&mut t, &mut l, &old, 11);
    // The rewrite goes out after the turnaround: under full verification
    // its read-back is the proof, so a copy of the first write's reply
    // (count 2 too) confirming it would prove nothing.
    assert!(matches!(t.poll(&mut l, 11), Step::WaitUntil(13)));
    let w = 13;
    assert!(transmitted(&mut t, &mut l, w).starts_with(b"!9926D"));
    t.sent(&mut l, w + 5);
    feed(&mut t, &mut l, &reply_26dh(2), w + 6);
    // The read-back waits out the copy of the old reply... which arrives
    // meanwhile: stale, not a comparison; its own copy may come 3 s later.
    assert!(matches!(t.poll(&mut l, w + 7), Step::WaitUntil(_)));
    assert_eq!(events(&mut t, &mut l, &old, w + 100), [Heard::Stale]);
    let Step::WaitUntil(q) = t.poll(&mut l, w + 101) else {
        panic!()
    };
    assert!(q > w + 100 + 3_000);
    assert!(transmitted(&mut t, &mut l, q).starts_with(b"!9921F"));
    t.sent(&mut l, q + 1);
    feed(&mut t, &mut l, &reply_21fh(&recs), q + 2);
    assert_eq!(t.poll(&mut l, q + 10), Step::Done(Ok(Guarantee::Verified)));
    assert_eq!(t.stats().rewrites, 1);
}

/// Under full verification a write's reply need not be provable: a copy
/// of an earlier write's reply (the same count) that seems to confirm a
/// frame the controller never got is found out by the frame's read-back,
/// and the frame is written again.
#[test]
fn a_write_a_copy_seemed_to_confirm_reads_back_different_and_is_rewritten() {
    let recs = records(4, 1);
    let cfg = TransferConfig {
        max_records: 2,
        ..TTA
    };
    let mut ctl = Controller::new();
    // Command 0 writes positions 1-2: its reply is repeated 100 ms later.
    // Command 2 (after the read-back) writes 3-4 and is lost on the way.
    ctl.faults.insert(
        0,
        Fault {
            copy_after_ms: Some(100),
            ..Fault::default()
        },
    );
    ctl.faults.insert(
        2,
        Fault {
            lost: true,
            ..Fault::default()
        },
    );
    let mut l = repeating();
    let mut t = Transfer::<_>::new(cfg, recs.clone().into_iter());
    let r = run(&mut t, &mut l, &mut ctl, 0);
    assert_eq!(r.result, Ok(Guarantee::Verified));
    assert_eq!(ctl.table.values().cloned().collect::<Vec<_>>(), recs);
    assert_eq!(t.stats().rewrites, 1, "the frame the copy confirmed");
}

/// A write whose reply counts every record but whose read-back lacks one:
/// the controller stored that record at another number (two flips in its
/// number field that the SC cannot see). The frame is rewritten and
/// verified, but the stray record may have overwritten a position written
/// before, which no read-back covers: the transfer ends in a typed
/// failure naming the record, never `Verified`.
#[test]
fn a_record_stored_at_another_number_ends_misplaced_not_verified() {
    let recs = records(4, 1);
    let cfg = TransferConfig {
        max_records: 2,
        ..TTA
    };
    let mut ctl = Controller::new();
    // The second frame (positions 3-4) stores position 4 at position 1,
    // over the record the first frame wrote and verified.
    ctl.misplace.insert(1, (4, 1));
    let mut l = Line::known(LineConfig::new(ST));
    let mut t = Transfer::<_>::new(cfg, recs.clone().into_iter());
    let r = run(&mut t, &mut l, &mut ctl, 0);
    assert_eq!(r.result, Err(Failure::Misplaced { position: 4 }));
    assert_eq!(t.stats().misplaced, 1);
    assert_eq!(t.stats().rewrites, 1);
    // Positions 3 and 4 are right again; position 1 holds the stray.
    assert_eq!(ctl.table.get(&4), Some(&recs[3]));
    assert_ne!(ctl.table.get(&1), Some(&recs[0]));
}
