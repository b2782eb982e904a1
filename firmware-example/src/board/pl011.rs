//! The ARM PL011 UART (the LM3S6965's three UARTs): 8N1 with its 16-byte
//! FIFOs on, driven by its interrupt through a serial line's interrupt end
//! (`crate::serial::IsrEnd`).
//!
//! Registers used: DR +0x00, FR +0x18, IBRD +0x24, FBRD +0x28, LCR_H +0x2C
//! (FEN turns the FIFOs on; written after the divisors, it latches them),
//! CR +0x30, IMSC +0x38, ICR +0x44.

use core::ptr::{read_volatile, write_volatile};

use crate::serial::{FlowControl, IsrEnd};

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

/// The modem lines a board wires beside a UART that has none of its own,
/// for [`FlowControl::RtsCts`]: RTS driven from the receive ring's level,
/// CTS read before each byte is handed to the transmitter.
pub struct Modem {
    /// Drives RTS (`true`: the peer may send).
    pub set_rts: fn(bool),
    /// Reads CTS (`true`: the peer may receive).
    pub cts: fn() -> bool,
}

/// One PL011, by its base address.
#[derive(Clone, Copy)]
pub struct Pl011(pub usize);

impl Pl011 {
    fn read(self, reg: usize) -> u32 {
        // SAFETY: `self.0` is a PL011's base; `reg` one of its registers.
        unsafe { read_volatile((self.0 + reg) as *const u32) }
    }

    fn write(self, reg: usize, value: u32) {
        // SAFETY: as in `read`.
        unsafe { write_volatile((self.0 + reg) as *mut u32, value) }
    }

    /// 8N1 at `baud` from a `clock_hz` UART clock, FIFOs on, receive
    /// interrupts on. (Parity is not set: QEMU's PL011 ignores it.)
    pub fn init(self, clock_hz: u32, baud: u32) {
        self.write(CR, 0);
        // Divisor = clock / (16 x baud) in 16.6 fixed point.
        let div64 = (clock_hz * 4).checked_div(baud).unwrap_or(0);
        self.write(IBRD, div64 >> 6);
        self.write(FBRD, div64 & 0x3F);
        self.write(LCR_H, LCR_H_WLEN_8 | LCR_H_FEN);
        self.write(ICR, INT_ALL);
        self.write(IMSC, INT_RX | INT_RT);
        self.write(CR, CR_UARTEN | CR_TXE | CR_RXE);
    }

    /// The interrupt handler's body: drains the receive FIFO into the ring
    /// (each byte stamped with `stamp()` if given), fills the transmit FIFO
    /// from it, and leaves the transmit interrupt on while bytes wait.
    pub fn service(self, end: &mut IsrEnd<'_>, stamp: Option<fn() -> u32>, modem: &Modem) {
        self.write(ICR, INT_RX | INT_RT);
        end.service();
        while self.read(FR) & FR_RXFE == 0 {
            let dr = self.read(DR);
            if dr & DR_OE != 0 {
                // The FIFO was full and the byte after it was lost.
                end.on_hw_overrun(1);
            }
            match stamp {
                Some(now_us) => end.on_receive_at(dr as u8, now_us()),
                None => end.on_receive(dr as u8),
            }
        }
        let rts_cts = end.flow() == FlowControl::RtsCts;
        if rts_cts {
            (modem.set_rts)(end.rts());
        }
        let cts = !rts_cts || (modem.cts)();
        while self.read(FR) & FR_TXFF == 0 {
            match end.next_tx(cts) {
                Some(b) => self.write(DR, u32::from(b)),
                None => break,
            }
        }
        self.write(ICR, INT_TX);
        let mut mask = INT_RX | INT_RT;
        if end.wants_tx() {
            mask |= INT_TX;
        }
        self.write(IMSC, mask);
    }
}
