//! The position table: its records, their wire layouts, and the layouts of
//! the messages that carry runs of them (209H, 21FH, 22DH, 244H, 245H,
//! 26DH, 290H, 291H). Both halves of the record codec (reading and writing,
//! and showing a record to a [`Visitor`]) live here, and every message
//! declaration and streaming engine takes these layouts from here.
//!
//! A record is position number, axis pattern, acceleration (0.01 G),
//! deceleration (0.01 G), speed (mm/s) and one signed 0.001 mm coordinate
//! per axis set in the pattern, ascending. The messages differ only in the
//! width of the position number (3 or 4 hex digits, or none where the
//! message gives a start number instead) and in a trailing per-record
//! "extended data" byte; a [`RecordLayout`] states which. A
//! [`PositionStream`] adds the fields before the records.
//!
//! ```
//! use iai_protocol_b::position::{PositionRecord, RecordLayout};
//! use iai_protocol_b::field::Writer;
//! // Position 1, axes 1+2, 0.30 G, 0.30 G, 100 mm/s, +100.000 mm, -25.500 mm.
//! let rec = PositionRecord::new(1, 30, 30, 100, &[(1, 100_000), (2, -25_500)]).unwrap();
//! let mut buf = [0u8; 64];
//! let mut w = Writer::new(&mut buf);
//! RecordLayout::NUMBER_4.write_record(&rec, &mut w).unwrap();
//! assert_eq!(w.written(), b"000103001E001E0064000186A0FFFF9C64");
//! ```

use crate::axis::{per_axis_values, AxisPattern, PerAxis, MAX_AXES};
use crate::catalogue;
use crate::codec::{
    counted, inspect_items, Counted, FieldCodec, Fixed, GroupInfo, Inspect, Value, Visitor,
};
use crate::error::{Error, Result};
use crate::field::{decode_unsigned, FieldSpec, Reader, Writer};
use crate::frame::{Frame, Header, ENVELOPE_LEN, TRAILER_LEN};

/// One record of the position table.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PositionRecord {
    /// Position number (0 where the layout has none: 244H, 290H).
    pub number: u16,
    /// Axes that carry a coordinate in this record.
    pub axes: AxisPattern,
    /// Acceleration in 0.01 G (0 = the controller's default).
    pub acceleration: u16,
    /// Deceleration in 0.01 G (0 = the controller's default).
    pub deceleration: u16,
    /// Speed in mm/s (0 = the controller's default).
    pub speed: u16,
    /// Coordinates in 0.001 mm (0.001 deg on a rotary axis), one per axis
    /// of `axes`, ascending.
    pub positions: PerAxis<i32>,
    /// Extended data byte (22DH, 290H, 291H only; 0 elsewhere).
    pub extended: u8,
}

impl PositionRecord {
    /// A record from `(axis, coordinate)` pairs (any order; see
    /// [`per_axis_values`]): the axis pattern always matches the
    /// coordinates.
    pub fn new(
        number: u16,
        acceleration: u16,
        deceleration: u16,
        speed: u16,
        coords: &[(u8, i32)],
    ) -> Result<Self> {
        let (axes, positions) = per_axis_values(coords)?;
        Ok(PositionRecord {
            number,
            axes,
            acceleration,
            deceleration,
            speed,
            positions,
            extended: 0,
        })
    }

    /// The coordinate of axis `axis` (1..=8), if the record has one.
    pub fn position(&self, axis: u8) -> Option<i32> {
        let idx = self.axes.iter().position(|a| a == axis)?;
        self.positions.get(idx).copied()
    }
}

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
        let r = self.write_inner(rec, w);
        if r.is_err() {
            w.truncate(mark);
        }
        r
    }

    fn write_inner(self, rec: &PositionRecord, w: &mut Writer<'_>) -> Result<()> {
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

/// The reserved `00` before the prefix of 22DH, 290H and 291H.
pub const RESERVED: Fixed = Fixed(b"00");

/// The shape of a message whose body is a prefix and a run of position
/// records: `[00] [start] count record…`. The message declarations and the
/// streaming engines both take their layouts from these descriptors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PositionStream {
    /// Message ID (from the catalogue).
    pub id: u16,
    /// Frame kind that carries the records (command for writes, response for queries).
    pub header: Header,
    /// Whether the body starts with the reserved `00`.
    pub reserved: bool,
    /// Width of the start-number field; 0 when records carry their own numbers.
    pub start_width: u8,
    /// Width of the record-count field (also of the position numbers in
    /// the query commands).
    pub count_width: u8,
    /// Largest record count the format allows.
    pub max_records: u16,
    /// Layout of one record.
    pub layout: RecordLayout,
}

