//! Instructions per wire byte of the core's hex paths, for two 26DH
//! workloads, on whatever Cortex-M core runs it (M0, M3, M4).
//!
//! It needs SysTick, CPUID and a print function, nothing of a board;
//! `src/bin/icount_bench.rs` is the program around it (which also runs
//! the line workloads of `src/bench_line.rs`, timed the same way), and
//! `host-tests/src/bin/icount.rs` runs it under QEMU with `-icount`.
//!
//! # Counting
//! Under `-icount shift=S,sleep=off` every instruction advances QEMU's
//! virtual clock by 2^S ns, and SysTick counts that clock: ticks are
//! proportional to instructions, identical from run to run. The ratio
//! depends on the core clock the board model gives SysTick, so the bench
//! does not assume it: it times a two-instruction loop (`subs`, `bne`) at
//! two lengths and takes instructions per tick from the difference.
//! SysTick runs free with its interrupt off; every timed piece is far
//! shorter than a wrap. Instructions, not cycles.
//!
//! # What is counted, per wire byte of the same frames
//! - `encode`: `PositionStreamEncoder::read` pulled in 64-byte chunks into
//!   RAM, the records handed over by reference (`records.iter()`).
//! - `encode-frame`: the same encoder read into the whole frame buffer at
//!   once (a transmit buffer as large as the frame: one `read` gives the
//!   frame, the next `Ok(0)`).
//! - `decode`: `PositionStreamDecoder::decode` over the whole frame, one
//!   `StreamEvent::Record` per record, each moved out to the caller.
//! - `decode-records`: `PositionStreamDecoder::decode_records` over the
//!   whole frame into a caller's array of 8 records, refilled until `End`.
//! - `push`: `FrameDecoder::push`, one byte at a time, the frame out.
//! - `checksum`: `Checksum::update` over the frame.
//!
//! The frames are the ones a bridge writes to a TTA: 26DH commands of at
//! most 2,051 bytes (24 records of 8 axes, 1,982 bytes; or 78 records of 1
//! axis, 2,042 bytes), eight of each, every record different.
//!
//! # Output
//! Lines for the host to read (all numbers decimal):
//! `bench core <name> <cpuid>`, `bench calibration <instructions> <ticks>`,
//! then per workload and figure `bench <workload> <what> <ticks> <bytes>`
//! (net ticks, the timer's own overhead already subtracted); the program
//! prints `bench ok` or `bench failed <why>` last.

use core::hint::black_box;
use core::sync::atomic::{compiler_fence, Ordering};

use cortex_m::peripheral::{CPUID, SYST};
use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::checksum::Checksum;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::{PositionStreamDecoder, PositionStreamEncoder, StreamEvent};

/// One workload: 26DH frames of `per_frame` records of `axes` axes.
struct Workload {
    name: &'static str,
    axes: u8,
    per_frame: u16,
}

/// Frames per workload.
const FRAMES: u16 = 8;
/// The two workloads; both frame sizes fit the decoder's default capacity.
const WORKLOADS: [Workload; 2] = [
    Workload {
        name: "26dh-8axis",
        axes: 8,
        per_frame: 24,
    },
    Workload {
        name: "26dh-1axis",
        axes: 1,
        per_frame: 78,
    },
];
/// Records of the largest frame.
const MAX_PER_FRAME: usize = 78;
/// Largest frame: the TTA's limit.
const FRAME_CAP: usize = 2051;
/// Chunk the encoder is pulled in (a UART transmit path's buffer).
const CHUNK: usize = 64;
/// Records `decode_records` fills per call.
const BATCH: usize = 8;

/// The SysTick counter mask (24 bits).
const SYST_MASK: u32 = 0x00FF_FFFF;
/// SysTick CSR: counter on, clocked by the core clock, no interrupt.
const SYST_CSR_ENABLE_CORE_CLOCK: u32 = 0b101;

/// Lets SysTick count freely over 24 bits without its interrupt.
fn start_counter() {
    // SAFETY: the bench is the only code running; these writes switch the
    // SysTick interrupt off, so no handler and no other code uses SysTick
    // while the bench reads it.
    unsafe {
        let syst = &*SYST::PTR;
        syst.csr.write(0);
        syst.rvr.write(SYST_MASK);
        syst.cvr.write(0);
        syst.csr.write(SYST_CSR_ENABLE_CORE_CLOCK);
    }
}

/// SysTick ticks `f` took (the counter counts down), and its result.
#[inline(always)]
pub(crate) fn timed<R>(f: impl FnOnce() -> R) -> (u32, R) {
    compiler_fence(Ordering::SeqCst);
    let t0 = SYST::get_current();
    compiler_fence(Ordering::SeqCst);
    let r = f();
    compiler_fence(Ordering::SeqCst);
    let t1 = SYST::get_current();
    compiler_fence(Ordering::SeqCst);
    (t0.wrapping_sub(t1) & SYST_MASK, r)
}

