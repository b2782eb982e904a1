//! Arm MPS2 with the AN386 image (QEMU `mps2-an386`): Cortex-M4F, CMSDK APB
//! UARTs (one-byte transmit and receive buffers, separate RX and TX
//! interrupt lines per UART).

use core::ptr::{read_volatile, write_volatile};

use cortex_m::peripheral::NVIC;

use super::{default_handler, Irq, UartHw, Vector};

/// Name printed in the start-up banner.
pub const NAME: &str = "mps2-an386";

/// Core clock as QEMU models it (SYSCLK 25 MHz); SysTick counts it.
pub const CORE_CLOCK_HZ: u32 = 25_000_000;

/// CMSDK APB UART base addresses of UART0..UART2.
const UART_BASE: [usize; 3] = [0x4000_4000, 0x4000_5000, 0x4000_6000];
/// NVIC interrupt numbers of UART0..UART2 receive; transmit is one more.
const UART_RX_IRQ: [u16; 3] = [0, 2, 4];

/// First serial port (`-serial` #1): the host side.
pub const UPSTREAM: Uart = Uart::new(0);
/// Second serial port (`-serial` #2): the controller side.
pub const DOWNSTREAM: Uart = Uart::new(1);

// Register offsets.
const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const INTCLEAR: usize = 0x0C;
const BAUDDIV: usize = 0x10;

// STATE bits.
const STATE_TXFULL: u32 = 1 << 0;
const STATE_RXFULL: u32 = 1 << 1;
// CTRL bits.
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_TX_INTEN: u32 = 1 << 2;
const CTRL_RX_INTEN: u32 = 1 << 3;
// INTSTATUS / INTCLEAR bits.
const INT_TX: u32 = 1 << 0;
const INT_RX: u32 = 1 << 1;
const INT_TX_OVERRUN: u32 = 1 << 2;
const INT_RX_OVERRUN: u32 = 1 << 3;

/// One CMSDK APB UART.
#[derive(Clone, Copy, Debug)]
pub struct Uart {
    base: usize,
    rx_irq: Irq,
    tx_irq: Irq,
}

impl Uart {
    const fn new(index: usize) -> Self {
        Self {
            base: UART_BASE[index],
            rx_irq: Irq(UART_RX_IRQ[index]),
            tx_irq: Irq(UART_RX_IRQ[index] + 1),
        }
    }

    fn read(&self, offset: usize) -> u32 {
        // SAFETY: `base + offset` is a CMSDK UART register of this device.
        unsafe { read_volatile((self.base + offset) as *const u32) }
    }

    fn write(&self, offset: usize, value: u32) {
        // SAFETY: `base + offset` is a CMSDK UART register of this device.
        unsafe { write_volatile((self.base + offset) as *mut u32, value) }
    }
}

impl UartHw for Uart {
    unsafe fn init(&self) {
        self.write(CTRL, 0);
        // 115200 baud from the 25 MHz APB clock. QEMU ignores the rate but
        // refuses to send or receive while BAUDDIV < 16.
        self.write(BAUDDIV, CORE_CLOCK_HZ / 115_200);
        self.write(INTCLEAR, INT_TX | INT_RX | INT_TX_OVERRUN | INT_RX_OVERRUN);
        self.write(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_INTEN);
        // SAFETY: both lines of this UART are in the vector table below and
        // their handler only touches state that is ready by now.
        unsafe {
            NVIC::unmask(self.rx_irq);
            NVIC::unmask(self.tx_irq);
        }
    }

    fn read_byte(&self) -> Option<u8> {
        if self.read(STATE) & STATE_RXFULL == 0 {
            None
        } else {
            Some(self.read(DATA) as u8)
        }
    }

    fn write_byte(&self, byte: u8) -> bool {
        if self.read(STATE) & STATE_TXFULL != 0 {
            false
        } else {
            self.write(DATA, u32::from(byte));
            true
        }
    }

    fn set_interrupts(&self, rx: bool, tx: bool) {
        let mut ctrl = CTRL_TX_EN | CTRL_RX_EN;
        if rx {
            ctrl |= CTRL_RX_INTEN;
        }
        if tx {
            ctrl |= CTRL_TX_INTEN;
        }
        self.write(CTRL, ctrl);
    }

    fn ack_rx(&self) {
        self.write(INTCLEAR, INT_RX | INT_RX_OVERRUN);
    }

    fn ack_tx(&self) {
        self.write(INTCLEAR, INT_TX | INT_TX_OVERRUN);
    }

    fn pend(&self) {
        NVIC::pend(self.rx_irq);
    }
}

/// Device interrupts 0..=5: UART0 RX/TX (0, 1) and UART1 RX/TX (2, 3) each
/// share one handler; UART2 (4, 5) goes to the default handler.
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
pub static __INTERRUPTS: [Vector; 6] = [
    crate::uart::upstream_interrupt,
    crate::uart::upstream_interrupt,
    crate::uart::downstream_interrupt,
    crate::uart::downstream_interrupt,
    default_handler,
    default_handler,
];
