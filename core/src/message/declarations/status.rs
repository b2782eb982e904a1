//! Queries of the controller's state and identity: 200H Test Call, 201H
//! Version Code, 212H Axis Status (and [`AxisStatus`], the per-axis block
//! 2A1H and 2A3H reuse), 213H Program Status, 215H System Status and 216H
//! Error Detail. Pages: the 212H and 215H status bits, manual pp. 27 and
//! 30 (quoted on the fields); 216H, TTA pp. 32-33 and 2003 p. 31.
//! **Inferred**: what 216H sends in `type_2` for type 5 (`00`; the manual
//! says "not used").

use super::{dec, hex, shex, text};
use crate::axis::{AxisPattern, PerAxis};
use crate::codec::*;
use crate::error::Result;
use crate::message::wire;

wire! {
    /// 200H Test Call: 10 characters the controller echoes.
    ///
    /// Carried raw, not hex-coded. Keep them printable: CR LF inside would
    /// end the frame early (the manuals say "any 10 characters").
    pub struct TestCall {
        /// The 10 characters.
        pub test_string: [u8; 10] = text(10),
    }
}

wire! {
    /// 200H response: the 10 characters echoed.
    pub struct TestCallResponse {
        /// The echoed characters.
        pub test_string: [u8; 10] = text(10),
    }
}

wire! {
    /// 201H Version Code Query.
    pub struct VersionQuery {
        /// 0 main CPU application, 1 main CPU core, 2 driver CPU, 3 mounted
        /// SIO (3 is TTA-only; see [`crate::profile`]).
        pub unit_type: u8 = hex(2),
        /// Which device of that type, from 0.
        pub device_number: u8 = hex(1),
    }
}

wire! {
    /// 201H response: the echoed unit, its codes, version and build time
    /// (every part of the date is hex: year 2024 is `07E8`).
    pub struct VersionResponse {
        /// Echo of the command's unit type.
        pub unit_type: u8 = hex(2),
        /// Echo of the command's device number.
        pub device_number: u8 = hex(1),
        /// Model code.
        pub model_code: u8 = hex(2),
        /// Unit code.
        pub unit_code: u8 = hex(2),
        /// Version number.
        pub version_number: u16 = hex(4),
        /// Build year.
        pub year: u16 = hex(4) => "year",
        /// Build month.
        pub month: u8 = hex(2) => "month",
        /// Build day.
        pub day: u8 = hex(2) => "day",
        /// Build hour.
        pub hour: u8 = hex(2) => "h",
        /// Build minute.
        pub minute: u8 = hex(2) => "min",
        /// Build second.
        pub second: u8 = hex(2) => "s",
    }
}

wire! {
    /// 212H Axis Status Query.
    pub struct AxisStatusQuery {
        /// Axes to report.
        pub query_axis_pattern: AxisPattern = hex(2),
    }
}

wire! {
    /// The status block of one axis in a 212H (and 2A1H, 2A3H) response.
    pub struct AxisStatus {
        /// Status bits (manual p. 27): bit 0 axis in use, bits 1-2 homing
        /// state (2 = done), bit 3 servo on, bit 4 positioning completed,
        /// bit 5 push error.
        pub axis_status: u8 = hex(2),
        /// Sensor inputs (4 bits).
        pub sensor_input_status: u8 = hex(1),
        /// Axis error code (0 = none).
        pub error_code: u16 = hex(3),
        /// Encoder status bits.
        pub encoder_status: u8 = hex(2),
        /// Current position, 0.001 mm.
        pub current_position: i32 = shex(8) => "0.001mm",
    }
}

wire! {
    /// 212H response: one status block per axis of the pattern, ascending.
    pub struct AxisStatusResponse {
        /// Axes reported.
        pub axis_pattern: AxisPattern = hex(2),
        /// Their status blocks.
        pub axes: PerAxis<AxisStatus> = per_axis(axis_pattern, Nested),
    }
}

/// Bits 1-2 of [`AxisStatus::axis_status`]: the axis's home return
/// (manual p. 27).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Homing {
    /// 0: not yet performed.
    NotDone,
    /// 1: returning to the origin.
    Returning,
    /// 2: completed.
    Done,
    /// 3: not defined by the manual.
    Undefined,
}

/// How an operation command ended, by the check the manual gives for
/// IAI-protocol moves (p. 27): once bit 0 (axis in use) is off, bit 4
/// says it completed, bit 5 that a push failed, neither that it was
/// cancelled (error, emergency stop).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MoveOutcome {
    /// Bit 4: positioning completed successfully.
    Completed,
    /// Bit 5: push error detected.
    PushError,
    /// Neither: cancelled by an error, an emergency stop or similar.
    Cancelled,
}