impl PositionStream {
    /// 26DH Change Position Data Continuous Write 2 (TTA p. 60).
    pub const CHANGE_2: Self = Self::write(
        catalogue::CHANGE_POSITION_DATA_2.id,
        false,
        0,
        4,
        20_000,
        RecordLayout::NUMBER_4,
    );
    /// 245H Change Position Data Continuous Write (3-digit numbers; TTA
    /// p. 45, 2003 p. 41).
    pub const CHANGE: Self = Self::write(
        catalogue::CHANGE_POSITION_DATA.id,
        false,
        0,
        3,
        3_000,
        RecordLayout::NUMBER_3,
    );
    /// 244H Position Data Range-Specification Continuous Write (TTA p. 44,
    /// 2003 p. 40).
    pub const RANGE: Self = Self::write(
        catalogue::RANGE_WRITE_POSITION_DATA.id,
        false,
        3,
        3,
        3_000,
        RecordLayout::RANGE,
    );
    /// 290H Position Data Range-Specification Continuous Write 3 (TTA
    /// p. 63; catalogue status: partial).
    pub const RANGE_3: Self = Self::write(
        catalogue::RANGE_WRITE_POSITION_DATA_3.id,
        true,
        4,
        4,
        20_000,
        RecordLayout::RANGE_EXTENDED,
    );
    /// 291H Change Position Data Continuous Write 3 (TTA p. 64; catalogue
    /// status: partial, the field order is a chosen reading of an
    /// inconsistent table).
    pub const CHANGE_3: Self = Self::write(
        catalogue::CHANGE_POSITION_DATA_3.id,
        true,
        0,
        4,
        20_000,
        RecordLayout::NUMBER_4_EXTENDED,
    );
    /// 209H Effective Position Data Query, response (TTA p. 19, 2003 p. 18).
    pub const QUERY_RESPONSE: Self = Self::query(
        catalogue::EFFECTIVE_POSITION_QUERY.id,
        false,
        3,
        3_000,
        RecordLayout::NUMBER_3,
    );
    /// 21FH Effective Position Data Query 2, response (TTA p. 35; the
    /// printed "max 2000" is read as 20,000, as its own arithmetic says).
    pub const QUERY_2_RESPONSE: Self = Self::query(
        catalogue::EFFECTIVE_POSITION_QUERY_2.id,
        false,
        4,
        20_000,
        RecordLayout::NUMBER_4,
    );
    /// 22DH Effective Position Data Query 3, response (TTA p. 36).
    pub const QUERY_3_RESPONSE: Self = Self::query(
        catalogue::EFFECTIVE_POSITION_QUERY_3.id,
        true,
        4,
        20_000,
        RecordLayout::NUMBER_4_EXTENDED,
    );

    /// Every known position stream.
    pub const ALL: [Self; 8] = [
        Self::CHANGE_2,
        Self::CHANGE,
        Self::RANGE,
        Self::RANGE_3,
        Self::CHANGE_3,
        Self::QUERY_RESPONSE,
        Self::QUERY_2_RESPONSE,
        Self::QUERY_3_RESPONSE,
    ];

    const fn write(
        id: u16,
        reserved: bool,
        start: u8,
        count: u8,
        max: u16,
        layout: RecordLayout,
    ) -> Self {
        PositionStream {
            id,
            header: Header::Command,
            reserved,
            start_width: start,
            count_width: count,
            max_records: max,
            layout,
        }
    }

    const fn query(id: u16, reserved: bool, count: u8, max: u16, layout: RecordLayout) -> Self {
        PositionStream {
            id,
            header: Header::Response,
            reserved,
            start_width: 0,
            count_width: count,
            max_records: max,
            layout,
        }
    }

