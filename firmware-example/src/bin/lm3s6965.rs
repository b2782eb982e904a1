//! The bridge on a TI Stellaris LM3S6965 (QEMU `lm3s6965evb`, Cortex-M3).
//!
//! UART0 (PA0/PA1) faces the host, UART1 (PD2/PD3) the controller, UART2
//! (PG0/PG1) is the Modbus RTU port of the gateway (`firmware_example::modbus`),
//! all PL011s with 16-byte FIFOs, interrupt-driven through the `lm3s6965`
//! device crate; the Modbus port stamps each byte with the microsecond
//! clock for the silence between frames. The watchdog resets the MCU if the loop stops feeding it
//! for two periods of [`WATCHDOG_MS`]. The configuration comes from the
//! block at `_bridge_config` (last flash page, see `memory.x`).
//!
//! RTS/CTS: the LM3S6965's UARTs have no modem lines, so with
//! [`FlowControl::RtsCts`] the board drives RTS on PB0 (high: the host may
//! send) from the receive ring's level, and reads CTS on PB1 (high: the
//! host may receive) before each byte it transmits. QEMU cannot show these
//! lines (its serial sockets carry no modem signals); the logic is tested
//! in the host model.
#![no_std]
#![no_main]
#![cfg_attr(
    feature = "stall",
    allow(unreachable_code, unused_variables, unused_mut)
)]

#[path = "../runtime.rs"]
mod runtime;

use core::mem::MaybeUninit;
use core::ptr::{addr_of_mut, read_volatile, write_volatile};

use cortex_m::peripheral::NVIC;
use cortex_m_rt::entry;
use firmware_example::bridge::Bridge;
use firmware_example::modbus::Gateway;
use firmware_example::serial::{
    DownstreamRings, FlowControl, IsrEnd, ModbusRings, UartRings, UpstreamRings, DOWNSTREAM_MARKS,
};
use lm3s6965::{interrupt, Interrupt};
use runtime::Handoff;

/// Name printed in the start-up banner.
const NAME: &str = "lm3s6965evb";
/// Core clock at reset (12 MHz, the board's crystal; the firmware keeps it).
const CORE_CLOCK_HZ: u32 = 12_000_000;
/// Watchdog period: the first timeout raises its (masked) interrupt, the
/// second resets the MCU, so a loop stalled for 2 to 4 s resets it.
const WATCHDOG_MS: u32 = 2_000;

static mut UP_LINE: UpstreamRings = UartRings::new();
static mut DOWN_LINE: DownstreamRings = UartRings::new();
/// The bridge's state, written once at start (kept out of `.data`, whose
/// initial image would cost as much flash as the bridge has bytes).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();
/// The Modbus port's rings.
static mut MODBUS_LINE: ModbusRings = UartRings::new();
/// The gateway's state, written once at start.
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();

/// The interrupt ends, handed from `main` to the handlers.
static UP_END: Handoff = runtime::handoff();
static DOWN_END: Handoff = runtime::handoff();
static MODBUS_END: Handoff = runtime::handoff();

// System control (clock gating) and GPIO.
const SYSCTL_RCGC0: usize = 0x400F_E100;
const SYSCTL_RCGC1: usize = 0x400F_E104;
const SYSCTL_RCGC2: usize = 0x400F_E108;
const GPIO_A: usize = 0x4000_4000;
const GPIO_B: usize = 0x4000_5000;
const GPIO_D: usize = 0x4000_7000;
const GPIO_G: usize = 0x4002_6000;
const GPIO_DIR: usize = 0x400;
const GPIO_AFSEL: usize = 0x420;
const GPIO_DEN: usize = 0x51C;
/// GPIO data register masked to one pin (address bits 9:2 select pins).
const fn gpio_pin(port: usize, pin: u32) -> usize {
    port + ((1 << pin) << 2)
}
const RTS_PIN: usize = gpio_pin(GPIO_B, 0);
const CTS_PIN: usize = gpio_pin(GPIO_B, 1);

// Watchdog (0x4000_0000).
const WDT_LOAD: usize = 0x4000_0000;
const WDT_CTL: usize = 0x4000_0008;
const WDT_ICR: usize = 0x4000_000C;

