//! The Arm MPS2 with the AN386 image (QEMU `mps2-an386`, Cortex-M4F):
//! CMSDK APB UARTs with one-byte buffers and separate receive and transmit
//! interrupts, and the CMSDK watchdog (its interrupt is the NMI here),
//! through the `mps2-an386` device crate.
//!
//! The watchdog resets the board if the loop stops feeding it for two
//! periods. The CMSDK UART has no modem lines: this board offers no flow
//! control but XON/XOFF (RTS/CTS in the configuration block is treated as
//! none, and the status query reports what is in force).

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use cortex_m::peripheral::NVIC;
use cortex_m_rt::exception;
use mps2_an386::uart::{self, RegisterBlock};
use mps2_an386::{interrupt, watchdog, Interrupt};

use super::clock::start_tick;
use super::config_page::load_config;
use super::lines::{handoff, in_handoff, setup, Handoff, Statics};
use super::report::banner;
use super::run::serve;
use crate::bridge::Bridge;
use crate::serial::{DownstreamRings, FlowControl, IsrEnd, UartRings, UpstreamRings};

/// A board built on the AN386 image: which UART is which, the clock.
pub struct Board {
    /// Name printed in the start-up banner.
    pub name: &'static str,
    /// Core and APB clock.
    pub core_clock_hz: u32,
    /// The host's UART.
    pub host: Uart,
    /// The controller's UART.
    pub controller: Uart,
    /// Watchdog period.
    pub watchdog_ms: u32,
}

/// The UARTs this module serves.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Uart {
    /// UART0.
    Uart0,
    /// UART1.
    Uart1,
}

impl Uart {
    fn regs(self) -> Option<&'static RegisterBlock> {
        let i = match self {
            Uart::Uart0 => 0,
            Uart::Uart1 => 1,
        };
        // SAFETY: this is the mps2-an386 board; the UARTs this module
        // serves belong to it (their handlers and `init`).
        unsafe { mps2_an386::uart(i) }
    }

    /// The receive and transmit interrupts.
    fn interrupts(self) -> [Interrupt; 2] {
        match self {
            Uart::Uart0 => [Interrupt::UART0RX, Interrupt::UART0TX],
            Uart::Uart1 => [Interrupt::UART1RX, Interrupt::UART1TX],
        }
    }

    fn end(self) -> &'static Handoff {
        match self {
            Uart::Uart0 => &END0,
            Uart::Uart1 => &END1,
        }
    }

    fn pend(self) -> &'static dyn Fn() {
        match self {
            Uart::Uart0 => &pend_uart0,
            Uart::Uart1 => &pend_uart1,
        }
    }

    /// 8N1 at `baud` (QEMU refuses to move bytes while BAUDDIV < 16),
    /// receive interrupt on.
    fn init(self, clock_hz: u32, baud: u32) {
        let Some(r) = self.regs() else { return };
        r.ctrl.write(0);
        r.bauddiv.write((clock_hz / baud.max(1)).max(16));
        r.intstatus
            .write(uart::INT_TX | uart::INT_RX | uart::INT_TX_OVERRUN | uart::INT_RX_OVERRUN);
        r.ctrl
            .write(uart::CTRL_TX_EN | uart::CTRL_RX_EN | uart::CTRL_RX_INTEN);
    }

    /// The receive handler's body (the transmit interrupt pends it).
    fn service(self) {
        if let Some(r) = self.regs() {
            in_handoff(self.end(), |e| service(r, e));
        }
    }
}

/// The interrupt handler body (receive and transmit share it).
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

static END0: Handoff = handoff();
static END1: Handoff = handoff();

fn pend_uart0() {
    NVIC::pend(Interrupt::UART0RX);
}

fn pend_uart1() {
    NVIC::pend(Interrupt::UART1RX);
}

/// UART0: receive and transmit share the end (the transmit interrupt pends
/// the receive one, whose handler does both; they have the same priority,
/// so they never preempt each other).
#[interrupt]
fn UART0RX() {
    Uart::Uart0.service();
}

#[interrupt]
fn UART0TX() {
    NVIC::pend(Interrupt::UART0RX);
}

#[interrupt]
fn UART1RX() {
    Uart::Uart1.service();
}

#[interrupt]
fn UART1TX() {
    NVIC::pend(Interrupt::UART1RX);
}

/// The watchdog's first timeout: leave it raised so that the second one
/// resets the board.
#[exception]
unsafe fn NonMaskableInt() {}

/// Starts the watchdog for `period_ms`.
fn start_watchdog(period_ms: u32) {
    // SAFETY: this board's watchdog; only `run` and the feed use it.
    let (wd, lock) = unsafe { (mps2_an386::watchdog(), mps2_an386::watchdog_lock()) };
    lock.write(watchdog::UNLOCK);
    wd.load.write(watchdog::CLOCK_HZ / 1_000 * period_ms);
    wd.control
        .write(watchdog::CONTROL_INTEN | watchdog::CONTROL_RESEN);
}

fn feed_watchdog() {
    // SAFETY: as in `start_watchdog`.
    unsafe { mps2_an386::watchdog() }.intclr.write(1);
}

static mut UP_LINE: UpstreamRings = UartRings::new();
static mut DOWN_LINE: DownstreamRings = UartRings::new();
/// The bridge's state, written once at start (kept out of `.data`).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();

/// The bridge between the host's and the controller's UARTs until the
/// host's quit sequence.
#[inline]
pub fn run(board: &Board) -> ! {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, board.core_clock_hz);
    let (mut cfg, source) = load_config();
    if cfg.flow == FlowControl::RtsCts {
        cfg.flow = FlowControl::None;
    }
    board.host.init(board.core_clock_hz, cfg.upstream_baud);
    board
        .controller
        .init(board.core_clock_hz, cfg.downstream_baud);
    // SAFETY: `run` runs once; these are the only references to these
    // statics, and the interrupts that use the ends are unmasked only
    // after `setup` handed them over.
    let statics = unsafe {
        Statics {
            bridge: &mut *addr_of_mut!(BRIDGE),
            up: &mut *addr_of_mut!(UP_LINE),
            down: &mut *addr_of_mut!(DOWN_LINE),
            pend_up: board.host.pend(),
            pend_down: board.controller.pend(),
            up_end: board.host.end(),
            down_end: board.controller.end(),
        }
    };
    let (bridge, mut up, mut down) = setup(statics, cfg, source);
    for uart in [board.host, board.controller] {
        for irq in uart.interrupts() {
            // SAFETY: the handlers only touch their ends, handed over above.
            unsafe { NVIC::unmask(irq) };
        }
    }
    start_watchdog(board.watchdog_ms);
    banner(board.name, source, cfg.flow);
    serve(bridge, &mut up, &mut down, feed_watchdog)
}
