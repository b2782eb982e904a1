//! Throughput of the core's position-stream codec on whole 26DH tables
//! (20,000 records of 8 axes, 1,640,014 bytes; and of 1 axis, 520,014
//! bytes), beside three anchors run on the same bytes in the same run:
//!
//! - the straightforward std codec (`host_tests::naive`);
//! - two well-kept hex crates, `hex` (scalar, a table per byte) and
//!   `faster-hex` (SIMD where the CPU has it), encoding the binary values
//!   behind the frame's hex digits and decoding those digits (with
//!   validation). They do less than the core: no fields, no checksum, no
//!   streaming through a small buffer;
//! - `memcpy` of the frame: the floor for touching every byte once.
//!
//! Each figure is the median of timed runs (after a warm-up). The table
//! prints MB/s of wire bytes and the core's speed relative to each anchor
//! (`core/hex 1.50x` = the core takes two thirds of the `hex` crate's
//! time). The core also runs as its embedded callers use it: the encoder
//! given the records by reference (no clone) and the bulk decoder
//! (`decode_records` into an array); those rows carry their speed relative
//! to the `hex` crate. Figures, never assertions. Run:
//! `cargo bench -p host-tests`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use host_tests::table::table;
use iai_protocol_b::checksum::{BypassPolicy, Checksum};
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::{PositionStreamDecoder, PositionStreamEncoder, StreamEvent};

const RECORDS: u32 = 20_000;
/// Timed runs per figure (the median is printed) and the least time spent.
const RUNS: usize = 15;
const MIN_TIME: Duration = Duration::from_millis(300);

fn main() {
    // `cargo test --benches` runs this with `--test`: one quick pass only.
    let quick = std::env::args().any(|a| a == "--test");
    for axes in [8u8, 1] {
        workload(axes, quick);
    }
}

/// Median seconds of one call of `f`.
fn time<R>(quick: bool, mut f: impl FnMut() -> R) -> f64 {
    black_box(f());
    if quick {
        return 1.0;
    }
    let mut samples = Vec::with_capacity(RUNS);
    let start = Instant::now();
    while samples.len() < RUNS || start.elapsed() < MIN_TIME {
        let t = Instant::now();
        black_box(f());
        samples.push(t.elapsed().as_secs_f64());
    }
    samples.sort_by(f64::total_cmp);
    samples[samples.len() / 2]
}

fn encode_core(recs: &[PositionRecord], out: &mut [u8]) -> usize {
    let enc = PositionStreamEncoder::new(
        PositionStream::CHANGE_2,
        Station(0x99),
        0,
        recs.len() as u16,
        recs.iter().cloned(),
    )
    .unwrap();
    pull(enc, out)
}

/// [`encode_core`] with the records handed over by reference
/// (`recs.iter()`): no clone.
fn encode_core_by_ref(recs: &[PositionRecord], out: &mut [u8]) -> usize {
    let enc = PositionStreamEncoder::new(
        PositionStream::CHANGE_2,
        Station(0x99),
        0,
        recs.len() as u16,
        recs.iter(),
    )
    .unwrap();
    pull(enc, out)
}

/// The whole frame out of `enc` into `out`, 256 bytes per `read`.
fn pull<I>(mut enc: PositionStreamEncoder<I>, out: &mut [u8]) -> usize
where
    I: Iterator,
    I::Item: std::borrow::Borrow<PositionRecord>,
{
    let mut len = 0;
    loop {
        let end = (len + 256).min(out.len());
        let n = enc.read(&mut out[len..end]).unwrap();
        if n == 0 {
            return len;
        }
        len += n;
    }
}

fn decode_core(frame: &[u8]) -> u32 {
    let mut dec = PositionStreamDecoder::new(BypassPolicy::Reject);
    let mut n = 0u32;
    for chunk in frame.chunks(256) {
        let mut rest = chunk;
        while !rest.is_empty() {
            let r = dec.decode(rest);
            let (used, ev) = (r.consumed, r.status.complete());
            rest = &rest[used..];
            match ev {
                Some(StreamEvent::Record(r)) => {
                    black_box(r);
                    n += 1;
                }
                Some(StreamEvent::Error { error, .. }) => panic!("decode: {error}"),
                _ => {}
            }
        }
    }
    n
}

/// [`decode_core`] with the bulk path: `decode_records` into a caller's
/// array of 64 records, 256 input bytes at a time.
fn decode_core_records(frame: &[u8], batch: &mut [PositionRecord; 64]) -> u32 {
    let mut dec = PositionStreamDecoder::new(BypassPolicy::Reject);
    let mut n = 0u32;
    for chunk in frame.chunks(256) {
        let mut rest = chunk;
        while !rest.is_empty() {
            let r = dec.decode_records(rest, batch);
            let (used, k, ev) = (r.consumed, r.records, r.status.complete());
            rest = &rest[used..];
            black_box(&batch[..k]);
            n += k as u32;
            if let Some(StreamEvent::Error { error, .. }) = ev {
                panic!("decode_records: {error}");
            }
        }
    }
    n
}

struct Row {
    name: &'static str,
    secs: f64,
}

