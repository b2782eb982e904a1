//! The shapes of the messages whose body is a prefix and a run of position
//! records, `[00] [start] count record…` ([`PositionStream`]): 209H, 21FH
//! and 22DH responses (TTA pp. 19, 35, 36; 2003 p. 18), 244H, 245H, 26DH,
//! 290H and 291H commands (TTA pp. 44, 45, 60, 63, 64; 2003 pp. 40-41).
//! 290H and 291H are partly **inferred** (see their constants); the 21FH
//! maximum is read as 20,000 records.

use super::RecordLayout;
use crate::axis::MAX_AXES;
use crate::catalogue;
use crate::codec::{counted, Counted, Fixed};
use crate::error::{Error, Result};
use crate::field::{FieldSpec, Reader, Writer};
use crate::frame::{Frame, Header, ENVELOPE_LEN, TRAILER_LEN};

/// The reserved `00` before the prefix of 22DH, 290H and 291H.
pub const RESERVED: Fixed = Fixed(b"00");

/// The shape of a message whose body is a prefix and a run of position
/// records: `[00] [start] count record…`. The message declarations and the
/// streaming engines both take their layouts from these descriptors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PositionStream {
    /// Message ID (from the catalogue).
    pub id: u16,
    /// Frame kind that carries the records (command for writes, response for queries).
    pub header: Header,
    /// Whether the body starts with the reserved `00`.
    pub reserved: bool,
    /// Width of the start-number field; 0 when records carry their own numbers.
    pub start_width: u8,
    /// Width of the record-count field (also of the position numbers in
    /// the query commands).
    pub count_width: u8,
    /// Largest record count the format allows.
    pub max_records: u16,
    /// Layout of one record.
    pub layout: RecordLayout,
}

impl PositionStream {
    /// 26DH Change Position Data Continuous Write 2 (TTA p. 60).
    pub const CHANGE_2: Self = Self::write(
        catalogue::CHANGE_POSITION_DATA_2.id,
        false,
        0,
        4,
        20_000,
        RecordLayout::NUMBER_4,
    );
    /// 245H Change Position Data Continuous Write (3-digit numbers; TTA
    /// p. 45, 2003 p. 41).
    pub const CHANGE: Self = Self::write(
        catalogue::CHANGE_POSITION_DATA.id,
        false,
        0,
        3,
        3_000,
        RecordLayout::NUMBER_3,
    );
    /// 244H Position Data Range-Specification Continuous Write (TTA p. 44,
    /// 2003 p. 40).
    pub const RANGE: Self = Self::write(
        catalogue::RANGE_WRITE_POSITION_DATA.id,
        false,
        3,
        3,
        3_000,
        RecordLayout::RANGE,
    );
    /// 290H Position Data Range-Specification Continuous Write 3 (TTA
    /// p. 63; catalogue status: partial).
    pub const RANGE_3: Self = Self::write(
        catalogue::RANGE_WRITE_POSITION_DATA_3.id,
        true,
        4,
        4,
        20_000,
        RecordLayout::RANGE_EXTENDED,
    );
    /// 291H Change Position Data Continuous Write 3 (TTA p. 64; catalogue
    /// status: partial, the field order is a chosen reading of an
    /// inconsistent table).
    pub const CHANGE_3: Self = Self::write(
        catalogue::CHANGE_POSITION_DATA_3.id,
        true,
        0,
        4,
        20_000,
        RecordLayout::NUMBER_4_EXTENDED,
    );
    /// 209H Effective Position Data Query, response (TTA p. 19, 2003 p. 18).
    pub const QUERY_RESPONSE: Self = Self::query(
        catalogue::EFFECTIVE_POSITION_QUERY.id,
        false,
        3,
        3_000,
        RecordLayout::NUMBER_3,
    );
    /// 21FH Effective Position Data Query 2, response (TTA p. 35; the
    /// printed "max 2000" is read as 20,000, as its own arithmetic says).
    pub const QUERY_2_RESPONSE: Self = Self::query(
        catalogue::EFFECTIVE_POSITION_QUERY_2.id,
        false,
        4,
        20_000,
        RecordLayout::NUMBER_4,
    );
    /// 22DH Effective Position Data Query 3, response (TTA p. 36).
    pub const QUERY_3_RESPONSE: Self = Self::query(
        catalogue::EFFECTIVE_POSITION_QUERY_3.id,
        true,
        4,
        20_000,
        RecordLayout::NUMBER_4_EXTENDED,
    );