/// Runs exactly `2 * n` instructions (`n` >= 1): a `subs`/`bne` loop.
#[inline(always)]
fn spin(n: u32) {
    // SAFETY: register-only arithmetic and a local branch; no memory, no stack.
    unsafe {
        core::arch::asm!(
            "2:",
            "subs {n}, #1",
            "bne 2b",
            n = inout(reg) n.max(1) => _,
            options(nomem, nostack),
        );
    }
}

/// Instructions and ticks of the calibration loops' difference.
fn calibrate() -> (u64, u32) {
    const SHORT: u32 = 50_000;
    const LONG: u32 = 250_000;
    let (short, ()) = timed(|| spin(black_box(SHORT)));
    let (long, ()) = timed(|| spin(black_box(LONG)));
    (2 * u64::from(LONG - SHORT), long.wrapping_sub(short))
}

/// Core name from the CPUID part number.
fn core_name(cpuid: u32) -> &'static str {
    match (cpuid >> 4) & 0xFFF {
        0xC20 => "cortex-m0",
        0xC60 => "cortex-m0plus",
        0xC23 => "cortex-m3",
        0xC24 => "cortex-m4",
        0xC27 => "cortex-m7",
        _ => "unknown",
    }
}

/// A deterministic record: a pure function of `(i, axes)`, coordinates over
/// ±2,000,000 (±2 m), varied speeds (as `host_tests::table`).
pub(crate) fn record(i: u32, axes: u8) -> PositionRecord {
    let mut x = i.wrapping_mul(2_654_435_761) ^ u32::from(axes).wrapping_mul(40_503);
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        x
    };
    let mut positions = PerAxis::new();
    for _ in 0..axes {
        let _ = positions.push((next() % 4_000_001) as i32 - 2_000_000);
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

/// Encodes one 26DH frame of `recs` into `out`, pulled `chunk` bytes at a
/// time; its length, or `None`.
#[inline(always)]
fn encode_in(recs: &[PositionRecord], out: &mut [u8], chunk: usize) -> Option<usize> {
    let count = u16::try_from(recs.len()).ok()?;
    let mut enc = PositionStreamEncoder::new(
        PositionStream::CHANGE_2,
        Station(0x99),
        0,
        count,
        recs.iter(),
    )
    .ok()?;
    let mut len = 0;
    loop {
        let end = usize::saturating_add(len, chunk).min(out.len());
        match enc.read(out.get_mut(len..end)?) {
            Ok(0) => return Some(len),
            Ok(n) => len += n,
            Err(_) => return None,
        }
    }
}

/// [`encode_in`] 64-byte chunks.
#[inline(never)]
fn encode(recs: &[PositionRecord], out: &mut [u8]) -> Option<usize> {
    encode_in(recs, out, CHUNK)
}

/// [`encode_in`] one chunk as large as `out`.
#[inline(never)]
fn encode_frame(recs: &[PositionRecord], out: &mut [u8]) -> Option<usize> {
    encode_in(recs, out, usize::MAX)
}

/// Decodes one frame with the stream decoder; the records delivered, or
/// `None` on an error or a missing end.
#[inline(never)]
fn decode(frame: &[u8]) -> Option<u16> {
    let mut dec = PositionStreamDecoder::default();
    let mut input = frame;
    let mut records = 0;
    while !input.is_empty() {
        let r = dec.decode(input);
        let (used, ev) = (r.consumed, r.status);
        input = input.get(used..)?;
        match ev {
            Status::Complete(StreamEvent::Record(r)) => {
                black_box(r);
                records += 1;
            }
            Status::Complete(StreamEvent::End { .. }) => return Some(records),
            Status::Complete(StreamEvent::Error { .. }) => return None,
            Status::Partial | Status::Complete(StreamEvent::Start { .. }) => {}
        }
    }
    None
}

/// Decodes one frame with the stream decoder's bulk path into `recs`, the
/// caller's array (reused from frame to frame); the records delivered, or
/// `None`.
#[inline(never)]
fn decode_records(frame: &[u8], recs: &mut [PositionRecord; BATCH]) -> Option<u16> {
    let mut dec = PositionStreamDecoder::default();
    let mut input = frame;
    let mut records = 0;
    while !input.is_empty() {
        let r = dec.decode_records(input, recs);
        let (used, n, ev) = (r.consumed, r.records, r.status);
        input = input.get(used..)?;
        black_box(recs.get(..n)?);
        records += n as u16;
        match ev {
            Status::Complete(StreamEvent::End { .. }) => return Some(records),
            Status::Complete(StreamEvent::Error { .. }) => return None,
            _ => {}
        }
    }
    None
}

/// Pushes one frame through the frame decoder byte by byte; its length as
/// the decoder saw it, or `None`.
#[inline(never)]
fn push(dec: &mut FrameDecoder, frame: &[u8]) -> Option<usize> {
    let mut found = None;
    for &b in frame {
        match dec.push(b) {
            Status::Partial => {}
            Status::Complete(Event::Frame(f)) => found = Some(black_box(f.len())),
            Status::Complete(Event::Error(_)) => return None,
        }
    }
    found
}

/// The checksum of `frame`.
#[inline(never)]
fn checksum(frame: &[u8]) -> u8 {
    let mut c = Checksum::new();
    c.update(frame);
    c.value()
}

/// Net ticks of each figure of one workload.
#[derive(Default)]
struct Figures {
    encode: u32,
    encode_frame: u32,
    decode: u32,
    decode_records: u32,
    push: u32,
    checksum: u32,
    bytes: usize,
}

fn run_workload(
    w: &Workload,
    frame: &mut [u8; FRAME_CAP],
    empty: u32,
) -> Result<Figures, &'static str> {
    let mut recs: [PositionRecord; MAX_PER_FRAME] =
        core::array::from_fn(|_| PositionRecord::default());
    let recs = recs
        .get_mut(..usize::from(w.per_frame))
        .ok_or("workload larger than the record array")?;
    let mut dec: FrameDecoder = FrameDecoder::new();
    let mut batch: [PositionRecord; BATCH] = Default::default();
    let mut f = Figures::default();
    let net = |t: u32| t.saturating_sub(empty);
    for k in 0..u32::from(FRAMES) {
        for (i, r) in recs.iter_mut().enumerate() {
            *r = record(k * u32::from(w.per_frame) + i as u32, w.axes);
        }
        let recs: &[PositionRecord] = recs;

        let (t, len) = timed(|| encode(black_box(recs), black_box(&mut *frame)));
        let len = len.ok_or("encode failed")?;
        f.encode += net(t);
        let mut whole = [0u8; FRAME_CAP];
        let (t, n) = timed(|| encode_frame(black_box(recs), black_box(&mut whole)));
        if n != Some(len) || whole != *frame {
            return Err("encode_frame did not give the same frame");
        }
        f.encode_frame += net(t);
        let bytes = frame.get(..len).ok_or("frame longer than its buffer")?;
        f.bytes += len;

        let (t, n) = timed(|| decode(black_box(bytes)));
        if n != Some(w.per_frame) {
            return Err("decode did not give back every record");
        }
        f.decode += net(t);

        let (t, n) = timed(|| decode_records(black_box(bytes), black_box(&mut batch)));
        if n != Some(w.per_frame) {
            return Err("decode_records did not give back every record");
        }
        f.decode_records += net(t);

        let (t, n) = timed(|| push(black_box(&mut dec), black_box(bytes)));
        if n != Some(len) {
            return Err("the frame decoder did not return the frame");
        }
        f.push += net(t);

        let (t, sum) = timed(|| checksum(black_box(bytes)));
        black_box(sum);
        f.checksum += net(t);
    }
    Ok(f)
}

