//! Decoding any frame into its typed message.
//!
//! The catalogue below is the one list of message IDs with their command and
//! response types; the [`Command`] and [`Response`] enums, [`decode_any`],
//! [`message_name`], [`message_status`] and [`has_normal_response`] are all
//! generated from it.
//!
//! ```
//! use iai_protocol_b::checksum::BypassPolicy;
//! use iai_protocol_b::frame::Frame;
//! use iai_protocol_b::message::{decode_any, AnyMessage, Response};
//! let frame = Frame::new_checked(b"#992322C\r\n", BypassPolicy::default()).unwrap();
//! let decoded = decode_any(&frame).unwrap();
//! assert!(matches!(decoded.message, AnyMessage::Response(Response::ServoOnOffResponse(_))));
//! assert_eq!(decoded.frame.as_bytes(), b"#992322C\r\n");
//! ```

use super::codec::{Fields, Visitor};
use super::declarations::*;
use super::Message;
use crate::checksum::ChecksumMode;
use crate::error::{Error, Result};
use crate::frame::{emit_frame, Frame, Header, Station};

/// How completely the sources document a message (`status` in `messages.toml`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Status {
    /// Every field of both directions is documented.
    Complete,
    /// Some rows are missing or contradictory; the declared layout is the
    /// catalogue's chosen reading (see the type's documentation).
    Partial,
}

/// Facts about a command that are not part of its layout.
pub trait CommandInfo {
    /// Message ID.
    const ID: u16;
    /// Catalogue name.
    const NAME: &'static str;
    /// `false` only for 25BH (software reset): the controller never sends a
    /// normal response, so a host must not wait for or retry one.
    const HAS_NORMAL_RESPONSE: bool;
    /// Documentation status of the message.
    const STATUS: Status;
}

/// The error response: `&` + station + 3-digit error code, no message ID
/// and no data. The code's meaning is in the controller's manual, not in
/// the protocol documents.
///
/// ```
/// use iai_protocol_b::message::ErrorResponse;
/// use iai_protocol_b::frame::Station;
/// let mut buf = [0u8; 16];
/// let n = ErrorResponse { code: 0xABC }.emit(Station(0x99), &mut buf).unwrap();
/// assert_eq!(&buf[..n], b"&99ABC5E\r\n");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ErrorResponse {
    /// The error code (3 hex digits, 0..=0xFFF).
    pub code: u16,
}

impl ErrorResponse {
    /// Parses a checked `&` (or `%`) frame.
    pub fn parse(frame: &Frame<'_>) -> Result<Self> {
        if frame.header() != Header::Error {
            return Err(Error::UnexpectedHeader {
                expected: Header::Error,
                found: frame.header(),
            });
        }
        frame.reader().finish()?;
        Ok(ErrorResponse { code: frame.code() })
    }

    /// Emits the 10-byte frame with a computed checksum.
    pub fn emit(&self, station: Station, buf: &mut [u8]) -> Result<usize> {
        self.emit_with(station, ChecksumMode::Compute, buf)
    }

    /// Emits the frame with the given checksum mode.
    pub fn emit_with(&self, station: Station, mode: ChecksumMode, buf: &mut [u8]) -> Result<usize> {
        if self.code > 0xFFF {
            return Err(Error::ValueOutOfRange { offset: 3 });
        }
        emit_frame(buf, Header::Error, station, self.code, mode, |_| Ok(()))
    }
}

macro_rules! yes {
    ($t:ident) => {
        true
    };
}

