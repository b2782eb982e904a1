//! The bridge on an Arm MPS2 with the AN386 image (QEMU `mps2-an386`,
//! Cortex-M4F).
//!
//! UART0 faces the host, UART1 the controller: CMSDK APB UARTs with
//! one-byte buffers and separate receive and transmit interrupts, through
//! the `mps2-an386` device crate. The CMSDK watchdog (its interrupt is the
//! NMI here) resets the board if the loop stops feeding it for two periods
//! of [`WATCHDOG_MS`]. The CMSDK UART has no modem lines: this board offers
//! no flow control but XON/XOFF (RTS/CTS in the configuration block is
//! treated as none, and the status query reports what is in force).
#![no_std]
#![no_main]
#![cfg_attr(
    feature = "stall",
    allow(unreachable_code, unused_variables, unused_mut)
)]

#[path = "../runtime.rs"]
mod runtime;

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use cortex_m::peripheral::NVIC;
use cortex_m_rt::{entry, exception};
use firmware_example::bridge::Bridge;
use firmware_example::serial::{DownstreamRings, FlowControl, IsrEnd, UartRings, UpstreamRings};
use mps2_an386::uart::{self, RegisterBlock};
use mps2_an386::{interrupt, watchdog, Interrupt};
use runtime::Handoff;

/// Name printed in the start-up banner.
const NAME: &str = "mps2-an386";
/// Core and APB clock as QEMU models it (SYSCLK 25 MHz).
pub const CORE_CLOCK_HZ: u32 = 25_000_000;
/// Watchdog period (see the module docs).
const WATCHDOG_MS: u32 = 2_000;

static mut UP_LINE: UpstreamRings = UartRings::new();
static mut DOWN_LINE: DownstreamRings = UartRings::new();
/// The bridge's state, written once at start (kept out of `.data`, whose
/// initial image would cost as much flash as the bridge has bytes).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();

static UP_END: Handoff = runtime::handoff();
static DOWN_END: Handoff = runtime::handoff();

fn uart_regs(i: usize) -> &'static RegisterBlock {
    // SAFETY: this is the mps2-an386 board; UART0 and UART1 belong to the
    // bridge (their interrupt handlers and `init`).
    match unsafe { mps2_an386::uart(i) } {
        Some(r) => r,
        None => panic!("no such UART"),
    }
}

/// 8N1 at `baud` (QEMU refuses to move bytes while BAUDDIV < 16),
/// receive interrupt on.
fn init_uart(r: &RegisterBlock, baud: u32) {
    r.ctrl.write(0);
    r.bauddiv.write((CORE_CLOCK_HZ / baud.max(1)).max(16));
    r.intstatus
        .write(uart::INT_TX | uart::INT_RX | uart::INT_TX_OVERRUN | uart::INT_RX_OVERRUN);
    r.ctrl
        .write(uart::CTRL_TX_EN | uart::CTRL_RX_EN | uart::CTRL_RX_INTEN);
}

/// The interrupt handler body (receive and transmit lines share it).
///
/// The transmit interrupt fires when the transmit buffer empties while it
/// is enabled, and stays raised until cleared: it is cleared on entry, and
/// enabled before writing so that no completion is missed.
fn service(r: &RegisterBlock, end: &mut IsrEnd<'_>) {
    r.intstatus
        .write(uart::INT_RX | uart::INT_RX_OVERRUN | uart::INT_TX | uart::INT_TX_OVERRUN);
    end.service();
    if r.state.read() & uart::STATE_RXOVERRUN != 0 {
        r.state.write(uart::STATE_RXOVERRUN);
        end.on_hw_overrun(1);
    }
    if r.state.read() & uart::STATE_RXFULL != 0 {
        end.on_receive(r.data.read() as u8);
    }
    let base = uart::CTRL_TX_EN | uart::CTRL_RX_EN | uart::CTRL_RX_INTEN;
    if end.wants_tx() {
        r.ctrl.write(base | uart::CTRL_TX_INTEN);
        while r.state.read() & uart::STATE_TXFULL == 0 {
            match end.next_tx(true) {
                Some(b) => r.data.write(u32::from(b)),
                None => break,
            }
        }
    }
    if !end.wants_tx() {
        r.ctrl.write(base);
        r.intstatus.write(uart::INT_TX);
    }
}

fn pend_up() {
    NVIC::pend(Interrupt::UART0RX);
}

fn pend_down() {
    NVIC::pend(Interrupt::UART1RX);
}

/// UART0: receive and transmit share the end (the transmit interrupt pends
/// the receive one, whose handler does both; they have the same priority,
/// so they never preempt each other).
#[interrupt]
fn UART0RX() {
    static mut END: Option<IsrEnd<'static>> = None;
    runtime::with_end(END, &UP_END, |e| service(uart_regs(0), e));
}

#[interrupt]
fn UART0TX() {
    NVIC::pend(Interrupt::UART0RX);
}

#[interrupt]
fn UART1RX() {
    static mut END: Option<IsrEnd<'static>> = None;
    runtime::with_end(END, &DOWN_END, |e| service(uart_regs(1), e));
}

#[interrupt]
fn UART1TX() {
    NVIC::pend(Interrupt::UART1RX);
}

/// The watchdog's first timeout: leave it raised so that the second one
/// resets the board.
#[exception]
unsafe fn NonMaskableInt() {}

fn start_watchdog() {
    // SAFETY: this board's watchdog; only `main` and the feed use it.
    let (wd, lock) = unsafe { (mps2_an386::watchdog(), mps2_an386::watchdog_lock()) };
    lock.write(watchdog::UNLOCK);
    wd.load.write(watchdog::CLOCK_HZ / 1_000 * WATCHDOG_MS);
    wd.control
        .write(watchdog::CONTROL_INTEN | watchdog::CONTROL_RESEN);
}

fn feed_watchdog() {
    // SAFETY: as in `start_watchdog`.
    unsafe { mps2_an386::watchdog() }.intclr.write(1);
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals already taken");
    };
    runtime::start_tick(core.SYST, CORE_CLOCK_HZ);

    let (mut cfg, source) = runtime::load_config();
    if cfg.flow == FlowControl::RtsCts {
        cfg.flow = FlowControl::None;
    }
    init_uart(uart_regs(0), cfg.upstream_baud);
    init_uart(uart_regs(1), cfg.downstream_baud);

    // SAFETY: `main` runs once; these are the only references to these
    // statics, and the interrupts that use the ends are unmasked only
    // after `setup` handed them over.
    let statics = unsafe {
        runtime::Statics {
            bridge: &mut *addr_of_mut!(BRIDGE),
            up: &mut *addr_of_mut!(UP_LINE),
            down: &mut *addr_of_mut!(DOWN_LINE),
            pend_up: &pend_up,
            pend_down: &pend_down,
            up_end: &UP_END,
            down_end: &DOWN_END,
        }
    };
    let (bridge, mut up, mut down) = runtime::setup(statics, cfg, source);
    // SAFETY: the handlers only touch their ends, handed over above.
    unsafe {
        NVIC::unmask(Interrupt::UART0RX);
        NVIC::unmask(Interrupt::UART0TX);
        NVIC::unmask(Interrupt::UART1RX);
        NVIC::unmask(Interrupt::UART1TX);
    }
    start_watchdog();
    runtime::banner(NAME, source, cfg.flow);
    runtime::serve(bridge, &mut up, &mut down, feed_watchdog)
}
