//! The read-back engine, frame by frame, against the scripted controller
//! of [`crate::testing`].

extern crate std;
use std::vec::Vec;

use super::*;
use crate::line::LineConfig;
use crate::testing::{record, Controller, Fault, ST};

fn line() -> Line {
    Line::known(LineConfig::new(ST))
}

/// A table of `n` one-axis records, position i at i x 1000.
fn controller(n: u16) -> Controller {
    let mut ctl = Controller::new();
    for i in 1..=n {
        ctl.table.insert(i, record(i, i32::from(i) * 1_000));
    }
    ctl
}

/// The 21FH queries the controller got: when, and their head and count
/// fields.
fn read_queries(ctl: &Controller) -> impl Iterator<Item = (u32, &[u8])> {
    ctl.received
        .iter()
        .filter(|(_, c)| c.starts_with(b"!9921F"))
        .map(|(t, c)| (*t, &c[6..14]))
}

/// Runs `rb` on `line` against `ctl` to its end; the records delivered.
fn read(rb: &mut ReadBack, l: &mut Line, ctl: &mut Controller) -> Vec<PositionRecord> {
    let mut got = Vec::new();
    let r = {
        let mut engine = rb.delivering(|recs| got.extend(recs));
        crate::testing::run(&mut engine, l, ctl, 0)
    };
    assert!(r.result.is_ok(), "{:?}", r.result);
    got
}

#[test]
fn every_window_is_read_twice_and_delivered_in_order() {
    let mut ctl = controller(60);
    let mut rb: ReadBack = ReadBack::new(ReadBackConfig::new(Profile::TTA, 1, 60));
    let got = read(&mut rb, &mut line(), &mut ctl);
    assert_eq!(got, ctl.table.values().cloned().collect::<Vec<_>>());
    // 21FH from position 1, 24 positions (a 2,048-byte reply holds 24
    // 8-axis records): `!9921F` 0001 0018 SC.
    assert_eq!(ctl.received[0].1, b"!9921F00010018C6\r\n");
    let s = rb.stats();
    assert_eq!((s.windows_confirmed, s.queries), (3, 6));
    assert_eq!(s.records, 60);
}

/// Issue "one memory of the line", case 5: a 21FH reply with two digits
/// swapped (the SC still matches) and its copy 5 ms later from an echoing
/// converter agree with each other. The confirmation never asks a question
/// the copy could answer: it asks position 1 alone at once (the copy
/// carries 1 and 2, so it cannot pass for that reply), which the
/// controller answers, disagreeing; the next agrees with it, and the window
/// is delivered as the controller holds it.
#[test]
fn a_copy_of_a_reply_never_confirms_it() {
    let mut ctl = controller(2);
    ctl.faults.insert(
        0,
        Fault {
            copy_after_ms: Some(5),
            shows: Some((1, 1_094_151)),
            ..Fault::default()
        },
    );
    let mut l = Line::known(LineConfig::new(ST).with_duplicate_window(3_000));
    let mut rb: ReadBack = ReadBack::new(ReadBackConfig::new(Profile::TTA, 1, 2));
    let got = read(&mut rb, &mut l, &mut ctl);
    assert_eq!(
        got[0].positions[0], 1_000,
        "position 1 as the controller holds it"
    );
    assert_eq!(got, ctl.table.values().cloned().collect::<Vec<_>>());
    assert_eq!(rb.stats().disagreements, 1);
    let queries: Vec<&[u8]> = read_queries(&ctl).map(|(_, q)| q).collect();
    // 1+2, then 1+1 with no wait (the copy cannot pass for it).
    assert_eq!(queries[..2], [b"00010002", b"00010001"]);
    let first_reply_at = ctl.received[0].0 + 5;
    assert!(ctl.received[1].0 < first_reply_at + 5 + 3_000);
    // Every question after it could be answered by a copy of one before:
    // each waited out the copy window.
    let sent: Vec<u32> = read_queries(&ctl).map(|(t, _)| t).collect();
    for pair in sent[1..].windows(2) {
        assert!(pair[1] > pair[0] + 3_000, "{queries:?} at {sent:?}");
    }
}