    /// The stream carried by frames of this kind and ID, if any.
    pub fn find(header: Header, id: u16) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|s| s.header == header && s.id == id)
    }

    /// The count field's format.
    pub const fn count_field(&self) -> FieldSpec {
        FieldSpec::hex(self.count_width)
    }

    /// The start-number field's format (range writes).
    pub const fn start_field(&self) -> FieldSpec {
        FieldSpec::hex(self.start_width)
    }

    /// The codec of the count field and the records after it.
    pub const fn records(&self) -> Counted<RecordLayout> {
        counted(self.count_field(), self.max_records as usize, self.layout)
    }

    /// Bytes of the body before the first record.
    pub const fn prefix_len(&self) -> usize {
        (if self.reserved { RESERVED.0.len() } else { 0 })
            + self.start_width as usize
            + self.count_width as usize
    }

    /// Bytes of a frame without records (envelope, prefix, SC, CR, LF).
    pub const fn overhead(&self) -> usize {
        ENVELOPE_LEN + self.prefix_len() + TRAILER_LEN
    }

    /// Writes the prefix: `[00] [start] count`.
    pub fn write_prefix(&self, w: &mut Writer<'_>, start: u16, count: u16) -> Result<()> {
        if count > self.max_records {
            return Err(Error::CountTooLarge {
                count: usize::from(count),
                max: usize::from(self.max_records),
            });
        }
        if self.reserved {
            w.put(RESERVED.0)?;
        }
        if self.start_width > 0 {
            w.unsigned(self.start_field(), u64::from(start))?;
        }
        w.unsigned(self.count_field(), u64::from(count))
    }

    /// Reads the prefix; returns `(start, count)` (start 0 when absent).
    pub fn read_prefix(&self, r: &mut Reader<'_>) -> Result<(u16, u16)> {
        if self.reserved {
            let at = r.offset();
            if !r.take(RESERVED.0.len())?.eq_ignore_ascii_case(RESERVED.0) {
                return Err(Error::InvalidFixedField { offset: at });
            }
        }
        let start = if self.start_width > 0 {
            let at = r.offset();
            let s = r.unsigned(self.start_field())?;
            u16::try_from(s).map_err(|_| Error::ValueOutOfRange { offset: at })?
        } else {
            0
        };
        let at = r.offset();
        let count = r.unsigned(self.count_field())?;
        let count = u16::try_from(count).map_err(|_| Error::ValueOutOfRange { offset: at })?;
        if count > self.max_records {
            return Err(Error::CountTooLarge {
                count: usize::from(count),
                max: usize::from(self.max_records),
            });
        }
        Ok((start, count))
    }

    /// Parses the normal response to a position write: the same prefix,
    /// carrying the number of records written. Returns `(start, count)`.
    pub fn parse_reply(&self, frame: &Frame<'_>) -> Result<(u16, u16)> {
        if frame.header() != Header::Response {
            return Err(Error::UnexpectedHeader {
                expected: Header::Response,
                found: frame.header(),
            });
        }
        if frame.code() != self.id {
            return Err(Error::UnexpectedMessageId {
                expected: self.id,
                found: frame.code(),
            });
        }
        let mut r = frame.reader();
        let v = self.read_prefix(&mut r)?;
        r.finish()?;
        Ok(v)
    }

    /// The query whose response reads back what this write stores: 21FH
    /// for 26DH, 22DH for 290H and 291H (extended data), 209H for the
    /// 3-digit writes 244H and 245H. A query stream gives itself.
    pub const fn read_back(&self) -> PositionStream {
        if matches!(self.header, Header::Response) {
            return *self;
        }
        match (self.count_width, self.layout.extended) {
            (4, true) => Self::QUERY_3_RESPONSE,
            (4, false) => Self::QUERY_2_RESPONSE,
            _ => Self::QUERY_RESPONSE,
        }
    }

    /// Writes the body of this query stream's command: `[00] head count`
    /// (209H, 21FH, 22DH commands share the response's widths).
    pub fn write_query(&self, w: &mut Writer<'_>, head: u16, count: u16) -> Result<()> {
        if self.reserved {
            w.put(RESERVED.0)?;
        }
        w.unsigned(self.count_field(), u64::from(head))?;
        w.unsigned(self.count_field(), u64::from(count))
    }

    /// Positions one query may ask for so that its reply fits
    /// `max_response` bytes whatever the records hold (8 axes each): 24 for
    /// 21FH on a TTA. At least 1.
    pub const fn window(&self, max_response: usize) -> u16 {
        let room = max_response.saturating_sub(self.overhead());
        let per = room / self.layout.record_len(MAX_AXES);
        let per = if per < 1 { 1 } else { per };
        if per > self.max_records as usize {
            self.max_records
        } else {
            per as u16
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

    #[test]
    fn streams_know_their_read_back_query_and_window() {
        assert_eq!(
            PositionStream::CHANGE_2.read_back(),
            PositionStream::QUERY_2_RESPONSE
        );
        assert_eq!(
            PositionStream::CHANGE_3.read_back(),
            PositionStream::QUERY_3_RESPONSE
        );
        assert_eq!(
            PositionStream::RANGE_3.read_back(),
            PositionStream::QUERY_3_RESPONSE
        );
        assert_eq!(
            PositionStream::RANGE.read_back(),
            PositionStream::QUERY_RESPONSE
        );
        assert_eq!(
            PositionStream::CHANGE.read_back(),
            PositionStream::QUERY_RESPONSE
        );
        // 21FH on a TTA: (2048 - 14) / 82 = 24 positions per query.
        assert_eq!(PositionStream::QUERY_2_RESPONSE.window(2048), 24);
        assert_eq!(PositionStream::QUERY_RESPONSE.window(1024), 12);
        let mut buf = [0u8; 16];
        let mut w = Writer::new(&mut buf);
        PositionStream::QUERY_3_RESPONSE
            .write_query(&mut w, 0x10, 24)
            .unwrap();
        assert_eq!(w.written(), b"0000100018");
    }

    #[test]
    fn the_26dh_reply_prefix() {
        let f = Frame::new_checked(b"#9926D00180A\r\n", crate::checksum::BypassPolicy::Reject);
        let f = f.unwrap();
        assert_eq!(PositionStream::CHANGE_2.parse_reply(&f), Ok((0, 0x18)));
    }
}
