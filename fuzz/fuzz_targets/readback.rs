//! The read-back engine (`readback::ReadBack`) fed arbitrary replies.
//!
//! Input layout: a config (query kind, station, first and last position,
//! reply size limit, timeout, tries, start tick), then a script of what the
//! "controller" does whenever the engine waits: advance the clock, send
//! arbitrary fuzz bytes, send a generated reply (records numbered from
//! fuzz bytes, so sometimes outside the window, with a count that is
//! sometimes wrong), send an `&` error reply, or let the deadline pass.
//! Bytes the engine does not take (it stops at the reply it awaited) are
//! fed again after the next poll. When the script is used up the
//! controller is silent.
//!
//! Checked: no panic; every query asks a window inside `first..=last`,
//! windows advance without gaps; every record delivered lies inside the
//! window of the query it answers (and inside `first..=last`); the records
//! delivered add up to `stats().records`; the engine stops within a bounded
//! number of steps.
#![no_main]

#[path = "common/records.rs"]
mod records;

use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::field::{FieldSpec, Reader};
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::message::ErrorResponse;
use iai_protocol_b::readback::{ReadBack, ReadBackConfig, ReadStep};
use iai_protocol_b::stream::PositionStream;
use libfuzzer_sys::fuzz_target;
use records::Input;

const QUERIES: [PositionStream; 3] = [
    PositionStream::QUERY_2_RESPONSE,
    PositionStream::QUERY_3_RESPONSE,
    PositionStream::QUERY_RESPONSE,
];

/// (head, asked) of a query the engine sent.
fn parse_query(kind: PositionStream, bytes: &[u8], station: Station) -> (u32, u32) {
    let f =
        Frame::new_checked(bytes, BypassPolicy::Reject).expect("the engine sent an invalid query");
    assert_eq!(
        (f.header(), f.code(), f.station()),
        (Header::Command, kind.id, station)
    );
    let mut r: Reader<'_> = f.reader();
    if kind.reserved {
        assert_eq!(r.take(2).unwrap(), b"00");
    }
    let spec = FieldSpec::hex(kind.count_width);
    let head = r.unsigned(spec).unwrap() as u32;
    let asked = r.unsigned(spec).unwrap() as u32;
    r.finish().expect("nothing after the window");
    (head, asked)
}