/// A window's reply comes after its timeout and resend (the resend is
/// answered too, in order). What the window still owes is settled by a
/// fence before the next query, so the late reply never answers it.
#[test]
fn a_late_reply_never_answers_the_next_window() {
    let mut ctl = controller(48);
    // Positions 25..=48 are not defined: window 2 is empty.
    for n in 25..=48 {
        ctl.table.remove(&n);
    }
    ctl.faults.insert(
        0,
        Fault {
            late_ms: 3_500,
            ..Fault::default()
        },
    );
    let cfg = ReadBackConfig {
        confirm: false,
        ..ReadBackConfig::new(Profile::TTA, 1, 48)
    };
    let mut l = line();
    let mut rb: ReadBack = ReadBack::new(cfg);
    let (mut got, mut windows) = (Vec::new(), 0);
    let r = {
        let mut engine = rb.delivering(|recs| {
            windows += 1;
            got.extend(recs)
        });
        crate::testing::run(&mut engine, &mut l, &mut ctl, 0)
    };
    assert!(r.result.is_ok(), "{:?}", r.result);
    assert_eq!(got, ctl.table.values().cloned().collect::<Vec<_>>());
    // Each window delivered is proved by a fence; the first one's also
    // settles what the timed-out query owes (its late reply came before
    // the echo: stale).
    assert_eq!(l.stats().fences, windows);
    assert_eq!(rb.stats().retries, 1);
    assert_eq!(l.stats().unplaced, 0);
}

/// Confirmed reads: a confirmation that times out is asked again as the
/// first read of half the window; the rest is read once too, and one
/// confirmation of all four agrees with both (fuzz finding F10: a
/// confirmation never rests on a reply of a larger query it replaced).
#[test]
fn a_shrunk_window_is_confirmed_by_its_own_replies() {
    let mut ctl = controller(4);
    let cfg = ReadBackConfig {
        max_response: 360,
        ..ReadBackConfig::new(Profile::TTA, 1, 4)
    };
    assert_eq!(cfg.window(), 4);
    // 1+4 is read once; its confirmation is lost.
    ctl.faults.insert(
        1,
        Fault {
            silent: true,
            ..Fault::default()
        },
    );
    let mut l = line();
    let mut rb: ReadBack = ReadBack::new(cfg);
    let got = read(&mut rb, &mut l, &mut ctl);
    assert_eq!(got, ctl.table.values().cloned().collect::<Vec<_>>());
    let queries: Vec<&[u8]> = read_queries(&ctl).map(|(_, q)| q).collect();
    // 1+4, its confirmation (lost), 1+2 resent in its place (a first read
    // of the smaller window), 3+2 read once, then 1+4 confirming both.
    assert_eq!(
        queries[..],
        [
            b"00010004",
            b"00010004",
            b"00010002",
            b"00030002",
            b"00010004"
        ]
    );
    assert_eq!(rb.stats().windows_confirmed, 1);
}

/// After a window's reply is answered, the engine takes no more bytes until
/// the next poll has delivered it: a frame fed right behind it would
/// otherwise overwrite the reply in the decoder and its records be lost.
#[test]
fn an_answered_reply_is_held_until_it_is_polled() {
    let mut ctl = controller(3);
    let cfg = ReadBackConfig {
        confirm: false,
        ..ReadBackConfig::new(Profile::TTA, 1, 3)
    };
    // A line that expects copies: the stray one below is explained.
    let mut l = Line::known(LineConfig::new(ST).with_duplicate_window(1_000));
    let mut rb: ReadBack = ReadBack::new(cfg);
    let Step::Transmit(q) = rb.poll(&mut l, 0) else {
        panic!("a query first")
    };
    let q = q.to_vec();
    rb.sent(&mut l, 1);
    ctl.receive(&q, 1);
    let mut bytes = ctl.take(10_000);
    let reply_len = bytes.len();
    // A stray copy right behind it.
    bytes.extend_from_within(..reply_len);
    let r = rb.received(&mut l, &bytes, 20);
    assert_eq!(
        (r.consumed, r.status),
        (reply_len, Status::Complete(Heard::Answer))
    );
    // The copy is read by the line while the reply waits to be delivered.
    let mut rest = &bytes[reply_len..];
    while !rest.is_empty() {
        rest = &rest[rb.received(&mut l, rest, 21).consumed..];
    }
    assert_eq!(l.stats().stale, 1);
    // Before it is delivered, a fence proves the order; its echo is heard
    // while the reply is still held.
    let Step::Transmit(fence) = rb.poll(&mut l, 22) else {
        panic!("the proof's fence")
    };
    assert!(fence.starts_with(b"!99200"));
    let fence = fence.to_vec();
    rb.sent(&mut l, 23);
    ctl.receive(&fence, 23);
    let echo = ctl.take(10_000);
    let mut rest = &echo[..];
    while !rest.is_empty() {
        rest = &rest[rb.received(&mut l, rest, 30).consumed..];
    }
    match rb.poll(&mut l, 31) {
        Step::Done(Ok(Some(recs))) => assert_eq!(
            recs.collect::<Vec<_>>(),
            ctl.table.values().cloned().collect::<Vec<_>>()
        ),
        other => panic!("{other:?}"),
    }
}
