//! Position-table records, shared by every message that reads or writes
//! the position table (209H, 21FH, 22DH, 244H, 245H, 26DH, 290H, 291H).
//!
//! A record is position number, axis pattern, acceleration (0.01 G),
//! deceleration (0.01 G), speed (mm/s) and one signed 0.001 mm coordinate
//! per axis set in the pattern, ascending. The messages differ only in the
//! width of the position number (3 or 4 hex digits, or none where the
//! message gives a start number instead) and in a trailing per-record
//! "extended data" byte; a [`RecordLayout`] states which.
//!
//! ```
//! use iai_protocol_b::position::{PositionRecord, RecordLayout};
//! use iai_protocol_b::axis::AxisPattern;
//! use iai_protocol_b::field::Writer;
//! // EXAMPLES.md 6.1: position 1, axes 1+2, 0.30 G, 0.30 G, 100 mm/s, +100.000 mm, -25.500 mm
//! let rec = PositionRecord::new(1, 30, 30, 100, &[(1, 100_000), (2, -25_500)]).unwrap();
//! let mut buf = [0u8; 64];
//! let mut w = Writer::new(&mut buf);
//! RecordLayout::NUMBER_4.write_record(&rec, &mut w).unwrap();
//! assert_eq!(w.written(), b"000103001E001E0064000186A0FFFF9C64");
//! ```

use crate::axis::{AxisPattern, PerAxis};
use crate::error::{Error, Result};
use crate::field::{FieldSpec, Reader, Writer};
use crate::message::FieldCodec;

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
    /// A record from `(axis, coordinate)` pairs in ascending axis order.
    /// `None` if an axis is out of 1..=8 or the axes do not ascend.
    pub fn new(
        number: u16,
        acceleration: u16,
        deceleration: u16,
        speed: u16,
        coords: &[(u8, i32)],
    ) -> Option<Self> {
        let mut axes = AxisPattern::NONE;
        let mut positions = PerAxis::new();
        let mut last = 0u8;
        for &(axis, pos) in coords {
            if axis <= last {
                return None;
            }
            last = axis;
            axes = axes.with(axis)?;
            positions.push(pos).ok()?;
        }
        Some(PositionRecord {
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
const ACC: FieldSpec = FieldSpec::hex(4);
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
        self.number_width as usize + 2 + 12 + 8 * axes + if self.extended { 2 } else { 0 }
    }

    /// Offset, from the record start, where the axis pattern ends: a
    /// streaming reader needs this many bytes to know the record's length.
    pub const fn pattern_end(self) -> usize {
        self.number_width as usize + 2
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
        w.unsigned(ACC, u64::from(rec.acceleration))?;
        w.unsigned(ACC, u64::from(rec.deceleration))?;
        w.unsigned(ACC, u64::from(rec.speed))?;
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
        let axes = AxisPattern::from_bits(r.unsigned(AXES)? as u8);
        let acceleration = r.unsigned(ACC)? as u16;
        let deceleration = r.unsigned(ACC)? as u16;
        let speed = r.unsigned(ACC)? as u16;
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
}
