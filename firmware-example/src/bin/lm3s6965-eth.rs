//! The bridge on a TI Stellaris LM3S6965 (QEMU `lm3s6965evb`) with its host
//! side on Ethernet: protocol B over TCP ([`firmware_example::net`]).
//!
//! The host is a TCP connection on the protocol-B port (5020 unless the
//! network block names another), through the on-chip Ethernet MAC and
//! smoltcp; the controller stays on UART1 (PD2/PD3, a PL011 driven by its
//! interrupt as in the serial board). UART0 is not used. The watchdog
//! resets the MCU if the loop stops feeding it for two periods of
//! [`WATCHDOG_MS`]. The bridge's configuration comes from the block at
//! `_bridge_config`, the network's from the block [`BLOCK_OFFSET`] bytes
//! further on (see `net/config.rs`); the bridge's flow control setting
//! does not apply (TCP's window holds the host back).
//!
//! The Modbus gateway ([`firmware_example::modbus`]) serves Modbus TCP on
//! port 502 ([`firmware_example::net::modbus`]) and shares the controller
//! line with the bridge, as the serial board's gateway does; its settings
//! (unit ID, poll period, axes) come from the bridge's block.
//!
//! Under QEMU: `-nic user,model=stellaris,hostfwd=tcp:127.0.0.1:HOSTPORT-:5020`
//! (and `hostfwd=tcp:127.0.0.1:MBPORT-:502` for Modbus TCP; `restrict=on`
//! keeps the guest from reaching anything else). Once the interface has an
//! address the firmware prints
//! `firmware-example: protocol-b-tcp listening on A.B.C.D:PORT (SOURCE)`
//! and `firmware-example: modbus-tcp listening on A.B.C.D:502`.
#![no_std]
#![no_main]

// Shared with the serial boards; this board uses part of it.
#[allow(dead_code)]
#[path = "../runtime.rs"]
mod runtime;

use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut, read_volatile, write_volatile};

use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use firmware_example::bridge::Bridge;
use firmware_example::modbus::Gateway;
use firmware_example::net::config::{NetConfig, NetSource, BLOCK_LEN, BLOCK_OFFSET};
use firmware_example::net::modbus::{ModbusBuffers, MODBUS_PORT};
use firmware_example::net::stellaris::{self, Mmio, Regs, Stellaris, FRAME_CAP};
use firmware_example::net::{self, AddressSource, Buffers, Net, NetEvent, SocketSlots};
use firmware_example::serial::{DownstreamRings, FlowControl, IsrEnd, UartRings, DOWNSTREAM_MARKS};
use lm3s6965::{interrupt, Interrupt};
use runtime::{Handoff, Out};

/// Name printed in the start-up banner.
const NAME: &str = "lm3s6965evb-eth";
/// Core clock at reset (12 MHz; the firmware keeps it).
const CORE_CLOCK_HZ: u32 = 12_000_000;
/// Watchdog period: a loop stalled for 2 to 4 s resets the MCU.
const WATCHDOG_MS: u32 = 2_000;

static mut DOWN_LINE: DownstreamRings = UartRings::new();
/// The bridge and the network side, written once at start (kept out of
/// `.data`).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();
static mut NET: MaybeUninit<Net<'static>> = MaybeUninit::uninit();
static mut ETH: MaybeUninit<Stellaris<Mmio>> = MaybeUninit::uninit();
static mut SLOTS: MaybeUninit<SocketSlots<'static>> = MaybeUninit::uninit();
/// Zeroed: `.bss`.
static mut BUFFERS: Buffers = Buffers::new();
static mut MODBUS_BUFFERS: ModbusBuffers = ModbusBuffers::new();
static mut RX_FRAME: [u8; FRAME_CAP] = [0; FRAME_CAP];
static mut TX_FRAME: [u8; FRAME_CAP] = [0; FRAME_CAP];

/// The controller line's interrupt end, handed from `main` to UART1's
/// handler.
static DOWN_END: Handoff = runtime::handoff();

