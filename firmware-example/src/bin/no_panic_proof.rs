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
//! record layout, the frame skipper, the line (its ledger of replies that
//! may still arrive, and its fences, on a line that repeats frames), the
//! request client, the transfer engine (its write and streamed read-back
//! paths) and the read-back engine fed arbitrary reply bytes (including a
//! raw command frame passed through the client), the
//! encoders (`RecordLayout::put_record`, the whole-field record paths, and
//! `PositionStreamEncoder` for every position stream) on a record made of
//! those bytes, the bridge library (`Bridge::poll`, the configuration
//! block, the serial line) fed arbitrary bytes on both ports, and the
//! Modbus gateway (its frame handler on arbitrary frames, RTU and Modbus
//! TCP ADUs cut by `modbus::tcp::adu_len`, its polls and commands on the
//! bridge's line answered with arbitrary bytes), the configuration page
//! (the bridge's configuration messages through an editor over a page
//! store in RAM, the settings table's parsers on arbitrary keys and
//! values, the store's slot check on arbitrary slots). With the
//! `ethernet` feature too: the network block, the Stellaris MAC driver
//! reading arbitrary register values and handing smoltcp its tokens, the
//! bridge's end of a TCP host (`end_of_input`, `host_idle`), and the web
//! page's form parser, all fed from those bytes.
//!
//! Build: `cargo build --release --features no-panic-proof --bin
//! no_panic_proof --target thumbv7m-none-eabi` (add `ethernet` to the
//! features for the network side; a debug build keeps panic paths the
//! optimiser would remove, so only release builds prove it).
//!
//! smoltcp's interface and sockets cannot be linked into this proof: its
//! packet emitters index buffers it sized itself, and about 70 of those
//! bounds checks survive. With the `no-panic-audit` feature the program
//! also runs the whole network side (`Net` on the driver: ingress, egress,
//! DHCP, the protocol-B hosts, the Modbus TCP clients and the web page over
//! the bridge and the gateway) and its panic handler is an ordinary one, so that it
//! links; `tools/panic-audit.py` then lists every panic call left in the
//! image, by the source line it comes from, and fails if one comes from
//! this project's code or from a smoltcp line not in the reviewed list
//! (`firmware-example/no-panic-smoltcp.txt`).
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, FrameSkipper, Status};
use iai_protocol_b::engine::{feed, Driver, Step};
use iai_protocol_b::field::{FieldSpec, Reader};
use iai_protocol_b::frame::{read_envelope, Frame, Station};
use iai_protocol_b::message::{decode_any, AxisStatusQuery, Fields, GroupInfo, Value, Visitor};
use iai_protocol_b::position::{PositionRecord, PositionStream, RecordLayout};
use iai_protocol_b::table::{PositionStreamDecoder, PositionStreamEncoder, StreamEvent};
use iai_protocol_b::{
    client::Client, line::Line, line::LineConfig, profile::Profile, readback::ReadBack,
    readback::ReadBackConfig, transfer::Transfer, transfer::TransferConfig,
};

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use firmware_example::bridge::Bridge;
use firmware_example::config::editor::Editor;
use firmware_example::config::settings::{self, Settings};
use firmware_example::config::store::{self, MemFlash, PageStore, Store};
use firmware_example::config::{wire, Config};
use firmware_example::modbus::Gateway;
use firmware_example::serial::Port;
use firmware_example::serial::{self, FlowControl, Watermarks};

#[cfg(not(feature = "no-panic-audit"))]
extern "C" {
    /// Deliberately undefined (see the module docs).
    fn iai_protocol_b_decode_path_can_panic() -> !;
}

#[cfg(not(feature = "no-panic-audit"))]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    // SAFETY: never called; referencing it makes a surviving panic path a link error.
    unsafe { iai_protocol_b_decode_path_can_panic() }
}

/// The audit build's handler: it links, and the audit reads the calls to
/// it (and to the `core` functions that reach it) from the image.
#[cfg(feature = "no-panic-audit")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

/// No device interrupts are used; cortex-m-rt (with its `device` feature,
/// as the firmware builds it) still wants the table.
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
static __INTERRUPTS: [usize; 1] = [0];

/// Stand-in for bytes from a UART.
static INPUT: [u8; 4096] = [0; 4096];

static mut PAGE_RAM: [u8; 2048] = [0xFF; 2048];
static mut STORE: MaybeUninit<Store<MemFlash<'static, 1024, 4>>> = MaybeUninit::uninit();
static mut EDITOR: MaybeUninit<Editor<'static>> = MaybeUninit::uninit();

