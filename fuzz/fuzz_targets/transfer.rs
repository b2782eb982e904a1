//! The transfer engine (`transfer::Transfer`) against a fuzzed controller.
//!
//! Input layout: a config (stream kind, station, table size and seed,
//! frame limit, timeout, tries, late guard, start tick), then a script of
//! operations the "controller" performs whenever the engine waits: advance
//! the virtual clock, send arbitrary fuzz bytes, send a (possibly wrong)
//! normal reply to the frame last sent, send an `&` error reply, or let the
//! deadline pass. After a `Transmit`, a script byte may also deliver bytes
//! before the engine is told the frame was sent. When the script is used
//! up, the controller is silent and the clock jumps to each deadline.
//!
//! Checked: no panic; the engine stops (`Complete`, or `Failed` with no
//! resumes left) within a bounded number of steps; each frame sent carries
//! the next unconfirmed records of the table, in order; `records_confirmed`
//! never exceeds the table size and only grows, by exactly the record count
//! of the frame sent last, and only after `sent`; `Complete` only when every
//! record was confirmed.
#![no_main]

#[path = "common/records.rs"]
mod records;

use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::message::ErrorResponse;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::stream::PositionStream;
use iai_protocol_b::transfer::{Step, Transfer, TransferConfig, TransferError};
use libfuzzer_sys::fuzz_target;
use records::Input;

const WRITES: [PositionStream; 5] = [
    PositionStream::CHANGE_2,
    PositionStream::CHANGE,
    PositionStream::RANGE,
    PositionStream::RANGE_3,
    PositionStream::CHANGE_3,
];

/// A normal reply to a write: the same prefix with `count`.
fn reply(kind: PositionStream, station: Station, start: u16, count: u16) -> Vec<u8> {
    let mut buf = [0u8; 32];
    let n = emit_frame(
        &mut buf,
        Header::Response,
        station,
        kind.id,
        ChecksumMode::Compute,
        |w| {
            if kind.reserved {
                w.put(b"00")?;
            }
            if kind.start_width > 0 {
                w.unsigned(
                    iai_protocol_b::field::FieldSpec::hex(kind.start_width),
                    u64::from(start),
                )?;
            }
            w.unsigned(
                iai_protocol_b::field::FieldSpec::hex(kind.count_width),
                u64::from(count),
            )
        },
    )
    .expect("reply fits");
    buf[..n].to_vec()
}

