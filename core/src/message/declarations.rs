//! The message catalogue, one short declaration per message.
//!
//! Field names, widths, radix, signedness and units follow `messages.toml`
//! (TTA manual section 4-3, completed from the 2003 X-SEL specification).
//! Count fields are not stored: a [`Repeated`] group writes its own count.
//! Every message ID has a command type and, except 25BH, a response type;
//! messages whose reply carries no data have an empty response struct.
//!
//! A few Rust names predate the full catalogue and differ from its field
//! names: 212H/2A1H/2A3H `sensor_input_status` and `error_code`
//! (catalogue: `axis_sensor_input_status`, `axis_error_code`), 215H
//! `critical_system_error`, `latest_system_error`, `status_byte_N`
//! (catalogue: `…_number`, `system_status_byte_N`) and 216H `message`
//! (catalogue: `message_char`).
//!
//! Layouts marked **inferred** below are readings the sources do not state
//! outright; `messages.toml` has the reasoning.

use super::wire;
use crate::axis::{per_axis_values, AxisPattern, PerAxis};
use crate::codec::*;
use crate::error::Result;
use crate::field::FieldSpec;
use crate::position::{PositionRecord, PositionStream, RecordLayout, RESERVED};

/// Declares responses that carry no data (the bare 10-byte envelope).
macro_rules! bare_responses {
    ($( $(#[$m:meta])* $name:ident; )*) => {
        $( wire! { $(#[$m])* pub struct $name {} } )*
    };
}

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

// ---------------------------------------------------------------- 200H

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

// ---------------------------------------------------------------- 212H

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

// ---------------------------------------------------------------- 215H

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

// ---------------------------------------------------------------- 216H

wire! {
    /// 216H Error Detail Information Query (TTA pp. 32–33, 2003 p. 31).
    ///
    /// The record number is used by type 5 only and must be 0 otherwise;
    /// `type_2` is unused by type 5 and sent as `00` (**inferred**: the
    /// manual says "not used", not what to send). Both rules are checked
    /// when parsing and emitting ([`Error::ValueOutOfRange`](crate::Error::ValueOutOfRange) at the field).
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

// ---------------------------------------------------------------- 26DH

/// Position records as used by every position-table message; their
/// layouts are the [`PositionStream`] descriptors'.
pub type PositionRecords<'a> = Repeated<'a, PositionRecord, RecordLayout>;

wire! {
    /// 26DH Change Position Data Continuous Write 2: records, each naming
    /// its own position number (4 digits). Up to 20,000 records by format;
    /// the controller's buffer is the real limit (see [`crate::profile`]).
    pub struct ChangePositionData2<'a> {
        /// The records; the count field (4 hex digits) is written from its length.
        pub records: PositionRecords<'a> = PositionStream::CHANGE_2.records(),
    }
}

wire! {
    /// 26DH response: how many positions were written.
    pub struct ChangePositionData2Response {
        /// Number of positions written.
        pub number_of_changed_positions: u16 = PositionStream::CHANGE_2.count_field(),
    }
}

// ---------------------------------------------------------------- 201H, 208H

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
    /// 208H Number of Effective Position Data Query (no data).
    pub struct EffectivePositionCountQuery {}
}

wire! {
    /// 208H response.
    pub struct EffectivePositionCountResponse {
        /// Defined (non-empty) records of the position table (3 digits).
        pub number_of_effective_positions: u16 = hex(3),
    }
}

// ---------------------------------------------------------------- position table

wire! {
    /// 209H Effective Position Data Query (3-digit numbering).
    pub struct EffectivePositionQuery {
        /// First position number of the window.
        pub query_head_position_number: u16 = PositionStream::QUERY_RESPONSE.count_field(),
        /// Window length (the controller's send buffer limits the answer).
        pub number_of_query_records: u16 = PositionStream::QUERY_RESPONSE.count_field(),
    }
}

wire! {
    /// 209H response: the defined records in the window (possibly fewer
    /// than asked), each with its 3-digit position number.
    pub struct EffectivePositionResponse<'a> {
        /// The records; count field 3 hex digits, at most 3000.
        pub records: PositionRecords<'a> = PositionStream::QUERY_RESPONSE.records(),
    }
}

wire! {
    /// 21FH Effective Position Data Query 2 (4-digit numbering, TTA only).
    pub struct EffectivePositionQuery2 {
        /// First position number of the window.
        pub query_head_position_number: u16 = PositionStream::QUERY_2_RESPONSE.count_field(),
        /// Window length.
        pub number_of_query_records: u16 = PositionStream::QUERY_2_RESPONSE.count_field(),
    }
}

wire! {
    /// 21FH response. The manual prints "max 2000 records" but its own
    /// arithmetic gives 20,000, which is used here.
    pub struct EffectivePositionResponse2<'a> {
        /// The records; count field 4 hex digits.
        pub records: PositionRecords<'a> = PositionStream::QUERY_2_RESPONSE.records(),
    }
}

wire! {
    /// 22DH Effective Position Data Query 3 (with extended data, TTA only).
    pub struct EffectivePositionQuery3 {
        /// Reserved, always `00`.
        pub reserved: Reserved = RESERVED,
        /// First position number of the window.
        pub query_head_position_number: u16 = PositionStream::QUERY_3_RESPONSE.count_field(),
        /// Window length.
        pub number_of_query_records: u16 = PositionStream::QUERY_3_RESPONSE.count_field(),
    }
}

wire! {
    /// 22DH response: records with a trailing extended-data byte.
    pub struct EffectivePositionResponse3<'a> {
        /// Reserved, always `00`.
        pub reserved: Reserved = RESERVED,
        /// The records; count field 4 hex digits.
        pub records: PositionRecords<'a> = PositionStream::QUERY_3_RESPONSE.records(),
    }
}

wire! {
    /// 244H Position Data Range-Specification Continuous Write: records
    /// without numbers, written to consecutive positions from a start.
    pub struct RangeWritePositionData<'a> {
        /// First position written.
        pub change_start_position_number: u16 = PositionStream::RANGE.start_field(),
        /// The records (their `number` is not sent); count 3 hex digits.
        pub records: PositionRecords<'a> = PositionStream::RANGE.records(),
    }
}

