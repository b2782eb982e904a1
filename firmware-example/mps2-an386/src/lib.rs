//! Device crate for the Arm MPS2 board with the AN386 FPGA image
//! (Cortex-M4), as QEMU's `mps2-an386` machine models it.
//!
//! It gives what cortex-m-rt's `device` feature and the firmware need:
//! - [`Interrupt`], the 32 device interrupts, usable with
//!   `cortex_m::peripheral::NVIC` and cortex-m-rt's `#[interrupt]`;
//! - with the `rt` feature, the interrupt vector table and a `device.x`
//!   giving every handler a weak default (`DefaultHandler`);
//! - the register blocks the firmware uses: the CMSDK APB UARTs
//!   ([`uart`]) and the CMSDK APB watchdog ([`watchdog`]), at their
//!   addresses.
//!
//! Interrupt numbers and addresses: the AN385/AN386 memory and interrupt
//! map (the images share it), as QEMU's model wires it (checked with QEMU
//! 7.2's `info qtree`: five UARTs from 0x4000_4000, the watchdog at
//! 0x4000_8000 on the NMI).
#![no_std]
#![deny(missing_docs)]

pub use cortex_m::peripheral::Peripherals as CorePeripherals;
#[cfg(feature = "rt")]
pub use cortex_m_rt::interrupt;
pub use Interrupt as interrupt;

/// Number of priority bits the NVIC implements.
pub const NVIC_PRIO_BITS: u8 = 3;

/// The device interrupts.
#[allow(non_camel_case_types)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Interrupt {
    /// 0: UART0 receive.
    UART0RX = 0,
    /// 1: UART0 transmit.
    UART0TX = 1,
    /// 2: UART1 receive.
    UART1RX = 2,
    /// 3: UART1 transmit.
    UART1TX = 3,
    /// 4: UART2 receive.
    UART2RX = 4,
    /// 5: UART2 transmit.
    UART2TX = 5,
    /// 6: GPIO 0 combined.
    GPIO0 = 6,
    /// 7: GPIO 1 combined.
    GPIO1 = 7,
    /// 8: Timer 0.
    TIMER0 = 8,
    /// 9: Timer 1.
    TIMER1 = 9,
    /// 10: Dual timer.
    DUALTIMER = 10,
    /// 11: SPI 0.
    SPI0 = 11,
    /// 12: Overrun of UART0, UART1 or UART2 (ORed).
    UART_OVERFLOW = 12,
    /// 13: Ethernet (LAN9220).
    ETHERNET = 13,
    /// 14: Audio I2S.
    I2S = 14,
    /// 15: Touch screen.
    TOUCHSCREEN = 15,
    /// 16: GPIO 2 combined.
    GPIO2 = 16,
    /// 17: GPIO 3 combined.
    GPIO3 = 17,
    /// 18: UART3 receive.
    UART3RX = 18,
    /// 19: UART3 transmit.
    UART3TX = 19,
    /// 20: UART4 receive.
    UART4RX = 20,
    /// 21: UART4 transmit.
    UART4TX = 21,
    /// 22: ADC SPI.
    SPI1 = 22,
    /// 23: Shield SPI.
    SPI2 = 23,
    /// 24: GPIO 0 pin 0.
    GPIO0_0 = 24,
    /// 25: GPIO 0 pin 1.
    GPIO0_1 = 25,
    /// 26: GPIO 0 pin 2.
    GPIO0_2 = 26,
    /// 27: GPIO 0 pin 3.
    GPIO0_3 = 27,
    /// 28: GPIO 0 pin 4.
    GPIO0_4 = 28,
    /// 29: GPIO 0 pin 5.
    GPIO0_5 = 29,
    /// 30: GPIO 0 pin 6.
    GPIO0_6 = 30,
    /// 31: GPIO 0 pin 7.
    GPIO0_7 = 31,
}

// SAFETY: every variant is a device interrupt number of this board (0..32).
unsafe impl cortex_m::interrupt::InterruptNumber for Interrupt {
    #[inline(always)]
    fn number(self) -> u16 {
        self as u16
    }
}

/// One entry of the device vector table.
#[cfg(feature = "rt")]
#[doc(hidden)]
#[derive(Clone, Copy)]
pub struct Vector {
    /// The handler.
    pub handler: unsafe extern "C" fn(),
}

