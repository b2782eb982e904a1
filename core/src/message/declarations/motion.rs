//! Moves and axis commands: 232H Servo ON/OFF, 233H Home Return, the
//! moves 234H-237H and 26BH, 238H Stop, 262H Speed Change and the SCARA
//! moves 2D4H-2D6H (236H: TTA p. 41, 2003 p. 37; 238H's command byte:
//! manual p. 43; the SCARA operation types: manual p. 73), with the
//! builders every move shares: per-axis values from `(axis, value)` pairs
//! and the acceleration, deceleration and speed (0 = the parameter).

use super::{bare_responses, hex, shex};
use crate::axis::{per_axis_values, AxisPattern, PerAxis};
use crate::codec::*;
use crate::error::Result;
use crate::message::wire;

wire! {
    /// 232H Servo ON/OFF.
    pub struct ServoOnOff {
        /// Axes concerned.
        pub axis_pattern: AxisPattern = hex(2),
        /// 0 OFF, 1 ON.
        pub operation_type: u8 = hex(1),
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

impl HomeReturn {
    /// Home these axes at the parameters' speeds.
    pub fn of(axes: &[u8]) -> Result<Self> {
        Ok(HomeReturn {
            axis_pattern: AxisPattern::of(axes)?,
            ..Default::default()
        })
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
                "[`Error::InvalidAxis`](crate::error::Error::InvalidAxis).")]
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
    /// 262H response (no data).
    SpeedChangeResponse;
    /// 26BH response (no data).
    PositionNumberMove2Response;
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
    use crate::message::declarations::test_support::{emit, parse};
    use crate::message::Message;

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
    fn per_axis_commands_cannot_be_built_wrong() {
        assert_eq!(
            AbsoluteMove::to(&[(1, 0), (1, 5)]),
            Err(crate::error::Error::InvalidAxis { axis: 1 })
        );
        assert_eq!(
            RelativeMove::by(&[(0, 5)]),
            Err(crate::error::Error::InvalidAxis { axis: 0 })
        );
        let m = RelativeMove::by(&[(4, -1), (2, 2)]).unwrap();
        assert_eq!(m.axis_pattern.bits(), 0b1010);
        assert_eq!(m.relative_distance.as_slice(), &[2, -1]);
    }
}
