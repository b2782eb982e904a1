//! The TI Stellaris LM3S6965 (QEMU `lm3s6965evb`, Cortex-M3): clock
//! gating, pins, the watchdog, and its three PL011 UARTs
//! ([`super::pl011`]), each serving one line from its interrupt.
//!
//! [`run_gateway`] is the serial board: the bridge (host and controller
//! UARTs) and the Modbus RTU gateway on a third UART, whose bytes are
//! stamped with the microsecond clock for the silence between frames.
//! `ethernet::run` (feature `ethernet`) is the board with its host on
//! Ethernet.
//!
//! The watchdog interrupts (masked) on its first timeout and resets the
//! MCU on the second, so a loop stalled for one to two periods resets it.
//!
//! RTS/CTS: the UARTs have no modem lines, so with
//! [`crate::serial::FlowControl::RtsCts`] the board drives RTS on a GPIO
//! (high: the host may send) from the receive ring's level, and reads CTS
//! on another (high: the host may receive) before each byte it transmits.
//! QEMU cannot show these lines (its serial sockets carry no modem
//! signals); the logic is tested in the host model.

#[cfg(feature = "ethernet")]
pub mod ethernet;

use core::mem::MaybeUninit;
use core::ptr::{addr_of_mut, read_volatile, write_volatile};
use core::sync::atomic::{AtomicU32, AtomicU8, Ordering};

use cortex_m::peripheral::NVIC;
use lm3s6965::{interrupt, Interrupt};

use super::clock::start_tick;
use super::config_page::load_config;
use super::lines::{build_gateway, hand_over, handoff, in_handoff, setup, Handoff, Statics};
use super::pl011::{Modem, Pl011};
use super::report::banner;
use super::run::serve_gateway;
use crate::bridge::Bridge;
use crate::modbus::Gateway;
use crate::serial::{
    DownstreamRings, FlowControl, ModbusRings, UartRings, UpstreamRings, DOWNSTREAM_MARKS,
};

/// A board built on the LM3S6965: which UART is which, the RTS/CTS pins,
/// the clock.
pub struct Board {
    /// Name printed in the start-up banner.
    pub name: &'static str,
    /// Core clock (the firmware keeps the one it starts on).
    pub core_clock_hz: u32,
    /// The host's UART.
    pub host: Uart,
    /// The controller's UART.
    pub controller: Uart,
    /// The Modbus RTU port's UART.
    pub modbus: Uart,
    /// RTS output of the host line (RTS/CTS flow control).
    pub rts: Pin,
    /// CTS input of the host line.
    pub cts: Pin,
    /// Watchdog period.
    pub watchdog_ms: u32,
}

/// The LM3S6965's UARTs, each on its fixed pins.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Uart {
    /// UART0: PA0 receive, PA1 transmit.
    Uart0,
    /// UART1: PD2 receive, PD3 transmit.
    Uart1,
    /// UART2: PG0 receive, PG1 transmit.
    Uart2,
}

impl Uart {
    fn pl011(self) -> Pl011 {
        Pl011(match self {
            Uart::Uart0 => 0x4000_C000,
            Uart::Uart1 => 0x4000_D000,
            Uart::Uart2 => 0x4000_E000,
        })
    }

    fn interrupt(self) -> Interrupt {
        match self {
            Uart::Uart0 => Interrupt::UART0,
            Uart::Uart1 => Interrupt::UART1,
            Uart::Uart2 => Interrupt::UART2,
        }
    }

    /// Its receive and transmit pins: the port and the pins' mask.
    fn pins(self) -> (Port, u32) {
        match self {
            Uart::Uart0 => (Port::A, 0b11),
            Uart::Uart1 => (Port::D, 0b1100),
            Uart::Uart2 => (Port::G, 0b11),
        }
    }

    fn end(self) -> &'static Handoff {
        match self {
            Uart::Uart0 => &END0,
            Uart::Uart1 => &END1,
            Uart::Uart2 => &END2,
        }
    }

    /// Its bit in [`STAMPED`].
    fn bit(self) -> u8 {
        match self {
            Uart::Uart0 => 1,
            Uart::Uart1 => 1 << 1,
            Uart::Uart2 => 1 << 2,
        }
    }

    fn pend(self) -> &'static dyn Fn() {
        match self {
            Uart::Uart0 => &pend_uart0,
            Uart::Uart1 => &pend_uart1,
            Uart::Uart2 => &pend_uart2,
        }
    }

    /// Clock and pins (alternate function, digital) on; the PL011 at
    /// `baud`.
    fn init(self, core_clock_hz: u32, baud: u32) {
        let bit = match self {
            Uart::Uart0 => 1,
            Uart::Uart1 => 1 << 1,
            Uart::Uart2 => 1 << 2,
        };
        set_bits(SYSCTL_RCGC1, bit);
        let (port, pins) = self.pins();
        port.enable();
        set_bits(port.base() + GPIO_AFSEL, pins);
        set_bits(port.base() + GPIO_DEN, pins);
        self.pl011().init(core_clock_hz, baud);
    }

    /// The interrupt handler's body.
    fn service(self) {
        let stamp: Option<fn() -> u32> = if STAMPED.load(Ordering::Relaxed) & self.bit() != 0 {
            Some(super::clock::now_us)
        } else {
            None
        };
        in_handoff(self.end(), |e| self.pl011().service(e, stamp, &MODEM));
    }
}