wire! {
    /// 244H response.
    pub struct RangeWritePositionDataResponse {
        /// Echo of the start position.
        pub change_start_position_number: u16 = PositionStream::RANGE.start_field(),
        /// Positions written.
        pub number_of_changed_positions: u16 = PositionStream::RANGE.count_field(),
    }
}

wire! {
    /// 245H Change Position Data Continuous Write: records naming their own
    /// 3-digit position numbers.
    pub struct ChangePositionData<'a> {
        /// The records; count 3 hex digits.
        pub records: PositionRecords<'a> = PositionStream::CHANGE.records(),
    }
}

wire! {
    /// 245H response.
    pub struct ChangePositionDataResponse {
        /// Positions written.
        pub number_of_changed_positions: u16 = PositionStream::CHANGE.count_field(),
    }
}

wire! {
    /// 246H Position Data Clear.
    pub struct ClearPositionData {
        /// First position cleared.
        pub clear_start_position_number: u16 = hex(3),
        /// Number of positions cleared.
        pub number_of_clear_positions: u16 = hex(3),
    }
}

wire! {
    /// 290H Position Data Range-Specification Continuous Write 3 (TTA only):
    /// a reserved `00`, a 4-digit start number, then records without numbers
    /// but with an extended-data byte each.
    ///
    /// Status **partial**: the manual page breaks off inside the response
    /// table, so the response's end (checksum, CR LF right after the count)
    /// is assumed, and its two swapped format strings were resolved by size.
    pub struct RangeWritePositionData2<'a> {
        /// Reserved, always `00`.
        pub reserved: Reserved = RESERVED,
        /// First position written.
        pub change_start_position_number: u16 = PositionStream::RANGE_3.start_field(),
        /// The records; count 4 hex digits.
        pub records: PositionRecords<'a> = PositionStream::RANGE_3.records(),
    }
}

wire! {
    /// 290H response (end of frame assumed standard, see the command).
    pub struct RangeWritePositionData2Response {
        /// Reserved, always `00`.
        pub reserved: Reserved = RESERVED,
        /// Echo of the start position.
        pub change_start_position_number: u16 = PositionStream::RANGE_3.start_field(),
        /// Positions written.
        pub number_of_changed_positions: u16 = PositionStream::RANGE_3.count_field(),
    }
}

wire! {
    /// 291H Change Position Data Continuous Write 3 (TTA only).
    ///
    /// Status **partial**, layout **inferred**: the printed table
    /// contradicts itself. This follows the reading that matches the
    /// manual's 84-character record arithmetic — reserved `00`, a 4-digit
    /// count, then 26DH-style records each with its own 4-digit position
    /// number and a trailing extended-data byte. The printed alternative
    /// (start number before the count, records without numbers) is not
    /// supported: such a frame fails to parse. Verify on hardware.
    pub struct ChangePositionData3<'a> {
        /// Reserved, always `00`.
        pub reserved: Reserved = RESERVED,
        /// The records; count 4 hex digits.
        pub records: PositionRecords<'a> = PositionStream::CHANGE_3.records(),
    }
}

wire! {
    /// 291H response.
    pub struct ChangePositionData3Response {
        /// Reserved, always `00`.
        pub reserved: Reserved = RESERVED,
        /// Positions written.
        pub number_of_changed_positions: u16 = PositionStream::CHANGE_3.count_field(),
    }
}

// ---------------------------------------------------------------- ports, flags

/// Port or flag states: the number of ports or flags, and one byte per 8
/// of them (the last possibly partly used). That bit 0 is the lowest port
/// of its byte is **inferred** from the axis-pattern rule.
pub type PortData<'a> = Units<'a, u8, FieldSpec>;

wire! {
    /// 20BH Input Port Query.
    pub struct InputPortQuery {
        /// First port: must be a category head number plus a multiple of 8
        /// (the category heads are the controller's, not in the protocol
        /// documents, so not checked here).
        pub query_start_port_number: u16 = hex(4),
        /// Number of ports asked for (any number).
        pub number_of_query_ports: u16 = hex(4),
    }
}

wire! {
    /// 20BH response. The count field holds a number of *ports*, any
    /// number; one byte follows per 8 of them, the last possibly partly
    /// used (TTA p. 20, 2003 p. 19).
    pub struct InputPortResponse<'a> {
        /// First port reported.
        pub response_start_port_number: u16 = hex(4),
        /// The number of ports and their states (1 = ON), 8 per byte.
        pub input_port_data: PortData<'a> = counted_per(hex(4), 8, 8192, hex(2)),
    }
}

wire! {
    /// 20CH Output Port Query.
    pub struct OutputPortQuery {
        /// First port: must be a category head number plus a multiple of 8
        /// (the category heads are the controller's, not in the protocol
        /// documents, so not checked here).
        pub query_start_port_number: u16 = hex(4),
        /// Number of ports asked for (any number).
        pub number_of_query_ports: u16 = hex(4),
    }
}