impl AxisStatus {
    /// Bit 0: a task holds the axis (moving, paused, servo switching).
    pub const fn in_use(&self) -> bool {
        self.axis_status & 0x01 != 0
    }
    /// Bits 1-2: the home return.
    pub const fn homing(&self) -> Homing {
        match (self.axis_status >> 1) & 0x03 {
            0 => Homing::NotDone,
            1 => Homing::Returning,
            2 => Homing::Done,
            _ => Homing::Undefined,
        }
    }
    /// Bit 3: servo on.
    pub const fn servo_on(&self) -> bool {
        self.axis_status & 0x08 != 0
    }
    /// Bit 4: the last operation command completed successfully (valid
    /// only as a completion check after such a command).
    pub const fn completed(&self) -> bool {
        self.axis_status & 0x10 != 0
    }
    /// Bit 5: push error detected.
    pub const fn push_error(&self) -> bool {
        self.axis_status & 0x20 != 0
    }
    /// How the last operation command ended; `None` while the axis is in
    /// use. A push error wins over completion if both bits are set
    /// (**inferred**: the manual lists the cases, not their precedence).
    pub const fn outcome(&self) -> Option<MoveOutcome> {
        if self.in_use() {
            None
        } else if self.push_error() {
            Some(MoveOutcome::PushError)
        } else if self.completed() {
            Some(MoveOutcome::Completed)
        } else {
            Some(MoveOutcome::Cancelled)
        }
    }
    /// Sensor input bit 0: creep sensor on.
    pub const fn creep_sensor(&self) -> bool {
        self.sensor_input_status & 0x01 != 0
    }
    /// Sensor input bit 1: overrun sensor on.
    pub const fn overrun_sensor(&self) -> bool {
        self.sensor_input_status & 0x02 != 0
    }
    /// Sensor input bit 2: origin sensor on.
    pub const fn origin_sensor(&self) -> bool {
        self.sensor_input_status & 0x04 != 0
    }
}

impl AxisStatusQuery {
    /// The status of these axes (1..=8).
    pub fn of(axes: &[u8]) -> Result<Self> {
        Ok(AxisStatusQuery {
            query_axis_pattern: AxisPattern::of(axes)?,
        })
    }
}

