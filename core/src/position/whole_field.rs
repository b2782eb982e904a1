//! The record codec whole fields at a time, for the number widths of the
//! messages (0, 3 and 4 digits, with or without extended data): fixed
//! offsets and the word-at-a-time digit tables of [`crate::hex`]. Records
//! of other widths fall back to the field-at-a-time path of
//! [`RecordLayout`], which the tests below hold this one to.

use super::{PositionRecord, RecordLayout};
use crate::axis::{AxisPattern, MAX_AXES};
use crate::error::{Error, Result};
use crate::field::Writer;
use crate::hex;

/// The number of axes of every axis pattern (a table: the M4 has no
/// population count instruction).
// Indexing in a const initialiser is checked at compile time: it cannot panic at run time.
#[allow(clippy::indexing_slicing)]
static AXIS_COUNT: [u8; 256] = {
    let mut t = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        t[i] = (i as u8).count_ones() as u8;
        i += 1;
    }
    t
};

/// The number of axes of `axes`, from [`AXIS_COUNT`].
#[inline(always)]
pub(crate) fn axis_count(axes: AxisPattern) -> usize {
    usize::from(
        AXIS_COUNT
            .get(usize::from(axes.bits()))
            .copied()
            .unwrap_or(0),
    )
}

/// A fixed-size piece of `b` at offset `at` (`None` if `b` is too short:
/// with constant offsets into an array the check disappears).
#[inline(always)]
fn piece<const N: usize>(b: &[u8], at: usize) -> Option<&[u8; N]> {
    b.get(at..at + N)?.try_into().ok()
}

#[inline(always)]
fn piece_mut<const N: usize>(b: &mut [u8], at: usize) -> Option<&mut [u8; N]> {
    b.get_mut(at..at + N)?.try_into().ok()
}

/// The `NW` of [`put_as`] for a layout written a field at a time.
pub(crate) const PER_FIELD: usize = usize::MAX;

/// [`RecordLayout::put_record`] for `layout` with its shape known at
/// compile time: `NW` digits of number (0, 3 or 4), `HEAD` = `NW` + 14
/// bytes before the coordinates, `EXT` extended data; or `NW` =
/// [`PER_FIELD`] for any other layout. A loop over many records picks the
/// shape once, outside.
#[inline(always)]
pub(crate) fn put_as<const NW: usize, const HEAD: usize, const EXT: bool>(
    layout: RecordLayout,
    rec: &PositionRecord,
    out: &mut [u8],
) -> Result<(usize, u32)> {
    let len = len_as::<NW, HEAD, EXT>(layout, rec)?;
    let out = out.get_mut(..len).ok_or(Error::BufferTooSmall)?;
    Ok((len, put_exact::<NW, HEAD, EXT>(layout, rec, out)?))
}

/// The wire length of `rec` in `layout` (the shape of [`put_as`]), once
/// its coordinates are checked against its axis pattern.
#[inline(always)]
pub(crate) fn len_as<const NW: usize, const HEAD: usize, const EXT: bool>(
    layout: RecordLayout,
    rec: &PositionRecord,
) -> Result<usize> {
    let n = axis_count(rec.axes);
    if rec.positions.len() != n {
        return Err(Error::CountMismatch {
            expected: n,
            found: rec.positions.len(),
        });
    }
    Ok(if NW == PER_FIELD {
        layout.record_len(n)
    } else {
        HEAD + 8 * n + if EXT { 2 } else { 0 }
    })
}

/// [`put_as`] into `out` of exactly [`len_as`] bytes; the sum of the
/// bytes written.
#[inline(always)]
pub(crate) fn put_exact<const NW: usize, const HEAD: usize, const EXT: bool>(
    layout: RecordLayout,
    rec: &PositionRecord,
    out: &mut [u8],
) -> Result<u32> {
    let fast = if NW == PER_FIELD {
        None
    } else {
        put_fixed::<NW, HEAD, EXT>(rec, out)
    };
    match fast {
        Some(r) => r,
        None => {
            let mut w = Writer::new(out);
            layout.write_record_per_field(rec, &mut w)?;
            Ok(w.written().iter().map(|&b| u32::from(b)).sum())
        }
    }
}