/// Starts the counter, prints the core and the calibration; the ticks of
/// an empty timed piece (what every figure has taken off), or `None` if
/// SysTick does not count.
pub fn start(print: fn(core::fmt::Arguments<'_>)) -> Option<u32> {
    start_counter();
    let cpuid = CPUID::PTR;
    // SAFETY: a read of the read-only CPUID base register.
    let cpuid = unsafe { (*cpuid).base.read() };
    print(format_args!(
        "bench core {} {:#010x}\n",
        core_name(cpuid),
        cpuid
    ));
    let (cal_instr, cal_ticks) = calibrate();
    if cal_ticks == 0 {
        print(format_args!("bench failed SysTick does not count\n"));
        return None;
    }
    print(format_args!("bench calibration {cal_instr} {cal_ticks}\n"));
    let (empty, ()) = timed(|| ());
    Some(empty)
}

/// Runs every hex-path workload and prints the figures (see the module
/// docs). Returns whether every round trip checked out. Not inlined: its
/// buffers are off the stack before the line workloads take theirs.
#[inline(never)]
pub fn run(print: fn(core::fmt::Arguments<'_>), empty: u32) -> bool {
    let mut frame = [0u8; FRAME_CAP];
    for w in &WORKLOADS {
        match run_workload(w, &mut frame, empty) {
            Ok(f) => {
                for (what, t) in [
                    ("encode", f.encode),
                    ("encode-frame", f.encode_frame),
                    ("decode", f.decode),
                    ("decode-records", f.decode_records),
                    ("push", f.push),
                    ("checksum", f.checksum),
                ] {
                    print(format_args!("bench {} {what} {t} {}\n", w.name, f.bytes));
                }
            }
            Err(why) => {
                print(format_args!("bench failed {}: {why}\n", w.name));
                return false;
            }
        }
    }
    true
}
