//! The STM32G0 boards on embassy-stm32: the bridge alone
//! ([`run_bridge`], the STM32G030x8) and one upstream port that speaks
//! what the configuration block chooses ([`run_one_upstream`], the
//! STM32G070). The binary sets up embassy-stm32's drivers on its pins
//! (`BufferedUart`s with this module's [`upstream_uart`] and
//! [`controller_uart`] settings, the RTS and CTS GPIOs, the independent
//! watchdog) after reading the configuration page
//! ([`super::config_page::load_config`]); this module runs each line as a task
//! ([`super::embassy::line`]) and the bridge's loop as another.
//!
//! RTS and CTS are GPIOs ([`GpioModem`]), not the USART's own: the flow
//! decision is the line ring's level, which the USART's hardware RTS (its
//! receive register's) cannot show; CTS is read before each chunk handed
//! to the USART, whose 16-byte buffer may still go out after CTS drops.
//!
//! Written by hand: nothing (the SysTick clock is the Cortex-M core's, not
//! a peripheral of the STM32).

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::Spawner;
use embassy_stm32::gpio::{Input, Level, Output};
use embassy_stm32::peripherals::IWDG;
use embassy_stm32::usart::{
    self, BufferedUart, BufferedUartRx, BufferedUartTx, DataBits, Parity as UartParity, StopBits,
};
use embassy_stm32::wdg::IndependentWatchdog;

use super::clock::start_tick;
use super::embassy::line::{self, LinePort, Modem, Wake};
use super::embassy::{executor, serve};
use super::lines::{build_bridge, build_gateway};
use super::run::{finish, stall_if_asked};
use crate::bridge::Bridge;
use crate::config::{Config, Parity, Source, UpstreamProtocol};
use crate::modbus::Gateway;
use crate::serial::{
    DownstreamRings, FlowControl, ThreadEnd, UartRings, UpstreamRings, DOWNSTREAM_MARKS,
    UPSTREAM_MARKS,
};

/// Core clock: HSI16, embassy-stm32's default.
pub const CORE_CLOCK_HZ: u32 = 16_000_000;
/// Watchdog timeout (the IWDG runs from the 32 kHz LSI).
pub const WATCHDOG_US: u32 = 2_000_000;

/// The embassy-stm32 settings the boards start with (HSI16).
pub fn clocks() -> embassy_stm32::Config {
    embassy_stm32::Config::default()
}

/// The upstream USART's settings for what the port speaks: 8N1 at the
/// upstream rate for protocol B; for Modbus RTU the Modbus rate, with the
/// block's parity (8E1, 8O1) or two stop bits (8N2).
pub fn upstream_uart(cfg: &Config, speaks: UpstreamProtocol) -> usart::Config {
    match speaks {
        UpstreamProtocol::ProtocolB => uart(cfg.upstream_baud),
        UpstreamProtocol::ModbusRtu => {
            let mut c = uart(cfg.modbus.baud);
            match cfg.modbus.parity {
                Parity::None => c.stop_bits = StopBits::STOP2,
                Parity::Even => c.parity = UartParity::ParityEven,
                Parity::Odd => c.parity = UartParity::ParityOdd,
            }
            c
        }
    }
}

/// The controller USART's settings: 8N1 at the downstream rate.
pub fn controller_uart(cfg: &Config) -> usart::Config {
    uart(cfg.downstream_baud)
}

/// 8N1 at `baud`, its task woken at every byte.
fn uart(baud: u32) -> usart::Config {
    let mut c = usart::Config::default();
    c.baudrate = baud;
    c.data_bits = DataBits::DataBits8;
    c.eager_reads = Some(1);
    c
}

/// RTS and CTS of the upstream port on GPIOs (high: may send).
pub struct GpioModem {
    /// RTS, an output.
    pub rts: Output<'static>,
    /// CTS, an input.
    pub cts: Input<'static>,
}

impl Modem for GpioModem {
    fn set_rts(&mut self, high: bool) {
        self.rts
            .set_level(if high { Level::High } else { Level::Low });
    }
    fn cts(&mut self) -> bool {
        self.cts.is_high()
    }
}

