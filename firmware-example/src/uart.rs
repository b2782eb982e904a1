//! Interrupt-driven serial ports on top of the board's register-level UARTs.
//!
//! Each port has a receive and a transmit ring buffer. The UART interrupt
//! handler is the only code that touches the UART: it moves received bytes
//! into the receive ring and queued bytes from the transmit ring into the
//! transmitter. Thread code only touches the rings, through [`Serial`],
//! which implements the `embedded-io` traits.
//!
//! Flow control: when the receive ring is full the handler leaves further
//! bytes in the UART and masks its receive interrupt; the UART then stops
//! taking bytes (QEMU holds them back in the socket), so nothing is lost.
//! Reading from the ring re-triggers the handler.

use core::cell::UnsafeCell;
use core::fmt;
use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use crate::board::{self, UartHw};

/// Bytes each ring holds (a power of two).
pub const RING_SIZE: usize = 256;

/// How long [`Serial`]'s blocking `read`, `write` and `flush` wait for the
/// other side before giving up with [`Error::TimedOut`], unless changed with
/// [`Serial::set_timeout_ms`].
pub const DEFAULT_TIMEOUT_MS: u32 = 1_000;

/// Single-producer single-consumer byte ring, safe between one interrupt
/// handler and thread code on a single core.
struct Ring {
    buf: UnsafeCell<[u8; RING_SIZE]>,
    /// Total bytes ever pushed (wrapping); written by the producer only.
    head: AtomicUsize,
    /// Total bytes ever popped (wrapping); written by the consumer only.
    tail: AtomicUsize,
}

// SAFETY: the producer only writes slots between `head` and `tail + SIZE`,
// the consumer only reads slots between `tail` and `head`, and each index is
// published with release/acquire ordering after the slot access. Each ring
// has exactly one producer context and one consumer context (see `Port`).
unsafe impl Sync for Ring {}

impl Ring {
    const fn new() -> Self {
        Self {
            buf: UnsafeCell::new([0; RING_SIZE]),
            head: AtomicUsize::new(0),
            tail: AtomicUsize::new(0),
        }
    }

    fn len(&self) -> usize {
        let head = self.head.load(Ordering::Acquire);
        let tail = self.tail.load(Ordering::Acquire);
        head.wrapping_sub(tail)
    }

    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn is_full(&self) -> bool {
        self.len() >= RING_SIZE
    }

    /// Producer side: append as many of `data` as fit; returns the count.
    fn push(&self, data: &[u8]) -> usize {
        let head = self.head.load(Ordering::Relaxed);
        let tail = self.tail.load(Ordering::Acquire);
        let free = RING_SIZE - head.wrapping_sub(tail);
        let n = free.min(data.len());
        let buf = self.buf.get().cast::<u8>();
        for (i, &byte) in data[..n].iter().enumerate() {
            let slot = head.wrapping_add(i) % RING_SIZE;
            // SAFETY: `slot` is free (between head and tail + SIZE), and only
            // the producer writes free slots.
            unsafe { buf.add(slot).write_volatile(byte) };
        }
        self.head.store(head.wrapping_add(n), Ordering::Release);
        n
    }

    /// Consumer side: the oldest byte, without removing it.
    fn peek(&self) -> Option<u8> {
        let tail = self.tail.load(Ordering::Relaxed);
        let head = self.head.load(Ordering::Acquire);
        if head == tail {
            return None;
        }
        // SAFETY: the slot at `tail` is filled and only the consumer reads it.
        Some(unsafe {
            self.buf
                .get()
                .cast::<u8>()
                .add(tail % RING_SIZE)
                .read_volatile()
        })
    }

    /// Consumer side: remove `n` bytes (at most `len()`).
    fn discard(&self, n: usize) {
        let tail = self.tail.load(Ordering::Relaxed);
        self.tail.store(tail.wrapping_add(n), Ordering::Release);
    }

    /// Consumer side: move up to `out.len()` bytes out; returns the count.
    fn pop(&self, out: &mut [u8]) -> usize {
        let tail = self.tail.load(Ordering::Relaxed);
        let head = self.head.load(Ordering::Acquire);
        let n = head.wrapping_sub(tail).min(out.len());
        let buf = self.buf.get().cast::<u8>();
        for (i, byte) in out[..n].iter_mut().enumerate() {
            let slot = tail.wrapping_add(i) % RING_SIZE;
            // SAFETY: `slot` is filled (between tail and head) and only the
            // consumer reads filled slots.
            *byte = unsafe { buf.add(slot).read_volatile() };
        }
        self.tail.store(tail.wrapping_add(n), Ordering::Release);
        n
    }
}

/// Driver state of one UART.
///
/// Roles: `rx` is produced by the interrupt handler and consumed by the
/// [`Serial`]; `tx` the other way round. `taken` makes the `Serial` unique.
///
/// Everything here starts zeroed, so the rings live in `.bss`; the
/// register-level UART is kept apart (see [`upstream_interrupt`]).
struct Port {
    rx: Ring,
    tx: Ring,
    /// Set by the handler when it left bytes in the UART for want of room.
    rx_stalled: AtomicBool,
    taken: AtomicBool,
}