/// What the engine put in a frame: (start, records).
fn sent_records(kind: PositionStream, bytes: &[u8]) -> (u16, Vec<PositionRecord>) {
    let f =
        Frame::new_checked(bytes, BypassPolicy::Reject).expect("the engine sent an invalid frame");
    assert_eq!((f.header(), f.code()), (Header::Command, kind.id));
    let mut r = f.reader();
    let (start, count) = kind.read_prefix(&mut r).expect("prefix");
    let recs: Vec<_> = (0..count)
        .map(|_| kind.layout.read_record(&mut r).expect("record"))
        .collect();
    r.finish().expect("nothing after the records");
    (start, recs)
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let c = input.u8();
    let kind = WRITES[usize::from(c % 5)];
    let station = Station(if c & 0x80 != 0 { 0x99 } else { input.u8() });
    let size = usize::from(input.u8() % 48);
    let seed = input.u8();
    // Range writes (244H, 290H): the table ends inside the start field's
    // range, `start + size <= max + 1`, up to exactly its top (which once
    // failed after every record was confirmed; fixed in the core).
    let start_max = match kind.start_width {
        0 => 0u32,
        w => (1u32 << (4 * u32::from(w))) - 1,
    };
    let start =
        (u32::from(input.u16()) & start_max).min((start_max + 1).saturating_sub(size as u32)) as u16;
    // Between one 8-axis record and ~1 KiB per frame.
    let min_frame = kind.overhead() + kind.layout.record_len(8);
    let max_frame = min_frame + usize::from(input.u8()) * 4;
    let cfg = TransferConfig {
        station,
        stream: kind,
        start,
        max_frame,
        timeout_ms: 1 + u32::from(input.u8()) * 20,
        max_tries: 1 + input.u8() % 3,
        turnaround_ms: 1 + u32::from(input.u8() % 4),
        checksum: ChecksumMode::Compute,
        late_guard_ms: u32::from(input.u16()),
    };
    let mut now = input.u32();
    let mut resumes = input.u8() % 3;

    let first_number = input.u16();
    let table = records::table(kind.layout, seed, first_number, size);
    let mut t: Transfer<_, 2051> = Transfer::new(cfg, table.clone().into_iter());
    let max_steps =
        64 + 8 * data.len() + 16 * size * usize::from(cfg.max_tries) * (1 + usize::from(resumes));

    // The frame last transmitted: (record count, whether `sent` was called).
    let mut outstanding: Option<(u16, bool)> = None;
    let mut last_start = 0u16;
    let mut confirmed = 0u32;
    let mut steps = 0usize;

    // Checks the counters after anything the engine was told.
    macro_rules! check {
        ($t:expr, $outstanding:expr, $confirmed:expr) => {{
            let s = $t.stats();
            assert!(
                s.records_confirmed as usize <= table.len(),
                "more confirmed than the table"
            );
            if s.records_confirmed != $confirmed {
                let grew = s
                    .records_confirmed
                    .checked_sub($confirmed)
                    .expect("confirmed shrank");
                match $outstanding {
                    Some((n, true)) => {
                        assert_eq!(grew, u32::from(n), "confirmed grew by a count never sent")
                    }
                    other => panic!("confirmed grew by {grew} with frame {other:?}"),
                }
                $outstanding = None;
                $confirmed = s.records_confirmed;
            }
        }};
    }

    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        match t.poll(now) {
            Step::Transmit(bytes) => {
                let (s, recs) = sent_records(kind, bytes);
                assert!(bytes.len() <= max_frame);
                assert!(!recs.is_empty());
                let from = confirmed as usize;
                assert_eq!(
                    &recs[..],
                    &table[from..from + recs.len()],
                    "records out of order"
                );
                if kind.start_width > 0 {
                    assert_eq!(
                        u32::from(s),
                        u32::from(start) + confirmed,
                        "wrong start number"
                    );
                }
                last_start = s;
                outstanding = Some((recs.len() as u16, false));
                // Bytes that arrive while the frame is still going out.
                if let Some(op) = input.next() {
                    if op & 0xC0 == 0xC0 {
                        let r = reply(kind, station, s, recs.len() as u16);
                        t.received(&r, now);
                        check!(t, outstanding, confirmed);
                        assert_eq!(t.stats().records_confirmed, confirmed);
                    }
                    now = now.wrapping_add(u32::from(op & 0x0F));
                }
                t.sent(now);
                if let Some((_, s)) = outstanding.as_mut() {
                    *s = true;
                }
            }
            Step::WaitUntil(deadline) => {
                assert!(
                    deadline.wrapping_sub(now).wrapping_sub(1) <= 0x7FFF_FFFF,
                    "waits for the past"
                );
                match input.next() {
                    None => now = deadline,
                    Some(op) => match op % 6 {
                        0 => now = now.wrapping_add(u32::from(input.u16())),
                        1 => {
                            let n = usize::from(input.u8());
                            let bytes = input.take(n);
                            t.received(bytes, now);
                        }
                        2 | 3 => {
                            // A normal reply, sometimes with a wrong count or station.
                            let count = match outstanding {
                                Some((n, _)) if op & 0x80 == 0 => n,
                                _ => u16::from(input.u8()),
                            };
                            let st = if op & 0x40 == 0 {
                                station
                            } else {
                                Station(input.u8())
                            };
                            let r = reply(kind, st, last_start, count);
                            let split = usize::from(input.u8()) % (r.len() + 1);
                            t.received(&r[..split], now);
                            now = now.wrapping_add(u32::from(op >> 4 & 3));
                            t.received(&r[split..], now);
                        }
                        4 => {
                            let mut buf = [0u8; 16];
                            let n = ErrorResponse {
                                code: input.u16() & 0xFFF,
                            }
                            .emit(station, &mut buf)
                            .unwrap();
                            t.received(&buf[..n], now);
                        }
                        _ => now = deadline,
                    },
                }
                check!(t, outstanding, confirmed);
            }
            Step::NeedRecords => panic!("an iterator source is never pending"),
            Step::Complete(stats) => {
                assert_eq!(stats, t.stats());
                assert_eq!(
                    stats.records_confirmed as usize,
                    table.len(),
                    "Complete before every record was confirmed"
                );
                assert!(outstanding.is_none());
                break;
            }
            Step::Failed(e) => {
                match e {
                    TransferError::Timeout | TransferError::ErrorResponse { .. } => {}
                    other => panic!("unexpected failure {other:?}"),
                }
                assert!((t.stats().records_confirmed as usize) < table.len());
                if resumes == 0 || input.is_empty() {
                    break;
                }
                resumes -= 1;
                t.resume(now);
            }
        }
        check!(t, outstanding, confirmed);
    }
    let s = t.stats();
    assert!(s.frames_confirmed <= s.frames_sent);
    assert!(s.retries < s.frames_sent.max(1));
});
