//! The STM32G0 boards (`stm32g030`, the bridge alone; `stm32g070`, one
//! upstream port that speaks what the configuration chooses): two USARTs,
//! the pins, the watchdog and the statics of the lines and the bridge.
//!
//! Pins (the same on both parts): USART2 (PA2 TX, PA3 RX) is the upstream
//! port, USART1 (PA9 TX, PA10 RX) the controller's. With RTS/CTS, RTS is
//! PA1 as a GPIO output driven from the receive ring's level, and CTS is
//! PA0 in its USART function (the USART stops transmitting while it is
//! high). The core runs from the 16 MHz HSI (the reset clock). The
//! independent watchdog (IWDG, 32 kHz LSI / 64) resets the MCU if the loop
//! stops feeding it for `WATCHDOG_MS`.

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, Ordering};

use crate::bridge::Bridge;
use crate::config::Parity;
use crate::serial::{DownstreamRings, FlowControl, IsrEnd, UartRings, UpstreamRings};
use cortex_m::peripheral::NVIC;

#[cfg(feature = "board-stm32g030")]
use stm32g0::stm32g030 as pac;
#[cfg(feature = "board-stm32g070")]
use stm32g0::stm32g070 as pac;

use pac::{interrupt, Interrupt, GPIOA, IWDG, RCC, USART1, USART2};

use super::clock::{now_us, start_tick};
use super::image::load_config;
use super::lines::{handoff, in_handoff, setup, Handoff, Statics};
use super::run::{serve, serve_one_upstream};
use crate::config::UpstreamProtocol;
use crate::modbus::Gateway;

/// Core and USART clock at reset (HSI16).
const CORE_CLOCK_HZ: u32 = 16_000_000;
/// Watchdog timeout.
const WATCHDOG_MS: u32 = 2_000;

/// The upstream port's rings.
static mut UP_LINE: UpstreamRings = UartRings::new();
/// The controller port's rings.
static mut DOWN_LINE: DownstreamRings = UartRings::new();
/// The bridge's state, written once at start (kept out of `.data`, whose
/// initial image would cost as much flash as the bridge has bytes).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();

/// The interrupt ends, handed from `main` to the handlers.
static UP_END: Handoff = handoff();
/// See [`UP_END`].
static DOWN_END: Handoff = handoff();

/// Whether the upstream handler stamps each byte with the microsecond
/// clock (the port speaks Modbus RTU: frames end at a silence).
static UP_STAMPED: AtomicBool = AtomicBool::new(false);

type UsartRegs = pac::usart1::RegisterBlock;

// USART bits.
const ISR_PE: u32 = 1 << 0;
const ISR_ORE: u32 = 1 << 3;
const ISR_RXNE: u32 = 1 << 5;
const ISR_TXE: u32 = 1 << 7;
const CR1_UE: u32 = 1 << 0;
const CR1_RE: u32 = 1 << 2;
const CR1_TE: u32 = 1 << 3;
const CR1_RXNEIE: u32 = 1 << 5;
const CR1_TXEIE: u32 = 1 << 7;
const CR1_PS: u32 = 1 << 9;
const CR1_PCE: u32 = 1 << 10;
const CR1_M0: u32 = 1 << 12;
const CR2_STOP_2: u32 = 0b10 << 12;
const CR3_CTSE: u32 = 1 << 9;

/// The upstream USART.
fn up_regs() -> &'static UsartRegs {
    // SAFETY: USART2 belongs to the upstream port.
    unsafe { &*USART2::ptr() }
}

/// The controller's USART.
fn down_regs() -> &'static UsartRegs {
    // SAFETY: USART1 belongs to the bridge's downstream.
    unsafe { &*USART1::ptr() }
}

/// The frame format of a USART: 8 data bits and 1 stop bit, or with
/// `parity` a parity bit too (`Parity::None`: 2 stop bits instead, as the
/// Modbus serial line asks).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Format {
    /// 8N1 (protocol B).
    Plain,
    /// The Modbus line's: 8E1, 8O1 or 8N2.
    Modbus(Parity),
}

/// Sets a USART to `baud` and `format`, CTS on if asked, receive
/// interrupts on.
fn init_usart(r: &UsartRegs, baud: u32, format: Format, cts: bool) {
    r.cr1().write(|w| unsafe { w.bits(0) });
    r.brr()
        .write(|w| unsafe { w.bits(CORE_CLOCK_HZ / baud.max(1)) });
    let (frame, stop) = match format {
        Format::Plain => (0, 0),
        Format::Modbus(Parity::None) => (0, CR2_STOP_2),
        // A 9-bit word: 8 data bits and the parity bit.
        Format::Modbus(Parity::Even) => (CR1_M0 | CR1_PCE, 0),
        Format::Modbus(Parity::Odd) => (CR1_M0 | CR1_PCE | CR1_PS, 0),
    };
    r.cr2().write(|w| unsafe { w.bits(stop) });
    r.cr3()
        .write(|w| unsafe { w.bits(if cts { CR3_CTSE } else { 0 }) });
    r.cr1()
        .write(|w| unsafe { w.bits(frame | CR1_UE | CR1_RE | CR1_TE | CR1_RXNEIE) });
}

