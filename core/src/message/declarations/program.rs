//! Program control and system commands: 252H Alarm Reset, the program
//! commands 253H-257H, 25BH Software Reset (no normal response, 2003
//! p. 50), 25CH Drive-Source Recovery, 25EH Pause Cancellation and 271H
//! Controller Function Specification 2 (TTA only).

use super::{bare_responses, hex};
use crate::codec::*;
use crate::message::wire;

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

bare_responses! {
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
    /// 271H response (no data).
    ControllerFunction2Response;
}
