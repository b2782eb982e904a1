//! Decoding any frame into its typed message.
//!
//! The table below binds each [`crate::catalogue`] entry to its command and
//! response types; the [`Message`] and [`Request`] implementations, the
//! [`Command`] and [`Response`] enums and [`decode_any`] are generated from
//! it. It names catalogue entries, never raw IDs.
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

use super::declarations::*;
use super::{Message, Request};
use crate::catalogue::{self, MessageInfo};
use crate::checksum::ChecksumMode;
use crate::codec::{Fields, Visitor};
use crate::error::{Error, Result};
use crate::frame::{emit_frame, Frame, Header, Station};

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

/// 25BH's "response": the controller sends no normal response to a
/// software reset (2003 p. 50). [`Request::Response`] of
/// [`SoftwareReset`]; parsing or emitting one always fails with
/// [`Error::UnknownMessageId`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NoNormalResponse;

impl<'r> super::Wire<'r> for NoNormalResponse {
    fn read(_: &mut crate::field::Reader<'r>) -> Result<Self> {
        Err(Error::UnknownMessageId {
            id: catalogue::SOFTWARE_RESET.id,
        })
    }
    fn write(&self, _: &mut crate::field::Writer<'_>) -> Result<()> {
        Err(Error::UnknownMessageId {
            id: catalogue::SOFTWARE_RESET.id,
        })
    }
    fn wire_len(&self) -> usize {
        0
    }
}

impl<'r> Message<'r> for NoNormalResponse {
    const INFO: &'static MessageInfo = &catalogue::SOFTWARE_RESET;
    const HEADER: Header = Header::Response;
}