fn workload(axes: u8, quick: bool) {
    let recs: Vec<PositionRecord> = table(RECORDS, axes, 42).collect();
    let text = host_tests::naive::encode_26dh(0x99, &recs);
    let frame = text.as_bytes().to_vec();
    let len = frame.len();
    let mut out = vec![0u8; len];
    assert_eq!(encode_core(&recs, &mut out), len);
    assert_eq!(out, frame, "core and naive encoders disagree");
    assert_eq!(decode_core(&frame), RECORDS);
    let mut batch: [PositionRecord; 64] = std::array::from_fn(|_| PositionRecord::default());
    assert_eq!(decode_core_records(&frame, &mut batch), RECORDS);
    out.fill(0);
    assert_eq!(encode_core_by_ref(&recs, &mut out), len);
    assert_eq!(out, frame, "by reference, the encoder gives the same frame");

    // The hex digits of the frame (count, records, SC) and their binary values.
    let digits = &frame[6..len - 2];
    let mut binary = vec![0u8; digits.len() / 2];
    hex::decode_to_slice(digits, &mut binary).unwrap();
    let mut digits_out = vec![0u8; digits.len()];

    let encode = [
        Row {
            name: "core streaming encoder",
            secs: time(quick, || encode_core(black_box(&recs), &mut out)),
        },
        Row {
            name: "core encoder, records by ref",
            secs: time(quick, || encode_core_by_ref(black_box(&recs), &mut out)),
        },
        Row {
            name: "naive format!",
            secs: time(quick, || {
                host_tests::naive::encode_26dh(0x99, black_box(&recs)).len()
            }),
        },
        Row {
            name: "hex::encode_to_slice",
            secs: time(quick, || {
                hex::encode_to_slice(black_box(&binary), &mut digits_out).unwrap()
            }),
        },
        Row {
            name: "faster_hex::hex_encode_upper",
            secs: time(quick, || {
                faster_hex::hex_encode_upper(black_box(&binary), &mut digits_out)
                    .unwrap()
                    .len()
            }),
        },
        Row {
            name: "memcpy",
            secs: time(quick, || out.copy_from_slice(black_box(&frame))),
        },
    ];
    let decode = [
        Row {
            name: "core streaming decoder",
            secs: time(quick, || decode_core(black_box(&frame))),
        },
        Row {
            name: "core decode_records (bulk)",
            secs: time(quick, || decode_core_records(black_box(&frame), &mut batch)),
        },
        Row {
            name: "naive from_str_radix",
            secs: time(quick, || {
                host_tests::naive::decode_26dh(black_box(&text))
                    .unwrap()
                    .len()
            }),
        },
        Row {
            name: "hex::decode_to_slice",
            secs: time(quick, || {
                hex::decode_to_slice(black_box(digits), &mut binary).unwrap()
            }),
        },
        Row {
            name: "faster_hex::hex_decode",
            secs: time(quick, || {
                faster_hex::hex_decode(black_box(digits), &mut binary).unwrap()
            }),
        },
        Row {
            name: "memcpy",
            secs: time(quick, || out.copy_from_slice(black_box(&frame))),
        },
    ];
    let checksum = [
        Row {
            name: "core Checksum::update",
            secs: time(quick, || Checksum::of(black_box(&frame))),
        },
        Row {
            name: "memcpy",
            secs: time(quick, || out.copy_from_slice(black_box(&frame))),
        },
    ];
    // What handing the records to the encoder costs the caller (cloning
    // them out of the Vec), timed apart: it is inside the encoder's figure.
    let handover = time(quick, || {
        for r in black_box(&recs).iter().cloned() {
            black_box(r);
        }
    });
    if quick {
        return;
    }
    println!(
        "26DH, {RECORDS} records x {axes} axes: {len} wire bytes ({} hex digits for the crates)",
        digits.len()
    );
    report("encode", &encode, len, digits.len());
    let own = encode[0].secs - handover;
    println!(
        "  encode   (cloning the records for it: {:.3} ms of that; without it the encoder runs at {:.1} MB/s, core/hex {:.2}x)",
        handover * 1e3,
        len as f64 / own / 1e6,
        (len as f64 / own) / (digits.len() as f64 / encode[3].secs)
    );
    report("decode", &decode, len, digits.len());
    report("checksum", &checksum, len, digits.len());
    println!();
}

/// Prints MB/s of each row and the first row's speed relative to the
/// others; other rows of the core ("core ...") get their speed relative to
/// the `hex` crate's row.
fn report(what: &str, rows: &[Row], wire: usize, digits: usize) {
    let core = &rows[0];
    let hex_rate = rows
        .iter()
        .find(|r| short(r.name) == "hex")
        .map(|r| digits as f64 / r.secs);
    for row in rows {
        // The crates see only the digits; count the bytes each one touched.
        let bytes = if row.name.contains("hex") {
            digits
        } else {
            wire
        };
        let per_sec = bytes as f64 / row.secs / 1e6;
        let core_rate = wire as f64 / core.secs;
        let ratio = core_rate / (bytes as f64 / row.secs);
        let rel = if std::ptr::eq(row, core) {
            String::new()
        } else if row.name.starts_with("core") {
            hex_rate.map_or(String::new(), |h| {
                format!("  core/hex {:.2}x", wire as f64 / row.secs / h)
            })
        } else {
            format!("  core/{} {ratio:.2}x", short(row.name))
        };
        println!(
            "  {what:<8} {:<30} {per_sec:>9.1} MB/s {:>9.3} ms{rel}",
            row.name,
            row.secs * 1e3
        );
    }
}

/// The anchor's short name for the ratio column.
fn short(name: &str) -> &str {
    match name.split(':').next() {
        Some("hex") => "hex",
        Some("faster_hex") => "faster-hex",
        _ => name.split_whitespace().next().unwrap_or(name),
    }
}
