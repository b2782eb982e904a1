//! Instruction counts of the core's position-stream codec (the `bench`
//! feature): encode an N-record, 8-axis 26DH table into RAM with
//! [`PositionStreamEncoder`], decode it again with
//! [`PositionStreamDecoder`], and print instructions per wire byte through
//! semihosting.
//!
//! Counting: run on QEMU `mps2-an386` with `-icount shift=5,sleep=off`.
//! Each instruction then takes 2^5 ns of virtual time and SysTick counts
//! the 25 MHz core clock (40 ns), so instructions = SysTick ticks x 1.25,
//! the same on every run. The DWT cycle counter is not modelled by QEMU.
//! The count includes the 1 kHz SysTick interrupt (about 20 instructions
//! every 31,250) and excludes the record generator (measured apart and
//! subtracted). Instructions, not cycles: no pipeline or wait states.

use core::hint::black_box;
use core::sync::atomic::{AtomicU32, Ordering};

use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::stream::{
    PositionStream, PositionStreamDecoder, PositionStreamEncoder, StreamEvent,
};

use crate::board;

/// Records in the table (8 axes each: 82 bytes per record on the wire).
pub const RECORDS: u16 = 200;
/// Axes per record.
const AXES: u8 = 8;
/// Wire size of the frame: 14 bytes overhead + 82 per record.
const FRAME_LEN: usize = 14 + 82 * RECORDS as usize;

/// The encoded frame (only linked in with the `bench` feature).
struct Buf(core::cell::UnsafeCell<[u8; FRAME_LEN]>);
// SAFETY: used by thread code only, once.
unsafe impl Sync for Buf {}
static FRAME: Buf = Buf(core::cell::UnsafeCell::new([0; FRAME_LEN]));
static TAKEN: AtomicU32 = AtomicU32::new(0);

/// A deterministic record with `AXES` coordinates.
fn record(i: u32) -> PositionRecord {
    let mut x = i.wrapping_mul(2_654_435_761) | 1;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x
    };
    let mut positions = PerAxis::new();
    for _ in 0..AXES {
        let _ = positions.push((next() % 4_000_001) as i32 - 2_000_000);
    }
    PositionRecord {
        number: i as u16 + 1,
        axes: AxisPattern::first(AXES),
        acceleration: (next() % 200) as u16,
        deceleration: (next() % 200) as u16,
        speed: (next() % 2000) as u16,
        positions,
        extended: 0,
    }
}

fn records() -> impl Iterator<Item = PositionRecord> {
    (0..u32::from(RECORDS)).map(record)
}

/// SysTick ticks since start: ms x reload + elapsed part of the current ms.
fn ticks() -> u64 {
    let per_ms = u64::from(board::CORE_CLOCK_HZ / board::TICK_HZ);
    loop {
        let ms = board::now_ms();
        let cvr = cortex_m::peripheral::SYST::get_current();
        if board::now_ms() == ms {
            // The counter counts down from `per_ms - 1`.
            return u64::from(ms) * per_ms + (per_ms - 1 - u64::from(cvr));
        }
    }
}

/// Instructions (x100) from SysTick ticks at `-icount shift=5`.
fn instructions_x100(ticks: u64) -> u64 {
    ticks * 125
}

fn measure(f: impl FnOnce()) -> u64 {
    let t0 = ticks();
    f();
    ticks() - t0
}

/// Run the benchmark and print the figures.
pub fn run(print: fn(core::fmt::Arguments<'_>)) -> bool {
    if TAKEN.swap(1, Ordering::AcqRel) != 0 {
        return false;
    }
    // SAFETY: `TAKEN` makes this the only reference ever made.
    let frame = unsafe { &mut *FRAME.0.get() };

    let empty = measure(|| {});
    let generator = measure(|| {
        for r in records() {
            black_box(r);
        }
    }) - empty;

    let mut len = 0;
    let mut ok = true;
    let encode = measure(|| {
        match PositionStreamEncoder::new(
            PositionStream::CHANGE_2,
            Station(0x99),
            0,
            RECORDS,
            records(),
        ) {
            Ok(mut enc) => loop {
                // UART-sized chunks, as a transmit path would pull them.
                let end = (len + 64).min(frame.len());
                match enc.read(&mut frame[len..end]) {
                    Ok(0) => break,
                    Ok(n) => len += n,
                    Err(_) => {
                        ok = false;
                        break;
                    }
                }
            },
            Err(_) => ok = false,
        }
    })
    .saturating_sub(empty + generator);
    ok &= len == FRAME_LEN;

    let mut decoded = 0u32;
    let decode = measure(|| {
        let mut dec = PositionStreamDecoder::default();
        let mut input: &[u8] = &frame[..len];
        while !input.is_empty() {
            let (used, ev) = dec.decode(input);
            input = &input[used..];
            match ev {
                StreamEvent::Record(r) => {
                    black_box(r);
                    decoded += 1;
                }
                StreamEvent::End { .. } => break,
                StreamEvent::Error { .. } => {
                    ok = false;
                    break;
                }
                _ => {}
            }
        }
    })
    .saturating_sub(empty);
    ok &= decoded == u32::from(RECORDS);

    let per_byte = |t: u64| {
        let x100 = instructions_x100(t) / len.max(1) as u64;
        (x100 / 100, x100 % 100)
    };
    let (e_int, e_frac) = per_byte(encode);
    let (d_int, d_frac) = per_byte(decode);
    print(format_args!(
        "bench: table {} records x {} axes, {} wire bytes (26DH)\n",
        RECORDS, AXES, len
    ));
    print(format_args!(
        "bench: encode {} instructions, {}.{:02} per byte\n",
        instructions_x100(encode) / 100,
        e_int,
        e_frac
    ));
    print(format_args!(
        "bench: decode {} instructions, {}.{:02} per byte\n",
        instructions_x100(decode) / 100,
        d_int,
        d_frac
    ));
    print(format_args!(
        "bench: (record generator {} instructions, excluded; ok={})\n",
        instructions_x100(generator) / 100,
        ok
    ));
    ok
}
