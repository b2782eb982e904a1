//! Link-time proof that the core's receive paths contain no panic.
//!
//! This program runs every decoding path of `iai-protocol-b` on bytes the
//! optimiser cannot see (they pass through `black_box`). Its panic handler
//! calls a function that exists nowhere: if any panic path of those decoders
//! survives optimisation, the handler is referenced and the link fails with
//! "undefined symbol: iai_protocol_b_decode_path_can_panic". A successful
//! `cargo build --release --bin no_panic_proof` is the proof.
//!
//! Covered: the frame decoder, `Frame::new_checked`, `decode_any` and the
//! field visitor of every message, the position-stream decoder, every
//! record layout, and the request client, the transfer engine (its write
//! and streamed read-back paths) and the read-back engine fed arbitrary
//! reply bytes, including a raw command frame passed through the client.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::client::{Client, ClientConfig, ClientStep};
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::field::{FieldSpec, Reader};
use iai_protocol_b::frame::{Frame, Station};
use iai_protocol_b::message::{decode_any, AxisStatusQuery, Fields, GroupInfo, Value, Visitor};
use iai_protocol_b::position::RecordLayout;
use iai_protocol_b::readback::{ReadBack, ReadBackConfig, ReadStep};
use iai_protocol_b::stream::{PositionStreamDecoder, StreamEvent};
use iai_protocol_b::transfer::{Step, Transfer, TransferConfig};

extern "C" {
    /// Deliberately undefined (see the module docs).
    fn iai_protocol_b_decode_path_can_panic() -> !;
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    // SAFETY: never called; referencing it makes a surviving panic path a link error.
    unsafe { iai_protocol_b_decode_path_can_panic() }
}

/// No device interrupts are used; cortex-m-rt (with its `device` feature,
/// as the firmware builds it) still wants the table.
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
static __INTERRUPTS: [usize; 1] = [0];

/// Stand-in for bytes from a UART.
static INPUT: [u8; 4096] = [0; 4096];

/// Visits every field and keeps the values alive.
struct Sink;
impl Visitor for Sink {
    fn field(&mut self, name: &'static str, unit: &'static str, spec: FieldSpec, value: Value<'_>) {
        black_box((name, unit, spec, value));
    }
    fn enter_group(&mut self, name: &'static str, info: GroupInfo) {
        black_box((name, info));
    }
    fn leave_group(&mut self) {}
}

fn wire() -> &'static [u8] {
    let input: &[u8] = black_box(&INPUT[..]);
    input.get(..black_box(input.len())).unwrap_or(&[])
}

#[entry]
fn main() -> ! {
    let input = wire();

    // Frames from a byte stream, then their typed meaning.
    let mut dec: FrameDecoder = FrameDecoder::with_policy(black_box(BypassPolicy::Accept));
    let mut rest = input;
    loop {
        let d = dec.decode(rest);
        rest = rest.get(d.consumed..).unwrap_or(&[]);
        match d.event {
            Event::NeedMore => break,
            Event::Frame(f) => {
                if let Ok(m) = decode_any(&f) {
                    m.message.fields(&mut Sink);
                }
            }
            Event::Error(e) => {
                black_box(e);
            }
        }
    }
    if let Ok(f) = Frame::new_checked(input, black_box(BypassPolicy::Reject)) {
        let _ = black_box(decode_any(&f).map(|m| m.frame.len()));
    }

    // A position table, record by record.
    let mut sd = PositionStreamDecoder::new(black_box(BypassPolicy::Reject));
    let mut rest = input;
    while !rest.is_empty() {
        let (used, ev) = sd.decode(rest);
        rest = rest.get(used..).unwrap_or(&[]);
        match ev {
            StreamEvent::NeedMore => {}
            StreamEvent::End { .. } | StreamEvent::Error { .. } => sd.reset(),
            other => {
                black_box(other);
            }
        }
    }
    for layout in [
        RecordLayout::NUMBER_3,
        RecordLayout::NUMBER_4,
        RecordLayout::NUMBER_4_EXTENDED,
        RecordLayout::RANGE,
        RecordLayout::RANGE_EXTENDED,
    ] {
        let mut r = Reader::new(input, 6);
        let _ = black_box(layout.read_record(&mut r));
    }

    // The engines, answered with arbitrary bytes.
    let now = black_box(0u32);
    let mut t: Transfer<_> = Transfer::new(TransferConfig::tta(Station(0x99)), core::iter::empty());
    black_box(t.received(input, now));
    if let Step::Transmit(b) = t.poll(now) {
        black_box(b);
    }
    t.sent(now);
    t.received_all(input, now);
    black_box(t.poll(now.wrapping_add(black_box(5_000))));
    black_box(t.mismatched_positions().count());
    let mut c: Client = Client::new(ClientConfig::new(Station(0x99)).with_error_detail());
    let _ = black_box(c.start_frame(input, now));
    if let Ok(q) = AxisStatusQuery::of(black_box(&[1, 2])) {
        let _ = black_box(c.start(&q, now));
    }
    if let ClientStep::Transmit(b) = c.poll(now) {
        black_box(b);
    }
    c.sent(now);
    c.received_all(input, now);
    black_box(c.poll(now.wrapping_add(black_box(3_000))));
    let _ = black_box(c.response::<AxisStatusQuery>().map(|r| r.axes.len()));
    let mut rb: ReadBack = ReadBack::new(ReadBackConfig::tta(Station(0x99), 1, 100));
    if let ReadStep::Transmit(b) = rb.poll(now) {
        black_box(b);
    }
    rb.sent(now);
    black_box(rb.received_all(input, now));
    if let ReadStep::Records(recs) = rb.poll(now) {
        for r in recs {
            black_box(r);
        }
    }

    loop {
        cortex_m::asm::wfi();
    }
}
