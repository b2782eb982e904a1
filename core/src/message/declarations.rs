//! The message catalogue, one short declaration per message.
//!
//! Field names, widths, radix and signedness follow `messages.toml` (TTA
//! manual section 4-3, completed from the 2003 X-SEL specification). Count
//! fields are not stored: a [`Repeated`] group writes its own count.

use super::codec::*;
use super::wire;
use crate::axis::{AxisPattern, PerAxis};
use crate::field::FieldSpec;
use crate::position::{PositionRecord, RecordLayout};

const fn hex(w: u8) -> FieldSpec {
    FieldSpec::hex(w)
}
const fn shex(w: u8) -> FieldSpec {
    FieldSpec::signed_hex(w)
}
const fn dec(w: u8) -> FieldSpec {
    FieldSpec::dec(w)
}
const fn text(w: u8) -> FieldSpec {
    FieldSpec::text(w)
}

/// Frame offsets of the 200H test string.
pub(crate) const TEST_STRING_SPAN: (usize, usize) = (6, 16);
/// Frame offset of the first character of the 216H response's message.
pub(crate) const ERROR_DETAIL_MESSAGE_AT: usize = 90;

// ---------------------------------------------------------------- 200H

wire! {
    /// 200H Test Call: 10 characters the controller echoes.
    ///
    /// Carried raw, not hex-coded. Keep them printable: CR LF inside would
    /// end the frame early (the manuals say "any 10 characters").
    [command 0x200]
    pub struct TestCall {
        /// The 10 characters.
        pub test_string: [u8; 10] = text(10),
    }
}

wire! {
    /// 200H response: the 10 characters echoed.
    [response 0x200]
    pub struct TestCallResponse {
        /// The echoed characters.
        pub test_string: [u8; 10] = text(10),
    }
}

// ---------------------------------------------------------------- 212H

wire! {
    /// 212H Axis Status Query.
    [command 0x212]
    pub struct AxisStatusQuery {
        /// Axes to report.
        pub query_axis_pattern: AxisPattern = hex(2),
    }
}

wire! {
    /// The status block of one axis in a 212H (and 2A1H, 2A3H) response.
    pub struct AxisStatus {
        /// Status bits: bit 0 servo on, bit 2 home done, bits 4/5 moving (see manual p. 27).
        pub axis_status: u8 = hex(2),
        /// Sensor inputs (4 bits).
        pub sensor_input_status: u8 = hex(1),
        /// Axis error code (0 = none).
        pub error_code: u16 = hex(3),
        /// Encoder status bits.
        pub encoder_status: u8 = hex(2),
        /// Current position, 0.001 mm.
        pub current_position: i32 = shex(8),
    }
}

wire! {
    /// 212H response: one status block per axis of the pattern, ascending.
    [response 0x212]
    pub struct AxisStatusResponse {
        /// Axes reported.
        pub axis_pattern: AxisPattern = hex(2),
        /// Their status blocks.
        pub axes: PerAxis<AxisStatus> = per_axis(axis_pattern, Nested),
    }
}

// ---------------------------------------------------------------- 215H

wire! {
    /// 215H System Status Query (no data).
    [command 0x215]
    pub struct SystemStatusQuery {}
}

wire! {
    /// 215H response.
    [response 0x215]
    pub struct SystemStatusResponse {
        /// System mode (0 AUTO, 1 MANUAL, per manual p. 30).
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

// ---------------------------------------------------------------- 216H

wire! {
    /// 216H Error Detail Information Query.
    [command 0x216]
    pub struct ErrorDetailQuery {
        /// 0 system, 1 axis, 2 program, 3 error-list record,
        /// 5 error-list record with extended count (TTA only).
        pub type_1: u8 = hex(1),
        /// Meaning depends on `type_1` (system: 0 critical / 1 latest; axis
        /// number; program number; list record number).
        pub type_2: u8 = hex(2),
        /// Record number for type 5, otherwise 0 ("error number" in the 2003 spec).
        pub record_number: u16 = hex(3),
    }
}

wire! {
    /// 216H response: error number, eight detail words, seven decimal
    /// reserved fields and a message string (always empty on the TTA).
    [response 0x216]
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

// ---------------------------------------------------------------- 26DH

/// The records of a 26DH command.
pub type PositionRecords4<'a> = Repeated<'a, PositionRecord, RecordLayout>;

wire! {
    /// 26DH Change Position Data Continuous Write 2: records, each naming
    /// its own position number (4 digits). Up to 20,000 records by format;
    /// the controller's buffer is the real limit (see [`crate::profile`]).
    [command 0x26D]
    pub struct ChangePositionData2<'a> {
        /// The records; the count field (4 hex digits) is written from its length.
        pub records: PositionRecords4<'a> = counted(hex(4), 20_000, RecordLayout::NUMBER_4),
    }
}

wire! {
    /// 26DH response: how many positions were written.
    [response 0x26D]
    pub struct ChangePositionData2Response {
        /// Number of positions written.
        pub number_of_changed_positions: u16 = hex(4),
    }
}