/// A GPIO port.
#[derive(Clone, Copy)]
pub enum Port {
    /// GPIO port A.
    A,
    /// GPIO port B.
    B,
    /// GPIO port D.
    D,
    /// GPIO port G.
    G,
}

impl Port {
    fn base(self) -> usize {
        match self {
            Port::A => 0x4000_4000,
            Port::B => 0x4000_5000,
            Port::D => 0x4000_7000,
            Port::G => 0x4002_6000,
        }
    }

    /// Turns the port's clock on.
    fn enable(self) {
        set_bits(
            SYSCTL_RCGC2,
            match self {
                Port::A => 1,
                Port::B => 1 << 1,
                Port::D => 1 << 3,
                Port::G => 1 << 6,
            },
        );
    }
}

/// One GPIO pin.
#[derive(Clone, Copy)]
pub struct Pin(pub Port, pub u8);

impl Pin {
    /// The pin's data register, masked to the pin (address bits 9:2 select
    /// the pins a read or write touches).
    fn data(self) -> usize {
        self.0.base() + ((1 << self.1) << 2)
    }

    fn mask(self) -> u32 {
        1 << self.1
    }

    /// The pin in 16 bits: the port's index, then the pin number.
    fn code(self) -> u16 {
        let port = match self.0 {
            Port::A => 0,
            Port::B => 1,
            Port::D => 2,
            Port::G => 3,
        };
        port << 8 | u16::from(self.1 & 7)
    }

    /// The pin [`Pin::code`] gave `code`.
    fn decode(code: u16) -> Pin {
        let port = match code >> 8 {
            0 => Port::A,
            1 => Port::B,
            2 => Port::D,
            _ => Port::G,
        };
        Pin(port, (code & 7) as u8)
    }
}

// System control (clock gating) and GPIO registers.
const SYSCTL_RCGC0: usize = 0x400F_E100;
const SYSCTL_RCGC1: usize = 0x400F_E104;
const SYSCTL_RCGC2: usize = 0x400F_E108;
const GPIO_DIR: usize = 0x400;
const GPIO_AFSEL: usize = 0x420;
const GPIO_DEN: usize = 0x51C;
/// RCGC0: the watchdog's clock.
const RCGC0_WDT: u32 = 1 << 3;

// Watchdog.
const WDT_LOAD: usize = 0x4000_0000;
const WDT_CTL: usize = 0x4000_0008;
const WDT_ICR: usize = 0x4000_000C;

fn read(addr: usize) -> u32 {
    // SAFETY: every address used is a register of this device.
    unsafe { read_volatile(addr as *const u32) }
}

fn write(addr: usize, value: u32) {
    // SAFETY: every address used is a register of this device.
    unsafe { write_volatile(addr as *mut u32, value) }
}

fn set_bits(addr: usize, bits: u32) {
    write(addr, read(addr) | bits);
}

/// The interrupt ends, handed from `main` to the handlers.
static END0: Handoff = handoff();
static END1: Handoff = handoff();
static END2: Handoff = handoff();
/// Whether a UART's handler stamps each byte (the Modbus port).
/// The UARTs whose handler stamps each byte (the Modbus port's), by
/// [`Uart::bit`].
static STAMPED: AtomicU8 = AtomicU8::new(0);
/// The RTS and CTS pins: RTS's port and pin in the low half-word, CTS's in
/// the high one (see [`Pin::code`]).
static MODEM_PINS: AtomicU32 = AtomicU32::new(0);

/// The host line's modem lines on the pins [`MODEM_PINS`] names.
static MODEM: Modem = Modem {
    set_rts: |high| {
        let rts = Pin::decode(MODEM_PINS.load(Ordering::Relaxed) as u16);
        write(rts.data(), if high { 0xFF } else { 0 });
    },
    cts: || {
        let cts = Pin::decode((MODEM_PINS.load(Ordering::Relaxed) >> 16) as u16);
        read(cts.data()) != 0
    },
};

fn pend_uart0() {
    NVIC::pend(Interrupt::UART0);
}

fn pend_uart1() {
    NVIC::pend(Interrupt::UART1);
}

fn pend_uart2() {
    NVIC::pend(Interrupt::UART2);
}

#[interrupt]
fn UART0() {
    Uart::Uart0.service();
}