impl Port {
    const fn new() -> Self {
        Self {
            rx: Ring::new(),
            tx: Ring::new(),
            rx_stalled: AtomicBool::new(false),
            taken: AtomicBool::new(false),
        }
    }

    /// The interrupt handler body.
    fn service(&self, hw: &board::Uart) {
        // Receive: acknowledge first, so a byte arriving while we drain
        // raises the interrupt again instead of being forgotten.
        hw.ack_rx();
        let mut stalled = false;
        loop {
            if self.rx.is_full() {
                stalled = true;
                break;
            }
            match hw.read_byte() {
                Some(byte) => {
                    self.rx.push(&[byte]);
                }
                None => break,
            }
        }
        self.rx_stalled.store(stalled, Ordering::Release);

        // Transmit: fill the transmitter, then acknowledge.
        while let Some(byte) = self.tx.peek() {
            if !hw.write_byte(byte) {
                break;
            }
            self.tx.discard(1);
        }
        hw.ack_tx();

        hw.set_interrupts(!stalled, !self.tx.is_empty());
    }
}

static UPSTREAM: Port = Port::new();
static DOWNSTREAM: Port = Port::new();

/// Interrupt handler of the upstream UART (referenced by the board's
/// vector table).
pub extern "C" fn upstream_interrupt() {
    UPSTREAM.service(&board::UPSTREAM);
}

/// Interrupt handler of the downstream UART (referenced by the board's
/// vector table).
pub extern "C" fn downstream_interrupt() {
    DOWNSTREAM.service(&board::DOWNSTREAM);
}

/// Set up both UARTs and return their `(upstream, downstream)` handles.
/// `None` if called before.
pub fn take() -> Option<(Serial, Serial)> {
    let up = Serial::take(&UPSTREAM, board::UPSTREAM)?;
    let down = Serial::take(&DOWNSTREAM, board::DOWNSTREAM)?;
    Some((up, down))
}

/// Errors of [`Serial`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// Nothing arrived (read) or nothing drained (write, flush) within the
    /// port's timeout.
    TimedOut,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::TimedOut => f.write_str("serial port timed out"),
        }
    }
}

impl core::error::Error for Error {}

impl embedded_io::Error for Error {
    fn kind(&self) -> embedded_io::ErrorKind {
        match self {
            Error::TimedOut => embedded_io::ErrorKind::TimedOut,
        }
    }
}

/// Thread-side handle of one interrupt-driven serial port.
///
/// `read`, `write` and `flush` sleep in WFI while they wait, for at most the
/// port's timeout; use `read_ready` / `write_ready` to never wait.
pub struct Serial {
    port: &'static Port,
    hw: board::Uart,
    timeout_ms: u32,
}

impl Serial {
    fn take(port: &'static Port, hw: board::Uart) -> Option<Self> {
        if port.taken.swap(true, Ordering::AcqRel) {
            return None;
        }
        // SAFETY: first and only initialisation of this UART; its rings are
        // empty statics, so the handler may run from here on.
        unsafe { hw.init() };
        Some(Self {
            port,
            hw,
            timeout_ms: DEFAULT_TIMEOUT_MS,
        })
    }

    /// Change how long blocking calls wait before [`Error::TimedOut`].
    #[allow(dead_code)] // Part of the driver API; the pump never blocks.
    pub fn set_timeout_ms(&mut self, timeout_ms: u32) {
        self.timeout_ms = timeout_ms;
    }

    /// Sleep until `ready()` holds; `Err` after the timeout.
    fn wait(&self, mut ready: impl FnMut() -> bool) -> Result<(), Error> {
        let start = board::now_ms();
        loop {
            if ready() {
                return Ok(());
            }
            if board::now_ms().wrapping_sub(start) >= self.timeout_ms {
                return Err(Error::TimedOut);
            }
            board::sleep_unless(&mut ready);
        }
    }
}

impl embedded_io::ErrorType for Serial {
    type Error = Error;
}

impl embedded_io::ReadReady for Serial {
    fn read_ready(&mut self) -> Result<bool, Error> {
        Ok(!self.port.rx.is_empty())
    }
}

impl embedded_io::Read for Serial {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        let rx = &self.port.rx;
        self.wait(|| !rx.is_empty())?;
        let n = rx.pop(buf);
        if self.port.rx_stalled.swap(false, Ordering::AcqRel) {
            // The handler left bytes in the UART; there is room now.
            self.hw.pend();
        }
        Ok(n)
    }
}

impl embedded_io::WriteReady for Serial {
    fn write_ready(&mut self) -> Result<bool, Error> {
        Ok(!self.port.tx.is_full())
    }
}

impl embedded_io::Write for Serial {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        let tx = &self.port.tx;
        self.wait(|| !tx.is_full())?;
        let n = tx.push(buf);
        // Let the handler start the transmitter.
        self.hw.pend();
        Ok(n)
    }

    fn flush(&mut self) -> Result<(), Error> {
        let tx = &self.port.tx;
        self.wait(|| tx.is_empty())
    }
}