    /// Every known position stream.
    pub const ALL: [Self; 8] = [
        Self::CHANGE_2,
        Self::CHANGE,
        Self::RANGE,
        Self::RANGE_3,
        Self::CHANGE_3,
        Self::QUERY_RESPONSE,
        Self::QUERY_2_RESPONSE,
        Self::QUERY_3_RESPONSE,
    ];

    const fn write(
        id: u16,
        reserved: bool,
        start: u8,
        count: u8,
        max: u16,
        layout: RecordLayout,
    ) -> Self {
        PositionStream {
            id,
            header: Header::Command,
            reserved,
            start_width: start,
            count_width: count,
            max_records: max,
            layout,
        }
    }

    const fn query(id: u16, reserved: bool, count: u8, max: u16, layout: RecordLayout) -> Self {
        PositionStream {
            id,
            header: Header::Response,
            reserved,
            start_width: 0,
            count_width: count,
            max_records: max,
            layout,
        }
    }

    /// The stream carried by frames of this kind and ID, if any.
    pub fn find(header: Header, id: u16) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|s| s.header == header && s.id == id)
    }

    /// The count field's format.
    pub const fn count_field(&self) -> FieldSpec {
        FieldSpec::hex(self.count_width)
    }

    /// The start-number field's format (range writes).
    pub const fn start_field(&self) -> FieldSpec {
        FieldSpec::hex(self.start_width)
    }

    /// The codec of the count field and the records after it.
    pub const fn records(&self) -> Counted<RecordLayout> {
        counted(self.count_field(), self.max_records as usize, self.layout)
    }

    /// Bytes of the body before the first record.
    pub const fn prefix_len(&self) -> usize {
        (if self.reserved { RESERVED.0.len() } else { 0 })
            + self.start_width as usize
            + self.count_width as usize
    }

    /// Bytes of a frame of this kind holding `records`, header through LF.
    pub fn frame_len<B: core::borrow::Borrow<super::PositionRecord>>(
        &self,
        records: impl Iterator<Item = B>,
    ) -> usize {
        let body: usize = records
            .map(|r| self.layout.record_len(r.borrow().axes.count()))
            .sum();
        self.overhead() + body
    }

    /// Bytes of a frame without records (envelope, prefix, SC, CR, LF).
    pub const fn overhead(&self) -> usize {
        ENVELOPE_LEN + self.prefix_len() + TRAILER_LEN
    }

    /// Writes the prefix: `[00] [start] count`.
    pub fn write_prefix(&self, w: &mut Writer<'_>, start: u16, count: u16) -> Result<()> {
        if count > self.max_records {
            return Err(Error::CountTooLarge {
                count: usize::from(count),
                max: usize::from(self.max_records),
            });
        }
        if self.reserved {
            w.put(RESERVED.0)?;
        }
        if self.start_width > 0 {
            w.unsigned(self.start_field(), u64::from(start))?;
        }
        w.unsigned(self.count_field(), u64::from(count))
    }

    /// Reads the prefix; returns `(start, count)` (start 0 when absent).
    pub fn read_prefix(&self, r: &mut Reader<'_>) -> Result<(u16, u16)> {
        if self.reserved {
            let at = r.offset();
            if !r.take(RESERVED.0.len())?.eq_ignore_ascii_case(RESERVED.0) {
                return Err(Error::InvalidFixedField { offset: at });
            }
        }
        let start = if self.start_width > 0 {
            let at = r.offset();
            let s = r.unsigned(self.start_field())?;
            u16::try_from(s).map_err(|_| Error::ValueOutOfRange { offset: at })?
        } else {
            0
        };
        let at = r.offset();
        let count = r.unsigned(self.count_field())?;
        let count = u16::try_from(count).map_err(|_| Error::ValueOutOfRange { offset: at })?;
        if count > self.max_records {
            return Err(Error::CountTooLarge {
                count: usize::from(count),
                max: usize::from(self.max_records),
            });
        }
        Ok((start, count))
    }

    /// Parses the normal response to a position write: the same prefix,
    /// carrying the number of records written. Returns `(start, count)`.
    pub fn parse_reply(&self, frame: &Frame<'_>) -> Result<(u16, u16)> {
        if frame.header() != Header::Response {
            return Err(Error::UnexpectedHeader {
                expected: Header::Response,
                found: frame.header(),
            });
        }
        if frame.code() != self.id {
            return Err(Error::UnexpectedMessageId {
                expected: self.id,
                found: frame.code(),
            });
        }
        let mut r = frame.reader();
        let v = self.read_prefix(&mut r)?;
        r.finish()?;
        Ok(v)
    }

    /// The query whose response reads back what this write stores: 21FH
    /// for 26DH, 22DH for 290H and 291H (extended data), 209H for the
    /// 3-digit writes 244H and 245H. A query stream gives itself.
    pub const fn read_back(&self) -> PositionStream {
        if matches!(self.header, Header::Response) {
            return *self;
        }
        match (self.count_width, self.layout.extended) {
            (4, true) => Self::QUERY_3_RESPONSE,
            (4, false) => Self::QUERY_2_RESPONSE,
            _ => Self::QUERY_RESPONSE,
        }
    }

    /// Writes the body of this query stream's command: `[00] head count`
    /// (209H, 21FH, 22DH commands share the response's widths).
    pub fn write_query(&self, w: &mut Writer<'_>, head: u16, count: u16) -> Result<()> {
        if self.reserved {
            w.put(RESERVED.0)?;
        }
        w.unsigned(self.count_field(), u64::from(head))?;
        w.unsigned(self.count_field(), u64::from(count))
    }

    /// Positions one query may ask for so that its reply fits
    /// `max_response` bytes whatever the records hold (8 axes each): 24 for
    /// 21FH on a TTA. At least 1.
    pub const fn window(&self, max_response: usize) -> u16 {
        let room = max_response.saturating_sub(self.overhead());
        let per = room / self.layout.record_len(MAX_AXES);
        let per = if per < 1 { 1 } else { per };
        if per > self.max_records as usize {
            self.max_records
        } else {
            per as u16
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_know_their_read_back_query_and_window() {
        assert_eq!(
            PositionStream::CHANGE_2.read_back(),
            PositionStream::QUERY_2_RESPONSE
        );
        assert_eq!(
            PositionStream::CHANGE_3.read_back(),
            PositionStream::QUERY_3_RESPONSE
        );
        assert_eq!(
            PositionStream::RANGE_3.read_back(),
            PositionStream::QUERY_3_RESPONSE
        );
        assert_eq!(
            PositionStream::RANGE.read_back(),
            PositionStream::QUERY_RESPONSE
        );
        assert_eq!(
            PositionStream::CHANGE.read_back(),
            PositionStream::QUERY_RESPONSE
        );
        // 21FH on a TTA: (2048 - 14) / 82 = 24 positions per query.
        assert_eq!(PositionStream::QUERY_2_RESPONSE.window(2048), 24);
        assert_eq!(PositionStream::QUERY_RESPONSE.window(1024), 12);
        let mut buf = [0u8; 16];
        let mut w = Writer::new(&mut buf);
        PositionStream::QUERY_3_RESPONSE
            .write_query(&mut w, 0x10, 24)
            .unwrap();
        assert_eq!(w.written(), b"0000100018");
    }

    #[test]
    fn the_26dh_reply_prefix() {
        let f = Frame::new_checked(b"#9926D00180A\r\n", crate::checksum::BypassPolicy::Reject);
        let f = f.unwrap();
        assert_eq!(PositionStream::CHANGE_2.parse_reply(&f), Ok((0, 0x18)));
    }
}
