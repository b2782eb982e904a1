//! A controller's position table and its answers, for the `transfer` and
//! `readback` targets: it applies position writes (26DH, 245H, 244H, 290H,
//! 291H) and answers the read-back queries (21FH, 22DH, 209H) from what it
//! holds, as a TTA does (the defined records of the window, in position
//! order).
#![allow(dead_code)]

use std::collections::BTreeMap;

use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::field::{FieldSpec, Reader, Writer};
use iai_protocol_b::frame::{emit_envelope, emit_frame, emit_trailer, Frame, Header, Station};
use iai_protocol_b::message::ErrorResponse;
use iai_protocol_b::position::{PositionRecord, PositionStream};

/// Position number -> the record stored there (its `number` is the
/// position; `extended` is 0 unless the write carries extended data).
pub type Table = BTreeMap<u16, PositionRecord>;

/// The records of a write frame, numbered by the positions they go to
/// (start + i for the range writes 244H and 290H). `None` if the frame is
/// not a valid write of `kind`.
pub fn parse_write(kind: PositionStream, bytes: &[u8]) -> Option<(u16, Vec<PositionRecord>)> {
    let f = Frame::new_checked(bytes, BypassPolicy::Reject).ok()?;
    if f.header() != Header::Command || f.code() != kind.id {
        return None;
    }
    let mut r = f.reader();
    let (start, count) = kind.read_prefix(&mut r).ok()?;
    let mut recs = Vec::with_capacity(usize::from(count));
    for i in 0..count {
        let mut rec = kind.layout.read_record(&mut r).ok()?;
        if kind.layout.number_width == 0 {
            rec.number = start.wrapping_add(i);
        }
        recs.push(rec);
    }
    r.finish().ok()?;
    Some((start, recs))
}

/// The position a source record of a write goes to (range writes number
/// their records from `start`).
pub fn position_of(kind: PositionStream, start: u16, index: usize, rec: &PositionRecord) -> u16 {
    if kind.layout.number_width == 0 {
        start.wrapping_add(index as u16)
    } else {
        rec.number
    }
}

/// Stores `recs` (already numbered by position).
pub fn apply(table: &mut Table, recs: &[PositionRecord]) {
    for r in recs {
        table.insert(r.number, r.clone());
    }
}

/// What the table must hold after writing `source` with `kind` from
/// `start`: the last record written to each position.
pub fn expected(kind: PositionStream, start: u16, source: &[PositionRecord]) -> Table {
    let mut t = Table::new();
    for (i, rec) in source.iter().enumerate() {
        let mut r = rec.clone();
        r.number = position_of(kind, start, i, rec);
        t.insert(r.number, r);
    }
    t
}

/// The normal response to a write: the prefix with `count`.
pub fn write_reply(kind: PositionStream, station: Station, start: u16, count: u16) -> Vec<u8> {
    let mut buf = [0u8; 32];
    let n = emit_frame(
        &mut buf,
        Header::Response,
        station,
        kind.id,
        ChecksumMode::Compute,
        |w| {
            if kind.reserved {
                w.put(b"00")?;
            }
            if kind.start_width > 0 {
                w.unsigned(FieldSpec::hex(kind.start_width), u64::from(start))?;
            }
            w.unsigned(FieldSpec::hex(kind.count_width), u64::from(count))
        },
    )
    .expect("reply fits");
    buf[..n].to_vec()
}

/// An `&` reply with `code` (0..=0xFFF).
pub fn error_reply(station: Station, code: u16) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = ErrorResponse { code: code & 0xFFF }
        .emit(station, &mut buf)
        .expect("error reply fits");
    buf[..n].to_vec()
}

/// `(head, asked)` of a read-back query of `kind` (the query's response
/// stream: 21FH, 22DH, 209H), if `bytes` is one for `station`.
pub fn parse_query(kind: PositionStream, station: Station, bytes: &[u8]) -> Option<(u16, u16)> {
    let f = Frame::new_checked(bytes, BypassPolicy::Reject).ok()?;
    if (f.header(), f.code(), f.station()) != (Header::Command, kind.id, station) {
        return None;
    }
    let mut r: Reader<'_> = f.reader();
    if kind.reserved && r.take(2).ok()? != b"00" {
        return None;
    }
    let spec = FieldSpec::hex(kind.count_width);
    let head = r.unsigned(spec).ok()? as u16;
    let asked = r.unsigned(spec).ok()? as u16;
    r.finish().ok()?;
    Some((head, asked))
}

/// The records of `table` in the window `head..head + asked`, as a
/// controller reports them in a read-back reply.
pub fn window(table: &Table, head: u16, asked: u16) -> Vec<PositionRecord> {
    let end = u32::from(head) + u32::from(asked);
    table
        .range(head..)
        .take_while(|(&n, _)| u32::from(n) < end)
        .map(|(_, r)| r.clone())
        .collect()
}

/// A read-back reply of `kind` carrying `recs` (in the query's layout: the
/// 3-digit 209H keeps numbers below 0x1000 and no extended byte).
pub fn query_reply(kind: PositionStream, station: Station, recs: &[PositionRecord]) -> Vec<u8> {
    let len = kind.overhead()
        + recs
            .iter()
            .map(|r| kind.layout.record_len(r.axes.count()))
            .sum::<usize>();
    let mut buf = vec![0u8; len];
    let mut w = Writer::new(&mut buf);
    emit_envelope(&mut w, Header::Response, station, kind.id).expect("envelope");
    kind.write_prefix(&mut w, 0, recs.len() as u16)
        .expect("count fits");
    for r in recs {
        kind.layout
            .write_record(r, &mut w)
            .expect("stored record fits");
    }
    emit_trailer(&mut w, ChecksumMode::Compute).expect("trailer");
    assert_eq!(w.len(), len);
    buf
}

/// Swaps two different adjacent hex digits of one coordinate of one
/// record with axes: the frame's SC does not change, the value does (what
/// only reading back can catch). `pick` chooses the record, axis and digit
/// pair. Returns the index of the record changed.
pub fn swap_digits(recs: &mut [PositionRecord], pick: u32) -> Option<usize> {
    let with_axes: Vec<usize> = (0..recs.len())
        .filter(|&i| !recs[i].positions.is_empty())
        .collect();
    if with_axes.is_empty() {
        return None;
    }
    let i = with_axes[pick as usize % with_axes.len()];
    let rec = &mut recs[i];
    let a = (pick as usize / 8) % rec.positions.len();
    let v = rec.positions[a] as u32;
    let digit = |k: u32| (v >> (28 - 4 * k)) & 0xF;
    for step in 0..7 {
        let j = (pick / 64 + step) % 7;
        let (x, y) = (digit(j), digit(j + 1));
        if x != y {
            let mut w = v & !(0xFF << (24 - 4 * j));
            w |= (y << (28 - 4 * j)) | (x << (24 - 4 * j));
            rec.positions[a] = w as i32;
            return Some(i);
        }
    }
    None
}

/// Replaces one byte of `frame` (not the header, CR or LF) with another
/// value that is no header byte, CR or LF: the SC no longer checks, and no
/// new frame can start inside it. Returns whether a byte was changed.
pub fn corrupt_byte(frame: &mut [u8], pick: u32) -> bool {
    if frame.len() < 4 {
        return false;
    }
    let at = 1 + pick as usize % (frame.len() - 3);
    let mut new = (pick >> 16) as u8;
    for _ in 0..256 {
        if new != frame[at] && !matches!(new, b'!' | b'#' | b'&' | b'%' | b'\r' | b'\n') {
            frame[at] = new;
            return true;
        }
        new = new.wrapping_add(1);
    }
    false
}