macro_rules! bind {
    ( $(
        ($info:ident, $cmd:ident $(<$cl:lifetime>)?, $resp:ident $(<$rl:lifetime>)?)
    ),* $(,)? ) => {
        $(
            impl<'a> Message<'a> for $cmd $(<$cl>)? {
                const INFO: &'static MessageInfo = &catalogue::$info;
                const HEADER: Header = Header::Command;
            }
            impl<'a> Request<'a> for $cmd $(<$cl>)? {
                type Response<'r> = $resp $(<$rl>)?;
            }
        )*
        bind!(@responses $( $info, $resp $(<$rl>)?; )*);

        /// Any typed command.
        #[derive(Debug, Clone, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Command<'a> { $(
            #[doc = concat!("Command ", stringify!($cmd), ".")]
            $cmd($cmd $(<$cl>)?),
        )* }

        impl<'a> Command<'a> {
            /// Parses a checked `!` frame as the command its ID names.
            pub fn parse(frame: &Frame<'a>) -> Result<Self> {
                match frame.code() {
                    $( id if id == catalogue::$info.id =>
                        <$cmd $(<$cl>)? as Message<'a>>::parse(frame).map(Command::$cmd), )*
                    id => Err(Error::UnknownMessageId { id }),
                }
            }
            /// The catalogue entry.
            pub fn info(&self) -> &'static MessageInfo {
                match self { $( Command::$cmd(_) => &catalogue::$info, )* }
            }
            /// The message ID.
            pub fn id(&self) -> u16 {
                self.info().id
            }
            /// Length of the frame [`Command::emit`] writes.
            pub fn emit_len(&self) -> usize {
                match self { $( Command::$cmd(m) => m.emit_len(), )* }
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

        impl Command<'static> {
            /// Command `id` with every field at its default (zeros, empty
            /// groups). `None` for IDs outside the catalogue.
            pub fn default_for(id: u16) -> Option<Self> {
                match id {
                    $( id if id == catalogue::$info.id => Some(Command::$cmd(<$cmd>::default())), )*
                    _ => None,
                }
            }
        }
    };
    (@responses $( $info:ident, $resp:ident $(<$rl:lifetime>)?; )*) => {
        bind!(@normal [] $( $info, $resp $(<$rl>)?; )*);
    };
    // Collects every response type but 25BH's, which has none.
    (@normal [$($acc:tt)*] SOFTWARE_RESET, NoNormalResponse; $($rest:tt)*) => {
        bind!(@normal [$($acc)*] $($rest)*);
    };
    (@normal [$($acc:tt)*] $info:ident, $resp:ident $(<$rl:lifetime>)?; $($rest:tt)*) => {
        bind!(@normal [$($acc)* ($info, $resp $(<$rl>)?)] $($rest)*);
    };
    (@normal [$( ($info:ident, $resp:ident $(<$rl:lifetime>)?) )*]) => {
        $(
            impl<'r> Message<'r> for $resp $(<$rl>)? {
                const INFO: &'static MessageInfo = &catalogue::$info;
                const HEADER: Header = Header::Response;
            }
        )*

        /// Any typed normal response.
        #[derive(Debug, Clone, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Response<'r> { $(
            #[doc = concat!("Response ", stringify!($resp), ".")]
            $resp($resp $(<$rl>)?),
        )* }

        impl<'r> Response<'r> {
            /// Parses a checked `#` frame as the response its ID names.
            /// 25BH has no normal response: [`Error::UnknownMessageId`].
            pub fn parse(frame: &Frame<'r>) -> Result<Self> {
                match frame.code() {
                    $( id if id == catalogue::$info.id =>
                        <$resp $(<$rl>)? as Message<'r>>::parse(frame).map(Response::$resp), )*
                    id => Err(Error::UnknownMessageId { id }),
                }
            }
            /// The catalogue entry.
            pub fn info(&self) -> &'static MessageInfo {
                match self { $( Response::$resp(_) => &catalogue::$info, )* }
            }
            /// The message ID.
            pub fn id(&self) -> u16 {
                self.info().id
            }
            /// Length of the frame [`Response::emit`] writes.
            pub fn emit_len(&self) -> usize {
                match self { $( Response::$resp(m) => m.emit_len(), )* }
            }
            /// Emits the whole frame (computed checksum); returns its length.
            pub fn emit(&self, station: Station, buf: &mut [u8]) -> Result<usize> {
                self.emit_with(station, ChecksumMode::Compute, buf)
            }
            /// Emits the whole frame with the given checksum mode.
            pub fn emit_with(&self, station: Station, mode: ChecksumMode, buf: &mut [u8]) -> Result<usize> {
                match self { $( Response::$resp(m) => m.emit_with(station, mode, buf), )* }
            }
        }

        impl Response<'static> {
            /// The response to command `id` with every field at its default
            /// (zeros, empty groups): a valid frame, e.g. for a simulator.
            /// `None` for 25BH (no normal response) and unknown IDs.
            pub fn default_for(id: u16) -> Option<Self> {
                match id {
                    $( id if id == catalogue::$info.id => Some(Response::$resp(<$resp>::default())), )*
                    _ => None,
                }
            }
        }

        impl Fields for Response<'_> {
            fn fields(&self, v: &mut dyn Visitor) {
                match self { $( Response::$resp(m) => m.fields(v), )* }
            }
        }
    };
}