fn no_restart() {}

/// An editor over a page store in RAM whose slots hold the input.
fn editor(input: &[u8]) -> &'static mut Editor<'static> {
    // SAFETY: called once, from `main`: the only references to these.
    unsafe {
        let ram = &mut *addr_of_mut!(PAGE_RAM);
        let n = input.len().min(ram.len());
        if let (Some(dst), Some(src)) = (ram.get_mut(..n), input.get(..n)) {
            dst.copy_from_slice(src);
        }
        let store = (*addr_of_mut!(STORE)).write(Store::open(MemFlash::new(ram), 0));
        let store: &'static mut dyn PageStore = store;
        (*addr_of_mut!(EDITOR)).write(Editor::new(store, no_restart, black_box(1)))
    }
}

/// The configuration page's parsers on arbitrary bytes.
fn config_page(input: &[u8]) {
    black_box(store::page_in(input, black_box(1024)));
    let mut s = Settings::from_page(input, black_box(false));
    let (key, value) = input.split_at(input.len().min(black_box(24)));
    if let (Ok(k), Ok(v)) = (core::str::from_utf8(key), core::str::from_utf8(value)) {
        let _ = black_box(s.set(k, v));
        for setting in settings::TABLE.iter() {
            let _ = black_box(settings::parse(setting.kind, v));
        }
    }
    let _ = black_box(s.check());
    let mut window = [0u8; 64];
    s.overlay(black_box(0), &mut window);
    black_box(window);
    let _ = black_box(wire::Request::parse(black_box(0xB21), input));
    let mut out = [0u8; 64];
    black_box(wire::parse_read_reply(input, &mut out));
}

/// A port that reads the given bytes and swallows what is written.
struct Wire<'a>(&'a [u8]);

impl embedded_io::ErrorType for Wire<'_> {
    type Error = core::convert::Infallible;
}
impl embedded_io::ReadReady for Wire<'_> {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(!self.0.is_empty())
    }
}
impl embedded_io::Read for Wire<'_> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let n = buf.len().min(self.0.len());
        let (head, rest) = self.0.split_at(n);
        if let Some(dst) = buf.get_mut(..n) {
            dst.copy_from_slice(head);
        }
        self.0 = rest;
        Ok(n)
    }
}
impl embedded_io::WriteReady for Wire<'_> {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(black_box(true))
    }
}
impl embedded_io::Write for Wire<'_> {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        black_box(buf);
        Ok(black_box(buf.len()))
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
impl Port for Wire<'_> {
    fn take_overruns(&mut self) -> u32 {
        black_box(0)
    }
}

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

