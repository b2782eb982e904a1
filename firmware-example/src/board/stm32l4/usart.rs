//! The STM32L4's USARTs (the same design as the STM32G0's: ISR, ICR, RDR,
//! TDR) as `embedded-io-async` ports: the interrupt moves bytes between
//! the data registers and two byte pipes, the task side awaits the pipes.
//!
//! Written by hand on `stm32-metapac` (the PAC embassy-stm32 is built on)
//! because embassy-stm32's `BufferedUart` does not run on QEMU 10's model
//! of this USART: its handler writes the status it read back to ICR,
//! reserved bits included, and the model's ICR clears whatever bits are
//! written (TXE and RXNE with them), so its transmitter never starts.
//! RM0351 has the reserved bits ignored; this driver writes ICR's defined
//! clear bits only, and runs the same on silicon.

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use stm32_metapac::usart::vals::{Ps, Stop, M0};
use stm32_metapac::usart::Usart as Regs;

use crate::config::Parity;

/// What the interrupt and the task share for one USART.
pub struct State {
    rx: Pipe<CriticalSectionRawMutex, 256>,
    tx: Pipe<CriticalSectionRawMutex, 8>,
    /// Received bytes the USART lost (overruns).
    lost: AtomicU32,
    /// Signalled when the transmit pipe ran empty.
    drained: Signal<CriticalSectionRawMutex, ()>,
}

impl State {
    /// An idle USART's state.
    pub const fn new() -> Self {
        State {
            rx: Pipe::new(),
            tx: Pipe::new(),
            lost: AtomicU32::new(0),
            drained: Signal::new(),
        }
    }
}

impl Default for State {
    fn default() -> Self {
        Self::new()
    }
}

/// The frame format: 8N1, or the Modbus line's 8E1, 8O1 or 8N2.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// 8N1 (protocol B).
    Plain,
    /// 8 data bits with this parity (`None`: two stop bits instead).
    Modbus(Parity),
}

/// One USART as a port: its registers and its state.
#[derive(Clone, Copy)]
pub struct Port {
    regs: Regs,
    state: &'static State,
}

impl Port {
    /// The USART at `regs` with `state` (its interrupt handler calls
    /// [`Port::on_interrupt`] with the same).
    pub const fn new(regs: Regs, state: &'static State) -> Self {
        Port { regs, state }
    }

    /// Sets the USART to `baud` from its `clock_hz` kernel clock in
    /// `format`, transmitter and receiver on, the receive interrupt on.
    /// Its clock must be on (RCC).
    pub fn init(&self, clock_hz: u32, baud: u32, format: Format) {
        let r = self.regs;
        r.cr1().write(|w| w.set_ue(false));
        let brr = clock_hz.checked_div(baud).unwrap_or(0).clamp(16, 0xFFFF);
        r.brr().write(|w| w.set_brr(brr as u16));
        r.cr2().write(|w| {
            if format == Format::Modbus(Parity::None) {
                w.set_stop(Stop::STOP2);
            }
        });
        r.cr3().write(|_| {});
        r.cr1().write(|w| {
            if let Format::Modbus(Parity::Even | Parity::Odd) = format {
                // A 9-bit word: 8 data bits and the parity bit.
                w.set_m0(M0::BIT9);
                w.set_pce(true);
                w.set_ps(if format == Format::Modbus(Parity::Odd) {
                    Ps::ODD
                } else {
                    Ps::EVEN
                });
            }
            w.set_ue(true);
            w.set_re(true);
            w.set_te(true);
            w.set_rxneie(true);
        });
    }

    /// The interrupt handler's body: a received byte into the receive
    /// pipe, the transmit pipe's next byte out, the transmit interrupt off
    /// once it ran empty.
    pub fn on_interrupt(&self) {
        let r = self.regs;
        let isr = r.isr().read();
        if isr.ore() || isr.fe() || isr.ne() || isr.pe() {
            // A framing, noise or parity error keeps its byte (a Modbus
            // frame's CRC rejects it); an overrun lost one.
            // Clear only the flags that were set (ORECF, FECF, NCF, PECF).
            r.icr().write(|w| {
                w.set_ore(isr.ore());
                w.set_fe(isr.fe());
                w.set_ne(isr.ne());
                w.set_pe(isr.pe());
            });
            if isr.ore() {
                self.state.lost.fetch_add(1, Ordering::Relaxed);
            }
        }
        if isr.rxne() {
            if self.state.rx.free_capacity() == 0 {
                // No room: leave the byte in RDR and the receive interrupt
                // off until the task reads (it turns it on again). On
                // silicon the next byte then overruns (ORE, counted
                // above); QEMU's model holds its input back instead.
                r.cr1().modify(|w| w.set_rxneie(false));
            } else {
                // With parity the ninth bit is the parity bit: dropped by
                // `as u8`.
                let byte = r.rdr().read().dr() as u8;
                let _ = self.state.rx.try_write(&[byte]);
            }
        }
        if isr.txe() && r.cr1().read().txeie() {
            let mut byte = [0u8];
            match self.state.tx.try_read(&mut byte) {
                Ok(_) => r.tdr().write(|w| w.set_dr(u16::from(byte[0]))),
                Err(_) => {
                    r.cr1().modify(|w| w.set_txeie(false));
                    self.state.drained.signal(());
                }
            }
        }
    }

    /// Turns the transmit interrupt on (the handler turns it off when the
    /// pipe runs empty).
    fn start_tx(&self) {
        let r = self.regs;
        cortex_m::interrupt::free(|_| r.cr1().modify(|w| w.set_txeie(true)));
    }

    /// Turns the receive interrupt on again (the handler turns it off
    /// while the receive pipe is full).
    fn resume_rx(&self) {
        let r = self.regs;
        cortex_m::interrupt::free(|_| r.cr1().modify(|w| w.set_rxneie(true)));
    }
}

/// Bytes were lost on receive (the USART overran).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lost;

impl core::fmt::Display for Lost {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("received bytes lost")
    }
}

impl core::error::Error for Lost {}

impl embedded_io_async::Error for Lost {
    fn kind(&self) -> embedded_io_async::ErrorKind {
        embedded_io_async::ErrorKind::Other
    }
}

impl embedded_io_async::ErrorType for Port {
    type Error = Lost;
}

impl embedded_io_async::Read for Port {
    /// What arrived (at least a byte); `Err(Lost)` once after bytes were
    /// lost.
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Lost> {
        if self.state.lost.load(Ordering::Relaxed) != 0 {
            self.state.lost.store(0, Ordering::Relaxed);
            return Err(Lost);
        }
        let n = self.state.rx.read(buf).await;
        self.resume_rx();
        Ok(n)
    }
}

impl embedded_io_async::ReadReady for Port {
    fn read_ready(&mut self) -> Result<bool, Lost> {
        Ok(!self.state.rx.is_empty())
    }
}

impl embedded_io_async::Write for Port {
    /// Queues what fits (at least a byte, waiting for room).
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Lost> {
        if buf.is_empty() {
            return Ok(0);
        }
        let n = self.state.tx.write(buf).await;
        self.start_tx();
        Ok(n)
    }

    /// Waits until every queued byte went to the transmitter.
    async fn flush(&mut self) -> Result<(), Lost> {
        while !self.state.tx.is_empty() {
            self.state.drained.wait().await;
        }
        Ok(())
    }
}
