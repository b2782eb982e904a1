//! Interrupt-driven serial lines: the rings between a UART interrupt
//! handler and the bridge, and the receive-side flow control.
//!
//! A [`UartRings`] holds two [`heapless::spsc`] queues (receive, transmit) and
//! the state both sides share. [`UartRings::split`] hands out:
//! * an [`IsrEnd`], owned by the UART interrupt handler: it pushes received
//!   bytes ([`IsrEnd::on_receive`]) and takes bytes to transmit
//!   ([`IsrEnd::next_tx`]);
//! * a [`ThreadEnd`], owned by the bridge: it implements the `embedded-io`
//!   traits and [`Port`].
//!
//! # Overruns
//! A byte that arrives while the receive ring is full is dropped and
//! counted, and so is a byte the UART itself lost (its overrun flag, passed
//! to [`IsrEnd::on_hw_overrun`]). That is what happens on real hardware; the
//! bridge reads the count with [`Port::take_overruns`].
//!
//! # Flow control (receive side)
//! When the receive ring reaches [`Watermarks::pause_at`] bytes the line
//! asks the sender to stop, and when it has drained to
//! [`Watermarks::resume_at`] asks it to go on:
//! * [`FlowControl::XonXoff`]: XOFF (0x13) and XON (0x11) are sent ahead of
//!   any queued data. Received XON/XOFF bytes are taken out of the data and
//!   start/stop this line's transmitter; the bridge lets an XOFF hold it at
//!   most [`crate::config::Config::xoff_hold_ms`] ([`Port::release_peer_stop`]):
//!   line noise can look like XOFF and never be followed by XON. While
//!   stopped past the mark, XOFF is repeated every [`XOFF_REPEAT`] bytes in
//!   case the first was lost.
//! * [`FlowControl::RtsCts`]: [`IsrEnd::rts`] says which level the board
//!   drives on RTS (`true`: the peer may send); the board passes the CTS
//!   input to [`IsrEnd::next_tx`].
//!
//! The decision is taken in the interrupt handler, on the byte that crosses
//! the mark; [`Watermarks::pause_at`] leaves room for the sender's latency
//! ([`Watermarks::for_latency`]).
//!
//! XON/XOFF and protocol B: every frame byte is printable ASCII or CR/LF,
//! except the free text of 200H (test string) and 216H (message string).
//! A 0x11 or 0x13 byte in such a text cannot cross a line with XON/XOFF on:
//! from the host it is taken as flow control (the frame's checksum then
//! fails and the bridge drops the command, unanswered), and the bridge
//! refuses to relay a controller reply holding one (see
//! [`crate::codes::XON_XOFF_IN_TEXT`]).

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use heapless::spsc::{Consumer, Producer, Queue};

/// XON (DC1): the receiver is ready again.
pub const XON: u8 = 0x11;
/// XOFF (DC3): the receiver asks the sender to stop.
pub const XOFF: u8 = 0x13;
/// While paused, XOFF is sent again after this many more bytes arrived
/// (more than a host sends after a first XOFF it did see).
pub const XOFF_REPEAT: usize = 32;

/// The upstream (host) line of every board: a 256-byte receive queue (255
/// usable) and a 64-byte transmit queue.
pub type UpstreamRings = UartRings<256, 64>;
/// The Modbus RTU line of the gateway (lm3s6965): the loop moves its
/// bytes to the RTU framer at every pass, so at the line rate the ring
/// only bridges a pass; its 255 usable bytes hold nearly the longest
/// request (256), so that a frame delivered faster than its line rate (a
/// pass that takes long, QEMU's bursts) is not cut; no flow control.
pub type ModbusRings = UartRings<256, 64>;
/// The downstream (controller) line of every board.
pub type DownstreamRings = UartRings<128, 64>;
/// Bytes a host may still send after it was told to stop (XOFF arrived, or
/// RTS dropped): a PC UART finishes its 16-byte transmit FIFO, plus the
/// byte on the wire. The boards leave this much room above the pause mark.
pub const HOST_LATENCY: usize = 17;

/// The receive marks of [`UpstreamRings`] for a host with [`HOST_LATENCY`].
pub const UPSTREAM_MARKS: Watermarks =
    Watermarks::for_latency(UpstreamRings::RX_CAPACITY, HOST_LATENCY);
/// The receive marks of [`DownstreamRings`] (no flow control downstream:
/// the controller's replies are short and the bridge always reads them).
pub const DOWNSTREAM_MARKS: Watermarks = Watermarks::for_latency(DownstreamRings::RX_CAPACITY, 0);

