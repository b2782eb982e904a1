//! The wire layout of a position record in one message ([`RecordLayout`]):
//! its field widths, reading and writing a record, and showing it to a
//! [`Visitor`]. Layouts of the messages' shapes take the whole-field path
//! ([`super::whole_field`]); the field-at-a-time path here is for other
//! number widths, names the offending byte of a malformed record, and is
//! the reference the whole-field path is tested against.

use super::whole_field::{put_as, read_fixed, read_into, read_run, PER_FIELD};
use super::PositionRecord;
use crate::axis::{AxisPattern, PerAxis, MAX_AXES};
use crate::codec::{inspect_items, FieldCodec, GroupInfo, Inspect, Value, Visitor};
use crate::error::{Error, Result};
use crate::field::{decode_unsigned, FieldSpec, Reader, Writer};
use crate::hex;

/// The wire layout of a position record in one particular message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RecordLayout {
    /// Width of the position-number field; 0 = no number on the wire.
    pub number_width: u8,
    /// Whether each record ends with a 2-hex-digit extended-data byte.
    pub extended: bool,
}

const AXES: FieldSpec = FieldSpec::hex(2);
const WORD: FieldSpec = FieldSpec::hex(4);

const COORD: FieldSpec = FieldSpec::signed_hex(8);

const EXT: FieldSpec = FieldSpec::hex(2);

impl RecordLayout {
    /// 3-digit position number (209H, 245H).
    pub const NUMBER_3: RecordLayout = RecordLayout {
        number_width: 3,
        extended: false,
    };
    /// 4-digit position number (21FH, 26DH).
    pub const NUMBER_4: RecordLayout = RecordLayout {
        number_width: 4,
        extended: false,
    };
    /// 4-digit number and extended data (22DH response, 291H).
    pub const NUMBER_4_EXTENDED: RecordLayout = RecordLayout {
        number_width: 4,
        extended: true,
    };
    /// No number: records follow a start number (244H).
    pub const RANGE: RecordLayout = RecordLayout {
        number_width: 0,
        extended: false,
    };
    /// No number, extended data (290H).
    pub const RANGE_EXTENDED: RecordLayout = RecordLayout {
        number_width: 0,
        extended: true,
    };

    /// Wire length of a record with `axes` effective axes.
    pub const fn record_len(self, axes: usize) -> usize {
        self.number_width as usize
            + AXES.len()
            + 3 * WORD.len()
            + COORD.len() * axes
            + if self.extended { EXT.len() } else { 0 }
    }

    /// Offset, from the record start, where the axis pattern ends: a
    /// streaming reader needs this many bytes to know the record's length.
    pub const fn pattern_end(self) -> usize {
        self.number_width as usize + AXES.len()
    }

    /// The length of the record starting at `bytes` (well-formed up to its
    /// axis pattern), from its pattern; `None` if `bytes` is too short or
    /// the pattern is not hex.
    pub fn record_len_at(self, bytes: &[u8]) -> Option<usize> {
        let end = self.pattern_end();
        let digits = bytes.get(end - AXES.len()..end)?;
        let bits = decode_unsigned(AXES, digits, 0).ok()?;
        Some(self.record_len(bits.count_ones() as usize))
    }

    /// Writes `rec` in this layout. Checks that the coordinates match the
    /// axis pattern and that every value fits its field; on error nothing
    /// of the record stays in `w`.
    pub fn write_record(self, rec: &PositionRecord, w: &mut Writer<'_>) -> Result<()> {
        let mark = w.len();
        let r = match self.put_record(rec, w.spare()) {
            Ok((len, _)) => w.reserve(len).map(|_| ()),
            Err(Error::ValueOutOfRange { .. }) => Err(Error::ValueOutOfRange { offset: mark }),
            Err(e) => Err(e),
        };
        if r.is_err() {
            w.truncate(mark);
        }
        r
    }