macro_rules! catalogue {
    ( $(
        ($id:literal, $name:literal, $status:ident,
         $cmd:ident $(<$cl:lifetime>)?, $( $resp:ident $(<$rl:lifetime>)? )? $(-)?)
    ),* $(,)? ) => {
        /// Every message ID of the catalogue, ascending.
        pub const MESSAGE_IDS: &[u16] = &[ $( $id ),* ];

        /// The catalogue name of a message ID.
        pub const fn message_name(id: u16) -> Option<&'static str> {
            match id { $( $id => Some($name), )* _ => None }
        }

        /// The documentation status of a message ID.
        pub const fn message_status(id: u16) -> Option<Status> {
            match id { $( $id => Some(Status::$status), )* _ => None }
        }

        /// Whether the controller answers command `id` with a normal
        /// response (`false` for 25BH and for unknown IDs).
        pub const fn has_normal_response(id: u16) -> bool {
            match id { $( $id => false $( || yes!($resp) )?, )* _ => false }
        }

        $(
            impl<'a> CommandInfo for $cmd $(<$cl>)? {
                const ID: u16 = $id;
                const NAME: &'static str = $name;
                const HAS_NORMAL_RESPONSE: bool = false $( || yes!($resp) )?;
                const STATUS: Status = Status::$status;
            }
        )*

        /// Any typed command.
        #[derive(Debug, Clone, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Command<'a> { $(
            #[doc = concat!("Command ", stringify!($id), " (", $name, ").")]
            $cmd($cmd $(<$cl>)?),
        )* }

        /// Any typed normal response.
        #[derive(Debug, Clone, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Response<'a> { $( $(
            #[doc = concat!("Normal response to ", stringify!($id), " (", $name, ").")]
            $resp($resp $(<$rl>)?),
        )? )* }

        impl<'a> Command<'a> {
            /// Parses a checked `!` frame as the command its ID names.
            pub fn parse(frame: &Frame<'a>) -> Result<Self> {
                match frame.code() {
                    $( $id => <$cmd $(<$cl>)? as Message<'a>>::parse(frame).map(Command::$cmd), )*
                    id => Err(Error::UnknownMessageId { id }),
                }
            }
            /// The message ID.
            pub fn id(&self) -> u16 {
                match self { $( Command::$cmd(_) => $id, )* }
            }
            /// Emits the whole frame (computed checksum); returns its length.
            pub fn emit(&self, station: Station, buf: &mut [u8]) -> Result<usize> {
                self.emit_with(station, ChecksumMode::Compute, buf)
            }
            /// Emits the whole frame with the given checksum mode.
            pub fn emit_with(&self, station: Station, mode: ChecksumMode, buf: &mut [u8]) -> Result<usize> {
                match self { $( Command::$cmd(m) => m.emit_with(station, mode, buf), )* }
            }
        }

        impl Fields for Command<'_> {
            fn fields(&self, v: &mut dyn Visitor) {
                match self { $( Command::$cmd(m) => m.fields(v), )* }
            }
        }

        impl<'a> Response<'a> {
            /// Parses a checked `#` frame as the response its ID names.
            /// 25BH has no normal response: [`Error::UnknownMessageId`].
            pub fn parse(frame: &Frame<'a>) -> Result<Self> {
                match frame.code() {
                    $( $( $id => <$resp $(<$rl>)? as Message<'a>>::parse(frame).map(Response::$resp), )? )*
                    id => Err(Error::UnknownMessageId { id }),
                }
            }
            /// The message ID.
            pub fn id(&self) -> u16 {
                match self { $( $( Response::$resp(_) => $id, )? )* }
            }
            /// Emits the whole frame (computed checksum); returns its length.
            pub fn emit(&self, station: Station, buf: &mut [u8]) -> Result<usize> {
                self.emit_with(station, ChecksumMode::Compute, buf)
            }
            /// Emits the whole frame with the given checksum mode.
            pub fn emit_with(&self, station: Station, mode: ChecksumMode, buf: &mut [u8]) -> Result<usize> {
                match self { $( $( Response::$resp(m) => m.emit_with(station, mode, buf), )? )* }
            }
        }

        impl Command<'static> {
            /// Command `id` with every field at its default (zeros, empty
            /// groups). `None` for unknown IDs.
            pub fn default_for(id: u16) -> Option<Self> {
                match id {
                    $( $id => Some(Command::$cmd(<$cmd>::default())), )*
                    _ => None,
                }
            }
        }

        impl Response<'static> {
            /// The response to command `id` with every field at its default
            /// (zeros, empty groups): a valid frame, e.g. for a simulator.
            /// `None` for 25BH (no normal response) and unknown IDs.
            pub fn default_for(id: u16) -> Option<Self> {
                match id {
                    $( $( $id => Some(Response::$resp(<$resp>::default())), )? )*
                    _ => None,
                }
            }
        }

        impl Fields for Response<'_> {
            fn fields(&self, v: &mut dyn Visitor) {
                match self { $( $( Response::$resp(m) => m.fields(v), )? )* }
            }
        }
    };
}

