//! The STM32L475 of the B-L475E-IOT01A board, as QEMU 10's
//! `b-l475e-iot01a` models it (and as on silicon): three USARTs serving
//! the host, the controller and a PLC's Modbus RTU line, each line a task
//! ([`super::embassy::line`]), the bridge and the gateway a task
//! ([`super::embassy::serve::gateway`]), as on the STM32G0 boards.
//!
//! Written by hand here, on `stm32-metapac` (the PAC embassy-stm32 is built
//! on), where embassy-stm32 itself does not run under QEMU 10:
//! - start-up: `embassy_stm32::init` waits for the backup domain's write
//!   access (`PWR_CR1.DBP`) to read back set, and QEMU leaves PWR
//!   unimplemented (it reads 0), so it never returns. The clock stays the
//!   reset MSI at 4 MHz; the RCC enables below turn the GPIO ports' and
//!   USARTs' clocks on (QEMU keeps a USART silent until then);
//! - the USARTs ([`usart`]): see there;
//! - the independent watchdog: QEMU does not model it (writes are
//!   dropped, so it never resets the board there); its key, prescaler and
//!   reload are written as RM0351 says, and the QEMU tests check those
//!   writes with `-d unimp`.
//!
//! RTS/CTS: none of these USARTs has the lines wired on this board;
//! RTS/CTS in the configuration block is treated as none.

pub mod usart;

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use cortex_m::peripheral::NVIC;
use stm32_metapac::gpio::vals::Moder;
use stm32_metapac::gpio::Gpio;
use stm32_metapac::iwdg::vals::{Key, Pr};
use stm32_metapac::{interrupt, Interrupt, GPIOA, GPIOB, GPIOD, IWDG, RCC};

use self::usart::{Format, Port, State};
use super::clock::start_tick;
use super::config_page::load_config;
use super::embassy::line::{self, LinePort, NoModem, Wake};
use super::embassy::{executor, serve};
use super::lines::{build_bridge, build_gateway};
use super::report::banner;
use super::run::{finish, stall_if_asked};
use crate::bridge::Bridge;
use crate::modbus::Gateway;
use crate::serial::{
    DownstreamRings, FlowControl, ModbusRings, ThreadEnd, UartRings, UpstreamRings,
    DOWNSTREAM_MARKS, UPSTREAM_MARKS,
};

/// Core and peripheral clock: the MSI's 4 MHz at reset.
pub const CORE_CLOCK_HZ: u32 = 4_000_000;

/// The board: which USART is which.
pub struct Board {
    /// Name printed in the start-up banner.
    pub name: &'static str,
    /// The host's USART.
    pub host: Usart,
    /// The controller's USART.
    pub controller: Usart,
    /// The Modbus RTU port's USART.
    pub modbus: Usart,
    /// Watchdog timeout.
    pub watchdog_ms: u32,
}

/// The USARTs this module serves, each on its pins of the B-L475E-IOT01A.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Usart {
    /// USART1 on PB6 (TX) and PB7 (RX), AF7: the ST-LINK's virtual COM
    /// port.
    Usart1,
    /// USART2 on PD5 (TX) and PD6 (RX), AF7: the PMOD connector.
    Usart2,
    /// UART4 on PA0 (TX) and PA1 (RX), AF8: the Arduino header's D1 and
    /// D0.
    Uart4,
}

static STATE1: State = State::new();
static STATE2: State = State::new();
static STATE4: State = State::new();

impl Usart {
    /// The USART as a port.
    pub fn port(self) -> Port {
        match self {
            Usart::Usart1 => Port::new(stm32_metapac::USART1, &STATE1),
            Usart::Usart2 => Port::new(stm32_metapac::USART2, &STATE2),
            Usart::Uart4 => Port::new(stm32_metapac::UART4, &STATE4),
        }
    }

    fn interrupt(self) -> Interrupt {
        match self {
            Usart::Usart1 => Interrupt::USART1,
            Usart::Usart2 => Interrupt::USART2,
            Usart::Uart4 => Interrupt::UART4,
        }
    }