    /// Writes `rec` at the start of `out`; returns the bytes written and
    /// their sum (what they add to the checksum). Checks as
    /// [`RecordLayout::write_record`]; `ValueOutOfRange` has offset 0. Number
    /// widths 0, 3 and 4 (every message's) write whole fields at a time
    /// ([`crate::hex`]), others a digit at a time.
    #[inline(always)]
    pub fn put_record(self, rec: &PositionRecord, out: &mut [u8]) -> Result<(usize, u32)> {
        match (self.number_width, self.extended) {
            (4, false) => put_as::<4, 18, false>(self, rec, out),
            (4, true) => put_as::<4, 18, true>(self, rec, out),
            (3, false) => put_as::<3, 17, false>(self, rec, out),
            (0, false) => put_as::<0, 14, false>(self, rec, out),
            (0, true) => put_as::<0, 14, true>(self, rec, out),
            _ => put_as::<PER_FIELD, 0, false>(self, rec, out),
        }
    }

    /// [`RecordLayout::write_record`] a field at a time through the
    /// [`Writer`] (on error part of the record may stay in `w`): the path
    /// for other number widths, and the reference the whole-field path is
    /// tested and fuzzed against.
    pub fn write_record_per_field(self, rec: &PositionRecord, w: &mut Writer<'_>) -> Result<()> {
        if rec.positions.len() != rec.axes.count() {
            return Err(Error::CountMismatch {
                expected: rec.axes.count(),
                found: rec.positions.len(),
            });
        }
        if self.number_width > 0 {
            w.unsigned(FieldSpec::hex(self.number_width), u64::from(rec.number))?;
        }
        w.unsigned(AXES, u64::from(rec.axes.bits()))?;
        w.unsigned(WORD, u64::from(rec.acceleration))?;
        w.unsigned(WORD, u64::from(rec.deceleration))?;
        w.unsigned(WORD, u64::from(rec.speed))?;
        for &p in rec.positions.iter() {
            w.signed(COORD, i64::from(p))?;
        }
        if self.extended {
            w.unsigned(EXT, u64::from(rec.extended))?;
        }
        Ok(())
    }

    /// Reads one record in this layout.
    pub fn read_record(self, r: &mut Reader<'_>) -> Result<PositionRecord> {
        match self.read_fast(r.rest()) {
            Some((rec, len, _)) => {
                r.take(len)?;
                Ok(rec)
            }
            None => self.read_record_per_field(r),
        }
    }

    /// Whole fields at a time: `Some((record, length, sum of its bytes))`
    /// for a complete, well-formed record in the layout of a message
    /// (number width 0, 3 or 4); `None` otherwise (the per-digit path then
    /// says what is wrong).
    #[inline(always)]
    pub fn read_fast(self, bytes: &[u8]) -> Option<(PositionRecord, usize, u32)> {
        match (self.number_width, self.extended) {
            (4, false) => read_fixed::<4, 18, false>(bytes),
            (4, true) => read_fixed::<4, 18, true>(bytes),
            (3, false) => read_fixed::<3, 17, false>(bytes),
            (0, false) => read_fixed::<0, 14, false>(bytes),
            (0, true) => read_fixed::<0, 14, true>(bytes),
            _ => None,
        }
    }