/// How the receive side of a line throttles its sender.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FlowControl {
    /// None: a sender that outruns the bridge loses bytes (counted as
    /// overruns).
    None,
    /// Software flow control with XON (0x11) / XOFF (0x13).
    XonXoff,
    /// Hardware flow control on the RTS and CTS lines.
    RtsCts,
}

impl FlowControl {
    /// Code in the configuration block and the status reply.
    pub const fn code(self) -> u8 {
        match self {
            FlowControl::None => 0,
            FlowControl::XonXoff => 1,
            FlowControl::RtsCts => 2,
        }
    }

    /// The mode with this code.
    pub const fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(FlowControl::None),
            1 => Some(FlowControl::XonXoff),
            2 => Some(FlowControl::RtsCts),
            _ => None,
        }
    }
}

/// Receive-ring levels (bytes) at which the sender is stopped and resumed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Watermarks {
    /// Ask the sender to stop once this many bytes wait.
    pub pause_at: usize,
    /// Ask it to go on once no more than this many wait.
    pub resume_at: usize,
}

impl Watermarks {
    /// Marks for a ring of `capacity` bytes whose sender may still send
    /// `latency` bytes after being told to stop: stop with `latency` plus
    /// a quarter of the ring free, go on at a quarter full.
    pub const fn for_latency(capacity: usize, latency: usize) -> Self {
        let quarter = capacity / 4;
        let free = latency.saturating_add(quarter);
        Watermarks {
            pause_at: capacity.saturating_sub(free),
            resume_at: quarter,
        }
    }
}

/// Counters and flags shared by both ends of a line. Each field has one
/// writer (noted), so plain atomic loads and stores suffice (Cortex-M0 has
/// no atomic read-modify-write).
#[derive(Debug)]
struct Shared {
    /// Received bytes lost so far (written by the interrupt side).
    overruns: AtomicU32,
    /// Overruns the thread side has already reported (thread side).
    overruns_seen: AtomicU32,
    /// The sender was asked to stop (interrupt side).
    paused: AtomicBool,
    /// The peer sent XOFF and no XON since: this line's transmitter is
    /// stopped (set by the interrupt side, cleared by either).
    peer_stopped: AtomicBool,
    /// Times the sender was asked to stop (interrupt side).
    pauses: AtomicU32,
    /// When the last byte arrived, in the board's microseconds, if the
    /// interrupt side stamps them ([`IsrEnd::on_receive_at`]).
    last_rx_us: AtomicU32,
    /// Whether `last_rx_us` was ever stamped (interrupt side).
    stamped: AtomicBool,
}

impl Shared {
    const fn new() -> Self {
        Shared {
            overruns: AtomicU32::new(0),
            overruns_seen: AtomicU32::new(0),
            paused: AtomicBool::new(false),
            peer_stopped: AtomicBool::new(false),
            pauses: AtomicU32::new(0),
            last_rx_us: AtomicU32::new(0),
            stamped: AtomicBool::new(false),
        }
    }
}

/// The rings and shared state of one serial line: `RX` and `TX` are the
/// queue sizes (each holds one byte less; use powers of two).
pub struct UartRings<const RX: usize, const TX: usize> {
    rx: Queue<u8, RX>,
    tx: Queue<u8, TX>,
    shared: Shared,
}

impl<const RX: usize, const TX: usize> Default for UartRings<RX, TX> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const RX: usize, const TX: usize> UartRings<RX, TX> {
    /// Empty rings (const: a line can live in a `static`).
    pub const fn new() -> Self {
        UartRings {
            rx: Queue::new(),
            tx: Queue::new(),
            shared: Shared::new(),
        }
    }

    /// Bytes the receive ring holds at most.
    pub const RX_CAPACITY: usize = RX - 1;

    /// Splits the line into its interrupt end and its thread end.
    ///
    /// `flow` and `marks` set the receive-side flow control; `pend` is
    /// called by the thread end when the interrupt end has work it cannot
    /// see by itself (the ring drained below [`Watermarks::resume_at`]
    /// while paused, or bytes were queued for transmission): on a board it
    /// sets the UART interrupt pending.
    pub fn split<'a>(
        &'a mut self,
        flow: FlowControl,
        marks: Watermarks,
        pend: &'a dyn Fn(),
    ) -> (IsrEnd<'a>, ThreadEnd<'a>) {
        let (rx_p, rx_c) = self.rx.split();
        let (tx_p, tx_c) = self.tx.split();
        let shared = &self.shared;
        (
            IsrEnd {
                rx: rx_p,
                tx: tx_c,
                shared,
                flow,
                marks,
                x_char: None,
                since_xoff: 0,
            },
            ThreadEnd {
                rx: rx_c,
                tx: tx_p,
                shared,
                marks,
                pend,
            },
        )
    }
}

