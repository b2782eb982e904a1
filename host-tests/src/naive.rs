//! The straightforward std implementation the benchmarks compare against:
//! `format!`/`write!` per field into a `String`, and parsing with
//! `from_str_radix` on string slices.

use std::fmt::Write;

use iai_protocol_b::position::PositionRecord;

/// Encodes a whole 26DH command frame into a `String`.
pub fn encode_26dh(station: u8, records: &[PositionRecord]) -> String {
    let mut s = String::new();
    write!(s, "!{station:02X}26D{:04X}", records.len()).unwrap();
    for r in records {
        write!(
            s,
            "{:04X}{:02X}{:04X}{:04X}{:04X}",
            r.number,
            r.axes.bits(),
            r.acceleration,
            r.deceleration,
            r.speed
        )
        .unwrap();
        for p in &r.positions {
            write!(s, "{:08X}", *p as u32).unwrap();
        }
    }
    let sum = s.bytes().fold(0u8, |a, b| a.wrapping_add(b));
    write!(s, "{sum:02X}\r\n").unwrap();
    s
}

/// Decodes a 26DH command frame from a `&str` into a `Vec` of records.
pub fn decode_26dh(frame: &str) -> Option<Vec<PositionRecord>> {
    let body_end = frame.len().checked_sub(4)?;
    let sum = frame[..body_end]
        .bytes()
        .fold(0u8, |a, b| a.wrapping_add(b));
    if u8::from_str_radix(&frame[body_end..body_end + 2], 16).ok()? != sum {
        return None;
    }
    let hex = |s: &str| u32::from_str_radix(s, 16).ok();
    let count = hex(&frame[6..10])? as usize;
    let mut at = 10;
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let number = hex(&frame[at..at + 4])? as u16;
        let bits = hex(&frame[at + 4..at + 6])? as u8;
        let acceleration = hex(&frame[at + 6..at + 10])? as u16;
        let deceleration = hex(&frame[at + 10..at + 14])? as u16;
        let speed = hex(&frame[at + 14..at + 18])? as u16;
        at += 18;
        let mut positions = iai_protocol_b::axis::PerAxis::new();
        for _ in 0..bits.count_ones() {
            positions.push(hex(&frame[at..at + 8])? as i32).ok()?;
            at += 8;
        }
        out.push(PositionRecord {
            number,
            axes: iai_protocol_b::axis::AxisPattern::from_bits(bits),
            acceleration,
            deceleration,
            speed,
            positions,
            extended: 0,
        });
    }
    Some(out)
}