    /// Reads records one after another from the start of `bytes` straight
    /// into `out`, overwriting them in place (no record is moved), until
    /// `out` is full or what follows is not a complete, well-formed record.
    /// Returns `(bytes read, records read, sum)`: the records are
    /// `out[..records]`, and the low byte of `sum` is the low byte of the
    /// sum of the bytes read, what they add to the checksum (its other bits
    /// mean nothing). `out[records]`, if there is one, may have been
    /// overwritten with a meaningless record.
    ///
    /// Number widths 0, 3 and 4 read whole fields at a time, others a field
    /// at a time. It never says what is wrong: where it stops,
    /// [`RecordLayout::read_record`] tells.
    ///
    /// ```
    /// use iai_protocol_b::position::{PositionRecord, RecordLayout};
    /// let wire = b"000103001E001E0064000186A0FFFF9C64000201000000000000000030392B";
    /// let mut out: [PositionRecord; 4] = Default::default();
    /// let (used, n, sum) = RecordLayout::NUMBER_4.read_records(wire, &mut out);
    /// assert_eq!((used, n), (60, 2), "the last 2 bytes are no record");
    /// assert_eq!(out[1].number, 2);
    /// assert_eq!(out[1].position(1), Some(12_345));
    /// assert_eq!(sum as u8, wire[..60].iter().fold(0u8, |s, &b| s.wrapping_add(b)));
    /// ```
    pub fn read_records(self, bytes: &[u8], out: &mut [PositionRecord]) -> (usize, usize, u32) {
        match (self.number_width, self.extended) {
            (4, false) => read_run::<4, 18, false>(bytes, out),
            (4, true) => read_run::<4, 18, true>(bytes, out),
            (3, false) => read_run::<3, 17, false>(bytes, out),
            (0, false) => read_run::<0, 14, false>(bytes, out),
            (0, true) => read_run::<0, 14, true>(bytes, out),
            _ => self.read_run_per_field(bytes, out),
        }
    }

    /// One record as [`RecordLayout::read_records`] reads it: into `rec`,
    /// `Some((length, sum))` with only the low byte of `sum` meaningful;
    /// `None` for other number widths and for what is not a complete,
    /// well-formed record.
    #[inline(always)]
    pub(crate) fn read_in_place(
        self,
        bytes: &[u8],
        rec: &mut PositionRecord,
    ) -> Option<(usize, u32)> {
        use hex::ModBatch as M;
        match (self.number_width, self.extended) {
            (4, false) => read_into::<4, 18, false, false, M>(bytes, rec),
            (4, true) => read_into::<4, 18, true, false, M>(bytes, rec),
            (3, false) => read_into::<3, 17, false, false, M>(bytes, rec),
            (0, false) => read_into::<0, 14, false, false, M>(bytes, rec),
            (0, true) => read_into::<0, 14, true, false, M>(bytes, rec),
            _ => None,
        }
    }

    /// [`RecordLayout::read_records`] a field at a time.
    fn read_run_per_field(self, bytes: &[u8], out: &mut [PositionRecord]) -> (usize, usize, u32) {
        let mut used = 0;
        let mut n = 0;
        for rec in out.iter_mut() {
            let mut r = Reader::new(bytes.get(used..).unwrap_or(&[]), 0);
            match self.read_record_per_field(&mut r) {
                Ok(got) => *rec = got,
                Err(_) => break,
            }
            used += r.offset();
            n += 1;
        }
        let read = bytes.get(..used).unwrap_or(&[]);
        let sum = read.iter().fold(0u32, |s, &b| s.wrapping_add(u32::from(b)));
        (used, n, sum)
    }

    /// [`RecordLayout::read_record`] a field at a time through the
    /// [`Reader`]: the path for other number widths and for malformed
    /// records (its errors name the offending byte), and the reference the
    /// whole-field path is tested and fuzzed against.
    pub fn read_record_per_field(self, r: &mut Reader<'_>) -> Result<PositionRecord> {
        let number_at = r.offset();
        let number = if self.number_width > 0 {
            let n = r.unsigned(FieldSpec::hex(self.number_width))?;
            u16::try_from(n).map_err(|_| Error::ValueOutOfRange { offset: number_at })?
        } else {
            0
        };
        // Each width fits its type: 2 hex digits in u8, 4 in u16, 8 in i32.
        let axes = AxisPattern::from_bits(r.unsigned(AXES)? as u8);
        let acceleration = r.unsigned(WORD)? as u16;
        let deceleration = r.unsigned(WORD)? as u16;
        let speed = r.unsigned(WORD)? as u16;
        let mut positions = PerAxis::new();
        for _ in 0..axes.count() {
            let p = r.signed(COORD)? as i32;
            // At most 8 axes: the push cannot fail.
            let _ = positions.push(p);
        }
        let extended = if self.extended {
            r.unsigned(EXT)? as u8
        } else {
            0
        };
        Ok(PositionRecord {
            number,
            axes,
            acceleration,
            deceleration,
            speed,
            positions,
            extended,
        })
    }
}

