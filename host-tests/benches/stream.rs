//! Throughput of the full 1.64 MB 26DH stream (20,000 records x 8 axes):
//! the core's streaming encoder/decoder against the straightforward std
//! implementation (`host_tests::naive`), in the same run. Figures are
//! printed by divan, never asserted. Run: `cargo bench -p host-tests`.

use divan::counter::BytesCount;
use divan::{black_box, Bencher};
use host_tests::table::table;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::stream::{
    PositionStream, PositionStreamDecoder, PositionStreamEncoder, StreamEvent,
};

const RECORDS: u32 = 20_000;
const FRAME_LEN: usize = 1_640_014;

fn main() {
    divan::main();
}

fn records() -> Vec<PositionRecord> {
    table(RECORDS, 8, 42).collect()
}

#[divan::bench(name = "encode: core streaming encoder (256-byte chunks)")]
fn encode_core(b: Bencher) {
    let recs = records();
    b.counter(BytesCount::new(FRAME_LEN)).bench(|| {
        let mut enc = PositionStreamEncoder::new(
            PositionStream::CHANGE_2,
            Station(0x99),
            0,
            RECORDS as u16,
            recs.iter().cloned(),
        )
        .unwrap();
        let mut chunk = [0u8; 256];
        let mut sum = 0usize;
        loop {
            let n = enc.read(&mut chunk).unwrap();
            if n == 0 {
                break;
            }
            sum += black_box(&chunk[..n]).len();
        }
        sum
    });
}

#[divan::bench(name = "encode: naive format! into a String")]
fn encode_naive(b: Bencher) {
    let recs = records();
    b.counter(BytesCount::new(FRAME_LEN))
        .bench(|| host_tests::naive::encode_26dh(0x99, black_box(&recs)).len());
}

fn frame() -> Vec<u8> {
    host_tests::naive::encode_26dh(0x99, &records()).into_bytes()
}

#[divan::bench(name = "decode: core streaming decoder (256-byte chunks)")]
fn decode_core(b: Bencher) {
    let bytes = frame();
    b.counter(BytesCount::new(FRAME_LEN)).bench(|| {
        let mut dec = PositionStreamDecoder::new(BypassPolicy::Reject);
        let mut n = 0u32;
        for chunk in bytes.chunks(256) {
            let mut rest = chunk;
            while !rest.is_empty() {
                let (used, ev) = dec.decode(rest);
                rest = &rest[used..];
                if let StreamEvent::Record(r) = ev {
                    black_box(r);
                    n += 1;
                }
            }
        }
        n
    });
}

#[divan::bench(name = "decode: naive from_str_radix into a Vec")]
fn decode_naive(b: Bencher) {
    let text = String::from_utf8(frame()).unwrap();
    b.counter(BytesCount::new(FRAME_LEN)).bench(|| {
        host_tests::naive::decode_26dh(black_box(&text))
            .unwrap()
            .len()
    });
}