/// The interrupt handler's end of a [`UartRings`].
pub struct IsrEnd<'a> {
    rx: Producer<'a, u8>,
    tx: Consumer<'a, u8>,
    shared: &'a Shared,
    flow: FlowControl,
    marks: Watermarks,
    /// XON or XOFF to send ahead of the data.
    x_char: Option<u8>,
    /// Bytes received since the last XOFF was queued.
    since_xoff: usize,
}

impl IsrEnd<'_> {
    /// The flow control in force.
    pub fn flow(&self) -> FlowControl {
        self.flow
    }

    /// One byte the UART received.
    pub fn on_receive(&mut self, byte: u8) {
        if self.flow == FlowControl::XonXoff && (byte == XON || byte == XOFF) {
            self.shared
                .peer_stopped
                .store(byte == XOFF, Ordering::Release);
            return;
        }
        if self.rx.enqueue(byte).is_err() {
            self.count_overruns(1);
        }
        let level = self.rx.len();
        let paused = self.shared.paused.load(Ordering::Relaxed);
        if !paused && level >= self.marks.pause_at {
            self.shared.paused.store(true, Ordering::Release);
            let pauses = self.shared.pauses.load(Ordering::Relaxed);
            self.shared
                .pauses
                .store(pauses.wrapping_add(1), Ordering::Relaxed);
            self.queue_xoff();
        } else if paused && self.flow == FlowControl::XonXoff {
            self.since_xoff = self.since_xoff.saturating_add(1);
            if self.since_xoff >= XOFF_REPEAT {
                self.queue_xoff();
            }
        }
    }

    /// One byte the UART received at `at_us` (the board's microsecond
    /// clock): what a Modbus RTU line needs to find the silence between
    /// frames even when the thread reads the ring late.
    pub fn on_receive_at(&mut self, byte: u8, at_us: u32) {
        // Stamped first: a reader that sees the byte sees its time.
        self.shared.last_rx_us.store(at_us, Ordering::Relaxed);
        self.shared.stamped.store(true, Ordering::Release);
        self.on_receive(byte);
    }

    /// The UART flagged `lost` bytes it could not keep (hardware overrun).
    pub fn on_hw_overrun(&mut self, lost: u32) {
        self.count_overruns(lost);
    }

    /// Call at every run of the interrupt handler (before transmitting):
    /// lets the sender go on once the ring has drained.
    pub fn service(&mut self) {
        if self.shared.paused.load(Ordering::Relaxed) && self.rx.len() <= self.marks.resume_at {
            self.shared.paused.store(false, Ordering::Release);
            if self.flow == FlowControl::XonXoff {
                // An XOFF still waiting to go out is simply dropped: the
                // sender never stopped.
                self.x_char = match self.x_char {
                    Some(XOFF) => None,
                    _ => Some(XON),
                };
            }
        }
    }

    /// The next byte to hand to the transmitter: a pending XON/XOFF first,
    /// then queued data unless the peer stopped this line (XOFF received,
    /// or `cts` false with RTS/CTS).
    pub fn next_tx(&mut self, cts: bool) -> Option<u8> {
        if let Some(c) = self.x_char.take() {
            return Some(c);
        }
        let stopped = match self.flow {
            FlowControl::None => false,
            FlowControl::XonXoff => self.peer_stopped(),
            FlowControl::RtsCts => !cts,
        };
        if stopped {
            None
        } else {
            self.tx.dequeue()
        }
    }

    /// Whether [`IsrEnd::next_tx`] may have something (keep the transmit
    /// interrupt enabled while it is true).
    pub fn wants_tx(&self) -> bool {
        self.x_char.is_some() || (self.tx.ready() && !self.peer_stopped())
    }

    fn peer_stopped(&self) -> bool {
        self.shared.peer_stopped.load(Ordering::Acquire)
    }

    /// The level to drive on RTS with [`FlowControl::RtsCts`]: `true` while
    /// the sender may send.
    pub fn rts(&self) -> bool {
        !self.shared.paused.load(Ordering::Relaxed)
    }

    /// Bytes waiting in the receive ring.
    pub fn rx_level(&self) -> usize {
        self.rx.len()
    }

    fn queue_xoff(&mut self) {
        if self.flow == FlowControl::XonXoff {
            // An XON still waiting to go out is dropped instead: the sender
            // is still stopped by the XOFF before it.
            self.x_char = match self.x_char {
                Some(XON) => None,
                _ => Some(XOFF),
            };
            self.since_xoff = 0;
        }
    }

    fn count_overruns(&mut self, n: u32) {
        let o = self.shared.overruns.load(Ordering::Relaxed);
        self.shared
            .overruns
            .store(o.wrapping_add(n), Ordering::Release);
    }
}

