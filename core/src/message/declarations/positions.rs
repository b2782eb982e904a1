//! The position-table messages: 208H count, the 209H, 21FH and 22DH
//! queries, the 244H, 245H, 26DH, 290H and 291H writes and the 246H clear.
//! Records and the fields around them take their layouts from
//! [`PositionStream`], so each width is stated once, in
//! [`crate::position`]. 290H and 291H are **partial** in the manual (see
//! each); the 21FH maximum is read as 20,000 records.

use super::{bare_responses, hex};
use crate::codec::*;
use crate::message::wire;
use crate::position::{PositionRecord, PositionStream, RecordLayout, RESERVED};

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

bare_responses! {
    /// 246H response (no data).
    ClearPositionDataResponse;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::declarations::test_support::{emit, parse};

    #[test]
    fn the_2003_worked_example_is_a_209h_query() {
        // 2003 p. 10: query 5 records from point 001, SC 54.
        let q = parse::<EffectivePositionQuery>(b"!9920900100554\r\n").unwrap();
        assert_eq!(q.query_head_position_number, 1);
        assert_eq!(q.number_of_query_records, 5);
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
}
