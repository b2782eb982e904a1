//! I/O and variables: the port and flag queries (20BH, 20CH, 20DH) and
//! changes (24AH, 24BH), and the integer, real and string variable
//! queries (20EH, 20FH, 210H) and changes (24CH, 24DH, 24EH) (port
//! counts: TTA p. 20, 2003 p. 19; 24AH: manual p. 47). **Inferred**: that bit 0 of a port byte is its
//! lowest port, and that 24DH writes in the controller's 20FH word order.

use super::{bare_responses, hex, shex};
use crate::codec::*;
use crate::field::FieldSpec;
use crate::message::wire;

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

bare_responses! {
    /// 24AH response (no data).
    OutputPortChangeResponse;
    /// 24BH response (no data).
    FlagChangeResponse;
    /// 24EH response (no data, unlike 24CH/24DH).
    StringVariableChangeResponse;
}