#[cfg(feature = "rt")]
extern "C" {
    fn UART0RX();
    fn UART0TX();
    fn UART1RX();
    fn UART1TX();
    fn UART2RX();
    fn UART2TX();
    fn GPIO0();
    fn GPIO1();
    fn TIMER0();
    fn TIMER1();
    fn DUALTIMER();
    fn SPI0();
    fn UART_OVERFLOW();
    fn ETHERNET();
    fn I2S();
    fn TOUCHSCREEN();
    fn GPIO2();
    fn GPIO3();
    fn UART3RX();
    fn UART3TX();
    fn UART4RX();
    fn UART4TX();
    fn SPI1();
    fn SPI2();
    fn GPIO0_0();
    fn GPIO0_1();
    fn GPIO0_2();
    fn GPIO0_3();
    fn GPIO0_4();
    fn GPIO0_5();
    fn GPIO0_6();
    fn GPIO0_7();
}

/// The device part of the vector table (cortex-m-rt places it after the
/// exceptions).
#[cfg(feature = "rt")]
#[doc(hidden)]
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
pub static __INTERRUPTS: [Vector; 32] = [
    Vector { handler: UART0RX },
    Vector { handler: UART0TX },
    Vector { handler: UART1RX },
    Vector { handler: UART1TX },
    Vector { handler: UART2RX },
    Vector { handler: UART2TX },
    Vector { handler: GPIO0 },
    Vector { handler: GPIO1 },
    Vector { handler: TIMER0 },
    Vector { handler: TIMER1 },
    Vector { handler: DUALTIMER },
    Vector { handler: SPI0 },
    Vector {
        handler: UART_OVERFLOW,
    },
    Vector { handler: ETHERNET },
    Vector { handler: I2S },
    Vector {
        handler: TOUCHSCREEN,
    },
    Vector { handler: GPIO2 },
    Vector { handler: GPIO3 },
    Vector { handler: UART3RX },
    Vector { handler: UART3TX },
    Vector { handler: UART4RX },
    Vector { handler: UART4TX },
    Vector { handler: SPI1 },
    Vector { handler: SPI2 },
    Vector { handler: GPIO0_0 },
    Vector { handler: GPIO0_1 },
    Vector { handler: GPIO0_2 },
    Vector { handler: GPIO0_3 },
    Vector { handler: GPIO0_4 },
    Vector { handler: GPIO0_5 },
    Vector { handler: GPIO0_6 },
    Vector { handler: GPIO0_7 },
];

/// A memory-mapped 32-bit register.
#[repr(transparent)]
pub struct Reg(core::cell::UnsafeCell<u32>);

impl Reg {
    /// Reads the register.
    #[inline(always)]
    pub fn read(&self) -> u32 {
        // SAFETY: `self` is a device register (see the peripheral types).
        unsafe { self.0.get().read_volatile() }
    }

    /// Writes the register.
    #[inline(always)]
    pub fn write(&self, value: u32) {
        // SAFETY: `self` is a device register (see the peripheral types).
        unsafe { self.0.get().write_volatile(value) }
    }
}

pub mod uart {
    //! CMSDK APB UART: one-byte transmit and receive buffers.
    use super::Reg;

    /// The registers.
    #[repr(C)]
    pub struct RegisterBlock {
        /// Received byte (read) / byte to send (write).
        pub data: Reg,
        /// [`STATE_TXFULL`], [`STATE_RXFULL`], overrun flags (write 1 to clear).
        pub state: Reg,
        /// Enables ([`CTRL_TX_EN`] ...).
        pub ctrl: Reg,
        /// Interrupt status (read) / clear (write 1).
        pub intstatus: Reg,
        /// Baud divider: the APB clock over the baud rate, at least 16.
        pub bauddiv: Reg,
    }

