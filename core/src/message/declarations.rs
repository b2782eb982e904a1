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

use super::codec::*;
use super::wire;
use crate::axis::{AxisPattern, PerAxis};
use crate::field::FieldSpec;
use crate::position::{PositionRecord, RecordLayout};

/// Declares responses that carry no data (the bare 10-byte envelope).
macro_rules! bare_responses {
    ($( $(#[$m:meta])* $name:ident = $id:literal; )*) => {
        $( wire! { $(#[$m])* [response $id] pub struct $name {} } )*
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

// ---------------------------------------------------------------- 201H, 208H

wire! {
    /// 201H Version Code Query.
    [command 0x201]
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
    [response 0x201]
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
    [command 0x208]
    pub struct EffectivePositionCountQuery {}
}

wire! {
    /// 208H response.
    [response 0x208]
    pub struct EffectivePositionCountResponse {
        /// Defined (non-empty) records of the position table (3 digits).
        pub number_of_effective_positions: u16 = hex(3),
    }
}

// ---------------------------------------------------------------- position table

/// Position records as used by every position-table message.
pub type PositionRecords<'a> = Repeated<'a, PositionRecord, RecordLayout>;

wire! {
    /// 209H Effective Position Data Query (3-digit numbering).
    [command 0x209]
    pub struct EffectivePositionQuery {
        /// First position number of the window.
        pub query_head_position_number: u16 = hex(3),
        /// Window length (the controller's send buffer limits the answer).
        pub number_of_query_records: u16 = hex(3),
    }
}

wire! {
    /// 209H response: the defined records in the window (possibly fewer
    /// than asked), each with its 3-digit position number.
    [response 0x209]
    pub struct EffectivePositionResponse<'a> {
        /// The records; count field 3 hex digits, at most 3000.
        pub records: PositionRecords<'a> = counted(hex(3), 3000, RecordLayout::NUMBER_3),
    }
}

wire! {
    /// 21FH Effective Position Data Query 2 (4-digit numbering, TTA only).
    [command 0x21F]
    pub struct EffectivePositionQuery2 {
        /// First position number of the window.
        pub query_head_position_number: u16 = hex(4),
        /// Window length.
        pub number_of_query_records: u16 = hex(4),
    }
}

wire! {
    /// 21FH response. The manual prints "max 2000 records" but its own
    /// arithmetic gives 20,000, which is used here.
    [response 0x21F]
    pub struct EffectivePositionResponse2<'a> {
        /// The records; count field 4 hex digits.
        pub records: PositionRecords<'a> = counted(hex(4), 20_000, RecordLayout::NUMBER_4),
    }
}

wire! {
    /// 22DH Effective Position Data Query 3 (with extended data, TTA only).
    [command 0x22D]
    pub struct EffectivePositionQuery3 {
        /// Reserved, always `00`.
        pub reserved: Reserved = Fixed(b"00"),
        /// First position number of the window.
        pub query_head_position_number: u16 = hex(4),
        /// Window length.
        pub number_of_query_records: u16 = hex(4),
    }
}

wire! {
    /// 22DH response: records with a trailing extended-data byte.
    [response 0x22D]
    pub struct EffectivePositionResponse3<'a> {
        /// Reserved, always `00`.
        pub reserved: Reserved = Fixed(b"00"),
        /// The records; count field 4 hex digits.
        pub records: PositionRecords<'a> =
            counted(hex(4), 20_000, RecordLayout::NUMBER_4_EXTENDED),
    }
}

wire! {
    /// 244H Position Data Range-Specification Continuous Write: records
    /// without numbers, written to consecutive positions from a start.
    [command 0x244]
    pub struct RangeWritePositionData<'a> {
        /// First position written.
        pub change_start_position_number: u16 = hex(3),
        /// The records (their `number` is not sent); count 3 hex digits.
        pub records: PositionRecords<'a> = counted(hex(3), 3000, RecordLayout::RANGE),
    }
}

wire! {
    /// 244H response.
    [response 0x244]
    pub struct RangeWritePositionDataResponse {
        /// Echo of the start position.
        pub change_start_position_number: u16 = hex(3),
        /// Positions written.
        pub number_of_changed_positions: u16 = hex(3),
    }
}

wire! {
    /// 245H Change Position Data Continuous Write: records naming their own
    /// 3-digit position numbers.
    [command 0x245]
    pub struct ChangePositionData<'a> {
        /// The records; count 3 hex digits.
        pub records: PositionRecords<'a> = counted(hex(3), 3000, RecordLayout::NUMBER_3),
    }
}

wire! {
    /// 245H response.
    [response 0x245]
    pub struct ChangePositionDataResponse {
        /// Positions written.
        pub number_of_changed_positions: u16 = hex(3),
    }
}

wire! {
    /// 246H Position Data Clear.
    [command 0x246]
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
    [command 0x290]
    pub struct RangeWritePositionData2<'a> {
        /// Reserved, always `00`.
        pub reserved: Reserved = Fixed(b"00"),
        /// First position written.
        pub change_start_position_number: u16 = hex(4),
        /// The records; count 4 hex digits.
        pub records: PositionRecords<'a> =
            counted(hex(4), 20_000, RecordLayout::RANGE_EXTENDED),
    }
}

wire! {
    /// 290H response (end of frame assumed standard, see the command).
    [response 0x290]
    pub struct RangeWritePositionData2Response {
        /// Reserved, always `00`.
        pub reserved: Reserved = Fixed(b"00"),
        /// Echo of the start position.
        pub change_start_position_number: u16 = hex(4),
        /// Positions written.
        pub number_of_changed_positions: u16 = hex(4),
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
    [command 0x291]
    pub struct ChangePositionData3<'a> {
        /// Reserved, always `00`.
        pub reserved: Reserved = Fixed(b"00"),
        /// The records; count 4 hex digits.
        pub records: PositionRecords<'a> =
            counted(hex(4), 20_000, RecordLayout::NUMBER_4_EXTENDED),
    }
}

wire! {
    /// 291H response.
    [response 0x291]
    pub struct ChangePositionData3Response {
        /// Reserved, always `00`.
        pub reserved: Reserved = Fixed(b"00"),
        /// Positions written.
        pub number_of_changed_positions: u16 = hex(4),
    }
}

// ---------------------------------------------------------------- ports, flags

/// Port or flag bytes: 8 consecutive ports/flags per byte. That bit 0 is
/// the lowest port of the byte is **inferred** from the axis-pattern rule.
pub type BitBytes<'a> = Repeated<'a, u8, FieldSpec>;

wire! {
    /// 20BH Input Port Query.
    [command 0x20B]
    pub struct InputPortQuery {
        /// First port: a category head number plus a multiple of 8.
        pub query_start_port_number: u16 = hex(4),
        /// Number of ports asked for.
        pub number_of_query_ports: u16 = hex(4),
    }
}

wire! {
    /// 20BH response. The count field holds a number of *ports*; one byte
    /// follows per 8 ports. The catalogue does not say how other counts
    /// round, so a count that is not a multiple of 8 is refused.
    [response 0x20B]
    pub struct InputPortResponse<'a> {
        /// First port reported.
        pub response_start_port_number: u16 = hex(4),
        /// Port states (1 = ON), 8 per byte; the count written is 8 × bytes.
        pub input_port_data: BitBytes<'a> = counted_per(hex(4), 8, 8192, hex(2)),
    }
}

