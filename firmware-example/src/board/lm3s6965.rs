//! TI Stellaris LM3S6965 (QEMU `lm3s6965evb`): Cortex-M3, ARM PL011 UARTs.
//!
//! Only the registers the bridge needs. On real silicon the UART and GPIO
//! clocks (SYSCTL RCGC1/RCGC2) and pin muxing would also need setting up;
//! QEMU does not gate the UARTs, so that is left out.

use core::ptr::{read_volatile, write_volatile};

use cortex_m::peripheral::NVIC;

use super::{default_handler, Irq, UartHw, Vector};

/// Name printed in the start-up banner.
pub const NAME: &str = "lm3s6965evb";

/// Core clock at reset as QEMU models it (12 MHz); SysTick counts it.
pub const CORE_CLOCK_HZ: u32 = 12_000_000;

/// PL011 base addresses of UART0..UART2.
const UART_BASE: [usize; 3] = [0x4000_C000, 0x4000_D000, 0x4000_E000];
/// NVIC interrupt numbers of UART0..UART2.
const UART_IRQ: [u16; 3] = [5, 6, 33];

/// First serial port (`-serial` #1): the host side.
pub const UPSTREAM: Uart = Uart::new(0);
/// Second serial port (`-serial` #2): the controller side.
pub const DOWNSTREAM: Uart = Uart::new(1);

// PL011 register offsets.
const DR: usize = 0x00;
const FR: usize = 0x18;
const IBRD: usize = 0x24;
const FBRD: usize = 0x28;
const LCR_H: usize = 0x2C;
const CR: usize = 0x30;
const IMSC: usize = 0x38;
const ICR: usize = 0x44;

// FR bits.
const FR_RXFE: u32 = 1 << 4;
const FR_TXFF: u32 = 1 << 5;
// LCR_H bits.
const LCR_H_FEN: u32 = 1 << 4;
const LCR_H_WLEN_8: u32 = 0b11 << 5;
// CR bits.
const CR_UARTEN: u32 = 1 << 0;
const CR_TXE: u32 = 1 << 8;
const CR_RXE: u32 = 1 << 9;
// Interrupt bits (IMSC, ICR).
const INT_RX: u32 = 1 << 4;
const INT_TX: u32 = 1 << 5;
const INT_RT: u32 = 1 << 6;
const INT_ALL: u32 = 0x7FF;

/// One PL011 UART.
#[derive(Clone, Copy, Debug)]
pub struct Uart {
    base: usize,
    irq: Irq,
}

impl Uart {
    const fn new(index: usize) -> Self {
        Self {
            base: UART_BASE[index],
            irq: Irq(UART_IRQ[index]),
        }
    }

    fn read(&self, offset: usize) -> u32 {
        // SAFETY: `base + offset` is a PL011 register of this device.
        unsafe { read_volatile((self.base + offset) as *const u32) }
    }

    fn write(&self, offset: usize, value: u32) {
        // SAFETY: `base + offset` is a PL011 register of this device.
        unsafe { write_volatile((self.base + offset) as *mut u32, value) }
    }
}

impl UartHw for Uart {
    unsafe fn init(&self) {
        self.write(CR, 0);
        // 115200 baud from the 12 MHz UART clock: 12e6 / (16 * 115200) = 6.51
        // (QEMU ignores the rate; real hardware would not).
        self.write(IBRD, 6);
        self.write(FBRD, 33);
        // LCR_H after the divisors latches them; FEN turns the 16-byte FIFOs on.
        self.write(LCR_H, LCR_H_WLEN_8 | LCR_H_FEN);
        self.write(ICR, INT_ALL);
        self.write(IMSC, INT_RX | INT_RT);
        self.write(CR, CR_UARTEN | CR_TXE | CR_RXE);
        // SAFETY: the handlers for this IRQ are in the vector table below
        // and only touch state that is ready by now (caller's contract).
        unsafe { NVIC::unmask(self.irq) };
    }

    fn read_byte(&self) -> Option<u8> {
        if self.read(FR) & FR_RXFE != 0 {
            None
        } else {
            // Bits 8..11 carry framing/parity/break/overrun flags; drop them.
            Some(self.read(DR) as u8)
        }
    }

    fn write_byte(&self, byte: u8) -> bool {
        if self.read(FR) & FR_TXFF != 0 {
            false
        } else {
            self.write(DR, u32::from(byte));
            true
        }
    }

    fn set_interrupts(&self, rx: bool, tx: bool) {
        let mut mask = 0;
        if rx {
            mask |= INT_RX | INT_RT;
        }
        if tx {
            mask |= INT_TX;
        }
        self.write(IMSC, mask);
    }

    fn ack_rx(&self) {
        self.write(ICR, INT_RX | INT_RT);
    }

    fn ack_tx(&self) {
        self.write(ICR, INT_TX);
    }

    fn pend(&self) {
        NVIC::pend(self.irq);
    }
}

/// Device interrupts 0..=33: UART0 is IRQ 5, UART1 is IRQ 6; UART2 (IRQ 33)
/// and everything else go to the default handler.
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
pub static __INTERRUPTS: [Vector; 34] = {
    let mut table: [Vector; 34] = [default_handler; 34];
    table[UART_IRQ[0] as usize] = crate::uart::upstream_interrupt;
    table[UART_IRQ[1] as usize] = crate::uart::downstream_interrupt;
    table
};