/// The interrupt handler body.
fn service(r: &UsartRegs, end: &mut IsrEnd<'_>, rts: bool, stamped: bool, parity_bits: u32) {
    end.service();
    let isr = r.isr().read().bits();
    if isr & ISR_ORE != 0 {
        r.icr().write(|w| unsafe { w.bits(ISR_ORE) });
        end.on_hw_overrun(1);
    }
    if isr & ISR_PE != 0 {
        // The byte is kept: the Modbus frame's CRC rejects it.
        r.icr().write(|w| unsafe { w.bits(ISR_PE) });
    }
    if isr & ISR_RXNE != 0 {
        // With parity the ninth bit is the parity bit: dropped by `as u8`.
        let byte = r.rdr().read().bits() as u8;
        if stamped {
            end.on_receive_at(byte, now_us());
        } else {
            end.on_receive(byte);
        }
    }
    if rts {
        // SAFETY: PA1 is the RTS output (set in `init_pins`).
        let gpioa = unsafe { &*GPIOA::ptr() };
        let bit = if end.rts() { 1 << 1 } else { 1 << 17 };
        gpioa.bsrr().write(|w| unsafe { w.bits(bit) });
    }
    if r.isr().read().bits() & ISR_TXE != 0 {
        // CTS is handled by the USART itself (CTSE).
        if let Some(b) = end.next_tx(true) {
            r.tdr().write(|w| unsafe { w.bits(u32::from(b)) });
        }
    }
    let mut cr1 = parity_bits | CR1_UE | CR1_RE | CR1_TE | CR1_RXNEIE;
    if end.wants_tx() {
        cr1 |= CR1_TXEIE;
    }
    r.cr1().write(|w| unsafe { w.bits(cr1) });
}

/// CR1's frame bits as [`init_usart`] set them (kept when the handler
/// rewrites CR1).
fn frame_bits(r: &UsartRegs) -> u32 {
    r.cr1().read().bits() & (CR1_M0 | CR1_PCE | CR1_PS)
}

/// Pends the upstream USART's interrupt.
fn pend_up() {
    NVIC::pend(Interrupt::USART2);
}

/// Pends the controller USART's interrupt.
fn pend_down() {
    NVIC::pend(Interrupt::USART1);
}

#[interrupt]
fn USART2() {
    in_handoff(&UP_END, |e| {
        let r = up_regs();
        let rts = e.flow() == FlowControl::RtsCts;
        let stamped = UP_STAMPED.load(Ordering::Relaxed);
        service(r, e, rts, stamped, frame_bits(r))
    });
}

#[interrupt]
fn USART1() {
    in_handoff(&DOWN_END, |e| {
        let r = down_regs();
        service(r, e, false, false, frame_bits(r))
    });
}

/// The upstream port speaks Modbus RTU: its handler stamps each byte.
fn stamp_upstream() {
    UP_STAMPED.store(true, Ordering::Relaxed);
}

/// Clocks for GPIOA and both USARTs; PA2/PA3/PA9/PA10 (and PA0 for CTS)
/// to AF1; PA1 a push-pull output for RTS.
fn init_pins(rts_cts: bool) {
    // SAFETY: start-up, nothing else uses these registers yet.
    let (rcc, gpioa) = unsafe { (&*RCC::ptr(), &*GPIOA::ptr()) };
    rcc.iopenr().modify(|r, w| unsafe { w.bits(r.bits() | 1) });
    rcc.apbenr1()
        .modify(|r, w| unsafe { w.bits(r.bits() | (1 << 17)) });
    rcc.apbenr2()
        .modify(|r, w| unsafe { w.bits(r.bits() | (1 << 14)) });
    let mut moder = gpioa.moder().read().bits();
    let mut afrl = gpioa.afrl().read().bits();
    let mut afrh = gpioa.afrh().read().bits();
    let mut alt = |pin: u32| {
        moder = (moder & !(0b11 << (2 * pin))) | (0b10 << (2 * pin));
        if pin < 8 {
            afrl = (afrl & !(0xF << (4 * pin))) | (1 << (4 * pin));
        } else {
            let p = pin - 8;
            afrh = (afrh & !(0xF << (4 * p))) | (1 << (4 * p));
        }
    };
    for pin in [2, 3, 9, 10] {
        alt(pin);
    }
    if rts_cts {
        alt(0);
        moder = (moder & !(0b11 << 2)) | (0b01 << 2);
    }
    gpioa.afrl().write(|w| unsafe { w.bits(afrl) });
    gpioa.afrh().write(|w| unsafe { w.bits(afrh) });
    gpioa.bsrr().write(|w| unsafe { w.bits(1 << 1) });
    gpioa.moder().write(|w| unsafe { w.bits(moder) });
}

