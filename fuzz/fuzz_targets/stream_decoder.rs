//! The position-stream decoder (`stream::PositionStreamDecoder`).
//!
//! Input layout: byte 0 bit 0 picks the mode, bits 1-2 the bypass policy;
//! byte 1: number k of chunk lengths (0-15); k chunk lengths (+1 each; the
//! last chunk takes the rest, cuts are reused cyclically).
//! - mode 0: the rest is a byte stream. Checked: no panic; the same events
//!   whether fed in those chunks through `decode` or byte by byte through
//!   `push`; `Start` at most once and first, `Record`s no more than
//!   announced, `End { records }` = records seen = announced, `Error {
//!   records_ok }` = `Record` events before it; after `End` / `Error`,
//!   `decode` consumes nothing (and says `NeedMore`) until `reset` (the
//!   driver then resets and decodes the rest of the stream).
//! - mode 1: the rest builds records; for every kind of
//!   `PositionStream::ALL`, they are encoded by `PositionStreamEncoder`
//!   (pulled in chunks), the frame passes `Frame::new_checked`, and the
//!   decoder (fed in chunks) gives back `Start`, the same records and `End`.
#![no_main]

#[path = "common/records.rs"]
mod records;

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::frame::{Frame, Station};
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::stream::{
    PositionStream, PositionStreamDecoder, PositionStreamEncoder, StreamEvent,
};
use libfuzzer_sys::fuzz_target;
use records::Input;

/// Checks the per-frame event grammar; returns the events.
#[derive(Default)]
struct Grammar {
    started: Option<u16>,
    records: u16,
}

impl Grammar {
    fn see(&mut self, ev: &StreamEvent) {
        match ev {
            StreamEvent::NeedMore => panic!("NeedMore is not an event"),
            StreamEvent::Start { kind, count, .. } => {
                assert!(self.started.is_none(), "two Start events in one frame");
                assert_eq!(self.records, 0);
                assert!(*count <= kind.max_records);
                assert!(PositionStream::ALL.contains(kind));
                self.started = Some(*count);
            }
            StreamEvent::Record(rec) => {
                let announced = self.started.expect("Record before Start");
                assert!(self.records < announced, "more records than announced");
                assert_eq!(rec.positions.len(), rec.axes.count());
                self.records += 1;
            }
            StreamEvent::End { records } => {
                assert_eq!(*records, self.records);
                assert_eq!(Some(*records), self.started, "End before every record came");
            }
            StreamEvent::Error { records_ok, .. } => {
                assert_eq!(
                    *records_ok, self.records,
                    "records_ok differs from the Record events"
                );
            }
        }
    }
}

fn is_final(ev: &StreamEvent) -> bool {
    matches!(ev, StreamEvent::End { .. } | StreamEvent::Error { .. })
}

fn chunk_lens<'c>(cuts: &'c [u8]) -> impl Iterator<Item = usize> + 'c {
    let mut i = 0;
    std::iter::from_fn(move || {
        if cuts.is_empty() {
            return Some(usize::MAX);
        }
        let c = cuts[i % cuts.len()] as usize + 1;
        i += 1;
        Some(c)
    })
}

/// Feeds `stream` in chunks; after a final event checks that nothing more
/// is consumed, then resets. Returns the events.
fn chunked(policy: BypassPolicy, cuts: &[u8], stream: &[u8]) -> Vec<StreamEvent> {
    let mut dec = PositionStreamDecoder::new(policy);
    let mut g = Grammar::default();
    let mut out = Vec::new();
    let mut rest = stream;
    let mut lens = chunk_lens(cuts);
    while !rest.is_empty() {
        let n = lens.next().unwrap().min(rest.len());
        let mut chunk = &rest[..n];
        rest = &rest[n..];
        while !chunk.is_empty() {
            let before = dec.offset();
            let (used, ev) = dec.decode(chunk);
            assert!(used <= chunk.len());
            assert!(dec.offset() >= before);
            if ev == StreamEvent::NeedMore {
                assert_eq!(used, chunk.len(), "NeedMore with input left");
                break;
            }
            g.see(&ev);
            chunk = &chunk[used..];
            if is_final(&ev) {
                // Nothing is consumed until reset, whatever follows.
                assert_eq!(dec.decode(chunk), (0, StreamEvent::NeedMore));
                assert_eq!(dec.decode(rest), (0, StreamEvent::NeedMore));
                assert_eq!(dec.decode(b"!"), (0, StreamEvent::NeedMore));
                assert_eq!(dec.push(b'#'), StreamEvent::NeedMore);
                dec.reset();
                assert_eq!(
                    (dec.offset(), dec.records_done(), dec.records_announced()),
                    (0, 0, 0)
                );
                g = Grammar::default();
            } else {
                assert!(used > 0, "an event without consuming");
            }
            out.push(ev);
        }
    }
    out
}

