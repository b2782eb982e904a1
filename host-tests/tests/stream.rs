//! Streaming encode/decode of position tables, checked against the typed
//! (whole-frame) path.

use host_tests::table::table;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::error::Error;
use iai_protocol_b::frame::{Frame, Station};
use iai_protocol_b::message::{ChangePositionData2, Message, Repeated};
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::{PositionStreamDecoder, PositionStreamEncoder, StreamEvent};

fn encode_all(kind: PositionStream, recs: &[PositionRecord], chunk: usize) -> Vec<u8> {
    let mut enc = PositionStreamEncoder::new(
        kind,
        Station(0x99),
        0,
        recs.len() as u16,
        recs.iter().cloned(),
    )
    .unwrap();
    let mut out = Vec::new();
    let mut buf = vec![0u8; chunk];
    loop {
        let n = enc.read(&mut buf).unwrap();
        if n == 0 {
            break;
        }
        out.extend_from_slice(&buf[..n]);
    }
    out
}

fn decode_all(bytes: &[u8]) -> (Vec<PositionRecord>, Option<StreamEvent>) {
    let mut dec = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
    let mut recs = Vec::new();
    let mut rest = bytes;
    while !rest.is_empty() {
        let r = dec.decode(rest);
        let (used, ev) = (r.consumed, r.status.complete());
        rest = &rest[used..];
        match ev {
            Some(StreamEvent::Record(r)) => recs.push(r),
            None | Some(StreamEvent::Start { .. }) => {}
            Some(other) => return (recs, Some(other)),
        }
    }
    (recs, None)
}

#[test]
fn streamed_26dh_equals_the_typed_frame() {
    let recs: Vec<_> = table(24, 8, 1).collect();
    let streamed = encode_all(PositionStream::CHANGE_2, &recs, 7);
    let typed = ChangePositionData2 {
        records: Repeated::from_slice(&recs),
    };
    let mut buf = vec![0u8; 4096];
    let n = typed.emit(Station(0x99), &mut buf).unwrap();
    assert_eq!(streamed, &buf[..n]);
    let frame = Frame::new_checked(&streamed, BypassPolicy::Reject).unwrap();
    let parsed = ChangePositionData2::parse(&frame).unwrap();
    assert!(parsed.records.iter().eq(recs.iter().cloned()));
}

#[test]
fn example_6_2_two_records_of_different_length() {
    let recs = [
        PositionRecord::new(1, 30, 30, 100, &[(1, 100_000), (2, -25_500)]).unwrap(),
        PositionRecord::new(2, 0, 0, 0, &[(1, 12_345)]).unwrap(),
    ];
    let wire = b"!9926D0002000103001E001E0064000186A0FFFF9C64000201000000000000000030392B\r\n";
    assert_eq!(encode_all(PositionStream::CHANGE_2, &recs, 1), wire);
    let (got, end) = decode_all(wire);
    assert_eq!(got, recs);
    assert_eq!(end, Some(StreamEvent::End { records: 2 }));
}

#[test]
fn full_size_table_round_trips_through_fixed_buffers() {
    let recs: Vec<_> = table(20_000, 8, 7).collect();
    let bytes = encode_all(PositionStream::CHANGE_2, &recs, 512);
    assert_eq!(bytes.len(), 1_640_014);
    let (got, end) = decode_all(&bytes);
    assert_eq!(end, Some(StreamEvent::End { records: 20_000 }));
    assert!(got == recs);
}

#[test]
fn every_position_stream_round_trips() {
    for kind in PositionStream::ALL {
        let mut recs: Vec<_> = table(12, 3, 3).collect();
        for r in &mut recs {
            if kind.layout.number_width == 0 {
                r.number = 0;
            }
            if kind.layout.number_width == 3 {
                r.number %= 0x1000;
            }
            if kind.layout.extended {
                r.extended = 0x5A;
            }
        }
        let bytes = encode_all(kind, &recs, 33);
        let (got, end) = decode_all(&bytes);
        assert_eq!(end, Some(StreamEvent::End { records: 12 }), "{kind:?}");
        assert_eq!(got, recs, "{kind:?}");
    }
}

#[test]
fn corruption_reports_the_records_that_were_well_formed() {
    let recs: Vec<_> = table(100, 4, 5).collect();
    let mut bytes = encode_all(PositionStream::CHANGE_2, &recs, 64);
    // Record k starts at 10 + 50k; put a non-hex byte inside record 40.
    bytes[10 + 50 * 40 + 20] = b'G';
    let (got, end) = decode_all(&bytes);
    assert_eq!(got.len(), 40);
    match end {
        Some(StreamEvent::Error {
            error: Error::InvalidHexDigit { offset, byte: b'G' },
            records_ok: 40,
        }) => {
            assert_eq!(offset, 10 + 50 * 40 + 20)
        }
        other => panic!("{other:?}"),
    }
    // A changed digit that stays hex is only caught by SC at the end.
    let mut bytes = encode_all(PositionStream::CHANGE_2, &recs, 64);
    bytes[10 + 50 * 60 + 20] ^= 0x01;
    let (got, end) = decode_all(&bytes);
    assert_eq!(got.len(), 100);
    assert!(matches!(
        end,
        Some(StreamEvent::Error {
            error: Error::ChecksumMismatch { .. },
            records_ok: 100
        })
    ));
}

#[test]
fn a_short_source_is_an_error_not_a_short_frame() {
    let recs: Vec<_> = table(3, 2, 1).collect();
    let mut enc = PositionStreamEncoder::new(
        PositionStream::CHANGE_2,
        Station(0x99),
        0,
        5,
        recs.into_iter(),
    )
    .unwrap();
    let mut buf = [0u8; 4096];
    assert_eq!(
        enc.read(&mut buf),
        Err(Error::CountMismatch {
            expected: 5,
            found: 3
        })
    );
}