wire! {
    /// 20CH Output Port Query.
    [command 0x20C]
    pub struct OutputPortQuery {
        /// First port: a category head number plus a multiple of 8.
        pub query_start_port_number: u16 = hex(4),
        /// Number of ports asked for.
        pub number_of_query_ports: u16 = hex(4),
    }
}

wire! {
    /// 20CH response, laid out as 20BH's.
    [response 0x20C]
    pub struct OutputPortResponse<'a> {
        /// First port reported.
        pub response_start_port_number: u16 = hex(4),
        /// Port states, 8 per byte; the count written is 8 × bytes.
        pub output_port_data: BitBytes<'a> = counted_per(hex(4), 8, 8192, hex(2)),
    }
}

wire! {
    /// 20DH Flag Query.
    [command 0x20D]
    pub struct FlagQuery {
        /// Program number; `00` = global flags.
        pub program_number: u8 = hex(2),
        /// First flag: a category head number plus a multiple of 8.
        pub query_start_flag_number: u16 = hex(4),
        /// Number of flags asked for.
        pub number_of_query_flags: u16 = hex(4),
    }
}

wire! {
    /// 20DH response: flags 8 per byte, counted like 20BH's ports.
    [response 0x20D]
    pub struct FlagResponse<'a> {
        /// Echo of the program number.
        pub program_number: u8 = hex(2),
        /// First flag reported.
        pub response_start_flag_number: u16 = hex(4),
        /// Flag states, 8 per byte; the count written is 8 × bytes.
        pub flag_data: BitBytes<'a> = counted_per(hex(4), 8, 8192, hex(2)),
    }
}