/// The buffers of the USARTs' drivers: each only bridges the time until
/// its line's task runs (the lines' rings are where bytes wait); the
/// transmit ones are small so that an XOFF is not queued far behind data
/// (see `super::embassy::line`).
pub struct Buffers {
    /// The upstream USART's transmit buffer.
    pub up_tx: &'static mut [u8],
    /// The upstream USART's receive buffer.
    pub up_rx: &'static mut [u8],
    /// The controller USART's transmit buffer.
    pub down_tx: &'static mut [u8],
    /// The controller USART's receive buffer.
    pub down_rx: &'static mut [u8],
}

static mut UP_TX: [u8; 8] = [0; 8];
static mut UP_RX: [u8; 32] = [0; 32];
static mut DOWN_TX: [u8; 8] = [0; 8];
static mut DOWN_RX: [u8; 32] = [0; 32];

/// The USARTs' buffers. Returns `None` after the first call.
pub fn buffers() -> Option<Buffers> {
    static TAKEN: AtomicBool = AtomicBool::new(false);
    // Load and store in a critical section: Cortex-M0 has no atomic swap.
    let taken = cortex_m::interrupt::free(|_| {
        let taken = TAKEN.load(Ordering::Relaxed);
        TAKEN.store(true, Ordering::Relaxed);
        taken
    });
    if taken {
        return None;
    }
    // SAFETY: handed out once (above); these are the only references.
    unsafe {
        Some(Buffers {
            up_tx: &mut *addr_of_mut!(UP_TX),
            up_rx: &mut *addr_of_mut!(UP_RX),
            down_tx: &mut *addr_of_mut!(DOWN_TX),
            down_rx: &mut *addr_of_mut!(DOWN_RX),
        })
    }
}

/// What a G0 board runs on, set up by its binary.
pub struct Parts {
    /// The configuration and where it came from
    /// ([`super::config_page::load_config`]).
    pub config: (Config, Source),
    /// The upstream USART ([`upstream_uart`]).
    pub upstream: BufferedUart<'static>,
    /// The controller's USART ([`controller_uart`]).
    pub controller: BufferedUart<'static>,
    /// The upstream port's RTS and CTS.
    pub modem: GpioModem,
    /// The independent watchdog, not yet started.
    pub watchdog: IndependentWatchdog<'static, IWDG>,
}

static mut UP_LINE: UpstreamRings = UartRings::new();
static mut DOWN_LINE: DownstreamRings = UartRings::new();
/// The bridge's and the gateway's state, written once at start.
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();

/// What each line's task waits for, and what tells the bridge's loop.
static UP_PENDED: Wake = Wake::new();
static DOWN_PENDED: Wake = Wake::new();
static MOVED: Wake = Wake::new();

fn pend_up() {
    UP_PENDED.signal(());
}

fn pend_down() {
    DOWN_PENDED.signal(());
}

/// A line as its task serves it.
type G0Line = LinePort<BufferedUartRx<'static>, BufferedUartTx<'static>, Option<GpioModem>>;

/// The lines as their tasks serve them, written once at start.
static mut UP_PORT: MaybeUninit<G0Line> = MaybeUninit::uninit();
static mut DOWN_PORT: MaybeUninit<G0Line> = MaybeUninit::uninit();

/// A line's task.
#[embassy_executor::task(pool_size = 2)]
async fn line_task(line: &'static mut G0Line) -> ! {
    line::serve(line, &MOVED).await
}

/// What the loop's task runs on, written once at start.
struct Lines {
    bridge: &'static mut Bridge,
    up: ThreadEnd<'static>,
    down: ThreadEnd<'static>,
    watchdog: IndependentWatchdog<'static, IWDG>,
}

static mut LINES: MaybeUninit<Lines> = MaybeUninit::uninit();

/// The bridge's loop alone, and its report at the quit sequence.
#[embassy_executor::task]
async fn bridge_task(l: &'static mut Lines) -> ! {
    stall_if_asked();
    let feed = || l.watchdog.pet();
    let result = serve::bridge(l.bridge, &mut l.up, &mut l.down, &MOVED, feed).await;
    finish(result, l.up.pauses())
}

