//! The position-stream decoder (`table::PositionStreamDecoder`) and
//! encoder (`table::PositionStreamEncoder`).
//!
//! Input layout: byte 0 bit 0 picks the mode, bits 1-2 the bypass policy,
//! bits 3-5 the room of the bulk decoder's record slice (1-8); byte 1:
//! number k of chunk lengths (0-15); k chunk lengths (+1 each; the last
//! chunk takes the rest, cuts are reused cyclically).
//! - mode 0: the rest is a byte stream. Three decoders run side by side:
//!   one fed in those chunks through `decode`, one byte by byte through
//!   `push`, one in the same chunks through the bulk `decode_records` (its
//!   records and event handed out one at a time); each event of the first
//!   is compared at once with the next event of the other two (nothing is
//!   stored). Checked: no panic; the same events; `Start` at most once and
//!   first, `Record`s no more than announced and each with one coordinate
//!   per axis, `End { records }` = records seen = announced, `Error {
//!   records_ok }` = `Record` events before it; an event consumes at least
//!   one byte; `offset()` never goes back; after `End` / `Error`, `decode`,
//!   `decode_records` and `push` consume nothing (and say `Partial`) until
//!   `reset`, which zeroes `offset`, `records_done` and `records_announced`
//!   (the driver then resets and decodes the rest); `decode_records`
//!   consumes at most its input, writes at most its room, never answers
//!   `Record`, and answers `Partial` with input left only when its slice
//!   is full; at the end the three agree on `offset()` and `records_done()`.
//! - mode 1: the rest builds up to 11 records; for every kind of
//!   `PositionStream::ALL`, they are encoded by `PositionStreamEncoder`
//!   (pulled in chunks of the cut lengths), the frame has the expected
//!   length and passes `Frame::new_checked`, and the decoder (fed in
//!   chunks) gives back `Start` (kind, station, start, count), the same
//!   records in order and `End`, compared as they come.
//!
//! The decoders answer `decoder::Received { consumed, status }`
//! (`decode_records`: `table::RecordsReceived { consumed, records, status }`).
//! The harness keeps everything on the stack (records, encoded frame,
//! encoder output chunks): no allocation per input.
#![no_main]

#[path = "common/records.rs"]
mod records;

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Received, Status};
use iai_protocol_b::frame::{Frame, Station};
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::table::{PositionStreamDecoder, PositionStreamEncoder, StreamEvent};
use libfuzzer_sys::fuzz_target;
use records::Input;

/// What a finished decoder answers until `reset`.
const NOTHING: Received<StreamEvent> = Received {
    consumed: 0,
    status: Status::Partial,
};

/// Records a round trip builds at most.
const MAX_RECORDS: usize = 11;
/// The longest frame of `MAX_RECORDS` records (84-byte records plus at
/// most 20 bytes of envelope, prefix and trailer), rounded up.
const MAX_FRAME: usize = 1024;

/// Checks the per-frame event grammar.
#[derive(Default)]
struct Grammar {
    started: Option<u16>,
    records: u16,
}

impl Grammar {
    fn see(&mut self, ev: &StreamEvent) {
        match ev {
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

/// Chunk lengths from the cuts, cyclically (the whole rest without cuts).
struct Lens<'c> {
    cuts: &'c [u8],
    i: usize,
}

impl Lens<'_> {
    fn next(&mut self) -> usize {
        if self.cuts.is_empty() {
            return usize::MAX;
        }
        let c = usize::from(self.cuts[self.i % self.cuts.len()]) + 1;
        self.i += 1;
        c
    }
}

/// The byte-by-byte decoder: the next event of a stream fed through `push`
/// (reset after each final event).
struct ByByte<'s> {
    dec: PositionStreamDecoder,
    rest: &'s [u8],
}

impl ByByte<'_> {
    fn next(&mut self) -> Option<StreamEvent> {
        while let Some((&b, rest)) = self.rest.split_first() {
            self.rest = rest;
            if let Status::Complete(ev) = self.dec.push(b) {
                if is_final(&ev) {
                    // Nothing more is taken until reset.
                    assert_eq!(self.dec.push(b'!'), Status::Partial);
                    self.dec.reset();
                }
                return Some(ev);
            }
        }
        None
    }
}