fn by_byte(policy: BypassPolicy, stream: &[u8]) -> Vec<StreamEvent> {
    let mut dec = PositionStreamDecoder::new(policy);
    let mut out = Vec::new();
    for &b in stream {
        let ev = dec.push(b);
        if ev != StreamEvent::NeedMore {
            if is_final(&ev) {
                dec.reset();
            }
            out.push(ev);
        }
    }
    out
}

fn arbitrary_stream(policy: BypassPolicy, cuts: &[u8], stream: &[u8]) {
    let a = chunked(policy, cuts, stream);
    let b = by_byte(policy, stream);
    assert_eq!(a, b, "events depend on the chunking");
}

fn round_trip(policy: BypassPolicy, cuts: &[u8], mut input: Input<'_>) {
    let station = Station(input.u8());
    let start_raw = input.u16();
    let n = usize::from(input.u8() % 12);
    let seed_records: Vec<u8> = input.take(400).to_vec();
    for kind in PositionStream::ALL {
        let mut src = Input(&seed_records);
        let recs: Vec<PositionRecord> = (0..n)
            .map(|_| records::arbitrary_record(kind.layout, &mut src))
            .collect();
        let start = match kind.start_width {
            0 => 0,
            w if w >= 4 => start_raw,
            w => start_raw & ((1 << (4 * w)) - 1),
        };
        let mut enc =
            PositionStreamEncoder::new(kind, station, start, n as u16, recs.clone().into_iter())
                .expect("encoder start");
        let mut frame = Vec::new();
        let mut lens = chunk_lens(cuts);
        loop {
            let want = lens.next().unwrap().min(256);
            let mut buf = vec![0u8; want];
            let got = enc.read(&mut buf).expect("valid records must encode");
            if got == 0 {
                break;
            }
            frame.extend_from_slice(&buf[..got]);
        }
        assert_eq!(enc.records_emitted() as usize, n);
        assert_eq!(
            frame.len(),
            kind.overhead()
                + recs
                    .iter()
                    .map(|r| kind.layout.record_len(r.axes.count()))
                    .sum::<usize>()
        );
        Frame::new_checked(&frame, policy).expect("encoded frame must check");

        let mut dec = PositionStreamDecoder::new(policy);
        let mut events = Vec::new();
        let mut rest = &frame[..];
        let mut lens = chunk_lens(cuts);
        while !rest.is_empty() {
            let k = lens.next().unwrap().min(rest.len());
            let (used, ev) = dec.decode(&rest[..k]);
            rest = &rest[used..];
            if ev != StreamEvent::NeedMore {
                events.push(ev);
            }
        }
        let mut expect = vec![StreamEvent::Start {
            kind,
            station,
            start,
            count: n as u16,
        }];
        expect.extend(recs.iter().cloned().map(StreamEvent::Record));
        expect.push(StreamEvent::End { records: n as u16 });
        assert_eq!(events, expect, "{kind:?}");
    }
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let config = input.u8();
    let k = usize::from(input.u8() % 16);
    let cuts = input.take(k).to_vec();
    let policy = match (config >> 1) & 3 {
        0 => BypassPolicy::CommandsOnly,
        1 => BypassPolicy::Reject,
        _ => BypassPolicy::Accept,
    };
    if config & 1 == 0 {
        arbitrary_stream(policy, &cuts, input.0);
    } else {
        round_trip(policy, &cuts, input);
    }
});
