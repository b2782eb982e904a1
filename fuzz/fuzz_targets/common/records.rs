//! Input cursor and position-record generators shared by the
//! `stream_decoder`, `transfer` and `readback` targets.
#![allow(dead_code)]

use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::position::{PositionRecord, RecordLayout};

/// Reads the fuzz input front to back; reads past the end give zeros.
pub struct Input<'a>(pub &'a [u8]);

impl<'a> Input<'a> {
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    pub fn u8(&mut self) -> u8 {
        match self.0.split_first() {
            Some((&b, rest)) => {
                self.0 = rest;
                b
            }
            None => 0,
        }
    }
    /// The next byte, or `None` once the input is used up.
    pub fn next(&mut self) -> Option<u8> {
        let (&b, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(b)
    }
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }
    /// Up to `n` bytes.
    pub fn take(&mut self, n: usize) -> &'a [u8] {
        let n = n.min(self.0.len());
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        a
    }
}

/// The number a layout can carry (0 without a number field).
pub fn fit_number(layout: RecordLayout, n: u16) -> u16 {
    match layout.number_width {
        0 => 0,
        w if w >= 4 => n,
        w => n & ((1u16 << (4 * w)) - 1),
    }
}

/// An arbitrary record that is valid in `layout`.
pub fn arbitrary_record(layout: RecordLayout, input: &mut Input<'_>) -> PositionRecord {
    let number = fit_number(layout, input.u16());
    let axes = AxisPattern::from_bits(input.u8());
    let mut positions = PerAxis::new();
    for _ in 0..axes.count() {
        let _ = positions.push(input.u32() as i32);
    }
    let extended = if layout.extended { input.u8() } else { 0 };
    PositionRecord {
        number,
        axes,
        acceleration: input.u16(),
        deceleration: input.u16(),
        speed: input.u16(),
        positions,
        extended,
    }
}

/// A deterministic table of `n` records valid in `layout`, numbered from
/// `first`, with 1 to 8 axes (some tables use all 8, the longest records).
pub fn table(layout: RecordLayout, seed: u8, first: u16, n: usize) -> Vec<PositionRecord> {
    (0..n)
        .map(|i| {
            let k = (seed as usize).wrapping_mul(31).wrapping_add(i * 7);
            let bits = if seed & 1 == 1 {
                0xFF
            } else {
                (k % 255 + 1) as u8
            };
            let axes = AxisPattern::from_bits(bits);
            let mut positions = PerAxis::new();
            for a in 0..axes.count() {
                let _ =
                    positions.push((k as i32).wrapping_mul(1000).wrapping_sub(a as i32 * 12345));
            }
            PositionRecord {
                number: fit_number(layout, first.wrapping_add(i as u16)),
                axes,
                acceleration: (k % 300) as u16,
                deceleration: (k % 200) as u16,
                speed: (k % 1000) as u16,
                positions,
                extended: if layout.extended { k as u8 } else { 0 },
            }
        })
        .collect()
}

/// Whether `FUZZ_TRACE` is set: the engine targets then print what they
/// send and receive (to replay a finding by hand).
pub fn tracing() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("FUZZ_TRACE").is_some())
}

/// `eprintln!` when `FUZZ_TRACE` is set.
#[macro_export]
macro_rules! trace {
    ($($t:tt)*) => {
        if $crate::records::tracing() {
            eprintln!($($t)*);
        }
    };
}

/// Checks a `WaitUntil(deadline)` at tick `now`: the deadline lies in the
/// future, at most `bound` ms ahead; before anything was sent an engine
/// never waits (finding F1, fixed: holds started at tick 0 and made a first
/// command past tick 2^31 wait until the clock wrapped). Returns the wait
/// in ms.
pub fn check_wait(now: u32, deadline: u32, bound: u64, nothing_sent: bool) -> u32 {
    let ahead = deadline.wrapping_sub(now);
    assert!(ahead.wrapping_sub(1) <= 0x7FFF_FFFF, "waits for the past");
    assert!(
        !nothing_sent,
        "waits {ahead} ms before the first send (now {now})"
    );
    assert!(
        u64::from(ahead) <= bound,
        "waits {ahead} ms (now {now}), more than any hold ({bound} ms)"
    );
    ahead
}