/// The bridge's end of a [`UartRings`]: never blocks.
pub struct ThreadEnd<'a> {
    rx: Consumer<'a, u8>,
    tx: Producer<'a, u8>,
    shared: &'a Shared,
    marks: Watermarks,
    pend: &'a dyn Fn(),
}

impl ThreadEnd<'_> {
    /// Bytes waiting in the receive ring.
    pub fn rx_level(&self) -> usize {
        self.rx.len()
    }

    /// Whether the sender is currently asked to stop.
    pub fn paused(&self) -> bool {
        self.shared.paused.load(Ordering::Acquire)
    }

    /// Times the sender was asked to stop since start.
    pub fn pauses(&self) -> u32 {
        self.shared.pauses.load(Ordering::Relaxed)
    }

    /// Received bytes lost since start.
    pub fn overruns(&self) -> u32 {
        self.shared.overruns.load(Ordering::Acquire)
    }

    /// Whether nothing waits to be transmitted.
    pub fn tx_idle(&self) -> bool {
        !self.tx.ready()
    }
}

impl embedded_io::ErrorType for ThreadEnd<'_> {
    type Error = core::convert::Infallible;
}

impl embedded_io::ReadReady for ThreadEnd<'_> {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.rx.ready())
    }
}

impl embedded_io::Read for ThreadEnd<'_> {
    /// Moves what is there (possibly nothing: check `read_ready` first).
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let mut n = 0;
        for slot in buf.iter_mut() {
            match self.rx.dequeue() {
                Some(b) => {
                    *slot = b;
                    n += 1;
                }
                None => break,
            }
        }
        if self.shared.paused.load(Ordering::Acquire) && self.rx.len() <= self.marks.resume_at {
            (self.pend)();
        }
        Ok(n)
    }
}

impl embedded_io::WriteReady for ThreadEnd<'_> {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.tx.ready())
    }
}

impl embedded_io::Write for ThreadEnd<'_> {
    /// Queues what fits (possibly nothing: check `write_ready` first).
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let mut n = 0;
        for &b in buf {
            if self.tx.enqueue(b).is_err() {
                break;
            }
            n += 1;
        }
        if n > 0 {
            (self.pend)();
        }
        Ok(n)
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// A serial port as the bridge sees it: non-blocking `embedded-io` plus an
/// overrun count.
pub trait Port:
    embedded_io::Read + embedded_io::ReadReady + embedded_io::Write + embedded_io::WriteReady
{
    /// Received bytes lost since the last call (receive ring full, or the
    /// UART's overrun flag). Ports that cannot lose bytes return 0.
    fn take_overruns(&mut self) -> u32 {
        0
    }

    /// Whether the peer stopped this port's transmitter (XOFF and no XON
    /// since).
    fn peer_stopped(&mut self) -> bool {
        false
    }

    /// Lets the transmitter go again as if XON had come (the XOFF held it
    /// too long: [`crate::config::Config::xoff_hold_ms`]).
    fn release_peer_stop(&mut self) {}

    /// When the last byte arrived (microseconds, the board's clock), if the
    /// port knows; `None`: the reader takes the time it reads a byte.
    fn last_rx_us(&mut self) -> Option<u32> {
        None
    }
}

/// A port that counts the bytes read from it and written to it (a line's
/// traffic counters), for a driver that moves the bytes itself.
pub struct Counted<'a, P> {
    port: &'a mut P,
    read: &'a mut u64,
    written: &'a mut u64,
}

impl<'a, P: Port> Counted<'a, P> {
    /// `port`, adding what is read to `read` and what is written to
    /// `written`.
    pub fn new(port: &'a mut P, read: &'a mut u64, written: &'a mut u64) -> Self {
        Counted {
            port,
            read,
            written,
        }
    }
}