wire! {
    /// 213H Program Status Query.
    pub struct ProgramStatusQuery {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 213H response.
    pub struct ProgramStatusResponse {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// Program status code.
        pub status: u8 = hex(1),
        /// Step being executed.
        pub executing_step_number: u16 = hex(4),
        /// Program error code (0 = none).
        pub program_error_code: u16 = hex(3),
        /// Step where the error occurred.
        pub error_step_number: u16 = hex(4),
    }
}

wire! {
    /// 215H System Status Query (no data).
    pub struct SystemStatusQuery {}
}

wire! {
    /// 215H response.
    pub struct SystemStatusResponse {
        /// System mode (manual p. 30): 0 indeterminable, 1 AUTO, 2 MANUAL,
        /// 3 and 4 update modes.
        pub system_mode: u8 = hex(1),
        /// Number of the most serious system error (0 = none).
        pub critical_system_error: u16 = hex(3),
        /// Number of the latest system error (0 = none).
        pub latest_system_error: u16 = hex(3),
        /// System status byte 1 (bit meanings: manual p. 30).
        pub status_byte_1: u8 = hex(2),
        /// System status byte 2.
        pub status_byte_2: u8 = hex(2),
        /// System status byte 3 (TTA: bit 4 = operation mode).
        pub status_byte_3: u8 = hex(2),
        /// System status byte 4.
        pub status_byte_4: u8 = hex(2),
    }
}

wire! {
    /// 216H Error Detail Information Query (TTA pp. 32–33, 2003 p. 31).
    ///
    /// The record number is used by type 5 only and must be 0 otherwise;
    /// `type_2` is unused by type 5 and sent as `00` (**inferred**: the
    /// manual says "not used", not what to send). Both rules are checked
    /// when parsing and emitting ([`Error::ValueOutOfRange`](crate::error::Error::ValueOutOfRange) at the field).
    pub struct ErrorDetailQuery {
        /// 0 system, 1 axis, 2 program, 3 error-list record,
        /// 5 error-list record with extended count (TTA only; the 2003
        /// spec knows 0–4, see [`crate::profile`]).
        pub type_1: u8 = hex(1),
        /// Meaning depends on `type_1` (system: 0 critical / 1 latest; axis
        /// number; program number; list record number); 0 for type 5.
        pub type_2: u8 = zero_unless(hex(2), type_1, |t| t != 5),
        /// Record number for type 5, otherwise 0 ("error number" in the
        /// 2003 spec, which has no type 5).
        pub record_number: u16 = zero_unless(hex(3), type_1, |t| t == 5),
    }
}

impl ErrorDetailQuery {
    /// The most serious system error (type 0, `00`).
    pub const fn critical_system_error() -> Self {
        ErrorDetailQuery {
            type_1: 0,
            type_2: 0,
            record_number: 0,
        }
    }
    /// The latest system error (type 0, `01`).
    pub const fn latest_system_error() -> Self {
        ErrorDetailQuery {
            type_1: 0,
            type_2: 1,
            record_number: 0,
        }
    }
    /// The error of axis `axis` (type 1).
    pub const fn axis(axis: u8) -> Self {
        ErrorDetailQuery {
            type_1: 1,
            type_2: axis,
            record_number: 0,
        }
    }
    /// The error of program `program` (type 2).
    pub const fn program(program: u8) -> Self {
        ErrorDetailQuery {
            type_1: 2,
            type_2: program,
            record_number: 0,
        }
    }
    /// Record `record` (from 1) of the error list (type 3).
    pub const fn list_record(record: u8) -> Self {
        ErrorDetailQuery {
            type_1: 3,
            type_2: record,
            record_number: 0,
        }
    }
    /// Record `record` (from 1) of the error list with the extended record
    /// count (type 5, TTA generation only).
    pub const fn list_record_extended(record: u16) -> Self {
        ErrorDetailQuery {
            type_1: 5,
            type_2: 0,
            record_number: record,
        }
    }
}

wire! {
    /// 216H response: error number, eight detail words, seven decimal
    /// reserved fields and a message string (always empty on the TTA).
    pub struct ErrorDetailResponse<'a> {
        /// Error number.
        pub error_number: u16 = hex(3),
        /// Detail 1: program number (system-down: type).
        pub detail_1: u32 = hex(8),
        /// Detail 2: step number (system-down: error code).
        pub detail_2: u32 = hex(8),
        /// Detail 3: axis number (system-down: info 1).
        pub detail_3: u32 = hex(8),
        /// Detail 4: position number, negative = interpolation point
        /// (system-down: info 2). The only signed detail word.
        pub detail_4: i32 = shex(8),
        /// Detail 5 (meaning undocumented).
        pub detail_5: u32 = hex(8),
        /// Detail 6 (meaning undocumented).
        pub detail_6: u32 = hex(8),
        /// Detail 7 (meaning undocumented).
        pub detail_7: u32 = hex(8),
        /// Detail 8 (meaning undocumented).
        pub detail_8: u32 = hex(8),
        /// Reserved, 2 decimal digits.
        pub reserved_1: u8 = dec(2),
        /// Reserved, 2 decimal digits.
        pub reserved_2: u8 = dec(2),
        /// Reserved, 2 decimal digits.
        pub reserved_3: u8 = dec(2),
        /// Reserved, 1 decimal digit.
        pub reserved_4: u8 = dec(1),
        /// Reserved, 2 decimal digits.
        pub reserved_5: u8 = dec(2),
        /// Reserved, 2 decimal digits.
        pub reserved_6: u8 = dec(2),
        /// Reserved, 4 decimal digits.
        pub reserved_7: u16 = dec(4),
        /// Message string, raw characters, at most 255 (count: 2 hex digits).
        pub message: &'a [u8] = CountedText { count: hex(2), max: 255 },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::declarations::test_support::{emit, parse, ST};
    use crate::message::Message;

    #[test]
    fn a_216h_record_number_is_only_for_type_5() {
        let (buf, n) = emit(&ErrorDetailQuery::latest_system_error());
        assert_eq!(&buf[..n], b"!992160010004D\r\n");
        let (buf, n) = emit(&ErrorDetailQuery::list_record_extended(1));
        assert_eq!(&buf[..n], b"!9921650000152\r\n");
        // Type 0 with a record number, and type 5 with a type 2: refused.
        assert_eq!(
            parse::<ErrorDetailQuery>(b"!992160010014E\r\n"),
            Err(crate::error::Error::ValueOutOfRange { offset: 9 })
        );
        let bad = ErrorDetailQuery {
            type_1: 5,
            type_2: 1,
            record_number: 1,
        };
        assert!(bad.emit(ST, &mut [0u8; 32]).is_err());
    }

    /// 212H for axes 1 and 2 (manual p. 27): axis 1 `1C` = homed, servo
    /// on, move completed, at 2.200 mm; axis 2 `0D` = in use, homed, servo
    /// on, origin sensor on, at -1.596 mm.
    #[test]
    fn a_212h_reply_reads_as_its_status_bits() {
        let r: AxisStatusResponse =
            parse(b"#99212031C000000000008980D400000FFFFF9C460\r\n").unwrap();
        let (a1, a2) = (r.axes.first().unwrap(), r.axes.get(1).unwrap());
        assert_eq!(
            (a1.in_use(), a1.homing(), a1.servo_on(), a1.completed()),
            (false, Homing::Done, true, true)
        );
        assert_eq!(a1.outcome(), Some(MoveOutcome::Completed));
        assert_eq!(a1.current_position, 2_200);
        assert_eq!(
            (a2.in_use(), a2.homing(), a2.servo_on()),
            (true, Homing::Done, true)
        );
        assert_eq!(a2.outcome(), None);
        assert!(a2.origin_sensor() && !a2.overrun_sensor() && !a2.creep_sensor());
        assert_eq!(a2.current_position, -1_596);
        let done = |s: u8| {
            AxisStatus {
                axis_status: s,
                ..*a1
            }
            .outcome()
        };
        assert_eq!(done(0x20), Some(MoveOutcome::PushError));
        assert_eq!(done(0x00), Some(MoveOutcome::Cancelled));
        assert_eq!(
            AxisStatus {
                axis_status: 0x02,
                ..*a1
            }
            .homing(),
            Homing::Returning
        );
    }
}
