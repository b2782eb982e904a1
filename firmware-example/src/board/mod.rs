//! Board layer: the only code that knows register addresses.
//!
//! Exactly one board is compiled in, chosen by a cargo feature:
//!
//! | feature            | QEMU machine  | target                  | UARTs             |
//! |--------------------|---------------|-------------------------|-------------------|
//! | `board-lm3s6965`   | `lm3s6965evb` | `thumbv7m-none-eabi`    | PL011 (16-byte FIFO) |
//! | `board-mps2-an386` | `mps2-an386`  | `thumbv7em-none-eabihf` | CMSDK APB UART    |
//!
//! Each board module provides a [`Uart`] type implementing [`UartHw`], the
//! constants [`UPSTREAM`] (first serial port) and [`DOWNSTREAM`] (second
//! serial port), [`CORE_CLOCK_HZ`], [`NAME`] and the device interrupt vector
//! table (`__INTERRUPTS`), whose UART entries call into [`crate::uart`].
//!
//! This module adds what is common to every Cortex-M board: the SysTick
//! millisecond clock and sleeping in WFI.

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::exception;

#[cfg(all(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
compile_error!(
    "select exactly one board: use `--no-default-features --features board-mps2-an386` for mps2-an386"
);
#[cfg(not(any(feature = "board-lm3s6965", feature = "board-mps2-an386")))]
compile_error!("select a board feature: `board-lm3s6965` or `board-mps2-an386`");

#[cfg(feature = "board-lm3s6965")]
mod lm3s6965;
#[cfg(feature = "board-lm3s6965")]
use lm3s6965 as imp;

#[cfg(all(feature = "board-mps2-an386", not(feature = "board-lm3s6965")))]
mod mps2_an386;
#[cfg(all(feature = "board-mps2-an386", not(feature = "board-lm3s6965")))]
use mps2_an386 as imp;

pub use imp::{Uart, CORE_CLOCK_HZ, DOWNSTREAM, NAME, UPSTREAM};

/// Register-level operations on one UART, used by the interrupt-driven
/// driver in [`crate::uart`]. None of these block.
pub trait UartHw {
    /// Configure the UART (8N1, FIFO where there is one, receiver and
    /// transmitter on, receive interrupts on, transmit interrupts off) and
    /// unmask its interrupt line(s) in the NVIC.
    ///
    /// # Safety
    /// Call once, before the interrupt handlers can run, with nothing else
    /// using this UART.
    unsafe fn init(&self);
    /// Take one received byte, if the hardware holds one.
    fn read_byte(&self) -> Option<u8>;
    /// Hand one byte to the transmitter; `false` if it has no room.
    fn write_byte(&self, byte: u8) -> bool;
    /// Choose which interrupt sources are enabled. Interrupt context only.
    fn set_interrupts(&self, rx: bool, tx: bool);
    /// Clear pending receive interrupts. Call before draining the receiver.
    fn ack_rx(&self);
    /// Clear pending transmit interrupts. Call after filling the transmitter.
    fn ack_tx(&self);
    /// Make this UART's interrupt handler run soon (NVIC set-pending), so
    /// thread code can hand work to it without touching UART registers.
    fn pend(&self);
}

/// NVIC interrupt number (`IRQn`) of a device interrupt.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Irq(pub u16);

// SAFETY: every `Irq` the board modules build names an interrupt that exists
// on that device.
unsafe impl cortex_m::interrupt::InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// One entry of the device interrupt vector table. Slots the firmware does
/// not use (reserved ones included) point at [`default_handler`].
pub type Vector = unsafe extern "C" fn();

extern "C" {
    /// The `DefaultHandler` symbol (defined below with `#[exception]`), for
    /// vector table slots the firmware does not use.
    #[link_name = "DefaultHandler"]
    pub fn default_handler();
}

/// System tick rate of [`now_ms`].
pub const TICK_HZ: u32 = 1_000;

static TICKS_MS: AtomicU32 = AtomicU32::new(0);

/// Start the 1 kHz SysTick interrupt behind [`now_ms`].
///
/// SysTick counts core clock cycles; the reload value assumes the core
/// clock QEMU gives the board at reset ([`CORE_CLOCK_HZ`]: 12 MHz on
/// lm3s6965evb, 25 MHz on mps2-an386). The firmware never changes clocks.
pub fn start_tick(mut syst: SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(CORE_CLOCK_HZ / TICK_HZ - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Milliseconds since [`start_tick`]; wraps after about 49.7 days, so
/// compare times with `wrapping_sub`.
pub fn now_ms() -> u32 {
    TICKS_MS.load(Ordering::Relaxed)
}

#[exception]
fn SysTick() {
    TICKS_MS.fetch_add(1, Ordering::Relaxed);
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    panic!("unexpected interrupt or exception {}", irqn);
}

/// Sleep in WFI unless `ready()` says there is work.
///
/// `ready` is checked with interrupts masked, so an interrupt that makes
/// work between the check and the WFI is not lost: a pending interrupt
/// wakes WFI even while masked, and its handler runs when this returns.
/// The 1 kHz tick bounds every sleep to at most a millisecond anyway.
pub fn sleep_unless(ready: &mut dyn FnMut() -> bool) {
    cortex_m::interrupt::free(|_| {
        if !ready() {
            cortex_m::asm::wfi();
        }
    });
}
