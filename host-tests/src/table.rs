//! Generated position tables for tests, the demo and benchmarks.

use iai_protocol_b::axis::AxisPattern;
use iai_protocol_b::axis::PerAxis;
use iai_protocol_b::position::PositionRecord;

/// A deterministic table of `records` records over `axes` axes (1..=8),
/// numbered from 1, with coordinates spread over ±2,000,000 (±2 m) and
/// varied speeds: record `i` is a pure function of `(i, axes, seed)`.
pub fn record(i: u32, axes: u8, seed: u32) -> PositionRecord {
    let mut x = i.wrapping_mul(2_654_435_761) ^ seed.wrapping_mul(40_503);
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x
    };
    let mut positions = PerAxis::new();
    for _ in 0..axes {
        let v = (next() % 4_000_001) as i32 - 2_000_000;
        positions.push(v).expect("at most 8 axes");
    }
    PositionRecord {
        number: (i % 20_000) as u16 + 1,
        axes: AxisPattern::first(axes),
        acceleration: (next() % 200) as u16,
        deceleration: (next() % 200) as u16,
        speed: (next() % 2000) as u16,
        positions,
        extended: 0,
    }
}

/// Iterator over a whole generated table.
pub fn table(records: u32, axes: u8, seed: u32) -> impl Iterator<Item = PositionRecord> + Clone {
    (0..records).map(move |i| record(i, axes, seed))
}