wire! {
    /// 20CH response, laid out as 20BH's.
    pub struct OutputPortResponse<'a> {
        /// First port reported.
        pub response_start_port_number: u16 = hex(4),
        /// The number of ports and their states, 8 per byte.
        pub output_port_data: PortData<'a> = counted_per(hex(4), 8, 8192, hex(2)),
    }
}

wire! {
    /// 20DH Flag Query.
    pub struct FlagQuery {
        /// Program number; `00` = global flags.
        pub program_number: u8 = hex(2),
        /// First flag: a category head number plus a multiple of 8 (not
        /// checked here, as for the ports).
        pub query_start_flag_number: u16 = hex(4),
        /// Number of flags asked for (any number).
        pub number_of_query_flags: u16 = hex(4),
    }
}

wire! {
    /// 20DH response: flags 8 per byte, counted like 20BH's ports.
    pub struct FlagResponse<'a> {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// First flag reported.
        pub response_start_flag_number: u16 = hex(4),
        /// The number of flags and their states, 8 per byte.
        pub flag_data: PortData<'a> = counted_per(hex(4), 8, 8192, hex(2)),
    }
}

wire! {
    /// 24AH Output Port Status Change.
    pub struct OutputPortChange {
        /// The port.
        pub output_port_number: u16 = hex(4),
        /// 0 OFF, 1 ON (manual p. 47).
        pub change_type: u8 = hex(1),
    }
}

wire! {
    /// 24BH Flag Status Change.
    pub struct FlagChange {
        /// Program number; `00` = global flags.
        pub program_number: u8 = hex(2),
        /// The flag.
        pub flag_number: u16 = hex(4),
        /// 0 OFF, 1 ON (the manuals' wording says "output port"; it sets the flag).
        pub change_type: u8 = hex(1),
    }
}

// ---------------------------------------------------------------- variables

/// Integer variables, signed 32-bit.
pub type IntegerValues<'a> = Repeated<'a, i32, FieldSpec>;
/// Real variables as sent; see [`WordOrder`] for the two orders.
pub type RealWires<'a> = Repeated<'a, RealWire, FieldSpec>;
/// String-variable characters, one code per 2 hex digits.
pub type CharCodes<'a> = Repeated<'a, u8, FieldSpec>;

wire! {
    /// 20EH Integer Variable Query.
    pub struct IntegerVariableQuery {
        /// Program number (0 = global variables).
        pub program_number: u8 = hex(2),
        /// First variable.
        pub query_start_variable_number: u16 = hex(3),
        /// Number of variables.
        pub number_of_query_variables: u8 = hex(2),
    }
}

wire! {
    /// 20EH response.
    pub struct IntegerVariableResponse<'a> {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// First variable reported.
        pub response_start_variable_number: u16 = hex(3),
        /// The values; count 2 hex digits.
        pub integer_variable_data: IntegerValues<'a> = counted(hex(2), 255, shex(8)),
    }
}

wire! {
    /// 20FH Real Variable Query.
    pub struct RealVariableQuery {
        /// Program number (0 = global variables).
        pub program_number: u8 = hex(2),
        /// First variable.
        pub query_start_variable_number: u16 = hex(3),
        /// Number of variables.
        pub number_of_query_variables: u8 = hex(2),
    }
}

wire! {
    /// 20FH response: doubles as 16 hex digits each, in the controller's
    /// configured [`WordOrder`] (apply it with [`RealWire::value`]).
    pub struct RealVariableResponse<'a> {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// First variable reported.
        pub response_start_variable_number: u16 = hex(3),
        /// The values as sent; count 2 hex digits.
        pub real_variable_data: RealWires<'a> =
            counted(hex(2), 255, hex(16)) => "IEEE-754 double bit pattern",
    }
}

wire! {
    /// 210H String Variable Query.
    pub struct StringVariableQuery {
        /// Program number (0 = global variables).
        pub program_number: u8 = hex(2),
        /// First variable.
        pub query_start_variable_number: u16 = hex(3),
        /// Number of variables (characters).
        pub number_of_query_variables: u8 = hex(2),
    }
}

wire! {
    /// 210H response: one character per variable, as its 2-digit code.
    pub struct StringVariableResponse<'a> {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// First variable reported.
        pub response_start_variable_number: u16 = hex(3),
        /// The character codes; count 2 hex digits.
        pub string_variable_data: CharCodes<'a> = counted(hex(2), 255, hex(2)) => "char code",
    }
}

wire! {
    /// 24CH Integer Variable Change.
    pub struct IntegerVariableChange<'a> {
        /// Program number (0 = global variables).
        pub program_number: u8 = hex(2),
        /// First variable written.
        pub change_start_variable_number: u16 = hex(3),
        /// The values; count 2 hex digits.
        pub integer_variable_data: IntegerValues<'a> = counted(hex(2), 255, shex(8)),
    }
}

wire! {
    /// 24CH response.
    pub struct IntegerVariableChangeResponse {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// Echo of the first variable.
        pub change_start_variable_number: u16 = hex(3),
        /// Variables written.
        pub number_of_changed_variables: u8 = hex(2),
    }
}