/// The bulk decoder (`decode_records` into `out[..room]`), fed in the same
/// chunks, its records and events handed out one at a time.
struct Bulk<'s, 'c> {
    dec: PositionStreamDecoder,
    rest: &'s [u8],
    chunk: &'s [u8],
    lens: Lens<'c>,
    out: [PositionRecord; 8],
    room: usize,
    /// Records of the last call not handed out yet (`out[next..have]`), then
    /// its event.
    next: usize,
    have: usize,
    event: Option<StreamEvent>,
}

impl Bulk<'_, '_> {
    fn next(&mut self) -> Option<StreamEvent> {
        loop {
            if self.next < self.have {
                self.next += 1;
                return Some(StreamEvent::Record(self.out[self.next - 1].clone()));
            }
            if let Some(ev) = self.event.take() {
                if is_final(&ev) {
                    // Nothing more is taken until reset.
                    let r = self.dec.decode_records(b"!", &mut self.out[..self.room]);
                    assert_eq!((r.consumed, r.records, r.status), (0, 0, Status::Partial));
                    self.dec.reset();
                }
                return Some(ev);
            }
            if self.chunk.is_empty() {
                if self.rest.is_empty() {
                    return None;
                }
                let n = self.lens.next().min(self.rest.len());
                (self.chunk, self.rest) = self.rest.split_at(n);
            }
            let r = self
                .dec
                .decode_records(self.chunk, &mut self.out[..self.room]);
            let (k, ev) = (r.records, r.status);
            assert!(r.consumed <= self.chunk.len());
            assert!(k <= self.room, "{k} records written into {}", self.room);
            assert!(
                !matches!(ev, Status::Complete(StreamEvent::Record(_))),
                "decode_records gave a Record event"
            );
            if ev == Status::Partial {
                assert!(
                    r.consumed == self.chunk.len() || k == self.room,
                    "Partial with input left and room in out"
                );
            }
            self.chunk = &self.chunk[r.consumed..];
            self.next = 0;
            self.have = k;
            self.event = ev.complete();
        }
    }
}

fn arbitrary_stream(policy: BypassPolicy, room: usize, cuts: &[u8], stream: &[u8]) {
    let mut dec = PositionStreamDecoder::new(policy);
    let mut other = ByByte {
        dec: PositionStreamDecoder::new(policy),
        rest: stream,
    };
    let mut bulk = Bulk {
        dec: PositionStreamDecoder::new(policy),
        rest: stream,
        chunk: &[],
        lens: Lens { cuts, i: 0 },
        out: Default::default(),
        room,
        next: 0,
        have: 0,
        event: None,
    };
    let mut g = Grammar::default();
    let mut rest = stream;
    let mut lens = Lens { cuts, i: 0 };
    while !rest.is_empty() {
        let n = lens.next().min(rest.len());
        let mut chunk = &rest[..n];
        rest = &rest[n..];
        while !chunk.is_empty() {
            let before = dec.offset();
            let Received {
                consumed: used,
                status,
            } = dec.decode(chunk);
            assert!(used <= chunk.len());
            assert!(dec.offset() >= before, "offset went back");
            let Status::Complete(ev) = status else {
                assert_eq!(used, chunk.len(), "Partial with input left");
                break;
            };
            assert!(used > 0, "an event without consuming");
            g.see(&ev);
            let theirs = other.next().expect("the byte-by-byte decoder ran dry");
            assert_eq!(ev, theirs, "events depend on the chunking");
            let bulk_ev = bulk.next().expect("the bulk decoder ran dry");
            assert_eq!(ev, bulk_ev, "decode_records differs from decode");
            chunk = &chunk[used..];
            if is_final(&ev) {
                // Nothing is consumed until reset, whatever follows.
                for later in [chunk, rest, b"!"] {
                    assert_eq!(dec.decode(later), NOTHING);
                }
                assert_eq!(dec.push(b'#'), Status::Partial);
                dec.reset();
                assert_eq!(
                    (dec.offset(), dec.records_done(), dec.records_announced()),
                    (0, 0, 0)
                );
                g = Grammar::default();
            } else {
                assert_eq!(dec.records_done(), g.records);
            }
        }
    }
    assert_eq!(
        other.next(),
        None,
        "the byte-by-byte decoder has more events"
    );
    assert_eq!(bulk.next(), None, "the bulk decoder has more events");
    assert_eq!(dec.offset(), bulk.dec.offset());
    assert_eq!(dec.records_done(), bulk.dec.records_done());
    assert_eq!(dec.offset(), other.dec.offset());
    assert_eq!(dec.records_done(), other.dec.records_done());
}