// System control: clock gating, the flash user registers (MAC address).
const SYSCTL_RCGC0: usize = 0x400F_E100;
const SYSCTL_RCGC1: usize = 0x400F_E104;
const SYSCTL_RCGC2: usize = 0x400F_E108;
const SYSCTL_USER0: usize = 0x400F_E1E0;
const SYSCTL_USER1: usize = 0x400F_E1E4;
/// RCGC2: the Ethernet MAC (bit 28) and PHY (bit 30), GPIO port D (bit 3).
const RCGC2_ETH: u32 = (1 << 28) | (1 << 30);
const GPIO_D: usize = 0x4000_7000;
const GPIO_AFSEL: usize = 0x420;
const GPIO_DEN: usize = 0x51C;

// Watchdog.
const WDT_LOAD: usize = 0x4000_0000;
const WDT_CTL: usize = 0x4000_0008;
const WDT_ICR: usize = 0x4000_000C;

// UART1 (PL011).
const UART1: usize = 0x4000_D000;
const DR: usize = 0x00;
const FR: usize = 0x18;
const IBRD: usize = 0x24;
const FBRD: usize = 0x28;
const LCR_H: usize = 0x2C;
const CR: usize = 0x30;
const IMSC: usize = 0x38;
const ICR: usize = 0x44;
const FR_RXFE: u32 = 1 << 4;
const FR_TXFF: u32 = 1 << 5;
const DR_OE: u32 = 1 << 11;
const LCR_H_FEN: u32 = 1 << 4;
const LCR_H_WLEN_8: u32 = 0b11 << 5;
const CR_UARTEN: u32 = 1 << 0;
const CR_TXE: u32 = 1 << 8;
const CR_RXE: u32 = 1 << 9;
const INT_RX: u32 = 1 << 4;
const INT_TX: u32 = 1 << 5;
const INT_RT: u32 = 1 << 6;
const INT_ALL: u32 = 0x7FF;

extern "C" {
    /// The configuration page (root memory map): the bridge's block, and
    /// the network block `BLOCK_OFFSET` bytes on.
    static _bridge_config: [u8; BLOCK_OFFSET + BLOCK_LEN];
}

fn read(addr: usize) -> u32 {
    // SAFETY: every address used is a register of this device.
    unsafe { read_volatile(addr as *const u32) }
}

fn write(addr: usize, value: u32) {
    // SAFETY: every address used is a register of this device.
    unsafe { write_volatile(addr as *mut u32, value) }
}

/// UART1 at `baud`, 8N1, FIFOs on, receive interrupts on.
fn uart_init(baud: u32) {
    write(UART1 + CR, 0);
    // Divisor = clock / (16 x baud) in 16.6 fixed point.
    let div64 = (CORE_CLOCK_HZ * 4).checked_div(baud).unwrap_or(0);
    write(UART1 + IBRD, div64 >> 6);
    write(UART1 + FBRD, div64 & 0x3F);
    write(UART1 + LCR_H, LCR_H_WLEN_8 | LCR_H_FEN);
    write(UART1 + ICR, INT_ALL);
    write(UART1 + IMSC, INT_RX | INT_RT);
    write(UART1 + CR, CR_UARTEN | CR_TXE | CR_RXE);
}

/// UART1's interrupt: drain the receive FIFO into the ring, fill the
/// transmit FIFO from it.
fn uart_service(end: &mut IsrEnd<'_>) {
    write(UART1 + ICR, INT_RX | INT_RT);
    end.service();
    while read(UART1 + FR) & FR_RXFE == 0 {
        let dr = read(UART1 + DR);
        if dr & DR_OE != 0 {
            end.on_hw_overrun(1);
        }
        end.on_receive(dr as u8);
    }
    while read(UART1 + FR) & FR_TXFF == 0 {
        match end.next_tx(true) {
            Some(b) => write(UART1 + DR, u32::from(b)),
            None => break,
        }
    }
    write(UART1 + ICR, INT_TX);
    let mut mask = INT_RX | INT_RT;
    if end.wants_tx() {
        mask |= INT_TX;
    }
    write(UART1 + IMSC, mask);
}

fn pend_down() {
    NVIC::pend(Interrupt::UART1);
}

#[interrupt]
fn UART1() {
    static mut END: Option<firmware_example::serial::IsrEnd<'static>> = None;
    runtime::with_end(END, &DOWN_END, uart_service);
}

