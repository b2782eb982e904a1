//! The position table: its records, their wire layouts, and the layouts of
//! the messages that carry runs of them (209H, 21FH, 22DH, 244H, 245H,
//! 26DH, 290H, 291H). Every message declaration and streaming engine
//! takes these layouts from here.
//!
//! A record ([`PositionRecord`]) is position number, axis pattern,
//! acceleration (0.01 G), deceleration (0.01 G), speed (mm/s) and one
//! signed 0.001 mm coordinate per axis set in the pattern, ascending. The
//! messages differ only in the width of the position number (3 or 4 hex
//! digits, or none where the message gives a start number instead) and in
//! a trailing per-record "extended data" byte; a [`RecordLayout`] states
//! which, and reads, writes and shows records to a
//! [`Visitor`](crate::codec::Visitor) a field at a time. A
//! [`PositionStream`] adds the fields before the records (TTA pp. 19,
//! 35-36, 44-45, 60, 63-64; 2003 pp. 18, 40-41).
//!
//! Submodules: `layout` (the record layouts, field at a time), `whole_field`
//! (the same codec whole fields at a time, for the message layouts, tested
//! against the first) and `kinds` (the position-stream messages and their shapes).
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

mod kinds;
mod layout;
mod whole_field;

pub use kinds::{PositionStream, RESERVED};
pub use layout::RecordLayout;
pub(crate) use whole_field::{len_as, put_exact, PER_FIELD};

use crate::axis::{per_axis_values, AxisPattern, PerAxis};
use crate::error::Result;

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