fn round_trip(policy: BypassPolicy, cuts: &[u8], mut input: Input<'_>) {
    let station = Station(input.u8());
    let start_raw = input.u16();
    let n = usize::from(input.u8()) % (MAX_RECORDS + 1);
    let seed_records = input.take(400);
    for kind in PositionStream::ALL {
        let mut src = Input(seed_records);
        let recs: [PositionRecord; MAX_RECORDS] =
            std::array::from_fn(|_| records::arbitrary_record(kind.layout, &mut src));
        let recs = &recs[..n];
        let start = match kind.start_width {
            0 => 0,
            w if w >= 4 => start_raw,
            w => start_raw & ((1 << (4 * w)) - 1),
        };
        let mut enc =
            PositionStreamEncoder::new(kind, station, start, n as u16, recs.iter().cloned())
                .expect("encoder start");
        let mut frame = [0u8; MAX_FRAME];
        let mut len = 0;
        let mut lens = Lens { cuts, i: 0 };
        loop {
            let want = lens.next().min(256).min(MAX_FRAME - len);
            let got = enc
                .read(&mut frame[len..len + want])
                .expect("valid records must encode");
            assert!(got <= want);
            if got == 0 {
                assert!(want > 0, "the frame outgrew the harness buffer");
                break;
            }
            len += got;
        }
        let frame = &frame[..len];
        assert_eq!(enc.records_emitted() as usize, n);
        assert_eq!(
            frame.len(),
            kind.overhead()
                + recs
                    .iter()
                    .map(|r| kind.layout.record_len(r.axes.count()))
                    .sum::<usize>()
        );
        Frame::new_checked(frame, policy).expect("encoded frame must check");

        let mut dec = PositionStreamDecoder::new(policy);
        let mut rest = frame;
        let mut lens = Lens { cuts, i: 0 };
        // 0: Start expected, 1..=n: record i-1, n+1: End, n+2: nothing more.
        let mut at = 0usize;
        while !rest.is_empty() {
            let k = lens.next().min(rest.len());
            let Received {
                consumed: used,
                status,
            } = dec.decode(&rest[..k]);
            rest = &rest[used..];
            let Status::Complete(ev) = status else {
                assert_eq!(used, k);
                continue;
            };
            match at {
                0 => assert_eq!(
                    ev,
                    StreamEvent::Start {
                        kind,
                        station,
                        start,
                        count: n as u16,
                    },
                    "{kind:?}"
                ),
                i if i <= n => match &ev {
                    StreamEvent::Record(r) => assert_eq!(*r, recs[i - 1], "{kind:?} record {i}"),
                    other => panic!("{kind:?}: {other:?} instead of record {i}"),
                },
                i if i == n + 1 => {
                    assert_eq!(ev, StreamEvent::End { records: n as u16 }, "{kind:?}")
                }
                _ => panic!("{kind:?}: an event after End: {ev:?}"),
            }
            at += 1;
        }
        assert_eq!(at, n + 2, "{kind:?}: the frame ended early");
    }
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let config = input.u8();
    let k = usize::from(input.u8() % 16);
    let cuts = input.take(k);
    let policy = match (config >> 1) & 3 {
        0 => BypassPolicy::CommandsOnly,
        1 => BypassPolicy::Reject,
        _ => BypassPolicy::Accept,
    };
    if config & 1 == 0 {
        let room = 1 + usize::from((config >> 3) & 7);
        arbitrary_stream(policy, room, cuts, input.0);
    } else {
        round_trip(policy, cuts, input);
    }
});