/// The whole-field path of [`put_as`] for one layout: `NW` digits of number (0, 3
/// or 4), `HEAD` = `NW` + 14 bytes before the coordinates; `out` is exactly the record.
#[inline(always)]
fn put_fixed<const NW: usize, const HEAD: usize, const EXT: bool>(
    rec: &PositionRecord,
    out: &mut [u8],
) -> Option<Result<u32>> {
    let (head, rest) = out.split_first_chunk_mut::<HEAD>()?;
    let mut sum = match NW {
        4 => hex::put4(rec.number, piece_mut::<4>(head, 0)?),
        3 => {
            if rec.number > 0xFFF {
                return Some(Err(Error::ValueOutOfRange { offset: 0 }));
            }
            let mut four = [0u8; 4];
            let s = hex::put4(rec.number, &mut four);
            let [_, a, b, c] = four;
            *piece_mut::<3>(head, 0)? = [a, b, c];
            s - u32::from(b'0')
        }
        _ => 0,
    };
    sum += hex::put2(rec.axes.bits(), piece_mut::<2>(head, NW)?);
    sum += hex::put4(rec.acceleration, piece_mut::<4>(head, NW + 2)?);
    sum += hex::put4(rec.deceleration, piece_mut::<4>(head, NW + 6)?);
    sum += hex::put4(rec.speed, piece_mut::<4>(head, NW + 10)?);
    let mut coords = rest.chunks_exact_mut(8);
    for (&p, d) in rec.positions.iter().zip(&mut coords) {
        sum += hex::put8(p as u32, d.try_into().ok()?);
    }
    if EXT {
        sum += hex::put2(rec.extended, coords.into_remainder().try_into().ok()?);
    }
    Some(Ok(sum))
}

/// [`RecordLayout::read_fast`] for one layout (see [`put_fixed`]).
#[inline(always)]
pub(super) fn read_fixed<const NW: usize, const HEAD: usize, const EXT: bool>(
    bytes: &[u8],
) -> Option<(PositionRecord, usize, u32)> {
    let mut rec = PositionRecord::default();
    let (len, sum) = read_into::<NW, HEAD, EXT, false, hex::Batch>(bytes, &mut rec)?;
    Some((rec, len, sum))
}

/// [`read_fixed`] into a record the caller holds: every field of `rec`
/// is overwritten, in place. `Some((length, sum))` for a complete,
/// well-formed record, the sum of its bytes as `D` keeps it (exact with
/// [`hex::Batch`], its low byte with [`hex::ModBatch`]); on `None`, `rec`
/// holds whatever was decoded before the check (meaningless, but a valid
/// record).
///
/// `RUN`: the record is one of a run ([`read_run`]); a record of one axis
/// then decodes its coordinate without the loop, which the icount bench
/// (`cargo run -p host-tests --bin icount`) shows saves a tenth of the
/// run's instructions for one-axis tables, and costs a record decoded on
/// its own more than it saves.
#[inline(always)]
pub(crate) fn read_into<const NW: usize, const HEAD: usize, const EXT: bool, const RUN: bool, D>(
    bytes: &[u8],
    rec: &mut PositionRecord,
) -> Option<(usize, u32)>
where
    D: hex::Digits + Default,
{
    let (head, rest) = bytes.split_first_chunk::<HEAD>()?;
    let mut b = D::default();
    let axes = AxisPattern::from_bits(b.decode2(piece::<2>(head, NW)?));
    // At most 8 (said again for the optimiser: the loop below then runs at
    // most 8 times, and is laid out straight rather than unrolled by 4).
    let n = axis_count(axes).min(MAX_AXES);
    let tail = 8 * n + if EXT { 2 } else { 0 };
    let rest = rest.get(..tail)?;
    rec.number = match NW {
        4 => b.decode4(piece::<4>(head, 0)?),
        3 => b.decode3(piece::<3>(head, 0)?),
        _ => 0,
    };
    rec.axes = axes;
    rec.acceleration = b.decode4(piece::<4>(head, NW + 2)?);
    rec.deceleration = b.decode4(piece::<4>(head, NW + 6)?);
    rec.speed = b.decode4(piece::<4>(head, NW + 10)?);
    rec.positions.clear();
    let mut coords = rest.chunks_exact(8);
    if RUN && n == 1 {
        // One axis: no loop to set up.
        let d = coords.next()?;
        let _ = rec.positions.push(b.decode8(d.try_into().ok()?) as i32);
    }
    for d in &mut coords {
        // At most 8 axes: the push cannot fail.
        let _ = rec.positions.push(b.decode8(d.try_into().ok()?) as i32);
    }
    rec.extended = if EXT {
        b.decode2(coords.remainder().try_into().ok()?)
    } else {
        0
    };
    if !b.is_valid() {
        return None;
    }
    Some((HEAD + tail, b.sum()))
}