bind! {
    (TEST_CALL, TestCall, TestCallResponse),
    (VERSION_QUERY, VersionQuery, VersionResponse),
    (EFFECTIVE_POSITION_COUNT_QUERY, EffectivePositionCountQuery, EffectivePositionCountResponse),
    (EFFECTIVE_POSITION_QUERY, EffectivePositionQuery, EffectivePositionResponse<'r>),
    (INPUT_PORT_QUERY, InputPortQuery, InputPortResponse<'r>),
    (OUTPUT_PORT_QUERY, OutputPortQuery, OutputPortResponse<'r>),
    (FLAG_QUERY, FlagQuery, FlagResponse<'r>),
    (INTEGER_VARIABLE_QUERY, IntegerVariableQuery, IntegerVariableResponse<'r>),
    (REAL_VARIABLE_QUERY, RealVariableQuery, RealVariableResponse<'r>),
    (STRING_VARIABLE_QUERY, StringVariableQuery, StringVariableResponse<'r>),
    (AXIS_STATUS_QUERY, AxisStatusQuery, AxisStatusResponse),
    (PROGRAM_STATUS_QUERY, ProgramStatusQuery, ProgramStatusResponse),
    (SYSTEM_STATUS_QUERY, SystemStatusQuery, SystemStatusResponse),
    (ERROR_DETAIL_QUERY, ErrorDetailQuery, ErrorDetailResponse<'r>),
    (EFFECTIVE_POSITION_QUERY_2, EffectivePositionQuery2, EffectivePositionResponse2<'r>),
    (EFFECTIVE_POSITION_QUERY_3, EffectivePositionQuery3, EffectivePositionResponse3<'r>),
    (SERVO_ON_OFF, ServoOnOff, ServoOnOffResponse),
    (HOME_RETURN, HomeReturn, HomeReturnResponse),
    (ABSOLUTE_MOVE, AbsoluteMove, AbsoluteMoveResponse),
    (RELATIVE_MOVE, RelativeMove, RelativeMoveResponse),
    (JOG_INCH, JogInch, JogInchResponse),
    (POSITION_NUMBER_MOVE, PositionNumberMove, PositionNumberMoveResponse),
    (OPERATION_STOP, OperationStop, OperationStopResponse),
    (RANGE_WRITE_POSITION_DATA, RangeWritePositionData<'a>, RangeWritePositionDataResponse),
    (CHANGE_POSITION_DATA, ChangePositionData<'a>, ChangePositionDataResponse),
    (CLEAR_POSITION_DATA, ClearPositionData, ClearPositionDataResponse),
    (OUTPUT_PORT_CHANGE, OutputPortChange, OutputPortChangeResponse),
    (FLAG_CHANGE, FlagChange, FlagChangeResponse),
    (INTEGER_VARIABLE_CHANGE, IntegerVariableChange<'a>, IntegerVariableChangeResponse),
    (REAL_VARIABLE_CHANGE, RealVariableChange<'a>, RealVariableChangeResponse),
    (STRING_VARIABLE_CHANGE, StringVariableChange<'a>, StringVariableChangeResponse),
    (ALARM_RESET, AlarmReset, AlarmResetResponse),
    (PROGRAM_RUN, ProgramRun, ProgramRunResponse),
    (PROGRAM_END, ProgramEnd, ProgramEndResponse),
    (PROGRAM_PAUSE, ProgramPause, ProgramPauseResponse),
    (PROGRAM_STEP, ProgramStep, ProgramStepResponse),
    (PROGRAM_RESUME, ProgramResume, ProgramResumeResponse),
    (SOFTWARE_RESET, SoftwareReset, NoNormalResponse),
    (DRIVE_SOURCE_RECOVERY, DriveSourceRecovery, DriveSourceRecoveryResponse),
    (PAUSE_CANCEL, PauseCancel, PauseCancelResponse),
    (SPEED_CHANGE, SpeedChange, SpeedChangeResponse),
    (POSITION_NUMBER_MOVE_2, PositionNumberMove2, PositionNumberMove2Response),
    (CHANGE_POSITION_DATA_2, ChangePositionData2<'a>, ChangePositionData2Response),
    (CONTROLLER_FUNCTION_2, ControllerFunction2, ControllerFunction2Response),
    (RANGE_WRITE_POSITION_DATA_3, RangeWritePositionData2<'a>, RangeWritePositionData2Response),
    (CHANGE_POSITION_DATA_3, ChangePositionData3<'a>, ChangePositionData3Response),
    (COORDINATE_SYSTEM_QUERY, CoordinateSystemQuery, CoordinateSystemResponse<'r>),
    (SCARA_AXIS_STATUS_QUERY, ScaraAxisStatusQuery, ScaraAxisStatusResponse),
    (INTERFERENCE_ZONE_QUERY, InterferenceZoneQuery, InterferenceZoneResponse<'r>),
    (SCARA_AXIS_STATUS_QUERY_2, ScaraAxisStatusQuery2, ScaraAxisStatusResponse2),
    (COORDINATE_SYSTEM_QUERY_2, CoordinateSystemQuery2, CoordinateSystemResponse2<'r>),
    (SCARA_ABSOLUTE_MOVE, ScaraAbsoluteMove, ScaraAbsoluteMoveResponse),
    (SCARA_RELATIVE_MOVE, ScaraRelativeMove, ScaraRelativeMoveResponse),
    (SCARA_POSITION_NUMBER_MOVE, ScaraPositionNumberMove, ScaraPositionNumberMoveResponse),
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
                crate::codec::Value::Unsigned(e.code.into()),
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
