//! SCARA queries: coordinate-system definitions (2A0H, 2A4H), SCARA axis
//! status (2A1H, 2A3H) and interference-check zones (2A2H) (kinds of
//! coordinate system: manual p. 65; 2A1H's per-axis block and 2A2H's
//! record tail from the 2003 spec).
//! **Inferred**: most of 2A3H's response after the axes 5-8 work
//! coordinate selection, and 2A4H's offsets (see each).

use super::status::AxisStatus;
use super::{hex, shex};
use crate::axis::{AxisPattern, PerAxis};
use crate::codec::*;
use crate::field::FieldSpec;
use crate::message::wire;

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