/// [`RecordLayout::read_records`] for one layout (see [`put_fixed`]).
#[inline(always)]
pub(super) fn read_run<const NW: usize, const HEAD: usize, const EXT: bool>(
    bytes: &[u8],
    out: &mut [PositionRecord],
) -> (usize, usize, u32) {
    let mut rest = bytes;
    let mut n = 0;
    let mut sum = 0u32;
    for rec in out.iter_mut() {
        let Some((len, s)) = read_into::<NW, HEAD, EXT, true, hex::ModBatch>(rest, rec) else {
            break;
        };
        rest = rest.get(len..).unwrap_or(&[]);
        n += 1;
        sum = sum.wrapping_add(s);
    }
    (bytes.len() - rest.len(), n, sum)
}

/// The whole-field record codec against the per-field reference.
#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::axis::PerAxis;
    use crate::field::Reader;

    const LAYOUTS: [RecordLayout; 5] = [
        RecordLayout::NUMBER_3,
        RecordLayout::NUMBER_4,
        RecordLayout::NUMBER_4_EXTENDED,
        RecordLayout::RANGE,
        RecordLayout::RANGE_EXTENDED,
    ];

    fn xorshift(seed: u32) -> impl FnMut() -> u32 {
        let mut x = seed | 1;
        move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        }
    }

    /// A record every field of which fits `layout`.
    fn record(layout: RecordLayout, next: &mut impl FnMut() -> u32) -> PositionRecord {
        let axes = AxisPattern::from_bits(next() as u8);
        let mut positions = PerAxis::new();
        for _ in 0..axes.count() {
            positions.push(next() as i32).unwrap();
        }
        let number = match layout.number_width {
            0 => 0,
            3 => (next() & 0xFFF) as u16,
            _ => next() as u16,
        };
        let extended = if layout.extended { next() as u8 } else { 0 };
        PositionRecord {
            number,
            axes,
            acceleration: next() as u16,
            deceleration: next() as u16,
            speed: next() as u16,
            positions,
            extended,
        }
    }

    fn per_field(layout: RecordLayout, rec: &PositionRecord) -> ([u8; 128], usize) {
        let mut buf = [0u8; 128];
        let mut w = Writer::new(&mut buf);
        layout.write_record_per_field(rec, &mut w).unwrap();
        let n = w.len();
        (buf, n)
    }

    #[test]
    fn golden_26dh_record() {
        let rec = PositionRecord::new(1, 30, 30, 100, &[(1, 100_000), (2, -25_500)]).unwrap();
        let mut out = [0u8; 40];
        let (len, sum) = RecordLayout::NUMBER_4.put_record(&rec, &mut out).unwrap();
        let wire = b"000103001E001E0064000186A0FFFF9C64";
        assert_eq!(&out[..len], wire);
        assert_eq!(sum, wire.iter().map(|&b| u32::from(b)).sum::<u32>());
        let (back, n, s) = RecordLayout::NUMBER_4.read_fast(wire).unwrap();
        assert_eq!((back, n, s), (rec, wire.len(), sum));
    }

    #[test]
    fn both_paths_agree_on_every_layout() {
        let mut next = xorshift(11);
        for layout in LAYOUTS {
            for _ in 0..400 {
                let rec = record(layout, &mut next);
                let (reference, n) = per_field(layout, &rec);
                let wire = &reference[..n];
                let mut out = [0u8; 128];
                let (len, sum) = layout.put_record(&rec, &mut out).unwrap();
                assert_eq!(&out[..len], wire, "{layout:?} {rec:?}");
                assert_eq!(sum & 0xFF, u32::from(hex::sum_bytewise(0, wire)));
                let mut buf = [0u8; 128];
                let mut w = Writer::new(&mut buf);
                layout.write_record(&rec, &mut w).unwrap();
                assert_eq!(w.written(), wire);

                // Read back, in both cases, with bytes after the record.
                let mut lower = [b'Z'; 130];
                lower[..n].copy_from_slice(wire);
                lower[..n].make_ascii_lowercase();
                for bytes in [&reference[..n + 2], &lower[..]] {
                    let (back, used, s) = layout.read_fast(bytes).unwrap();
                    assert_eq!((&back, used), (&rec, n));
                    assert_eq!(s, bytes[..n].iter().map(|&b| u32::from(b)).sum::<u32>());
                    let mut r = Reader::new(bytes, 0);
                    assert_eq!(layout.read_record_per_field(&mut r).as_ref(), Ok(&rec));
                    let mut r = Reader::new(bytes, 0);
                    assert_eq!(layout.read_record(&mut r).as_ref(), Ok(&rec));
                    assert_eq!(r.offset(), n);
                }
            }
        }
    }

    /// Every cut and every bad byte: no record from the fast path, and
    /// `read_record` reports what the per-field path reports.
    #[test]
    fn malformed_records_give_the_per_field_error() {
        let mut next = xorshift(5);
        for layout in LAYOUTS {
            for _ in 0..20 {
                let rec = record(layout, &mut next);
                let (wire, n) = per_field(layout, &rec);
                let same_error = |bytes: &[u8]| {
                    let mut a = Reader::new(bytes, 7);
                    let mut b = Reader::new(bytes, 7);
                    let fast = layout.read_record(&mut a);
                    assert!(fast.is_err());
                    assert_eq!(fast, layout.read_record_per_field(&mut b));
                };
                for cut in 0..n {
                    assert!(layout.read_fast(&wire[..cut]).is_none());
                    same_error(&wire[..cut]);
                }
                for at in 0..n {
                    for bad in [b'G', b'g', b' ', b'/', b':', b'@', 0x00, 0xFF] {
                        let mut w = wire;
                        w[at] = bad;
                        match layout.read_fast(&w[..n]) {
                            // A bad axis-pattern byte can shorten the record
                            // only if the pattern still decodes: it cannot.
                            Some(_) => panic!("{layout:?}: {bad:#04X} at {at} accepted"),
                            None => same_error(&w[..n]),
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn refusals() {
        let mut rec = PositionRecord::new(0x1000, 1, 2, 3, &[(3, -1)]).unwrap();
        let mut buf = [b'.'; 40];
        let mut w = Writer::new(&mut buf);
        w.put(b"!99").unwrap();
        assert_eq!(
            RecordLayout::NUMBER_3.write_record(&rec, &mut w),
            Err(Error::ValueOutOfRange { offset: 3 })
        );
        assert_eq!(w.written(), b"!99", "nothing of the record stays");
        let mut out = [0u8; 40];
        assert_eq!(
            RecordLayout::NUMBER_3.put_record(&rec, &mut out),
            Err(Error::ValueOutOfRange { offset: 0 })
        );
        rec.number = 0xFFF;
        assert_eq!(
            RecordLayout::NUMBER_3
                .put_record(&rec, &mut out)
                .map(|r| r.0),
            Ok(25)
        );
        assert_eq!(&out[..3], b"FFF");
        assert_eq!(
            RecordLayout::NUMBER_3.put_record(&rec, &mut out[..24]),
            Err(Error::BufferTooSmall)
        );
        rec.positions.push(7).unwrap();
        assert_eq!(
            RecordLayout::NUMBER_4.put_record(&rec, &mut out),
            Err(Error::CountMismatch {
                expected: 1,
                found: 2
            })
        );
    }

    /// A run of records and its wire bytes, with where each record ends.
    fn run(
        layout: RecordLayout,
        count: usize,
        next: &mut impl FnMut() -> u32,
    ) -> (
        std::vec::Vec<PositionRecord>,
        std::vec::Vec<u8>,
        std::vec::Vec<usize>,
    ) {
        let mut recs = std::vec::Vec::new();
        let mut wire = std::vec::Vec::new();
        let mut ends = std::vec::Vec::new();
        for _ in 0..count {
            let mut rec = record(RecordLayout::NUMBER_4_EXTENDED, next);
            let width = u32::from(layout.number_width);
            if width < 4 {
                rec.number &= ((1u32 << (4 * width)) - 1) as u16;
            }
            if !layout.extended {
                rec.extended = 0;
            }
            let (bytes, n) = per_field(layout, &rec);
            wire.extend_from_slice(&bytes[..n]);
            ends.push(wire.len());
            recs.push(rec);
        }
        (recs, wire, ends)
    }

    fn low_sum(bytes: &[u8]) -> u8 {
        bytes.iter().fold(0u8, |s, &b| s.wrapping_add(b))
    }

    /// `read_records` against `read_record`, record after record: whole
    /// runs into arrays of every size, runs cut anywhere, runs with a bad
    /// byte anywhere; both cases of digits.
    #[test]
    fn runs_of_records_read_in_place() {
        let mut next = xorshift(17);
        let other = RecordLayout {
            number_width: 5,
            extended: true,
        };
        for layout in LAYOUTS.into_iter().chain([other]) {
            for round in 0..30 {
                let count = 1 + round % 6;
                let (recs, mut wire, ends) = run(layout, count, &mut next);
                if round % 2 == 1 {
                    wire.make_ascii_lowercase();
                }
                // Whole runs, into every size of array (stale contents).
                for room in 0..=count + 1 {
                    let mut out = std::vec![record(layout, &mut next); room];
                    let (used, n, sum) = layout.read_records(&wire, &mut out);
                    let want = room.min(count);
                    let end = if want == 0 { 0 } else { ends[want - 1] };
                    assert_eq!((used, n), (end, want), "{layout:?} room {room}");
                    assert_eq!(&out[..n], &recs[..n]);
                    assert_eq!(sum as u8, low_sum(&wire[..used]));
                }
                // Cut anywhere: the whole records before the cut.
                let mut out = std::vec![PositionRecord::default(); count];
                for cut in 0..wire.len() {
                    let whole = ends.iter().filter(|&&e| e <= cut).count();
                    let (used, n, sum) = layout.read_records(&wire[..cut], &mut out);
                    let end = if whole == 0 { 0 } else { ends[whole - 1] };
                    assert_eq!((used, n), (end, whole), "{layout:?} cut {cut}");
                    assert_eq!(&out[..n], &recs[..n]);
                    assert_eq!(sum as u8, low_sum(&wire[..used]));
                }
                // A bad byte anywhere: the records before its record.
                for at in (0..wire.len()).step_by(3) {
                    for bad in [b'G', b'/', b':', b'@', b'`', b'g', 0x80, b'\n'] {
                        let mut w = wire.clone();
                        w[at] = bad;
                        let before = ends.iter().filter(|&&e| e <= at).count();
                        let (used, n, _) = layout.read_records(&w, &mut out);
                        let end = if before == 0 { 0 } else { ends[before - 1] };
                        assert_eq!((used, n), (end, before), "{layout:?} {bad:#04X} at {at}");
                        assert_eq!(&out[..n], &recs[..n]);
                        // What the one-record path says of the rest.
                        let mut r = Reader::new(&w[used..], 0);
                        assert!(layout.read_record(&mut r).is_err());
                    }
                }
            }
        }
    }

    /// The stream decoder's in-place reader: what `read_fast` reads, with
    /// the low byte of the sum; nothing of a malformed record.
    #[test]
    fn in_place_reads_agree_with_read_fast() {
        let mut next = xorshift(23);
        for layout in LAYOUTS {
            for _ in 0..200 {
                let rec = record(layout, &mut next);
                let (wire, n) = per_field(layout, &rec);
                let mut got = record(layout, &mut next);
                let (len, sum) = layout.read_in_place(&wire[..n + 3], &mut got).unwrap();
                assert_eq!((&got, len), (&rec, n));
                assert_eq!(sum as u8, low_sum(&wire[..n]));
                for cut in 0..n {
                    assert_eq!(layout.read_in_place(&wire[..cut], &mut got), None);
                }
                for at in 0..n {
                    let mut w = wire;
                    w[at] = b'x';
                    assert_eq!(layout.read_in_place(&w[..n], &mut got), None, "{at}");
                }
            }
        }
        let mut got = PositionRecord::default();
        let odd = RecordLayout {
            number_width: 2,
            extended: false,
        };
        assert_eq!(
            odd.read_in_place(b"0101000000000000000000000000", &mut got),
            None
        );
    }

    /// Number widths no message uses still work, a digit at a time.
    #[test]
    fn other_number_widths_take_the_per_field_path() {
        let mut next = xorshift(9);
        for width in [1u8, 2, 5, 8, 16] {
            let layout = RecordLayout {
                number_width: width,
                extended: width % 2 == 0,
            };
            for _ in 0..50 {
                let mut rec = record(RecordLayout::NUMBER_4_EXTENDED, &mut next);
                if width < 4 {
                    rec.number &= (1 << (4 * width)) - 1;
                }
                if !layout.extended {
                    rec.extended = 0;
                }
                let (wire, n) = per_field(layout, &rec);
                let mut out = [0u8; 128];
                let (len, sum) = layout.put_record(&rec, &mut out).unwrap();
                assert_eq!(&out[..len], &wire[..n]);
                assert_eq!(sum, wire[..n].iter().map(|&b| u32::from(b)).sum::<u32>());
                assert!(layout.read_fast(&wire[..n]).is_none());
                let mut r = Reader::new(&wire[..n], 0);
                assert_eq!(layout.read_record(&mut r), Ok(rec));
            }
        }
    }

    #[test]
    fn axis_counts() {
        for bits in 0..=255u8 {
            let p = AxisPattern::from_bits(bits);
            assert_eq!(axis_count(p), p.count());
        }
    }
}
