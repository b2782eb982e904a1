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
use crate::hex;

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
        let n = axis_count(rec.axes);
        if rec.positions.len() != n {
            return Err(Error::CountMismatch {
                expected: n,
                found: rec.positions.len(),
            });
        }
        let len = self.record_len(n);
        let out = out.get_mut(..len).ok_or(Error::BufferTooSmall)?;
        match self.put_fast(rec, out) {
            Some(Ok(sum)) => Ok((len, sum)),
            Some(Err(e)) => Err(e),
            None => {
                let mut w = Writer::new(out);
                self.write_record_per_field(rec, &mut w)?;
                Ok((len, w.written().iter().map(|&b| u32::from(b)).sum()))
            }
        }
    }

    /// The whole-field path of [`RecordLayout::put_record`]: `None` for a
    /// layout it does not handle. `out` is exactly the record.
    #[inline(always)]
    fn put_fast(self, rec: &PositionRecord, out: &mut [u8]) -> Option<Result<u32>> {
        match (self.number_width, self.extended) {
            (4, false) => put_fixed::<4, 18, false>(rec, out),
            (4, true) => put_fixed::<4, 18, true>(rec, out),
            (3, false) => put_fixed::<3, 17, false>(rec, out),
            (0, false) => put_fixed::<0, 14, false>(rec, out),
            (0, true) => put_fixed::<0, 14, true>(rec, out),
            _ => None,
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

/// [`RecordLayout::put_fast`] for one layout: `NW` digits of number (0, 3
/// or 4), `HEAD` = `NW` + 14 bytes before the coordinates.
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
fn read_fixed<const NW: usize, const HEAD: usize, const EXT: bool>(
    bytes: &[u8],
) -> Option<(PositionRecord, usize, u32)> {
    let (head, rest) = bytes.split_first_chunk::<HEAD>()?;
    let mut b = hex::Batch::new();
    let axes = AxisPattern::from_bits(b.decode2(piece::<2>(head, NW)?));
    let n = axis_count(axes);
    let tail = 8 * n + if EXT { 2 } else { 0 };
    let rest = rest.get(..tail)?;
    let number = match NW {
        4 => b.decode4(piece::<4>(head, 0)?),
        3 => {
            let [x, y, z] = *piece::<3>(head, 0)?;
            b.decode4(&[b'0', x, y, z])
        }
        _ => 0,
    };
    let acceleration = b.decode4(piece::<4>(head, NW + 2)?);
    let deceleration = b.decode4(piece::<4>(head, NW + 6)?);
    let speed = b.decode4(piece::<4>(head, NW + 10)?);
    let mut positions = PerAxis::new();
    let mut coords = rest.chunks_exact(8);
    for d in &mut coords {
        let _ = positions.push(b.decode8(d.try_into().ok()?) as i32);
    }
    let extended = if EXT {
        b.decode2(coords.remainder().try_into().ok()?)
    } else {
        0
    };
    if !b.is_valid() {
        return None;
    }
    // The '0' put before a 3-digit number is not on the wire.
    let sum = if NW == 3 {
        b.sum() - u32::from(b'0')
    } else {
        b.sum()
    };
    Some((
        PositionRecord {
            number,
            axes,
            acceleration,
            deceleration,
            speed,
            positions,
            extended,
        },
        HEAD + tail,
        sum,
    ))
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

/// The whole-field record codec against the per-field reference.
#[cfg(test)]
mod whole_fields {
    use super::*;

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