/// The MAC's interrupt only wakes the loop, which reads the frames.
#[interrupt]
fn ETHERNET() {
    let status = Mmio.read(stellaris::reg::RIS);
    Mmio.write(stellaris::reg::RIS, status);
}

/// Clocks for UART1, GPIO D, the watchdog and the Ethernet MAC and PHY;
/// UART1's pins to their alternate function.
fn init_clocks_and_pins() {
    write(SYSCTL_RCGC0, read(SYSCTL_RCGC0) | (1 << 3));
    write(SYSCTL_RCGC1, read(SYSCTL_RCGC1) | 0b10);
    write(SYSCTL_RCGC2, read(SYSCTL_RCGC2) | 0b1000 | RCGC2_ETH);
    write(GPIO_D + GPIO_AFSEL, read(GPIO_D + GPIO_AFSEL) | 0b1100);
    write(GPIO_D + GPIO_DEN, read(GPIO_D + GPIO_DEN) | 0b1100);
}

/// The network settings from their block in the configuration page.
fn load_net_config() -> (NetConfig, NetSource) {
    // SAFETY: the memory map reserves the configuration page; only read.
    let page = unsafe { &*addr_of!(_bridge_config) };
    NetConfig::from_block(page.get(BLOCK_OFFSET..).unwrap_or(&[]))
}

/// What `main` sets up.
struct Parts {
    bridge: &'static mut Bridge,
    gateway: &'static mut Gateway,
    net: &'static mut Net<'static>,
    eth: &'static mut Stellaris<Mmio>,
    down: firmware_example::serial::ThreadEnd<'static>,
}

/// Builds the bridge, the driver and the network side in their statics and
/// hands UART1's interrupt end over. Not inlined: its frame (the pieces
/// are built on the way into their statics) is gone before the loop runs.
#[inline(never)]
fn setup(now: u32) -> Parts {
    let (cfg, source) = runtime::load_config();
    let (net_cfg, net_source) = load_net_config();
    uart_init(cfg.downstream_baud);
    let mac = stellaris::mac_from_user(read(SYSCTL_USER0), read(SYSCTL_USER1));
    let seed = runtime::boot_seed();
    // SAFETY: `setup` runs once, from `main`; these are the only references
    // to these statics, and UART1's interrupt is unmasked only after its
    // end was handed over.
    let (bridge, gateway, net, eth, down) = unsafe {
        let bridge = (*addr_of_mut!(BRIDGE)).write(Bridge::new(cfg, source, seed));
        let gateway = (*addr_of_mut!(GATEWAY)).write(Gateway::new(cfg.modbus, cfg.policy));
        let eth = (*addr_of_mut!(ETH)).write(Stellaris::new(
            Mmio,
            &mut *addr_of_mut!(RX_FRAME),
            &mut *addr_of_mut!(TX_FRAME),
        ));
        eth.init(mac);
        let slots = (*addr_of_mut!(SLOTS)).write(net::EMPTY_SLOTS);
        let net = (*addr_of_mut!(NET)).write(Net::new(
            net_cfg,
            mac,
            u64::from(seed) << 32 | u64::from(runtime::boot_seed()),
            cfg.bridge_station,
            eth,
            slots,
            &mut *addr_of_mut!(BUFFERS),
            now,
        ));
        net.add_modbus(&mut *addr_of_mut!(MODBUS_BUFFERS), MODBUS_PORT);
        let line = &mut *addr_of_mut!(DOWN_LINE);
        let (down_isr, down) = line.split(FlowControl::None, DOWNSTREAM_MARKS, &pend_down);
        cortex_m::interrupt::free(|cs| DOWN_END.borrow(cs).set(Some(down_isr)));
        (bridge, gateway, net, eth, down)
    };
    runtime::banner(NAME, source, FlowControl::None);
    let mut out = Out::new();
    out.str("firmware-example: network block ")
        .str(match net_source {
            NetSource::Block => "Block",
            NetSource::Blank => "Blank",
            NetSource::Invalid(_) => "Invalid",
        });
    out.str(", MAC ");
    for (i, b) in mac.iter().enumerate() {
        if i > 0 {
            out.str(":");
        }
        hex_byte(&mut out, *b);
    }
    out.str("\n");
    Parts {
        bridge,
        gateway,
        net,
        eth,
        down,
    }
}