    /// STATE: the transmit buffer is full.
    pub const STATE_TXFULL: u32 = 1 << 0;
    /// STATE: a received byte waits.
    pub const STATE_RXFULL: u32 = 1 << 1;
    /// STATE: a received byte was overwritten (write 1 to clear).
    pub const STATE_RXOVERRUN: u32 = 1 << 3;
    /// CTRL: transmitter on.
    pub const CTRL_TX_EN: u32 = 1 << 0;
    /// CTRL: receiver on.
    pub const CTRL_RX_EN: u32 = 1 << 1;
    /// CTRL: transmit interrupt on.
    pub const CTRL_TX_INTEN: u32 = 1 << 2;
    /// CTRL: receive interrupt on.
    pub const CTRL_RX_INTEN: u32 = 1 << 3;
    /// INTSTATUS: transmit.
    pub const INT_TX: u32 = 1 << 0;
    /// INTSTATUS: receive.
    pub const INT_RX: u32 = 1 << 1;
    /// INTSTATUS: transmit overrun.
    pub const INT_TX_OVERRUN: u32 = 1 << 2;
    /// INTSTATUS: receive overrun.
    pub const INT_RX_OVERRUN: u32 = 1 << 3;
}

pub mod watchdog {
    //! CMSDK APB watchdog: counts WDOGCLK (25 MHz) down from LOAD; at zero
    //! it raises its interrupt (the NMI on this board) and reloads; at zero
    //! again with the interrupt still raised and reset enabled, it resets
    //! the system. Writing INTCLR clears the interrupt and reloads.
    use super::Reg;

    /// The registers (LOCK at offset 0xC00 is [`LOCK_OFFSET`]).
    #[repr(C)]
    pub struct RegisterBlock {
        /// Reload value.
        pub load: Reg,
        /// Current count (read only).
        pub value: Reg,
        /// [`CONTROL_INTEN`], [`CONTROL_RESEN`].
        pub control: Reg,
        /// Any write clears the interrupt and reloads the counter.
        pub intclr: Reg,
        /// Raw interrupt status.
        pub ris: Reg,
        /// Masked interrupt status.
        pub mis: Reg,
    }

    /// CONTROL: count and raise the interrupt.
    pub const CONTROL_INTEN: u32 = 1 << 0;
    /// CONTROL: reset on the second timeout.
    pub const CONTROL_RESEN: u32 = 1 << 1;
    /// Offset of the LOCK register from the base.
    pub const LOCK_OFFSET: usize = 0xC00;
    /// Value written to LOCK to allow register writes.
    pub const UNLOCK: u32 = 0x1ACC_E551;
    /// WDOGCLK on this board, Hz.
    pub const CLOCK_HZ: u32 = 25_000_000;
}

/// Base addresses of UART0..UART4.
pub const UART_BASE: [usize; 5] = [
    0x4000_4000,
    0x4000_5000,
    0x4000_6000,
    0x4000_7000,
    0x4000_9000,
];
/// Base address of the watchdog.
pub const WATCHDOG_BASE: usize = 0x4000_8000;

/// Interrupts of UART0..UART4: (receive, transmit).
pub const UART_IRQ: [(Interrupt, Interrupt); 5] = [
    (Interrupt::UART0RX, Interrupt::UART0TX),
    (Interrupt::UART1RX, Interrupt::UART1TX),
    (Interrupt::UART2RX, Interrupt::UART2TX),
    (Interrupt::UART3RX, Interrupt::UART3TX),
    (Interrupt::UART4RX, Interrupt::UART4TX),
];

/// The registers of UART `i` (0..5).
///
/// # Safety
/// Only on this board; the caller decides who owns the UART.
pub unsafe fn uart(i: usize) -> Option<&'static uart::RegisterBlock> {
    // SAFETY: a UART of this board lives at each of these addresses.
    UART_BASE
        .get(i)
        .map(|&b| unsafe { &*(b as *const uart::RegisterBlock) })
}

/// The watchdog's registers.
///
/// # Safety
/// Only on this board; the caller decides who owns the watchdog.
pub unsafe fn watchdog() -> &'static watchdog::RegisterBlock {
    // SAFETY: the watchdog lives at this address on this board.
    unsafe { &*(WATCHDOG_BASE as *const watchdog::RegisterBlock) }
}

/// The watchdog's LOCK register.
///
/// # Safety
/// As [`watchdog`].
pub unsafe fn watchdog_lock() -> &'static Reg {
    // SAFETY: LOCK is at this offset of the watchdog.
    unsafe { &*((WATCHDOG_BASE + watchdog::LOCK_OFFSET) as *const Reg) }
}

// SAFETY: registers are accessed with volatile loads and stores only.
unsafe impl Sync for Reg {}