catalogue! {
    (0x200, "Test Call", Complete, TestCall, TestCallResponse),
    (0x201, "Version Code Query", Complete, VersionQuery, VersionResponse),
    (0x208, "Number of Effective Position Data Query", Complete,
        EffectivePositionCountQuery, EffectivePositionCountResponse),
    (0x209, "Effective Position Data Query", Complete,
        EffectivePositionQuery, EffectivePositionResponse<'a>),
    (0x20B, "Input Port Query", Complete, InputPortQuery, InputPortResponse<'a>),
    (0x20C, "Output Port Query", Complete, OutputPortQuery, OutputPortResponse<'a>),
    (0x20D, "Flag Query", Complete, FlagQuery, FlagResponse<'a>),
    (0x20E, "Integer Variable Query", Complete, IntegerVariableQuery, IntegerVariableResponse<'a>),
    (0x20F, "Real Variable Query", Complete, RealVariableQuery, RealVariableResponse<'a>),
    (0x210, "String Variable Query", Complete, StringVariableQuery, StringVariableResponse<'a>),
    (0x212, "Axis Status Query", Complete, AxisStatusQuery, AxisStatusResponse),
    (0x213, "Program Status Query", Complete, ProgramStatusQuery, ProgramStatusResponse),
    (0x215, "System Status Query", Complete, SystemStatusQuery, SystemStatusResponse),
    (0x216, "Error Detail Information Query", Complete, ErrorDetailQuery, ErrorDetailResponse<'a>),
    (0x21F, "Effective Position Data Query 2", Complete,
        EffectivePositionQuery2, EffectivePositionResponse2<'a>),
    (0x22D, "Effective Position Data Query 3", Complete,
        EffectivePositionQuery3, EffectivePositionResponse3<'a>),
    (0x232, "Servo ON/OFF", Complete, ServoOnOff, ServoOnOffResponse),
    (0x233, "Home Return", Complete, HomeReturn, HomeReturnResponse),
    (0x234, "Absolute-Coordinate Specification Movement", Complete, AbsoluteMove, AbsoluteMoveResponse),
    (0x235, "Relative-Coordinate Specification Movement", Complete, RelativeMove, RelativeMoveResponse),
    (0x236, "Jogging/Inching", Complete, JogInch, JogInchResponse),
    (0x237, "Position-Number Specification Movement", Complete,
        PositionNumberMove, PositionNumberMoveResponse),
    (0x238, "Operation Stop & Cancel", Complete, OperationStop, OperationStopResponse),
    (0x244, "Position Data Range-Specification Continuous Write", Complete,
        RangeWritePositionData<'a>, RangeWritePositionDataResponse),
    (0x245, "Change Position Data Continuous Write", Complete,
        ChangePositionData<'a>, ChangePositionDataResponse),
    (0x246, "Position Data Clear", Complete, ClearPositionData, ClearPositionDataResponse),
    (0x24A, "Output Port Status Change", Complete, OutputPortChange, OutputPortChangeResponse),
    (0x24B, "Flag Status Change", Complete, FlagChange, FlagChangeResponse),
    (0x24C, "Integer Variable Change", Complete,
        IntegerVariableChange<'a>, IntegerVariableChangeResponse),
    (0x24D, "Real Variable Change", Complete, RealVariableChange<'a>, RealVariableChangeResponse),
    (0x24E, "String Variable Change", Complete,
        StringVariableChange<'a>, StringVariableChangeResponse),
    (0x252, "Alarm Reset", Complete, AlarmReset, AlarmResetResponse),
    (0x253, "Program Run", Complete, ProgramRun, ProgramRunResponse),
    (0x254, "Program End", Complete, ProgramEnd, ProgramEndResponse),
    (0x255, "Program Pause", Complete, ProgramPause, ProgramPauseResponse),
    (0x256, "Program One-Step Run", Complete, ProgramStep, ProgramStepResponse),
    (0x257, "Program Resume", Complete, ProgramResume, ProgramResumeResponse),
    (0x25B, "Software Reset", Complete, SoftwareReset, -),
    (0x25C, "Drive-Source Recovery Request", Complete, DriveSourceRecovery, DriveSourceRecoveryResponse),
    (0x25E, "Operation Pause Cancellation Request", Complete, PauseCancel, PauseCancelResponse),
    (0x262, "Speed Change", Complete, SpeedChange, SpeedChangeResponse),
    (0x26B, "Position-Number Specification Movement 2", Complete,
        PositionNumberMove2, PositionNumberMove2Response),
    (0x26D, "Change Position Data Continuous Write 2", Complete,
        ChangePositionData2<'a>, ChangePositionData2Response),
    (0x271, "Controller Function Specification 2", Complete,
        ControllerFunction2, ControllerFunction2Response),
    (0x290, "Position Data Range-Specification Continuous Write 3", Partial,
        RangeWritePositionData2<'a>, RangeWritePositionData2Response),
    (0x291, "Change Position Data Continuous Write 3", Partial,
        ChangePositionData3<'a>, ChangePositionData3Response),
    (0x2A0, "Coordinate System Definition Data Range-Specification Continuous Query", Complete,
        CoordinateSystemQuery, CoordinateSystemResponse<'a>),
    (0x2A1, "SCARA Axis Status Query", Complete, ScaraAxisStatusQuery, ScaraAxisStatusResponse),
    (0x2A2, "Simple-Interference-Check-Zone Definition Data Range-Specification Continuous Query", Complete,
        InterferenceZoneQuery, InterferenceZoneResponse<'a>),
    (0x2A3, "SCARA Axis Status Query 2", Partial, ScaraAxisStatusQuery2, ScaraAxisStatusResponse2),
    (0x2A4, "Coordinate System Definition Data Range-Specification Continuous Query 2", Complete,
        CoordinateSystemQuery2, CoordinateSystemResponse2<'a>),
    (0x2D4, "SCARA Absolute-Coordinate Specification Movement", Complete,
        ScaraAbsoluteMove, ScaraAbsoluteMoveResponse),
    (0x2D5, "SCARA Relative-Coordinate Specification Movement", Complete,
        ScaraRelativeMove, ScaraRelativeMoveResponse),
    (0x2D6, "SCARA Position-Number Specification Movement", Complete,
        ScaraPositionNumberMove, ScaraPositionNumberMoveResponse),
}

/// A typed command, normal response or error response.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AnyMessage<'a> {
    /// A `!` frame.
    Command(Command<'a>),
    /// A `#` frame.
    Response(Response<'a>),
    /// A `&` frame.
    Error(ErrorResponse),
}

impl Fields for AnyMessage<'_> {
    fn fields(&self, v: &mut dyn Visitor) {
        match self {
            AnyMessage::Command(m) => m.fields(v),
            AnyMessage::Response(m) => m.fields(v),
            AnyMessage::Error(e) => v.field(
                "error_code",
                "",
                crate::field::FieldSpec::hex(3),
                super::codec::Value::Unsigned(e.code.into()),
            ),
        }
    }
}

/// A frame together with its typed meaning.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Decoded<'a> {
    /// The raw frame.
    pub frame: Frame<'a>,
    /// What it says.
    pub message: AnyMessage<'a>,
}

/// Decodes any checked frame: by header into command, normal response or
/// error response, then by message ID into its type. An ID outside the
/// catalogue (or a `#` frame for 25BH, which has no normal response) is
/// [`Error::UnknownMessageId`]; the caller still holds the frame.
pub fn decode_any<'a>(frame: &Frame<'a>) -> Result<Decoded<'a>> {
    let message = match frame.header() {
        Header::Command => AnyMessage::Command(Command::parse(frame)?),
        Header::Response => AnyMessage::Response(Response::parse(frame)?),
        Header::Error => AnyMessage::Error(ErrorResponse::parse(frame)?),
    };
    Ok(Decoded {
        frame: *frame,
        message,
    })
}