wire! {
    /// 24AH Output Port Status Change.
    [command 0x24A]
    pub struct OutputPortChange {
        /// The port.
        pub output_port_number: u16 = hex(4),
        /// 0 OFF, 1 ON (manual p. 47).
        pub change_type: u8 = hex(1),
    }
}

wire! {
    /// 24BH Flag Status Change.
    [command 0x24B]
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
    [command 0x20E]
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
    [response 0x20E]
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
    [command 0x20F]
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
    [response 0x20F]
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
    [command 0x210]
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
    [response 0x210]
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
    [command 0x24C]
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
    [response 0x24C]
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
    [command 0x24D]
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
    [response 0x24D]
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
    [command 0x24E]
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
    [command 0x213]
    pub struct ProgramStatusQuery {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 213H response.
    [response 0x213]
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
    [command 0x232]
    pub struct ServoOnOff {
        /// Axes concerned.
        pub axis_pattern: AxisPattern = hex(2),
        /// 0 OFF, 1 ON.
        pub operation_type: u8 = hex(1),
    }
}

wire! {
    /// 233H Home Return.
    [command 0x233]
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
    [command 0x234]
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
    [command 0x235]
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
    /// 236H Jogging/Inching.
    [command 0x236]
    pub struct JogInch {
        /// Axes to move.
        pub axis_pattern: AxisPattern = hex(2),
        /// Acceleration.
        pub acceleration: u16 = hex(4) => "0.01G",
        /// Deceleration.
        pub deceleration: u16 = hex(4) => "0.01G",
        /// Speed.
        pub speed: u16 = hex(4) => "mm/s",
        /// Inching distance, a magnitude (unsigned; 0 = jog).
        pub inching_distance: u32 = hex(8) => "0.001mm",
        /// Direction / start-stop code (manual p. 41).
        pub operation_type: u8 = hex(1),
    }
}

wire! {
    /// 237H Position-Number Specification Movement (3-digit number).
    [command 0x237]
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
    [command 0x238]
    pub struct OperationStop {
        /// Axes to stop.
        pub stop_axis_pattern: AxisPattern = hex(2),
        /// Appended command byte (bit meanings: manual p. 43).
        pub appended_command_byte: u8 = hex(2),
    }
}

wire! {
    /// 262H Speed Change.
    [command 0x262]
    pub struct SpeedChange {
        /// Axes concerned.
        pub axis_pattern: AxisPattern = hex(2),
        /// New speed.
        pub speed: u16 = hex(4) => "mm/s",
    }
}

wire! {
    /// 26BH Position-Number Specification Movement 2 (4-digit number, TTA only).
    [command 0x26B]
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
    [command 0x252]
    pub struct AlarmReset {}
}

wire! {
    /// 253H Program Run.
    [command 0x253]
    pub struct ProgramRun {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 254H Program End.
    [command 0x254]
    pub struct ProgramEnd {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 255H Program Pause.
    [command 0x255]
    pub struct ProgramPause {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 256H Program One-Step Run.
    [command 0x256]
    pub struct ProgramStep {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 257H Program Resume.
    [command 0x257]
    pub struct ProgramResume {
        /// Program number.
        pub program_number: u8 = hex(2),
    }
}

wire! {
    /// 25BH Software Reset (no data). The controller sends **no** normal
    /// response (an error response is still possible) and accepts commands
    /// again after about 10 s; see
    /// [`CommandInfo::HAS_NORMAL_RESPONSE`](crate::message::CommandInfo::HAS_NORMAL_RESPONSE).
    [command 0x25B]
    pub struct SoftwareReset {}
}

wire! {
    /// 25CH Drive-Source Recovery Request (no data).
    [command 0x25C]
    pub struct DriveSourceRecovery {}
}

wire! {
    /// 25EH Operation Pause Cancellation Request (no data).
    [command 0x25E]
    pub struct PauseCancel {}
}

wire! {
    /// 271H Controller Function Specification 2 (TTA only): function word
    /// 9 and seven reserved words that must be `0000`. The words are
    /// cleared by power-off and software reset; send them again afterwards.
    [command 0x271]
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
    [command 0x2A0]
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
    [response 0x2A0]
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
    [command 0x2A1]
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
    [response 0x2A1]
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
    [command 0x2A2]
    pub struct InterferenceZoneQuery {
        /// First zone.
        pub query_zone_number: u8 = hex(2),
        /// Number of zones.
        pub number_of_query_records: u8 = hex(2),
    }
}

wire! {
    /// 2A2H response (record tail and the 16-record maximum from the 2003 spec).
    [response 0x2A2]
    pub struct InterferenceZoneResponse<'a> {
        /// First zone reported.
        pub zone_number: u8 = hex(2),
        /// The zones; count 2 hex digits, at most 16.
        pub zones: Repeated<'a, InterferenceZone, Nested> = counted(hex(2), 16, Nested),
    }
}

wire! {
    /// 2A3H SCARA Axis Status Query 2 (TTA only).
    [command 0x2A3]
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
    [response 0x2A3]
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
    [command 0x2A4]
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
    [response 0x2A4]
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
    [command 0x2D4]
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
    [command 0x2D5]
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
    [command 0x2D6]
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

// ---------------------------------------------------------------- data-less responses

bare_responses! {
    /// 232H response (no data).
    ServoOnOffResponse = 0x232;
    /// 233H response (no data).
    HomeReturnResponse = 0x233;
    /// 234H response (no data).
    AbsoluteMoveResponse = 0x234;
    /// 235H response (no data).
    RelativeMoveResponse = 0x235;
    /// 236H response (no data).
    JogInchResponse = 0x236;
    /// 237H response (no data).
    PositionNumberMoveResponse = 0x237;
    /// 238H response (no data).
    OperationStopResponse = 0x238;
    /// 246H response (no data).
    ClearPositionDataResponse = 0x246;
    /// 24AH response (no data).
    OutputPortChangeResponse = 0x24A;
    /// 24BH response (no data).
    FlagChangeResponse = 0x24B;
    /// 24EH response (no data, unlike 24CH/24DH).
    StringVariableChangeResponse = 0x24E;
    /// 252H response (no data).
    AlarmResetResponse = 0x252;
    /// 253H response (no data).
    ProgramRunResponse = 0x253;
    /// 254H response (no data).
    ProgramEndResponse = 0x254;
    /// 255H response (no data).
    ProgramPauseResponse = 0x255;
    /// 256H response (no data).
    ProgramStepResponse = 0x256;
    /// 257H response (no data).
    ProgramResumeResponse = 0x257;
    /// 25CH response (no data).
    DriveSourceRecoveryResponse = 0x25C;
    /// 25EH response (no data).
    PauseCancelResponse = 0x25E;
    /// 262H response (no data).
    SpeedChangeResponse = 0x262;
    /// 26BH response (no data).
    PositionNumberMove2Response = 0x26B;
    /// 271H response (no data).
    ControllerFunction2Response = 0x271;
    /// 2D4H response (no data).
    ScaraAbsoluteMoveResponse = 0x2D4;
    /// 2D5H response (no data).
    ScaraRelativeMoveResponse = 0x2D5;
    /// 2D6H response (no data).
    ScaraPositionNumberMoveResponse = 0x2D6;
}