wire! {
    /// 24DH Real Variable Change. The manuals show only the plain digit
    /// order here; applying the controller's 20FH word order to writes too
    /// is **inferred** (check by writing and reading back one value).
    pub struct RealVariableChange<'a> {
        /// Program number (0 = global variables).
        pub program_number: u8 = hex(2),
        /// First variable written.
        pub change_start_variable_number: u16 = hex(3),
        /// The values as sent (see [`RealValue::to_wire`]); count 2 hex digits.
        pub real_variable_data: RealWires<'a> =
            counted(hex(2), 255, hex(16)) => "IEEE-754 double bit pattern",
    }
}

wire! {
    /// 24DH response.
    pub struct RealVariableChangeResponse {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// Echo of the first variable.
        pub change_start_variable_number: u16 = hex(3),
        /// Variables written.
        pub number_of_changed_variables: u8 = hex(2),
    }
}

wire! {
    /// 24EH String Variable Change: one character per variable.
    pub struct StringVariableChange<'a> {
        /// Program number (0 = global variables).
        pub program_number: u8 = hex(2),
        /// First variable written.
        pub change_start_variable_number: u16 = hex(3),
        /// The character codes; count 2 hex digits.
        pub string_variable_data: CharCodes<'a> = counted(hex(2), 255, hex(2)) => "char code",
    }
}

// ---------------------------------------------------------------- program status

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

// ---------------------------------------------------------------- motion

wire! {
    /// 232H Servo ON/OFF.
    pub struct ServoOnOff {
        /// Axes concerned.
        pub axis_pattern: AxisPattern = hex(2),
        /// 0 OFF, 1 ON.
        pub operation_type: u8 = hex(1),
    }
}

wire! {
    /// 233H Home Return.
    pub struct HomeReturn {
        /// Axes to home.
        pub axis_pattern: AxisPattern = hex(2),
        /// End-search speed (0 = parameter value).
        pub end_search_speed: u16 = hex(3) => "mm/s",
        /// Creep speed (0 = parameter value).
        pub creep_speed: u16 = hex(3) => "mm/s",
    }
}

wire! {
    /// 234H Absolute-Coordinate Specification Movement.
    pub struct AbsoluteMove {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration (0 = default).
        pub acceleration: u16 = hex(4) => "0.01G",
        /// Deceleration (0 = default).
        pub deceleration: u16 = hex(4) => "0.01G",
        /// Speed (0 = default).
        pub speed: u16 = hex(4) => "mm/s",
        /// Target coordinate per axis of the pattern, ascending.
        pub absolute_coordinate: PerAxis<i32> = per_axis(axis_pattern, shex(8)) => "0.001mm",
    }
}

wire! {
    /// 235H Relative-Coordinate Specification Movement.
    pub struct RelativeMove {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration (0 = default).
        pub acceleration: u16 = hex(4) => "0.01G",
        /// Deceleration (0 = default).
        pub deceleration: u16 = hex(4) => "0.01G",
        /// Speed (0 = default).
        pub speed: u16 = hex(4) => "mm/s",
        /// Distance per axis of the pattern, ascending.
        pub relative_distance: PerAxis<i32> = per_axis(axis_pattern, shex(8)) => "0.001mm",
    }
}

wire! {
    /// 236H Jogging/Inching (TTA p. 41, 2003 p. 37). On SCARA only one
    /// axis may be named, and only while no servo axis is moving.
    pub struct JogInch {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration (0 = parameter; SCARA each-axis: %).
        pub acceleration: u16 = hex(4) => "0.01G",
        /// Deceleration (0 = parameter; SCARA each-axis: %).
        pub deceleration: u16 = hex(4) => "0.01G",
        /// Speed (0 = parameter; SCARA each-axis: %).
        pub speed: u16 = hex(4) => "mm/s",
        /// Inching distance, a magnitude (unsigned; 0 = jog).
        pub inching_distance: u32 = hex(8) => "0.001mm",
        /// Bit 0: direction ([`JogInch::POSITIVE`] or
        /// [`JogInch::NEGATIVE`]); bits 1–2: coordinate system, SCARA only
        /// (`JogInch::BASE`, `WORK`, `TOOL`, `EACH_AXIS`); bit 3: reserved
        /// for the system (send 0).
        pub operation_type: u8 = hex(1),
    }
}

impl JogInch {
    /// Bit 0 = 0: towards the negative end of the coordinate axis.
    pub const NEGATIVE: u8 = 0b0000;
    /// Bit 0 = 1: towards the positive end of the coordinate axis.
    pub const POSITIVE: u8 = 0b0001;
    /// Bits 1–2 = 0 (SCARA): base coordinate system.
    pub const BASE: u8 = 0 << 1;
    /// Bits 1–2 = 1 (SCARA): the selected work coordinate system.
    pub const WORK: u8 = 1 << 1;
    /// Bits 1–2 = 2 (SCARA): the selected tool coordinate system.
    pub const TOOL: u8 = 2 << 1;
    /// Bits 1–2 = 3 (SCARA): each axis on its own.
    pub const EACH_AXIS: u8 = 3 << 1;

    /// Inching `axis` by `distance` (0.001 mm; 0 jogs instead) in
    /// `direction` ([`JogInch::POSITIVE`] or [`JogInch::NEGATIVE`], plus a
    /// coordinate system on SCARA).
    pub fn inch(axis: u8, distance: u32, direction: u8) -> Result<Self> {
        Ok(JogInch {
            axis_pattern: AxisPattern::of(&[axis])?,
            inching_distance: distance,
            operation_type: direction & 0b0111,
            ..Default::default()
        })
    }
}