impl<'a> FieldCodec<'a, PositionRecord> for RecordLayout {
    fn read(&self, r: &mut Reader<'a>) -> Result<PositionRecord> {
        self.read_record(r)
    }
    fn write(&self, value: &PositionRecord, w: &mut Writer<'_>) -> Result<()> {
        self.write_record(value, w)
    }
    fn len(&self, value: &PositionRecord) -> usize {
        self.record_len(value.axes.count())
    }
}

impl Inspect<PositionRecord> for RecordLayout {
    fn inspect(&self, rec: &PositionRecord, _: &'static str, _: &'static str, v: &mut dyn Visitor) {
        let unsigned = |n: u16| Value::Unsigned(n.into());
        if self.number_width > 0 {
            let spec = FieldSpec::hex(self.number_width);
            v.field("position_number", "", spec, unsigned(rec.number));
        }
        v.field(
            "axis_pattern",
            "",
            AXES,
            Value::Unsigned(rec.axes.bits().into()),
        );
        v.field("acceleration", "0.01G", WORD, unsigned(rec.acceleration));
        v.field("deceleration", "0.01G", WORD, unsigned(rec.deceleration));
        v.field("speed", "mm/s", WORD, unsigned(rec.speed));
        let group = GroupInfo {
            count: rec.positions.len(),
            count_field: None,
            per_item: 1,
            units: rec.positions.len(),
            max: MAX_AXES,
        };
        inspect_items(
            &COORD,
            rec.positions.iter(),
            "position",
            "0.001mm",
            group,
            v,
        );
        if self.extended {
            v.field(
                "extended_data",
                "",
                EXT,
                Value::Unsigned(rec.extended.into()),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_26dh_record_in_golden_bytes_and_back() {
        // Position 1, axes 1+2, 0.30 G, 0.30 G, 100 mm/s, +100.000 mm, -25.500 mm.
        let wire = b"000103001E001E0064000186A0FFFF9C64";
        let rec = RecordLayout::NUMBER_4
            .read_record(&mut Reader::new(wire, 0))
            .unwrap();
        assert_eq!(
            rec,
            PositionRecord::new(1, 30, 30, 100, &[(1, 100_000), (2, -25_500)]).unwrap()
        );
        let mut buf = [0u8; 64];
        let mut w = Writer::new(&mut buf);
        RecordLayout::NUMBER_4.write_record(&rec, &mut w).unwrap();
        assert_eq!(w.written(), wire);
        assert_eq!(RecordLayout::NUMBER_4.record_len_at(wire), Some(wire.len()));
    }

    #[test]
    fn record_lengths_match_the_manual_arithmetic() {
        // 26DH: 18 + 8n (TTA p. 60), 82 at 8 axes; 22DH: 84 at 8 axes.
        assert_eq!(RecordLayout::NUMBER_4.record_len(8), 82);
        assert_eq!(RecordLayout::NUMBER_4_EXTENDED.record_len(8), 84);
        assert_eq!(RecordLayout::NUMBER_3.record_len(8), 81);
        assert_eq!(RecordLayout::RANGE.record_len(0), 14);
    }

    #[test]
    fn a_bad_record_leaves_nothing_in_the_writer() {
        let mut rec = PositionRecord::new(1, 0, 0, 0, &[(1, 5)]).unwrap();
        rec.axes = AxisPattern::first(2);
        let mut buf = [0u8; 64];
        let mut w = Writer::new(&mut buf);
        w.put(b"xy").unwrap();
        assert_eq!(
            RecordLayout::NUMBER_4.write_record(&rec, &mut w),
            Err(Error::CountMismatch {
                expected: 2,
                found: 1
            })
        );
        assert_eq!(w.written(), b"xy");
    }
}