/// Two lower-case hex digits.
fn hex_byte(out: &mut Out, b: u8) {
    let digits = b"0123456789abcdef";
    let pair = [
        digits.get(usize::from(b >> 4)).copied().unwrap_or(b'?'),
        digits.get(usize::from(b & 0xF)).copied().unwrap_or(b'?'),
    ];
    out.str(core::str::from_utf8(&pair).unwrap_or("??"));
}

/// Prints an address change: the line the gateway and the tests wait for.
fn report(event: NetEvent) {
    let mut out = Out::new();
    match event {
        NetEvent::Listening {
            address,
            source,
            port,
            modbus_port,
        } => {
            out.str("firmware-example: protocol-b-tcp listening on ");
            dotted(&mut out, address.address);
            out.str(":").dec(u64::from(port)).str(" (");
            out.str(match source {
                AddressSource::Dhcp => "dhcp",
                AddressSource::Static => "static",
                AddressSource::Fallback => "fallback",
            });
            out.str(")\n");
            if let Some(mb) = modbus_port {
                out.str("firmware-example: modbus-tcp listening on ");
                dotted(&mut out, address.address);
                out.str(":").dec(u64::from(mb)).str("\n");
            }
        }
        NetEvent::AddressLost => {
            out.str("firmware-example: DHCP lease lost\n");
        }
    }
}

/// An IPv4 address, dotted.
fn dotted(out: &mut Out, address: [u8; 4]) {
    for (i, b) in address.iter().enumerate() {
        if i > 0 {
            out.str(".");
        }
        out.dec(u64::from(*b));
    }
}

/// Start the watchdog: interrupt (masked) on the first timeout, reset on
/// the second.
fn start_watchdog() {
    write(WDT_LOAD, CORE_CLOCK_HZ / 1_000 * WATCHDOG_MS);
    write(WDT_CTL, 0b11);
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals already taken");
    };
    runtime::start_tick(core.SYST, CORE_CLOCK_HZ);
    init_clocks_and_pins();
    let Parts {
        bridge,
        gateway,
        net,
        eth,
        mut down,
    } = setup(runtime::now_ms());
    if let Some((address, source)) = net.address() {
        report(NetEvent::Listening {
            address,
            source,
            port: net.config().port,
            modbus_port: net.modbus().map(|m| m.port()),
        });
    }
    // SAFETY: the handlers only touch their own state, handed over above.
    unsafe {
        NVIC::unmask(Interrupt::UART1);
        NVIC::unmask(Interrupt::ETHERNET);
    }
    start_watchdog();
    if cfg!(feature = "stall") {
        Out::new().str("firmware-example: stalling the loop\n");
        #[allow(clippy::empty_loop)]
        loop {}
    }
    let result = net::run(
        bridge,
        gateway,
        net,
        eth,
        &mut down,
        runtime::now_ms,
        Stellaris::rx_pending,
        runtime::sleep_unless,
        || write(WDT_ICR, 1),
        report,
    );
    let h = net.hosts().stats();
    let d = eth.stats();
    Out::new()
        .str("firmware-example: tcp hosts ")
        .dec(u64::from(h.hosts))
        .str(" refused ")
        .dec(u64::from(h.refused))
        .str(" cut short ")
        .dec(u64::from(h.cut_short))
        .str(" stalled ")
        .dec(u64::from(h.stalled));
    if let Some(m) = net.modbus() {
        let m = m.stats();
        let g = gateway.stats();
        Out::new()
            .str("; modbus-tcp connections ")
            .dec(u64::from(m.connections))
            .str(" requests ")
            .dec(u64::from(m.requests))
            .str(" answered ")
            .dec(u64::from(g.answered))
            .str(" dropped ")
            .dec(u64::from(g.dropped))
            .str(" idle closed ")
            .dec(u64::from(m.idle_closed));
    }
    Out::new()
        .str("; frames in ")
        .dec(u64::from(d.rx_frames))
        .str(" out ")
        .dec(u64::from(d.tx_frames))
        .str(" dropped ")
        .dec(u64::from(d.rx_dropped))
        .str(" fifo resets ")
        .dec(u64::from(d.rx_resets))
        .str("\n");
    runtime::finish(result, 0)
}