wire! {
    /// 237H Position-Number Specification Movement (3-digit number).
    pub struct PositionNumberMove {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration (0 = the position's or default).
        pub acceleration: u16 = hex(4) => "0.01G",
        /// Deceleration.
        pub deceleration: u16 = hex(4) => "0.01G",
        /// Speed.
        pub speed: u16 = hex(4) => "mm/s",
        /// Target position number.
        pub position_number: u16 = hex(3),
    }
}

wire! {
    /// 238H Operation Stop & Cancel.
    pub struct OperationStop {
        /// Axes to stop.
        pub stop_axis_pattern: AxisPattern = hex(2),
        /// Appended command byte (bit meanings: manual p. 43).
        pub appended_command_byte: u8 = hex(2),
    }
}

wire! {
    /// 262H Speed Change.
    pub struct SpeedChange {
        /// Axes concerned.
        pub axis_pattern: AxisPattern = hex(2),
        /// New speed.
        pub speed: u16 = hex(4) => "mm/s",
    }
}

wire! {
    /// 26BH Position-Number Specification Movement 2 (4-digit number, TTA only).
    pub struct PositionNumberMove2 {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration.
        pub acceleration: u16 = hex(4) => "0.01G",
        /// Deceleration.
        pub deceleration: u16 = hex(4) => "0.01G",
        /// Speed.
        pub speed: u16 = hex(4) => "mm/s",
        /// Target position number (printed `XXX(h)`, but size 4).
        pub position_number: u16 = hex(4),
    }
}

// ---------------------------------------------------------------- program control, system

wire! {
    /// 252H Alarm Reset (no data).
    pub struct AlarmReset {}
}

wire! {
    /// 253H Program Run.
    pub struct ProgramRun {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 254H Program End.
    pub struct ProgramEnd {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 255H Program Pause.
    pub struct ProgramPause {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 256H Program One-Step Run.
    pub struct ProgramStep {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 257H Program Resume.
    pub struct ProgramResume {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 25BH Software Reset (no data). The controller sends **no** normal
    /// response (an error response is still possible) and accepts commands
    /// again after about 10 s; see
    /// [`catalogue::SOFTWARE_RESET`](crate::catalogue::SOFTWARE_RESET).
    pub struct SoftwareReset {}
}

wire! {
    /// 25CH Drive-Source Recovery Request (no data).
    pub struct DriveSourceRecovery {}
}

wire! {
    /// 25EH Operation Pause Cancellation Request (no data).
    pub struct PauseCancel {}
}

wire! {
    /// 271H Controller Function Specification 2 (TTA only): function word
    /// 9 and seven reserved words that must be `0000`. The words are
    /// cleared by power-off and software reset; send them again afterwards.
    pub struct ControllerFunction2 {
        /// Function word 9.
        pub function_word_9: u16 = hex(4),
        /// Reserved word 10.
        pub function_word_10: Reserved = Fixed(b"0000"),
        /// Reserved word 11.
        pub function_word_11: Reserved = Fixed(b"0000"),
        /// Reserved word 12.
        pub function_word_12: Reserved = Fixed(b"0000"),
        /// Reserved word 13.
        pub function_word_13: Reserved = Fixed(b"0000"),
        /// Reserved word 14.
        pub function_word_14: Reserved = Fixed(b"0000"),
        /// Reserved word 15.
        pub function_word_15: Reserved = Fixed(b"0000"),
        /// Reserved word 16.
        pub function_word_16: Reserved = Fixed(b"0000"),
    }
}

// ---------------------------------------------------------------- SCARA, coordinate systems

wire! {
    /// 2A0H Coordinate System Definition Data Range-Specification Continuous Query.
    pub struct CoordinateSystemQuery {
        /// Coordinate-system kind (manual p. 65).
        pub r#type: u8 = hex(1),
        /// First definition number.
        pub query_head_definition_number: u8 = hex(2),
        /// Number of definitions.
        pub number_of_query_records: u8 = hex(2),
    }
}

wire! {
    /// 2A0H response: each record is four signed offsets, X, Y, Z, R.
    pub struct CoordinateSystemResponse<'a> {
        /// Echo of the kind.
        pub r#type: u8 = hex(1),
        /// First definition reported.
        pub response_start_definition_number: u8 = hex(2),
        /// The records (R in 0.001 deg); count 2 hex digits, at most 128.
        pub coordinate_offset: Repeated<'a, [i32; 4], Array<FieldSpec>> =
            counted(hex(2), 128, Array(shex(8))) => "0.001mm",
    }
}

wire! {
    /// 2A1H SCARA Axis Status Query.
    pub struct ScaraAxisStatusQuery {
        /// Axes requested.
        pub query_axis_pattern: AxisPattern = hex(2),
        /// Coordinate type of the reported positions (bits 0–1).
        pub r#type: u8 = hex(1),
    }
}

wire! {
    /// 2A1H response: selections, common status, then a 212H-style block
    /// per axis (that block comes from the 2003 spec; the TTA page is lost).
    pub struct ScaraAxisStatusResponse {
        /// Selected work coordinate system.
        pub work_coordinate_selection: u8 = hex(2),
        /// Selected tool coordinate system.
        pub tool_coordinate_selection: u8 = hex(2),
        /// Arm system (bits 0–1: 0 right, 1 left, 2 indeterminable) and coordinate type.
        pub common_axis_status: u8 = hex(2),
        /// Axes reported (a missing axis = driver not connected).
        pub axis_pattern: AxisPattern = hex(2),
        /// Their status blocks.
        pub axes: PerAxis<AxisStatus> = per_axis(axis_pattern, Nested),
    }
}

wire! {
    /// One interference-check zone of a 2A2H response.
    pub struct InterferenceZone {
        /// Coordinate axes of the zone (at most 4).
        pub coordinate_axis_pattern: AxisPattern = hex(2),
        /// First corner, one value per axis.
        pub corner_1: PerAxis<i32> = per_axis_up_to(4, coordinate_axis_pattern, shex(8)) => "0.001mm",
        /// Opposite corner, one value per axis.
        pub corner_2: PerAxis<i32> = per_axis_up_to(4, coordinate_axis_pattern, shex(8)) => "0.001mm",
        /// Output port or global flag number.
        pub output_port_or_flag_number: u16 = hex(4),
        /// What an entry into the zone raises.
        pub entry_error_type: u8 = hex(2),
        /// Reserved.
        pub reserved_1: u8 = hex(2),
        /// Reserved.
        pub reserved_2: u8 = hex(2),
        /// Reserved.
        pub reserved_3: u8 = hex(2),
    }
}

wire! {
    /// 2A2H Simple-Interference-Check-Zone Definition Data Range-Specification Continuous Query.
    pub struct InterferenceZoneQuery {
        /// First zone.
        pub query_zone_number: u8 = hex(2),
        /// Number of zones.
        pub number_of_query_records: u8 = hex(2),
    }
}

wire! {
    /// 2A2H response (record tail and the 16-record maximum from the 2003 spec).
    pub struct InterferenceZoneResponse<'a> {
        /// First zone reported.
        pub zone_number: u8 = hex(2),
        /// The zones; count 2 hex digits, at most 16.
        pub zones: Repeated<'a, InterferenceZone, Nested> = counted(hex(2), 16, Nested),
    }
}

wire! {
    /// 2A3H SCARA Axis Status Query 2 (TTA only).
    pub struct ScaraAxisStatusQuery2 {
        /// Axes requested.
        pub query_axis_pattern: AxisPattern = hex(2),
        /// Coordinate types for axes 1–4 (bits 0–1) and 5–8 (bits 4–5);
        /// printed `X(h)` but size 2.
        pub r#type: u8 = hex(2),
    }
}

wire! {
    /// 2A3H response. Status **partial**: recovered up to the axes 5–8 work
    /// coordinate selection and the first byte of the per-axis block. The
    /// axes 5–8 tool selection and common status, the axis pattern and the
    /// rest of each per-axis block are **inferred** from 2A1H. Note the arm
    /// system codes differ from 2A1H (here 0 indeterminable, 1 right, 2 left).
    pub struct ScaraAxisStatusResponse2 {
        /// SCARA axes among the answered axes.
        pub scara_axis_pattern: AxisPattern = hex(2),
        /// Axes 1–4 work coordinate system.
        pub work_coordinate_selection_1_4: u8 = hex(2),
        /// Axes 1–4 tool coordinate system.
        pub tool_coordinate_selection_1_4: u8 = hex(2),
        /// Axes 1–4 arm system and coordinate type.
        pub common_status_1_4: u8 = hex(2),
        /// Axes 5–8 work coordinate system.
        pub work_coordinate_selection_5_8: u8 = hex(2),
        /// Axes 5–8 tool coordinate system (**inferred**).
        pub tool_coordinate_selection_5_8: u8 = hex(2),
        /// Axes 5–8 arm system and coordinate type (**inferred**).
        pub common_status_5_8: u8 = hex(2),
        /// Axes reported (**inferred**).
        pub axis_pattern: AxisPattern = hex(2),
        /// Their status blocks (all but the first byte **inferred**).
        pub axes: PerAxis<AxisStatus> = per_axis(axis_pattern, Nested),
    }
}

wire! {
    /// 2A4H Coordinate System Definition Data Range-Specification Continuous Query 2
    /// (TTA only): 2A0H with axis patterns.
    pub struct CoordinateSystemQuery2 {
        /// Axes requested.
        pub query_axis_pattern: AxisPattern = hex(2),
        /// Coordinate-system kind.
        pub r#type: u8 = hex(1),
        /// First definition number.
        pub query_head_definition_number: u8 = hex(2),
        /// Number of definitions.
        pub number_of_query_records: u8 = hex(2),
    }
}

wire! {
    /// 2A4H response: one offset per axis of the response pattern per
    /// record. The printed offsets ignore the axis-pattern row (copied from
    /// 2A0H); the row is kept and the offsets recomputed (**inferred**).
    pub struct CoordinateSystemResponse2<'a> {
        /// Axes reported.
        pub response_axis_pattern: AxisPattern = hex(2),
        /// Echo of the kind.
        pub r#type: u8 = hex(1),
        /// First definition reported.
        pub response_start_definition_number: u8 = hex(2),
        /// The records; count 2 hex digits.
        pub coordinate_offset: Repeated<'a, PerAxis<i32>, PerAxisCodec<FieldSpec>> =
            counted(hex(2), 255, per_axis(response_axis_pattern, shex(8))) => "0.001mm",
    }
}

wire! {
    /// 2D4H SCARA Absolute-Coordinate Specification Movement.
    pub struct ScaraAbsoluteMove {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration: % for PTP, 0.01 G for CP.
        pub acceleration: u16 = hex(4) => "% (PTP) or 0.01G (CP)",
        /// Deceleration: % for PTP, 0.01 G for CP.
        pub deceleration: u16 = hex(4) => "% (PTP) or 0.01G (CP)",
        /// Speed: % for PTP, mm/s for CP.
        pub speed: u16 = hex(4) => "% (PTP) or mm/s (CP)",
        /// PTP/CP and arm-system choice (manual p. 73).
        pub positioning_operation_type: u8 = hex(2),
        /// Target per axis, ascending.
        pub absolute_coordinate: PerAxis<i32> = per_axis(axis_pattern, shex(8)) => "0.001mm",
    }
}

wire! {
    /// 2D5H SCARA Relative-Coordinate Specification Movement.
    pub struct ScaraRelativeMove {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration: % for PTP, 0.01 G for CP.
        pub acceleration: u16 = hex(4) => "% (PTP) or 0.01G (CP)",
        /// Deceleration: % for PTP, 0.01 G for CP.
        pub deceleration: u16 = hex(4) => "% (PTP) or 0.01G (CP)",
        /// Speed: % for PTP, mm/s for CP.
        pub speed: u16 = hex(4) => "% (PTP) or mm/s (CP)",
        /// PTP/CP and arm-system choice.
        pub positioning_operation_type: u8 = hex(2),
        /// Distance per axis, ascending.
        pub relative_distance: PerAxis<i32> = per_axis(axis_pattern, shex(8)) => "0.001mm",
    }
}

wire! {
    /// 2D6H SCARA Position-Number Specification Movement.
    pub struct ScaraPositionNumberMove {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration: % for PTP, 0.01 G for CP.
        pub acceleration: u16 = hex(4) => "% (PTP) or 0.01G (CP)",
        /// Deceleration: % for PTP, 0.01 G for CP.
        pub deceleration: u16 = hex(4) => "% (PTP) or 0.01G (CP)",
        /// Speed: % for PTP, mm/s for CP.
        pub speed: u16 = hex(4) => "% (PTP) or mm/s (CP)",
        /// PTP/CP and arm-system choice.
        pub positioning_operation_type: u8 = hex(2),
        /// Target position number (row from the 2003 spec).
        pub position_number: u16 = hex(3),
    }
}

// ---------------------------------------------------------------- constructors

/// Builders for the acceleration, deceleration and speed that every
/// motion command carries (0 = the controller's parameter).
macro_rules! motion_profile {
    ($($ty:ident),* $(,)?) => {$(
        impl $ty {
            /// With this acceleration (0.01 G, or % on SCARA PTP).
            pub const fn with_acceleration(mut self, value: u16) -> Self {
                self.acceleration = value;
                self
            }
            /// With this deceleration (0.01 G, or % on SCARA PTP).
            pub const fn with_deceleration(mut self, value: u16) -> Self {
                self.deceleration = value;
                self
            }
            /// With this speed (mm/s, or % on SCARA PTP).
            pub const fn with_speed(mut self, value: u16) -> Self {
                self.speed = value;
                self
            }
        }
    )*};
}

motion_profile!(
    AbsoluteMove,
    RelativeMove,
    JogInch,
    PositionNumberMove,
    PositionNumberMove2,
    ScaraAbsoluteMove,
    ScaraRelativeMove,
    ScaraPositionNumberMove,
);

/// Constructors of the commands whose per-axis values follow an axis
/// pattern: built from `(axis, value)` pairs, so the two always agree.
macro_rules! per_axis_constructor {
    ($($ty:ident :: $ctor:ident => $values:ident, $what:literal;)*) => {$(
        impl $ty {
            #[doc = concat!("A command for the axes of `pairs`, each with its ", $what,
                " (0.001 mm, 0.001 deg on a rotary axis), in any order; the axis pattern is ",
                "derived from them. Acceleration, deceleration and speed are 0 (the ",
                "controller's parameters). An axis outside 1..=8 or named twice is ",
                "[`Error::InvalidAxis`](crate::Error::InvalidAxis).")]
            pub fn $ctor(pairs: &[(u8, i32)]) -> Result<Self> {
                let (axis_pattern, $values) = per_axis_values(pairs)?;
                Ok($ty { axis_pattern, $values, ..Default::default() })
            }
        }
    )*};
}

per_axis_constructor! {
    AbsoluteMove::to => absolute_coordinate, "target coordinate";
    RelativeMove::by => relative_distance, "distance";
    ScaraAbsoluteMove::to => absolute_coordinate, "target coordinate";
    ScaraRelativeMove::by => relative_distance, "distance";
}

impl AxisStatusQuery {
    /// The status of these axes (1..=8).
    pub fn of(axes: &[u8]) -> Result<Self> {
        Ok(AxisStatusQuery {
            query_axis_pattern: AxisPattern::of(axes)?,
        })
    }
}

impl ServoOnOff {
    /// Servo on (`true`) or off for these axes.
    pub fn new(axes: &[u8], on: bool) -> Result<Self> {
        Ok(ServoOnOff {
            axis_pattern: AxisPattern::of(axes)?,
            operation_type: u8::from(on),
        })
    }
}

impl HomeReturn {
    /// Home these axes at the parameters' speeds.
    pub fn of(axes: &[u8]) -> Result<Self> {
        Ok(HomeReturn {
            axis_pattern: AxisPattern::of(axes)?,
            ..Default::default()
        })
    }
}

// ---------------------------------------------------------------- data-less responses

bare_responses! {
    /// 232H response (no data).
    ServoOnOffResponse;
    /// 233H response (no data).
    HomeReturnResponse;
    /// 234H response (no data).
    AbsoluteMoveResponse;
    /// 235H response (no data).
    RelativeMoveResponse;
    /// 236H response (no data).
    JogInchResponse;
    /// 237H response (no data).
    PositionNumberMoveResponse;
    /// 238H response (no data).
    OperationStopResponse;
    /// 246H response (no data).
    ClearPositionDataResponse;
    /// 24AH response (no data).
    OutputPortChangeResponse;
    /// 24BH response (no data).
    FlagChangeResponse;
    /// 24EH response (no data, unlike 24CH/24DH).
    StringVariableChangeResponse;
    /// 252H response (no data).
    AlarmResetResponse;
    /// 253H response (no data).
    ProgramRunResponse;
    /// 254H response (no data).
    ProgramEndResponse;
    /// 255H response (no data).
    ProgramPauseResponse;
    /// 256H response (no data).
    ProgramStepResponse;
    /// 257H response (no data).
    ProgramResumeResponse;
    /// 25CH response (no data).
    DriveSourceRecoveryResponse;
    /// 25EH response (no data).
    PauseCancelResponse;
    /// 262H response (no data).
    SpeedChangeResponse;
    /// 26BH response (no data).
    PositionNumberMove2Response;
    /// 271H response (no data).
    ControllerFunction2Response;
    /// 2D4H response (no data).
    ScaraAbsoluteMoveResponse;
    /// 2D5H response (no data).
    ScaraRelativeMoveResponse;
    /// 2D6H response (no data).
    ScaraPositionNumberMoveResponse;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::checksum::BypassPolicy;
    use crate::frame::{Frame, Station};
    use crate::message::Message;

    const ST: Station = Station(0x99);

    fn parse<'a, M: Message<'a>>(bytes: &'a [u8]) -> crate::Result<M> {
        M::parse(&Frame::new_checked(bytes, BypassPolicy::CommandsOnly)?)
    }

    fn emit<'a, M: Message<'a>>(m: &M) -> ([u8; 64], usize) {
        let mut buf = [0u8; 64];
        let n = m.emit(ST, &mut buf).unwrap();
        assert_eq!(n, m.emit_len());
        (buf, n)
    }

    #[test]
    fn a_234h_move_of_two_axes() {
        // Axes 1 and 2, 0.30 G, 0.30 G, 100 mm/s, +400.000 mm and -400.000 mm.
        let wire = b"!9923403001E001E006400061A80FFF9E58092\r\n";
        let m = AbsoluteMove::to(&[(1, 400_000), (2, -400_000)])
            .unwrap()
            .with_acceleration(30)
            .with_deceleration(30)
            .with_speed(100);
        let (buf, n) = emit(&m);
        assert_eq!(&buf[..n], wire);
        assert_eq!(parse::<AbsoluteMove>(wire).unwrap(), m);
        assert_eq!(
            parse::<AbsoluteMoveResponse>(b"#992342E\r\n").unwrap(),
            AbsoluteMoveResponse {}
        );
        // The ID comes from the catalogue, reachable with `use message::*`.
        assert_eq!(AbsoluteMove::ID, 0x234);
    }

    #[test]
    fn the_2003_worked_example_is_a_209h_query() {
        // 2003 p. 10: query 5 records from point 001, SC 54.
        let q = parse::<EffectivePositionQuery>(b"!9920900100554\r\n").unwrap();
        assert_eq!(q.query_head_position_number, 1);
        assert_eq!(q.number_of_query_records, 5);
    }

    #[test]
    fn a_216h_record_number_is_only_for_type_5() {
        let (buf, n) = emit(&ErrorDetailQuery::latest_system_error());
        assert_eq!(&buf[..n], b"!992160010004D\r\n");
        let (buf, n) = emit(&ErrorDetailQuery::list_record_extended(1));
        assert_eq!(&buf[..n], b"!9921650000152\r\n");
        // Type 0 with a record number, and type 5 with a type 2: refused.
        assert_eq!(
            parse::<ErrorDetailQuery>(b"!992160010014E\r\n"),
            Err(crate::Error::ValueOutOfRange { offset: 9 })
        );
        let bad = ErrorDetailQuery {
            type_1: 5,
            type_2: 1,
            record_number: 1,
        };
        assert!(bad.emit(ST, &mut [0u8; 32]).is_err());
    }

    #[test]
    fn a_244h_range_write_and_its_reply_echo_the_start() {
        // One record without axes at position 010H.
        let rec = PositionRecord::new(0, 30, 30, 100, &[]).unwrap();
        let recs = [rec];
        let cmd = RangeWritePositionData {
            change_start_position_number: 0x10,
            records: Repeated::from_slice(&recs),
        };
        let (buf, n) = emit(&cmd);
        assert_eq!(&buf[..n], b"!9924401000100001E001E006425\r\n");
        let reply = parse::<RangeWritePositionDataResponse>(b"#9924401000151\r\n").unwrap();
        assert_eq!(reply.change_start_position_number, 0x10);
        assert_eq!(reply.number_of_changed_positions, 1);
    }

    #[test]
    fn per_axis_commands_cannot_be_built_wrong() {
        assert_eq!(
            AbsoluteMove::to(&[(1, 0), (1, 5)]),
            Err(crate::Error::InvalidAxis { axis: 1 })
        );
        assert_eq!(
            RelativeMove::by(&[(0, 5)]),
            Err(crate::Error::InvalidAxis { axis: 0 })
        );
        let m = RelativeMove::by(&[(4, -1), (2, 2)]).unwrap();
        assert_eq!(m.axis_pattern.bits(), 0b1010);
        assert_eq!(m.relative_distance.as_slice(), &[2, -1]);
    }
}
