//! Proof that the core's paths allocate nothing: a counting global
//! allocator, switched on only around calls into the core.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

use host_tests::table::table;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::engine::{feed, Engine, Step};
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::{PositionStreamDecoder, PositionStreamEncoder, StreamEvent};
use iai_protocol_b::transfer::{Transfer, TransferConfig};
use iai_protocol_b::{line::Line, line::LineConfig, profile::Profile};
use iai_simulator::Simulator;

struct Counting;
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
thread_local!(static COUNTING: Cell<bool> = const { Cell::new(false) });

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Runs `f` with allocation counting on; returns its result.
fn core_call<T>(f: impl FnOnce() -> T) -> T {
    COUNTING.with(|c| c.set(true));
    let r = f();
    COUNTING.with(|c| c.set(false));
    r
}

fn allocations() -> u64 {
    ALLOCATIONS.load(Ordering::Relaxed)
}

#[test]
fn the_core_allocates_nothing() {
    let before = allocations();

    // Encode the full 1.64 MB table in 256-byte chunks into a preallocated buffer.
    let mut wire = vec![0u8; 1_640_014];
    let mut enc = core_call(|| {
        PositionStreamEncoder::new(
            PositionStream::CHANGE_2,
            Station(0x99),
            0,
            20_000,
            table(20_000, 8, 3),
        )
        .unwrap()
    });
    let mut at = 0;
    loop {
        let end = (at + 256).min(wire.len());
        let n = core_call(|| enc.read(&mut wire[at..end]).unwrap());
        if n == 0 {
            break;
        }
        at += n;
    }
    assert_eq!(at, wire.len());

    // Decode it record by record.
    let mut dec = PositionStreamDecoder::new(BypassPolicy::Reject);
    let mut records = 0u32;
    let mut rest = &wire[..];
    let end = core_call(|| loop {
        let r = dec.decode(rest);
        let (used, ev) = (r.consumed, r.status.complete());
        rest = &rest[used..];
        match ev {
            Some(StreamEvent::Record(_)) => records += 1,
            None | Some(StreamEvent::Start { .. }) => {}
            Some(other) => break other,
        }
    });
    assert_eq!(end, StreamEvent::End { records: 20_000 });
    assert_eq!(records, 20_000);

    // Frame decoder over a noisy stream.
    let mut fd: FrameDecoder = FrameDecoder::new();
    let noisy = b"zz#992322C\r\n!9926D000102\r\n#99212021C00000000002715AF\r\n";
    let frames = core_call(|| {
        let mut n = 0;
        let mut input = &noisy[..];
        loop {
            let d = fd.decode(input);
            input = &input[d.consumed..];
            match d.status.complete() {
                None => break n,
                Some(Event::Frame(_)) => n += 1,
                Some(Event::Error(_)) => {}
            }
        }
    });
    assert_eq!(frames, 2);

    // The transfer engine against the simulator (only engine calls counted).
    let mut sim = Simulator::tta(Station(0x99));
    let mut line = core_call(|| Line::new(LineConfig::new(Station(0x99)), 9));
    let mut t: Transfer<_> =
        core_call(|| Transfer::new(TransferConfig::new(Profile::TTA), table(2_000, 8, 4)));
    let verified = drive_counted(&mut t, &mut line, &mut sim);
    assert!(verified.is_ok());
    assert_eq!(t.stats().records_confirmed, 2_000);
    assert_eq!(t.stats().records_verified, 2_000);

    // The request engine: a 212H and its typed reply.
    let mut client: iai_protocol_b::client::Client = core_call(iai_protocol_b::client::Client::new);
    let q = iai_protocol_b::message::AxisStatusQuery::of(&[1, 2]).unwrap();
    let now = sim.next_output_at().unwrap_or(0) + 10_000;
    let ticket = core_call(|| client.start(&mut line, &q, now)).unwrap();
    let outcome = drive_counted(&mut client, &mut line, &mut sim);
    assert!(outcome.is_ok());
    let status = core_call(|| client.response(&ticket).map(|r| r.axes.len()));
    assert_eq!(status, Ok(2));

    assert_eq!(allocations() - before, 0, "the core allocated");
    println!(
        "RAM (size_of): FrameDecoder<2051> {} B, PositionStreamEncoder {} B (+ its source), \
         PositionStreamDecoder {} B, Transfer<_, 2051> {} B (+ its source), ReadBack<2048> {} B, \
         Client<2051, 2048> {} B, Client<64, 128> {} B",
        std::mem::size_of::<FrameDecoder>(),
        std::mem::size_of::<
            PositionStreamEncoder<std::iter::Empty<iai_protocol_b::position::PositionRecord>>,
        >(),
        std::mem::size_of::<PositionStreamDecoder>(),
        std::mem::size_of::<Transfer<std::iter::Empty<iai_protocol_b::position::PositionRecord>>>(),
        std::mem::size_of::<iai_protocol_b::readback::ReadBack>(),
        std::mem::size_of::<iai_protocol_b::client::Client>(),
        std::mem::size_of::<iai_protocol_b::client::Client<64, 128>>(),
    );
    println!("RAM (size_of): Line {} B", std::mem::size_of::<Line>());
}

/// Drives `engine` on `line` against `sim` in virtual time to its result,
/// counting the allocations of the engine's calls only.
fn drive_counted<G: Engine>(
    engine: &mut G,
    line: &mut Line,
    sim: &mut Simulator,
) -> Result<G::Output, iai_protocol_b::error::Failure> {
    let mut now = 0u32;
    loop {
        let reply = sim.take_output(now);
        core_call(|| feed(engine, line, &reply, now));
        let mut out = Vec::new();
        let step = core_call(|| match engine.poll(line, now) {
            Step::Transmit(b) => {
                // Copying out is the caller's business: count only the engine.
                COUNTING.with(|c| c.set(false));
                out.extend_from_slice(b);
                None
            }
            Step::WaitUntil(d) => Some(Err(d)),
            Step::Done(r) => Some(Ok(r)),
            Step::Idle => panic!("idle"),
        });
        match step {
            None => {
                sim.receive(&out, now);
                core_call(|| engine.sent(line, now));
            }
            Some(Err(d)) => now = sim.next_output_at().map_or(d, |r| r.min(d)).max(now + 1),
            Some(Ok(r)) => return r,
        }
    }
}
