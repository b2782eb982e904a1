//! The bridge on an STM32G030x8 (Cortex-M0+, 8 KiB RAM, 64 KiB flash; e.g.
//! STM32G030C8): the small part the size goal aims at. Its RAM is the 8 KiB
//! the goal names; its flash is the x8's, as the Cortex-M0 image does not
//! fit the x6's 32 KiB (see `memory-stm32g030.x`).
//!
//! Built and linked for its size figures only: QEMU has no model of it, and
//! it has not run on silicon. Pins: USART2 (PA2 TX, PA3 RX) faces the host,
//! USART1 (PA9 TX, PA10 RX) the controller. With RTS/CTS, RTS is PA1 as a
//! GPIO output driven from the receive ring's level, and CTS is PA0 in its
//! USART function (the USART stops transmitting while it is high). The
//! core runs from the 16 MHz HSI (the reset clock). The independent
//! watchdog (IWDG, 32 kHz LSI / 64) resets the MCU if the loop stops
//! feeding it for [`WATCHDOG_MS`].
#![no_std]
#![no_main]
// The PAC's `bits` writers are safe on some registers and not on others.
#![allow(unused_unsafe)]

#[path = "../runtime.rs"]
mod runtime;

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use firmware_example::bridge::Bridge;
use firmware_example::serial::{DownstreamLine, FlowControl, IsrEnd, Line, UpstreamLine};
use runtime::Handoff;
use stm32g0::stm32g030::{interrupt, Interrupt, GPIOA, IWDG, RCC, USART1, USART2};

/// Core and USART clock at reset (HSI16).
const CORE_CLOCK_HZ: u32 = 16_000_000;
/// Watchdog timeout.
const WATCHDOG_MS: u32 = 2_000;

static mut UP_LINE: UpstreamLine = Line::new();
static mut DOWN_LINE: DownstreamLine = Line::new();
/// The bridge's state, written once at start (kept out of `.data`, whose
/// initial image would cost as much flash as the bridge has bytes).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();

static UP_END: Handoff = runtime::handoff();
static DOWN_END: Handoff = runtime::handoff();

type UsartRegs = stm32g0::stm32g030::usart1::RegisterBlock;

// USART bits.
const ISR_ORE: u32 = 1 << 3;
const ISR_RXNE: u32 = 1 << 5;
const ISR_TXE: u32 = 1 << 7;
const CR1_UE: u32 = 1 << 0;
const CR1_RE: u32 = 1 << 2;
const CR1_TE: u32 = 1 << 3;
const CR1_RXNEIE: u32 = 1 << 5;
const CR1_TXEIE: u32 = 1 << 7;
const CR3_CTSE: u32 = 1 << 9;

fn up_regs() -> &'static UsartRegs {
    // SAFETY: USART2 belongs to the bridge's upstream.
    unsafe { &*USART2::ptr() }
}

fn down_regs() -> &'static UsartRegs {
    // SAFETY: USART1 belongs to the bridge's downstream.
    unsafe { &*USART1::ptr() }
}

fn init_usart(r: &UsartRegs, baud: u32, cts: bool) {
    r.cr1().write(|w| unsafe { w.bits(0) });
    r.brr()
        .write(|w| unsafe { w.bits(CORE_CLOCK_HZ / baud.max(1)) });
    r.cr3()
        .write(|w| unsafe { w.bits(if cts { CR3_CTSE } else { 0 }) });
    r.cr1()
        .write(|w| unsafe { w.bits(CR1_UE | CR1_RE | CR1_TE | CR1_RXNEIE) });
}

/// The interrupt handler body.
fn service(r: &UsartRegs, end: &mut IsrEnd<'_>, rts: bool) {
    end.service();
    let isr = r.isr().read().bits();
    if isr & ISR_ORE != 0 {
        r.icr().write(|w| unsafe { w.bits(ISR_ORE) });
        end.on_hw_overrun(1);
    }
    if isr & ISR_RXNE != 0 {
        end.on_receive(r.rdr().read().bits() as u8);
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
    let mut cr1 = CR1_UE | CR1_RE | CR1_TE | CR1_RXNEIE;
    if end.wants_tx() {
        cr1 |= CR1_TXEIE;
    }
    r.cr1().write(|w| unsafe { w.bits(cr1) });
}

fn pend_up() {
    NVIC::pend(Interrupt::USART2);
}

fn pend_down() {
    NVIC::pend(Interrupt::USART1);
}

#[interrupt]
fn USART2() {
    static mut END: Option<IsrEnd<'static>> = None;
    runtime::with_end(END, &UP_END, |e| {
        let rts = e.flow() == FlowControl::RtsCts;
        service(up_regs(), e, rts)
    });
}

#[interrupt]
fn USART1() {
    static mut END: Option<IsrEnd<'static>> = None;
    runtime::with_end(END, &DOWN_END, |e| service(down_regs(), e, false));
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

fn feed_watchdog() {
    // SAFETY: writing the reload key only.
    unsafe { &*IWDG::ptr() }
        .kr()
        .write(|w| unsafe { w.bits(0xAAAA as _) });
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals already taken");
    };
    runtime::start_tick(core.SYST, CORE_CLOCK_HZ);
    let (cfg, source) = runtime::load_config();
    let rts_cts = cfg.flow == FlowControl::RtsCts;
    init_pins(rts_cts);
    init_usart(up_regs(), cfg.upstream_baud, rts_cts);
    init_usart(down_regs(), cfg.downstream_baud, false);

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
        NVIC::unmask(Interrupt::USART1);
        NVIC::unmask(Interrupt::USART2);
    }
    start_watchdog();
    runtime::serve(bridge, &mut up, &mut down, feed_watchdog)
}