/// A record whose every field comes from `input`.
fn opaque_record(input: &[u8]) -> PositionRecord {
    let byte = |i: usize| input.get(i).copied().unwrap_or(0);
    let word = |i: usize| u16::from_le_bytes([byte(i), byte(i + 1)]);
    let axes = AxisPattern::from_bits(byte(2));
    let mut positions = PerAxis::new();
    for k in 0..axes.count() {
        let at = 12 + 4 * k;
        let _ = positions.push(i32::from_le_bytes([
            byte(at),
            byte(at + 1),
            byte(at + 2),
            byte(at + 3),
        ]));
    }
    PositionRecord {
        number: word(0),
        axes,
        acceleration: word(3),
        deceleration: word(5),
        speed: word(7),
        positions,
        extended: byte(9),
    }
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
        match d.status {
            Status::Partial => break,
            Status::Complete(Event::Frame(f)) => {
                if let Ok(m) = decode_any(&f) {
                    m.message.fields(&mut Sink);
                }
            }
            Status::Complete(Event::Error(e)) => {
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
        let r = sd.decode(rest);
        rest = rest.get(r.consumed..).unwrap_or(&[]);
        match r.status {
            Status::Partial => {}
            Status::Complete(StreamEvent::End { .. } | StreamEvent::Error { .. }) => sd.reset(),
            Status::Complete(other) => {
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
        let _ = black_box(layout.read_fast(input));
    }

    // The encoders, on a record made of bytes the optimiser cannot see.
    let rec = opaque_record(input);
    for layout in [
        RecordLayout::NUMBER_3,
        RecordLayout::NUMBER_4,
        RecordLayout::NUMBER_4_EXTENDED,
        RecordLayout::RANGE,
        RecordLayout::RANGE_EXTENDED,
        black_box(RecordLayout::NUMBER_4),
    ] {
        let mut out = [0u8; 96];
        let end = black_box(out.len());
        let _ = black_box(layout.put_record(&rec, out.get_mut(..end).unwrap_or(&mut [])));
    }
    for kind in PositionStream::ALL {
        let count = black_box(3u16);
        let records = core::iter::repeat_n(rec.clone(), usize::from(black_box(count)));
        if let Ok(mut enc) = PositionStreamEncoder::new(kind, Station(0x99), 0, count, records) {
            let mut chunk = [0u8; 64];
            loop {
                let end = black_box(chunk.len());
                match enc.read(chunk.get_mut(..end).unwrap_or(&mut [])) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => {
                        black_box((n, &chunk));
                    }
                }
            }
        }
    }

    // A frame passed over, summed as it goes.
    if let Some(env) = input.first_chunk::<6>() {
        if let Some((header, _, _)) = read_envelope(env) {
            let mut skip = FrameSkipper::new(header, env, black_box(BypassPolicy::Accept));
            for &b in input.get(6..).unwrap_or(&[]) {
                black_box(skip.push(b));
            }
        }
    }

    // The engines on a line that repeats frames (its ledger holds copies),
    // answered with arbitrary bytes; a fence first.
    let now = black_box(0u32);
    let cfg = LineConfig::new(Station(0x99)).with_duplicate_window(black_box(3_000));
    let mut line = Line::new(cfg, black_box(7));
    let mut t: Transfer<_> = Transfer::new(
        TransferConfig::new(Profile::TTA),
        core::iter::once(rec.clone()),
    );
    black_box(t.received(&mut line, input, now));
    if let Step::Transmit(b) = t.poll(&mut line, now) {
        black_box(b);
    }
    t.sent(&mut line, now);
    feed(&mut t, &mut line, input, now);
    black_box(t.poll(&mut line, now.wrapping_add(black_box(5_000))));
    black_box(t.mismatched_positions().count());
    // What the line hears while no engine runs, and a proof of order.
    let mut driver = Driver::new();
    let mut port = Wire(input);
    let mut clock = || now;
    black_box(driver.listen(&mut line, &mut port, &mut clock).is_ok());
    line.start_proof(now);
    black_box(line.poll(now));
    let mut c: Client = Client::new().with_error_detail().with_proof();
    let _ = black_box(c.start_frame(&mut line, input, now));
    let mut ticket = None;
    if let Ok(q) = AxisStatusQuery::of(black_box(&[1, 2])) {
        ticket = c.start(&mut line, &q, now).ok();
    }
    if let Step::Transmit(b) = c.poll(&mut line, now) {
        black_box(b);
    }
    c.sent(&mut line, now);
    feed(&mut c, &mut line, input, now);
    black_box(c.poll(&mut line, now.wrapping_add(black_box(3_000))));
    if let Some(t) = ticket {
        let _ = black_box(c.response(&t).map(|r| r.axes.len()));
    }
    let mut rb: ReadBack = ReadBack::new(ReadBackConfig::new(Profile::TTA, 1, 100));
    if let Step::Transmit(b) = rb.poll(&mut line, now) {
        black_box(b);
    }
    rb.sent(&mut line, now);
    black_box(rb.received(&mut line, input, now));
    if let Step::Done(Ok(Some(recs))) = rb.poll(&mut line, now) {
        for r in recs {
            black_box(r);
        }
    }
    black_box(line.stats());

    // The bridge, both ports fed arbitrary bytes, under any configuration,
    // its configuration messages answered through an editor.
    let (cfg, source) = Config::from_block(input);
    let mut bridge = Bridge::new(black_box(cfg), black_box(source), black_box(0));
    bridge.attach_editor(editor(input));
    config_page(input);
    let half = input.len() / 2;
    let mut up = Wire(input.get(..half).unwrap_or(&[]));
    let mut down = Wire(input.get(half..).unwrap_or(&[]));
    for tick in 0..black_box(64u32) {
        let _ = black_box(bridge.poll(&mut up, &mut down, black_box(tick)));
    }
    black_box(bridge.stats());

    // The gateway: arbitrary frames on its port (split where the input
    // says), its exchanges on the bridge's line answered with the same
    // bytes.
    let mut gateway = Gateway::new(black_box(cfg.modbus), black_box(cfg.policy));
    let mut mb = Wire(input);
    let mut down = Wire(input.get(half..).unwrap_or(&[]));
    let mut up = Wire(&[]);
    for tick in 0..black_box(64u32) {
        let us = black_box(tick.wrapping_mul(black_box(4_000)));
        let _ = black_box(gateway.serve(&mut mb, tick, us));
        let _ = black_box(bridge.poll_with(&mut up, &mut down, &mut gateway, black_box(tick)));
    }
    // Its Modbus TCP side: ADUs cut from the input where their length
    // fields say, each answered by the same handler.
    let mut resp = firmware_example::modbus::tcp::Response::new();
    let mut rest = input;
    for tick in 0..black_box(64u32) {
        let len = match firmware_example::modbus::tcp::adu_len(rest) {
            Some(Ok(n)) => n,
            _ => rest.len(),
        };
        let (adu, tail) = rest.split_at(len.min(rest.len()));
        gateway.serve_tcp(black_box(adu), &mut resp, black_box(tick));
        black_box(resp.as_slice());
        rest = tail;
    }
    black_box(gateway.stats());

    // The serial line's interrupt end, fed the same bytes.
    let mut line: serial::UartRings<256, 64> = serial::UartRings::new();
    let marks = Watermarks::for_latency(black_box(255), black_box(17));
    let (mut isr, mut thr) = line.split(black_box(FlowControl::XonXoff), marks, &|| {});
    for &b in input {
        isr.on_receive(b);
        isr.service();
        black_box(isr.next_tx(black_box(true)));
    }
    let mut buf = [0u8; 32];
    let _ = black_box(embedded_io::Read::read(&mut thr, &mut buf));
    black_box(thr.take_overruns());

    #[cfg(feature = "ethernet")]
    net::prove(input, &mut bridge, &mut gateway);

    loop {
        cortex_m::asm::wfi();
    }
}

/// The network side on registers that read arbitrary words.
#[cfg(feature = "ethernet")]
mod net {
    use core::cell::Cell;
    use core::hint::black_box;
    use core::ptr::addr_of_mut;

    use firmware_example::bridge::Bridge;
    use firmware_example::modbus::Gateway;
    use firmware_example::net::config::NetConfig;
    use firmware_example::net::stellaris::{Regs, Stellaris, FRAME_CAP};
    #[cfg(feature = "no-panic-audit")]
    use firmware_example::net::{
        http::HttpBuffers, modbus::ModbusBuffers, Buffers, Net, SocketSlots,
    };
    use smoltcp::phy::{Device, RxToken, TxToken};
    use smoltcp::time::Instant;

    use super::Wire;

    /// MAC registers whose every read is the next word of the input.
    struct Opaque<'a> {
        input: &'a [u8],
        at: Cell<usize>,
    }

    impl Regs for Opaque<'_> {
        fn read(&self, offset: usize) -> u32 {
            let at = self.at.get();
            self.at.set(black_box(at.wrapping_add(4) % 4096));
            let mut w = [0u8; 4];
            for (i, b) in w.iter_mut().enumerate() {
                *b = self.input.get(at.wrapping_add(i)).copied().unwrap_or(0);
            }
            black_box(u32::from_le_bytes(w) ^ black_box(offset as u32))
        }

        fn write(&self, offset: usize, value: u32) {
            black_box((offset, value));
        }
    }

    /// The driver on those registers.
    #[cfg(feature = "no-panic-audit")]
    type Eth<'a> = Stellaris<Opaque<'a>>;

    static mut RX: [u8; FRAME_CAP] = [0; FRAME_CAP];
    static mut TX: [u8; FRAME_CAP] = [0; FRAME_CAP];

    /// A frame length the optimiser cannot see.
    fn len_of(input: &[u8]) -> usize {
        usize::from(input.first().copied().unwrap_or(0)) << 4
    }

    pub fn prove(input: &'static [u8], bridge: &mut Bridge, gateway: &mut Gateway) {
        black_box(NetConfig::from_block(input));
        // The web page's form parser (its head parser, httparse, only in
        // the audit: see `stack`).
        let mut form = firmware_example::net::http::form::FormParser::new();
        for &b in input {
            black_box(form.push(b).map(|r| r.map(|(k, v)| (k.len(), v.len()))));
        }
        black_box(form.end().map(|r| r.map(|(k, v)| (k.len(), v.len()))));
        let regs = Opaque {
            input,
            at: Cell::new(0),
        };
        // SAFETY: `prove` runs once, from `main`: the only references.
        let (rx, tx) = unsafe { (&mut *addr_of_mut!(RX), &mut *addr_of_mut!(TX)) };
        let mut eth = Stellaris::new(regs, rx, tx);
        eth.init(black_box([2, 0, 0, 0, 0, 1]));
        let mut down = Wire(input);
        for tick in 0..black_box(64u32) {
            let t = Instant::from_millis(i64::from(black_box(tick)));
            black_box(eth.rx_pending());
            if let Some((rx, tx)) = eth.receive(t) {
                let len = rx.consume(|frame| black_box(frame.len()));
                tx.consume(black_box(len), |out| black_box(out.len()));
            }
            if let Some(tx) = eth.transmit(t) {
                tx.consume(black_box(len_of(input)), |out| {
                    let n = out.len().min(input.len());
                    if let (Some(o), Some(i)) = (out.get_mut(..n), input.get(..n)) {
                        o.copy_from_slice(i);
                    }
                });
            }
            black_box(eth.capabilities());
            let mut up = Wire(input);
            let _ = black_box(bridge.poll(&mut up, &mut down, black_box(tick)));
            black_box(bridge.end_of_input());
        }
        black_box(bridge.end_of_input());
        black_box(bridge.host_idle());
        black_box(eth.stats());
        #[cfg(feature = "no-panic-audit")]
        stack(input, &mut eth, bridge, gateway);
        #[cfg(not(feature = "no-panic-audit"))]
        black_box(gateway);
    }

    #[cfg(feature = "no-panic-audit")]
    static mut SLOTS: SocketSlots<'static> = firmware_example::net::EMPTY_SLOTS;
    #[cfg(feature = "no-panic-audit")]
    static mut BUFFERS: Buffers = Buffers::new();
    #[cfg(feature = "no-panic-audit")]
    static mut MODBUS: ModbusBuffers = ModbusBuffers::new();
    #[cfg(feature = "no-panic-audit")]
    static mut SPARKPLUG: firmware_example::net::sparkplug::SparkplugBuffers =
        firmware_example::net::sparkplug::SparkplugBuffers::new();
    #[cfg(feature = "no-panic-audit")]
    static mut HTTP: HttpBuffers = HttpBuffers::new();

    /// The whole network side, as `net::run` drives it: smoltcp's
    /// interface and sockets on the driver, DHCP or a static address from
    /// the block, the protocol-B hosts over the bridge, the Modbus TCP
    /// clients over the gateway, the web page and the Sparkplug edge node
    /// with the block read from the input (audit builds only: see the
    /// module docs).
    #[cfg(feature = "no-panic-audit")]
    fn stack(input: &'static [u8], eth: &mut Eth<'_>, bridge: &mut Bridge, gateway: &mut Gateway) {
        // SAFETY: `stack` runs once, from `prove`: the only references.
        let (slots, buffers, modbus, sparkplug, http) = unsafe {
            (
                &mut *addr_of_mut!(SLOTS),
                &mut *addr_of_mut!(BUFFERS),
                &mut *addr_of_mut!(MODBUS),
                &mut *addr_of_mut!(SPARKPLUG),
                &mut *addr_of_mut!(HTTP),
            )
        };
        let (cfg, _) = NetConfig::from_block(input);
        let station = black_box(firmware_example::config::Config::default().bridge_station);
        let mut net = Net::new(
            cfg,
            black_box([2, 0, 0, 0, 0, 1]),
            black_box(7),
            station,
            eth,
            slots,
            buffers,
            black_box(0),
        );
        net.add_modbus(modbus, black_box(502));
        let (sp, _) = firmware_example::net::sparkplug::config::SparkplugConfig::from_block(input);
        net.add_sparkplug(sp, black_box([2, 0, 0, 0, 0, 1]), sparkplug, black_box(0));
        net.add_http(http, black_box(80));
        black_box(firmware_example::net::http::request::parse(input));
        let mut down = Wire(input);
        for tick in 0..black_box(64u32) {
            black_box(net.poll_with(eth, bridge, Some(&mut *gateway), black_box(tick)));
            let mut up = net.host_port();
            let _ = black_box(bridge.poll_with(&mut up, &mut down, &mut *gateway, black_box(tick)));
            black_box(net.address());
            if let Some(node) = net.sparkplug_mut() {
                if black_box(tick) == 63 {
                    node.leave();
                }
            }
        }
    }
}