#[interrupt]
fn UART1() {
    Uart::Uart1.service();
}

#[interrupt]
fn UART2() {
    Uart::Uart2.service();
}

/// Starts the watchdog for `period_ms`: interrupt (left masked) on the
/// first timeout, reset on the second.
fn start_watchdog(core_clock_hz: u32, period_ms: u32) {
    set_bits(SYSCTL_RCGC0, RCGC0_WDT);
    write(WDT_LOAD, core_clock_hz / 1_000 * period_ms);
    write(WDT_CTL, 0b11);
}

/// Reloads the watchdog.
fn feed_watchdog() {
    write(WDT_ICR, 1);
}

/// RTS an output (high: the host may send), CTS an input.
fn init_modem(rts: Pin, cts: Pin) {
    for pin in [rts, cts] {
        pin.0.enable();
        set_bits(pin.0.base() + GPIO_DEN, pin.mask());
    }
    set_bits(rts.0.base() + GPIO_DIR, rts.mask());
    MODEM_PINS.store(
        u32::from(rts.code()) | u32::from(cts.code()) << 16,
        Ordering::Relaxed,
    );
    write(rts.data(), 0xFF);
}

static mut UP_LINE: UpstreamRings = UartRings::new();
static mut DOWN_LINE: DownstreamRings = UartRings::new();
static mut MODBUS_LINE: ModbusRings = UartRings::new();
/// The bridge's and the gateway's state, written once at start (kept out
/// of `.data`, whose initial image would cost as much flash as they have
/// bytes).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();

/// What the loop runs on, set up by [`boot`].
struct Booted {
    bridge: &'static mut Bridge,
    gateway: &'static mut Gateway,
    up: crate::serial::ThreadEnd<'static>,
    down: crate::serial::ThreadEnd<'static>,
    modbus: crate::serial::ThreadEnd<'static>,
    rts_cts: bool,
}

/// The serial board: the bridge between the host's and the controller's
/// UARTs, and the Modbus RTU gateway on its own UART sharing the
/// controller line, until the host's quit sequence.
///
/// `#[inline]`: compiled in the binary, with the library's generic loops
/// below it, which is where the optimiser keeps their stack frames
/// smallest (the lm3s6965's stack peak: 2,824 bytes after the demo, 3,472
/// when this is compiled in the library).
#[inline]
pub fn run_gateway(board: &Board) -> ! {
    let Booted {
        bridge,
        gateway,
        mut up,
        mut down,
        mut modbus,
        rts_cts,
    } = boot(board);
    let host = board.host.interrupt();
    serve_gateway(bridge, gateway, &mut up, &mut down, &mut modbus, || {
        feed_watchdog();
        if rts_cts {
            // CTS has no interrupt: look at it every pass.
            NVIC::pend(host);
        }
    })
}

/// Everything before the loop. Not inlined, so that its frame (the
/// configuration, the peripherals) is gone while the loop runs.
#[inline(never)]
fn boot(board: &Board) -> Booted {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, board.core_clock_hz);
    let (cfg, source) = load_config();
    board.host.init(board.core_clock_hz, cfg.upstream_baud);
    board
        .controller
        .init(board.core_clock_hz, cfg.downstream_baud);
    board.modbus.init(board.core_clock_hz, cfg.modbus.baud);
    init_modem(board.rts, board.cts);
    STAMPED.store(board.modbus.bit(), Ordering::Relaxed);

    // SAFETY: `boot` runs once; these are the only references to these
    // statics, and the interrupts that use the ends are unmasked only
    // after they were handed over.
    let (statics, gateway, modbus_line) = unsafe {
        (
            Statics {
                bridge: &mut *addr_of_mut!(BRIDGE),
                up: &mut *addr_of_mut!(UP_LINE),
                down: &mut *addr_of_mut!(DOWN_LINE),
                pend_up: board.host.pend(),
                pend_down: board.controller.pend(),
                up_end: board.host.end(),
                down_end: board.controller.end(),
            },
            &mut *addr_of_mut!(GATEWAY),
            &mut *addr_of_mut!(MODBUS_LINE),
        )
    };
    let (bridge, up, down) = setup(statics, cfg, source);
    let gateway = build_gateway(gateway, &cfg);
    let modbus = hand_over(
        modbus_line,
        FlowControl::None,
        DOWNSTREAM_MARKS,
        board.modbus.pend(),
        board.modbus.end(),
    );
    for uart in [board.host, board.controller, board.modbus] {
        // SAFETY: the handlers only touch their ends, handed over above.
        unsafe { NVIC::unmask(uart.interrupt()) };
    }
    start_watchdog(board.core_clock_hz, board.watchdog_ms);
    banner(board.name, source, cfg.flow);
    Booted {
        bridge,
        gateway,
        up,
        down,
        modbus,
        rts_cts: cfg.flow == FlowControl::RtsCts,
    }
}