    /// Its GPIO port, TX and RX pins and alternate function.
    fn pins(self) -> (Gpio, usize, usize, u8) {
        match self {
            Usart::Usart1 => (GPIOB, 6, 7, 7),
            Usart::Usart2 => (GPIOD, 5, 6, 7),
            Usart::Uart4 => (GPIOA, 0, 1, 8),
        }
    }

    /// Clocks on (the GPIO port's and the USART's), pins to their
    /// alternate function, the USART at `baud` in `format`, its interrupt
    /// unmasked; returns the port.
    pub fn init(self, baud: u32, format: Format) -> Port {
        cortex_m::interrupt::free(|_| {
            RCC.ahb2enr().modify(|w| match self {
                Usart::Usart1 => w.set_gpioben(true),
                Usart::Usart2 => w.set_gpioden(true),
                Usart::Uart4 => w.set_gpioaen(true),
            });
            match self {
                Usart::Usart1 => RCC.apb2enr().modify(|w| w.set_usart1en(true)),
                Usart::Usart2 => RCC.apb1enr1().modify(|w| w.set_usart2en(true)),
                Usart::Uart4 => RCC.apb1enr1().modify(|w| w.set_uart4en(true)),
            }
            let (gpio, tx, rx, af) = self.pins();
            for pin in [tx, rx] {
                gpio.afr(pin / 8).modify(|w| w.set_afr(pin % 8, af));
                gpio.moder().modify(|w| w.set_moder(pin, Moder::ALTERNATE));
            }
        });
        let port = self.port();
        port.init(CORE_CLOCK_HZ, baud, format);
        // SAFETY: the handler only touches this USART's state and registers.
        unsafe { NVIC::unmask(self.interrupt()) };
        port
    }
}

#[interrupt]
fn USART1() {
    Usart::Usart1.port().on_interrupt();
}

#[interrupt]
fn USART2() {
    Usart::Usart2.port().on_interrupt();
}

#[interrupt]
fn UART4() {
    Usart::Uart4.port().on_interrupt();
}

/// The independent watchdog: `ms` at the 32 kHz LSI over 64 (2 ms a
/// count, 8.19 s at most).
pub struct Watchdog;

impl Watchdog {
    /// Starts it (it cannot be stopped again).
    pub fn start(ms: u32) -> Self {
        IWDG.kr().write(|w| w.set_key(Key::START));
        IWDG.kr().write(|w| w.set_key(Key::ENABLE));
        IWDG.pr().write(|w| w.set_pr(Pr::DIVIDE_BY64));
        IWDG.rlr()
            .write(|w| w.set_rl((ms / 2).clamp(1, 0xFFF) as u16));
        // The new prescaler and reload take a few LSI cycles to apply.
        while IWDG.sr().read().0 != 0 {}
        IWDG.kr().write(|w| w.set_key(Key::RESET));
        Watchdog
    }

    /// Reloads it.
    pub fn feed(&mut self) {
        IWDG.kr().write(|w| w.set_key(Key::RESET));
    }
}

/// A line as its task serves it.
type L4Line = LinePort<Port, Port, NoModem>;

static mut UP_PORT: MaybeUninit<L4Line> = MaybeUninit::uninit();
static mut DOWN_PORT: MaybeUninit<L4Line> = MaybeUninit::uninit();
static mut MODBUS_PORT: MaybeUninit<L4Line> = MaybeUninit::uninit();

static mut UP_LINE: UpstreamRings = UartRings::new();
static mut DOWN_LINE: DownstreamRings = UartRings::new();
static mut MODBUS_LINE: ModbusRings = UartRings::new();
/// The bridge's and the gateway's state, written once at start.
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();

static UP_PENDED: Wake = Wake::new();
static DOWN_PENDED: Wake = Wake::new();
static MODBUS_PENDED: Wake = Wake::new();
static MOVED: Wake = Wake::new();

fn pend_up() {
    UP_PENDED.signal(());
}

fn pend_down() {
    DOWN_PENDED.signal(());
}

fn pend_modbus() {
    MODBUS_PENDED.signal(());
}