/// Starts the independent watchdog.
fn start_watchdog() {
    // SAFETY: only `main` and the feed touch the IWDG.
    let iwdg = unsafe { &*IWDG::ptr() };
    iwdg.kr().write(|w| unsafe { w.bits(0xCCCC as _) });
    iwdg.kr().write(|w| unsafe { w.bits(0x5555 as _) });
    // LSI 32 kHz / 64 = 500 Hz.
    iwdg.pr().write(|w| unsafe { w.bits(0b100 as _) });
    iwdg.rlr()
        .write(|w| unsafe { w.bits((WATCHDOG_MS / 2) as _) });
    iwdg.kr().write(|w| unsafe { w.bits(0xAAAA as _) });
}

/// Reloads the watchdog.
fn feed_watchdog() {
    // SAFETY: writing the reload key only.
    unsafe { &*IWDG::ptr() }
        .kr()
        .write(|w| unsafe { w.bits(0xAAAA as _) });
}

/// The statics `setup` builds the bridge and the lines in.
///
/// # Safety
/// Call once, from `main`: the statics' only references; unmask the
/// USARTs' interrupts only after `setup` handed their ends over.
unsafe fn statics() -> Statics {
    // SAFETY: the caller's contract.
    unsafe {
        Statics {
            bridge: &mut *addr_of_mut!(BRIDGE),
            up: &mut *addr_of_mut!(UP_LINE),
            down: &mut *addr_of_mut!(DOWN_LINE),
            pend_up: &pend_up,
            pend_down: &pend_down,
            up_end: &UP_END,
            down_end: &DOWN_END,
        }
    }
}

/// Unmasks both USARTs' interrupts (after their ends were handed over).
fn unmask_usarts() {
    // SAFETY: the handlers only touch their ends, handed over before.
    unsafe {
        NVIC::unmask(Interrupt::USART1);
        NVIC::unmask(Interrupt::USART2);
    }
}

/// The bridge alone (the STM32G030x8): USART2 faces the host, USART1 the
/// controller, until the host's quit sequence.
pub fn run_bridge() -> ! {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, CORE_CLOCK_HZ);
    let (cfg, source) = load_config();
    let rts_cts = cfg.flow == FlowControl::RtsCts;
    init_pins(rts_cts);
    init_usart(up_regs(), cfg.upstream_baud, Format::Plain, rts_cts);
    init_usart(down_regs(), cfg.downstream_baud, Format::Plain, false);
    // SAFETY: called once; the interrupts are unmasked after `setup`.
    let statics = unsafe { statics() };
    let (bridge, mut up, mut down) = setup(statics, cfg, source);
    unmask_usarts();
    start_watchdog();
    serve(bridge, &mut up, &mut down, feed_watchdog)
}

/// The gateway's state, written once at start.
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();

/// One upstream port (the STM32G070): protocol B through the bridge, or
/// Modbus RTU through the gateway, as the configuration block chooses
/// (byte 19, bit 2); on the Modbus line the USART frames 8E1, 8O1 or 8N2
/// as the block's parity says.
pub fn run_one_upstream() -> ! {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, CORE_CLOCK_HZ);
    let (mut cfg, source) = load_config();
    let speaks = cfg.upstream;
    let modbus = speaks == UpstreamProtocol::ModbusRtu;
    if modbus {
        // No flow control on a Modbus line (its bytes are binary).
        cfg.flow = FlowControl::None;
        stamp_upstream();
    }
    let rts_cts = cfg.flow == FlowControl::RtsCts;
    init_pins(rts_cts);
    let (baud, format) = if modbus {
        (cfg.modbus.baud, Format::Modbus(cfg.modbus.parity))
    } else {
        (cfg.upstream_baud, Format::Plain)
    };
    init_usart(up_regs(), baud, format, rts_cts);
    init_usart(down_regs(), cfg.downstream_baud, Format::Plain, false);
    // SAFETY: called once; the interrupts are unmasked after `setup`.
    let (statics, gateway) = unsafe {
        (
            statics(),
            (*addr_of_mut!(GATEWAY)).write(Gateway::new(cfg.modbus, cfg.policy)),
        )
    };
    let (bridge, mut up, mut down) = setup(statics, cfg, source);
    unmask_usarts();
    start_watchdog();
    serve_one_upstream(speaks, bridge, gateway, &mut up, &mut down, feed_watchdog)
}