/// A reply carrying `numbers.len()` records (count field `count`).
fn reply(
    kind: PositionStream,
    station: Station,
    count: u16,
    recs_input: &mut Input<'_>,
    n: usize,
    base: u32,
    spread: u8,
) -> Vec<u8> {
    let mut buf = vec![0u8; 4096];
    let res = emit_frame(
        &mut buf,
        Header::Response,
        station,
        kind.id,
        ChecksumMode::Compute,
        |w| {
            if kind.reserved {
                w.put(b"00")?;
            }
            w.unsigned(FieldSpec::hex(kind.count_width), u64::from(count))?;
            for i in 0..n {
                let mut rec = records::arbitrary_record(kind.layout, recs_input);
                // Mostly inside the window, sometimes around or outside it.
                let num = base
                    .wrapping_add(i as u32 * u32::from(spread % 3))
                    .wrapping_add(u32::from(rec.number % 4))
                    .wrapping_sub(u32::from(spread >> 6));
                rec.number = records::fit_number(kind.layout, num as u16);
                kind.layout.write_record(&rec, w)?;
            }
            Ok(())
        },
    );
    match res {
        Ok(len) => buf[..len].to_vec(),
        Err(_) => Vec::new(),
    }
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let c = input.u8();
    let kind = QUERIES[usize::from(c % 3)];
    let station = Station(if c & 0x80 != 0 { 0x99 } else { input.u8() });
    let first = records::fit_number(kind.layout, input.u16());
    let span = input.u8();
    let last = records::fit_number(kind.layout, first.saturating_add(u16::from(span)));
    let last = last.max(first);
    let max_response =
        kind.overhead() + kind.layout.record_len(8) * (1 + usize::from(input.u8() % 8));
    let cfg = ReadBackConfig {
        station,
        stream: kind,
        first,
        last,
        max_response,
        timeout_ms: 1 + u32::from(input.u8()) * 20,
        max_tries: 1 + input.u8() % 3,
        turnaround_ms: 1 + u32::from(input.u8() % 4),
    };
    let mut now = input.u32();
    let mut rb: ReadBack<2048> = ReadBack::new(cfg);
    let windows = (u32::from(last) - u32::from(first)) / u32::from(cfg.window()) + 1;
    let max_steps = 64 + 8 * data.len() + 8 * windows as usize * usize::from(cfg.max_tries);

    let mut window: Option<(u32, u32)> = None;
    let mut next_head = u32::from(first);
    let mut delivered = 0u32;
    let mut pending: Vec<u8> = Vec::new();
    let mut steps = 0usize;

    macro_rules! feed {
        ($rb:expr, $now:expr) => {{
            let used = $rb.received(&pending, $now);
            assert!(used <= pending.len());
            pending.drain(..used);
        }};
    }

    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        match rb.poll(now) {
            ReadStep::Transmit(q) => {
                let (head, asked) = parse_query(kind, q, station);
                assert!(asked >= 1 && asked <= u32::from(cfg.window()));
                assert!(
                    head >= u32::from(first) && head + asked - 1 <= u32::from(last),
                    "window {head}+{asked} outside {first}..={last}"
                );
                if window != Some((head, asked)) {
                    assert_eq!(head, next_head, "windows skip or repeat");
                    next_head = head + asked;
                }
                window = Some((head, asked));
                rb.sent(now);
            }
            ReadStep::WaitUntil(deadline) => {
                assert!(
                    deadline.wrapping_sub(now).wrapping_sub(1) <= 0x7FFF_FFFF,
                    "waits for the past"
                );
                match input.next() {
                    None => {
                        pending.clear();
                        now = deadline;
                    }
                    Some(op) => match op % 6 {
                        0 => now = now.wrapping_add(u32::from(input.u16())),
                        1 => {
                            let n = usize::from(input.u8());
                            pending.extend_from_slice(input.take(n));
                        }
                        2 | 3 => {
                            let (head, asked) = window.unwrap_or((0, 1));
                            let n = usize::from(input.u8()) % (asked as usize + 2);
                            let count = if op & 0x80 == 0 {
                                n as u16
                            } else {
                                u16::from(input.u8())
                            };
                            let st = if op & 0x40 == 0 {
                                station
                            } else {
                                Station(input.u8())
                            };
                            let spread = input.u8();
                            pending.extend(reply(kind, st, count, &mut input, n, head, spread));
                        }
                        4 => {
                            let mut buf = [0u8; 16];
                            let n = ErrorResponse {
                                code: input.u16() & 0xFFF,
                            }
                            .emit(station, &mut buf)
                            .unwrap();
                            pending.extend_from_slice(&buf[..n]);
                        }
                        _ => now = deadline,
                    },
                }
                feed!(rb, now);
            }
            ReadStep::Records(recs) => {
                let (head, asked) = window.expect("records before any query");
                for rec in recs {
                    let n = u32::from(rec.number);
                    assert!(
                        n >= head && n < head + asked,
                        "record {n} outside the window {head}..{}",
                        head + asked
                    );
                    assert!(n >= u32::from(first) && n <= u32::from(last));
                    assert_eq!(rec.positions.len(), rec.axes.count());
                    delivered += 1;
                }
                assert_eq!(delivered, rb.stats().records);
                window = None;
                feed!(rb, now);
            }
            ReadStep::Complete(stats) => {
                assert_eq!(stats.records, delivered);
                assert_eq!(
                    next_head,
                    u32::from(last) + 1,
                    "Complete before the last window"
                );
                break;
            }
            ReadStep::Failed(_) => break,
        }
    }
});
