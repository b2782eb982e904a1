//! Position records: `RecordLayout::read_record` on arbitrary bytes, and
//! write -> read round trips of arbitrary records; the whole-field paths
//! (`read_record`, `read_fast`, `put_record`) against the per-field
//! reference (`read_record_per_field`, `write_record_per_field`).
//!
//! Input layout: byte 0 picks the layout (number width 0-16 from bits 0-4
//! modulo 17, extended data from bit 7); byte 1 bit 0 picks the mode:
//! 0 = read the rest as a record, 1 = build a record from the rest and
//! round-trip it.
#![no_main]

use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::error::Error;
use iai_protocol_b::field::{Reader, Writer};
use iai_protocol_b::position::{PositionRecord, RecordLayout};
use libfuzzer_sys::fuzz_target;

fn take<const K: usize>(data: &mut &[u8]) -> [u8; K] {
    let mut out = [0u8; K];
    for (o, b) in out.iter_mut().zip(data.iter()) {
        *o = *b;
    }
    *data = data.get(K..).unwrap_or(&[]);
    out
}

fn read_arbitrary(layout: RecordLayout, data: &[u8]) {
    // The whole-field path and the per-field reference agree on every
    // input: the same record and length, or the same error.
    let mut r = Reader::new(data, 0);
    let mut reference = Reader::new(data, 0);
    let got = layout.read_record(&mut r);
    assert_eq!(got, layout.read_record_per_field(&mut reference));
    if got.is_ok() {
        assert_eq!(r.remaining(), reference.remaining());
        let message_layout = matches!(
            (layout.number_width, layout.extended),
            (0 | 4, _) | (3, false)
        );
        match layout.read_fast(data) {
            Some((rec, len, sum)) => {
                assert!(message_layout);
                assert_eq!(Ok(&rec), got.as_ref());
                assert_eq!(len, data.len() - r.remaining());
                assert_eq!(sum, data[..len].iter().map(|&b| u32::from(b)).sum::<u32>());
            }
            None => assert!(!message_layout, "a message layout reads whole fields"),
        }
    }
    let mut r = Reader::new(data, 0);
    let Ok(rec) = layout.read_record(&mut r) else {
        return;
    };
    let used = data.len() - r.remaining();
    assert_eq!(used, layout.record_len(rec.axes.count()));
    assert_eq!(rec.positions.len(), rec.axes.count());
    if !layout.extended {
        assert_eq!(rec.extended, 0);
    }
    // Writing the record back gives the bytes read, hex digits upper-cased.
    let mut buf = [0u8; 128];
    let mut w = Writer::new(&mut buf);
    layout
        .write_record(&rec, &mut w)
        .expect("a record read must write");
    assert_eq!(w.written(), &data[..used].to_ascii_uppercase()[..]);
}

fn round_trip(layout: RecordLayout, mut data: &[u8]) {
    let [n0, n1, axes, a0, a1, d0, d1, s0, s1, ext, extra] = take::<11>(&mut data);
    let mut positions = PerAxis::new();
    let want = AxisPattern::from_bits(axes).count();
    // Sometimes one coordinate too many or too few.
    let count = match extra % 8 {
        0 => want.saturating_sub(1),
        1 => (want + 1).min(8),
        _ => want,
    };
    for _ in 0..count {
        let _ = positions.push(i32::from_le_bytes(take::<4>(&mut data)));
    }
    let rec = PositionRecord {
        number: u16::from_le_bytes([n0, n1]),
        axes: AxisPattern::from_bits(axes),
        acceleration: u16::from_le_bytes([a0, a1]),
        deceleration: u16::from_le_bytes([d0, d1]),
        speed: u16::from_le_bytes([s0, s1]),
        positions,
        extended: ext,
    };
    // The whole-field writer and the per-field reference write the same
    // bytes, or fail alike.
    let mut reference = [0u8; 128];
    let mut rw = Writer::new(&mut reference);
    let per_field = layout.write_record_per_field(&rec, &mut rw);
    let mut direct = [0u8; 128];
    match layout.put_record(&rec, &mut direct) {
        Ok((len, sum)) => {
            assert!(per_field.is_ok());
            assert_eq!(&direct[..len], rw.written());
            assert_eq!(
                sum,
                direct[..len].iter().map(|&b| u32::from(b)).sum::<u32>()
            );
        }
        Err(e) => assert_eq!(Err(e), per_field),
    }
    let mut buf = [0u8; 128];
    let mut w = Writer::new(&mut buf);
    let fits = layout.number_width == 0
        || layout.number_width >= 4
        || u64::from(rec.number) < 1u64 << (4 * u32::from(layout.number_width));
    match layout.write_record(&rec, &mut w) {
        Ok(()) => {
            assert!(fits && rec.positions.len() == rec.axes.count());
            assert_eq!(w.len(), layout.record_len(rec.axes.count()));
            let mut r = Reader::new(w.written(), 0);
            let back = layout
                .read_record(&mut r)
                .expect("a written record must read");
            assert_eq!(r.remaining(), 0);
            let mut expect = rec.clone();
            if layout.number_width == 0 {
                expect.number = 0;
            }
            if !layout.extended {
                expect.extended = 0;
            }
            assert_eq!(back, expect);
        }
        Err(Error::CountMismatch { expected, found }) => {
            assert_eq!((expected, found), (rec.axes.count(), rec.positions.len()));
            assert!(w.is_empty(), "a failed write must leave nothing behind");
        }
        Err(Error::ValueOutOfRange { .. }) => {
            assert!(!fits);
            assert!(w.is_empty(), "a failed write must leave nothing behind");
        }
        Err(e) => panic!("unexpected error {e:?}"),
    }
}

fuzz_target!(|data: &[u8]| {
    let [config, mode] = take::<2>(&mut &data[..]);
    let data = data.get(2..).unwrap_or(&[]);
    let layout = RecordLayout {
        number_width: (config & 0x1F) % 17,
        extended: config & 0x80 != 0,
    };
    if mode & 1 == 0 {
        read_arbitrary(layout, data);
    } else {
        round_trip(layout, data);
    }
});