/// A line's task.
#[embassy_executor::task(pool_size = 3)]
async fn line_task(line: &'static mut L4Line) -> ! {
    line::serve(line, &MOVED).await
}

/// What the loop's task runs on, written once at start.
struct Loop {
    bridge: &'static mut Bridge,
    gateway: &'static mut Gateway,
    up: ThreadEnd<'static>,
    down: ThreadEnd<'static>,
    modbus: ThreadEnd<'static>,
    watchdog: Watchdog,
}

static mut LOOP: MaybeUninit<Loop> = MaybeUninit::uninit();

/// The bridge and the gateway, and their report at the quit sequence.
#[embassy_executor::task]
async fn gateway_task(l: &'static mut Loop) -> ! {
    stall_if_asked();
    let (bridge, gateway) = (&mut *l.bridge, &mut *l.gateway);
    let (up, down, modbus) = (&mut l.up, &mut l.down, &mut l.modbus);
    let feed = || l.watchdog.feed();
    let result = serve::gateway(bridge, gateway, up, down, modbus, &MOVED, feed).await;
    finish(result, l.up.pauses())
}

/// The board: the bridge between the host's and the controller's USARTs
/// and the Modbus RTU gateway on its own USART, sharing the controller
/// line, until the host's quit sequence.
#[inline]
pub fn run(board: &Board) -> ! {
    let (lines, l) = boot(board);
    executor::run(|spawner| {
        for line in lines {
            if let Ok(t) = line_task(line) {
                spawner.spawn(t);
            }
        }
        if let Ok(t) = gateway_task(l) {
            spawner.spawn(t);
        }
    })
}

/// Everything before the tasks run. Not inlined, so that its frame (the
/// configuration, the pieces built on the way into their statics) is gone
/// while they run.
#[inline(never)]
fn boot(board: &Board) -> ([&'static mut L4Line; 3], &'static mut Loop) {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, CORE_CLOCK_HZ);
    let (mut cfg, source) = load_config();
    if cfg.flow == FlowControl::RtsCts {
        cfg.flow = FlowControl::None;
    }
    let host = board.host.init(cfg.upstream_baud, Format::Plain);
    let controller = board.controller.init(cfg.downstream_baud, Format::Plain);
    let modbus = board
        .modbus
        .init(cfg.modbus.baud, Format::Modbus(cfg.modbus.parity));
    let watchdog = Watchdog::start(board.watchdog_ms);
    // SAFETY: `run` runs once; these are the only references to these
    // statics.
    let (lines, l) = unsafe {
        let bridge = build_bridge(&mut *addr_of_mut!(BRIDGE), cfg, source);
        let gateway = build_gateway(&mut *addr_of_mut!(GATEWAY), &cfg);
        let (up_end, up) = (*addr_of_mut!(UP_LINE)).split(cfg.flow, UPSTREAM_MARKS, &pend_up);
        let (down_end, down) =
            (*addr_of_mut!(DOWN_LINE)).split(FlowControl::None, DOWNSTREAM_MARKS, &pend_down);
        let (modbus_end, modbus_thread) =
            (*addr_of_mut!(MODBUS_LINE)).split(FlowControl::None, DOWNSTREAM_MARKS, &pend_modbus);
        let port = |uart: Port, end, stamped, pended| LinePort {
            rx: uart,
            tx: uart,
            end,
            modem: NoModem,
            stamped,
            pended,
        };
        (
            [
                (*addr_of_mut!(UP_PORT)).write(port(host, up_end, false, &UP_PENDED)),
                (*addr_of_mut!(DOWN_PORT)).write(port(controller, down_end, false, &DOWN_PENDED)),
                (*addr_of_mut!(MODBUS_PORT)).write(port(modbus, modbus_end, true, &MODBUS_PENDED)),
            ],
            (*addr_of_mut!(LOOP)).write(Loop {
                bridge,
                gateway,
                up,
                down,
                modbus: modbus_thread,
                watchdog,
            }),
        )
    };
    banner(board.name, source, cfg.flow);
    (lines, l)
}