// PL011 register offsets and bits.
const UART_BASE: [usize; 3] = [0x4000_C000, 0x4000_D000, 0x4000_E000];
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

fn read(addr: usize) -> u32 {
    // SAFETY: every address used is a register of this device.
    unsafe { read_volatile(addr as *const u32) }
}

fn write(addr: usize, value: u32) {
    // SAFETY: every address used is a register of this device.
    unsafe { write_volatile(addr as *mut u32, value) }
}

/// One PL011.
#[derive(Clone, Copy)]
struct Uart(usize);

impl Uart {
    /// 8N1 at `baud`, FIFOs on, receive interrupts on.
    fn init(self, baud: u32) {
        write(self.0 + CR, 0);
        // Divisor = clock / (16 x baud) in 16.6 fixed point.
        let div64 = (CORE_CLOCK_HZ * 4).checked_div(baud).unwrap_or(0);
        write(self.0 + IBRD, div64 >> 6);
        write(self.0 + FBRD, div64 & 0x3F);
        // LCR_H after the divisors latches them.
        write(self.0 + LCR_H, LCR_H_WLEN_8 | LCR_H_FEN);
        write(self.0 + ICR, INT_ALL);
        write(self.0 + IMSC, INT_RX | INT_RT);
        write(self.0 + CR, CR_UARTEN | CR_TXE | CR_RXE);
    }

    /// The interrupt handler body: drain the receive FIFO into the ring,
    /// fill the transmit FIFO from it.
    fn service(self, end: &mut IsrEnd<'_>, stamped: bool) {
        write(self.0 + ICR, INT_RX | INT_RT);
        end.service();
        while read(self.0 + FR) & FR_RXFE == 0 {
            let dr = read(self.0 + DR);
            if dr & DR_OE != 0 {
                // The FIFO was full and the byte after it was lost.
                end.on_hw_overrun(1);
            }
            if stamped {
                end.on_receive_at(dr as u8, runtime::now_us());
            } else {
                end.on_receive(dr as u8);
            }
        }
        let flow = end.flow();
        if flow == FlowControl::RtsCts {
            write(RTS_PIN, if end.rts() { 1 } else { 0 });
        }
        let cts = flow != FlowControl::RtsCts || read(CTS_PIN) & 0b10 != 0;
        while read(self.0 + FR) & FR_TXFF == 0 {
            match end.next_tx(cts) {
                Some(b) => write(self.0 + DR, u32::from(b)),
                None => break,
            }
        }
        write(self.0 + ICR, INT_TX);
        let mut mask = INT_RX | INT_RT;
        if end.wants_tx() {
            mask |= INT_TX;
        }
        write(self.0 + IMSC, mask);
    }
}

fn pend_up() {
    NVIC::pend(Interrupt::UART0);
}

fn pend_down() {
    NVIC::pend(Interrupt::UART1);
}

#[interrupt]
fn UART0() {
    runtime::in_handoff(&UP_END, |e| Uart(UART_BASE[0]).service(e, false));
}

#[interrupt]
fn UART1() {
    runtime::in_handoff(&DOWN_END, |e| Uart(UART_BASE[1]).service(e, false));
}

fn pend_modbus() {
    NVIC::pend(Interrupt::UART2);
}

#[interrupt]
fn UART2() {
    runtime::in_handoff(&MODBUS_END, |e| Uart(UART_BASE[2]).service(e, true));
}

/// Clocks for the UARTs, their GPIO ports and the watchdog; UART pins to
/// their alternate function; RTS (PB0) an output, CTS (PB1) an input.
fn init_pins() {
    write(SYSCTL_RCGC0, read(SYSCTL_RCGC0) | (1 << 3));
    write(SYSCTL_RCGC1, read(SYSCTL_RCGC1) | 0b111);
    write(SYSCTL_RCGC2, read(SYSCTL_RCGC2) | 0b100_1011);
    write(GPIO_G + GPIO_AFSEL, read(GPIO_G + GPIO_AFSEL) | 0b11);
    write(GPIO_G + GPIO_DEN, read(GPIO_G + GPIO_DEN) | 0b11);
    write(GPIO_A + GPIO_AFSEL, read(GPIO_A + GPIO_AFSEL) | 0b11);
    write(GPIO_A + GPIO_DEN, read(GPIO_A + GPIO_DEN) | 0b11);
    write(GPIO_D + GPIO_AFSEL, read(GPIO_D + GPIO_AFSEL) | 0b1100);
    write(GPIO_D + GPIO_DEN, read(GPIO_D + GPIO_DEN) | 0b1100);
    write(GPIO_B + GPIO_DIR, read(GPIO_B + GPIO_DIR) | 0b01);
    write(GPIO_B + GPIO_DEN, read(GPIO_B + GPIO_DEN) | 0b11);
    write(RTS_PIN, 1);
}