/// The loop of one upstream port that speaks `speaks`, and its report.
#[embassy_executor::task]
async fn one_upstream_task(
    speaks: UpstreamProtocol,
    gateway: &'static mut Gateway,
    l: &'static mut Lines,
) -> ! {
    stall_if_asked();
    let (bridge, up, down) = (&mut *l.bridge, &mut l.up, &mut l.down);
    let feed = || l.watchdog.pet();
    let result = serve::one_upstream(speaks, bridge, gateway, up, down, &MOVED, feed).await;
    finish(result, l.up.pauses())
}

/// Builds the bridge and the lines (the upstream stamped when it speaks
/// Modbus), starts the watchdog, spawns the lines' tasks and, with
/// `spawn_loop`, the loop's.
fn run(
    parts: Parts,
    modbus: bool,
    spawn_loop: impl FnOnce(Spawner, &Config, &'static mut Lines),
) -> ! {
    let (cfg, up_line, down_line, lines) = boot(parts, modbus);
    executor::run(|spawner| {
        for line in [up_line, down_line] {
            if let Ok(t) = line_task(line) {
                spawner.spawn(t);
            }
        }
        spawn_loop(spawner, &cfg, lines);
    })
}

/// Everything before the tasks run. Not inlined, so that its frame (the
/// pieces built on the way into their statics) is gone while they run.
#[inline(never)]
fn boot(
    parts: Parts,
    modbus: bool,
) -> (
    Config,
    &'static mut G0Line,
    &'static mut G0Line,
    &'static mut Lines,
) {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, CORE_CLOCK_HZ);
    let Parts {
        config: (mut cfg, source),
        upstream,
        controller,
        modem,
        mut watchdog,
    } = parts;
    if modbus {
        // No flow control on a Modbus line (its bytes are binary).
        cfg.flow = FlowControl::None;
    }
    let modem = (cfg.flow == FlowControl::RtsCts).then_some(modem);
    watchdog.unleash();
    // SAFETY: `boot` runs once; these are the only references to these
    // statics.
    unsafe {
        let bridge = build_bridge(&mut *addr_of_mut!(BRIDGE), cfg, source);
        let up_rings = &mut *addr_of_mut!(UP_LINE);
        let down_rings = &mut *addr_of_mut!(DOWN_LINE);
        let (up_end, up) = up_rings.split(cfg.flow, UPSTREAM_MARKS, &pend_up);
        let (down_end, down) = down_rings.split(FlowControl::None, DOWNSTREAM_MARKS, &pend_down);
        let (up_tx, up_rx) = upstream.split();
        let (down_tx, down_rx) = controller.split();
        (
            cfg,
            (*addr_of_mut!(UP_PORT)).write(LinePort {
                rx: up_rx,
                tx: up_tx,
                end: up_end,
                modem,
                stamped: modbus,
                pended: &UP_PENDED,
            }),
            (*addr_of_mut!(DOWN_PORT)).write(LinePort {
                rx: down_rx,
                tx: down_tx,
                end: down_end,
                modem: None,
                stamped: false,
                pended: &DOWN_PENDED,
            }),
            (*addr_of_mut!(LINES)).write(Lines {
                bridge,
                up,
                down,
                watchdog,
            }),
        )
    }
}

/// The bridge alone (the STM32G030x8) between the upstream and controller
/// USARTs, until the host's quit sequence.
#[inline]
pub fn run_bridge(parts: Parts) -> ! {
    run(parts, false, |spawner, _, lines| {
        if let Ok(t) = bridge_task(lines) {
            spawner.spawn(t);
        }
    })
}

/// One upstream port (the STM32G070) that speaks what the configuration
/// block chooses (byte 19, bit 2): protocol B through the bridge, or
/// Modbus RTU through the gateway, the bridge then keeping the controller
/// line with no protocol-B host.
#[inline]
pub fn run_one_upstream(parts: Parts) -> ! {
    let speaks = parts.config.0.upstream;
    run(
        parts,
        speaks == UpstreamProtocol::ModbusRtu,
        |spawner, cfg, lines| {
            // SAFETY: called once (from `run`); the only reference to it.
            let gateway = build_gateway(unsafe { &mut *addr_of_mut!(GATEWAY) }, cfg);
            if let Ok(t) = one_upstream_task(speaks, gateway, lines) {
                spawner.spawn(t);
            }
        },
    )
}

/// Stops the board where it cannot run (a USART refused its settings):
/// sleeps for ever, the watchdog not started.
pub fn halt() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}