impl<P: Port> embedded_io::ErrorType for Counted<'_, P> {
    type Error = P::Error;
}
impl<P: Port> embedded_io::ReadReady for Counted<'_, P> {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        self.port.read_ready()
    }
}
impl<P: Port> embedded_io::Read for Counted<'_, P> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let n = self.port.read(buf)?;
        *self.read += n as u64;
        Ok(n)
    }
}
impl<P: Port> embedded_io::WriteReady for Counted<'_, P> {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        self.port.write_ready()
    }
}
impl<P: Port> embedded_io::Write for Counted<'_, P> {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let n = self.port.write(buf)?;
        *self.written += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        self.port.flush()
    }
}
impl<P: Port> Port for Counted<'_, P> {
    fn take_overruns(&mut self) -> u32 {
        self.port.take_overruns()
    }
    fn peer_stopped(&mut self) -> bool {
        self.port.peer_stopped()
    }
    fn release_peer_stop(&mut self) {
        self.port.release_peer_stop()
    }
    fn last_rx_us(&mut self) -> Option<u32> {
        self.port.last_rx_us()
    }
}

impl Port for ThreadEnd<'_> {
    fn peer_stopped(&mut self) -> bool {
        self.shared.peer_stopped.load(Ordering::Acquire)
    }

    fn release_peer_stop(&mut self) {
        self.shared.peer_stopped.store(false, Ordering::Release);
        // The interrupt side resumes transmitting.
        (self.pend)();
    }

    fn take_overruns(&mut self) -> u32 {
        let total = self.shared.overruns.load(Ordering::Acquire);
        let seen = self.shared.overruns_seen.load(Ordering::Relaxed);
        self.shared.overruns_seen.store(total, Ordering::Relaxed);
        total.wrapping_sub(seen)
    }

    fn last_rx_us(&mut self) -> Option<u32> {
        self.shared
            .stamped
            .load(Ordering::Acquire)
            .then(|| self.shared.last_rx_us.load(Ordering::Relaxed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_io::{Read, Write};

    #[test]
    fn xoff_at_the_mark_xon_after_draining() {
        let mut line: UartRings<16, 8> = UartRings::new();
        let marks = Watermarks {
            pause_at: 10,
            resume_at: 3,
        };
        let (mut isr, mut thr) = line.split(FlowControl::XonXoff, marks, &|| {});
        for b in 0..9u8 {
            isr.on_receive(b'0' + b);
        }
        assert_eq!(isr.next_tx(true), None);
        isr.on_receive(b'x');
        assert!(thr.paused());
        assert_eq!(isr.next_tx(true), Some(XOFF));
        let mut buf = [0u8; 7];
        assert_eq!(thr.read(&mut buf).unwrap(), 7);
        isr.service();
        assert_eq!(isr.next_tx(true), Some(XON));
        assert!(!thr.paused());
        assert_eq!(thr.pauses(), 1);
    }

    #[test]
    fn full_ring_counts_overruns_and_received_xoff_stops_tx() {
        let mut line: UartRings<4, 8> = UartRings::new();
        let marks = Watermarks::for_latency(3, 0);
        let (mut isr, mut thr) = line.split(FlowControl::XonXoff, marks, &|| {});
        for b in *b"abcde" {
            isr.on_receive(b);
        }
        assert_eq!(thr.take_overruns(), 2);
        assert_eq!(thr.take_overruns(), 0);
        assert_eq!(thr.write(b"hi").unwrap(), 2);
        isr.next_tx(true); // the XOFF queued at the mark
        isr.on_receive(XOFF);
        assert_eq!(isr.next_tx(true), None);
        isr.on_receive(XON);
        assert_eq!(isr.next_tx(true), Some(b'h'));
    }

    #[test]
    fn rts_follows_the_marks_and_cts_gates_tx() {
        let mut line: UartRings<8, 8> = UartRings::new();
        let marks = Watermarks {
            pause_at: 4,
            resume_at: 1,
        };
        let (mut isr, mut thr) = line.split(FlowControl::RtsCts, marks, &|| {});
        for b in *b"abcd" {
            assert!(isr.rts());
            isr.on_receive(b);
        }
        assert!(!isr.rts());
        let mut buf = [0u8; 3];
        thr.read(&mut buf).unwrap();
        isr.service();
        assert!(isr.rts());
        thr.write(b"z").unwrap();
        assert_eq!(isr.next_tx(false), None);
        assert_eq!(isr.next_tx(true), Some(b'z'));
        // RTS/CTS passes 0x13 through as data.
        isr.on_receive(XOFF);
        assert_eq!(thr.rx_level(), 2);
    }
}