/// Start the watchdog: interrupt (left masked) on the first timeout, reset
/// on the second.
fn start_watchdog() {
    write(WDT_LOAD, CORE_CLOCK_HZ / 1_000 * WATCHDOG_MS);
    write(WDT_CTL, 0b11);
}

fn feed_watchdog() {
    write(WDT_ICR, 1);
}

/// Builds the gateway in its static and hands the Modbus port's interrupt
/// end over. Not inlined, so that its stack frame (the gateway may be
/// built on the way into its static) is gone before the loop runs.
#[inline(never)]
fn setup_gateway(
    cfg: firmware_example::config::Config,
) -> (
    &'static mut Gateway,
    firmware_example::serial::ThreadEnd<'static>,
) {
    // SAFETY: called once from `main`; these are the only references to
    // these statics, and UART2's interrupt is unmasked only after its end
    // was handed over.
    unsafe {
        let gateway = (*addr_of_mut!(GATEWAY)).write(Gateway::new(cfg.modbus, cfg.policy));
        let (isr, thread) =
            (*addr_of_mut!(MODBUS_LINE)).split(FlowControl::None, DOWNSTREAM_MARKS, &pend_modbus);
        cortex_m::interrupt::free(|cs| MODBUS_END.borrow(cs).set(Some(isr)));
        (gateway, thread)
    }
}

/// What the loop runs on, set up by [`boot`].
struct Booted {
    bridge: &'static mut Bridge,
    gateway: &'static mut Gateway,
    up: firmware_example::serial::ThreadEnd<'static>,
    down: firmware_example::serial::ThreadEnd<'static>,
    modbus: firmware_example::serial::ThreadEnd<'static>,
    rts_cts: bool,
}

#[entry]
fn main() -> ! {
    let Booted {
        bridge,
        gateway,
        mut up,
        mut down,
        mut modbus,
        rts_cts,
    } = boot();
    runtime::serve_gateway(bridge, gateway, &mut up, &mut down, &mut modbus, || {
        feed_watchdog();
        if rts_cts {
            // CTS has no interrupt: look at it every pass.
            pend_up();
        }
    })
}

/// Everything before the loop. Not inlined, so that its frame (the
/// configuration, the peripherals) is gone while the loop runs.
#[inline(never)]
fn boot() -> Booted {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals already taken");
    };
    runtime::start_tick(core.SYST, CORE_CLOCK_HZ);
    let (cfg, source) = runtime::load_config();
    init_pins();
    let up_hw = Uart(UART_BASE[0]);
    let down_hw = Uart(UART_BASE[1]);
    up_hw.init(cfg.upstream_baud);
    down_hw.init(cfg.downstream_baud);
    // Parity is not set: QEMU's PL011 ignores it, and the line is 8N1.
    Uart(UART_BASE[2]).init(cfg.modbus.baud);

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
    let (bridge, up, down) = runtime::setup(statics, cfg, source);
    let (gateway, modbus) = setup_gateway(cfg);
    // SAFETY: the handlers only touch their ends, handed over above.
    unsafe {
        NVIC::unmask(Interrupt::UART0);
        NVIC::unmask(Interrupt::UART1);
        NVIC::unmask(Interrupt::UART2);
    }
    start_watchdog();
    runtime::banner(NAME, source, cfg.flow);
    Booted {
        bridge,
        gateway,
        up,
        down,
        modbus,
        rts_cts: cfg.flow == FlowControl::RtsCts,
    }
}
