//! A serial line's interrupt end ([`IsrEnd`]) served by a task over any
//! `embedded-io-async` port (embassy-stm32's `BufferedUart` on the
//! STM32G0 boards, the emulator's USART driver on the STM32L475), in place
//! of a UART interrupt handler: the task hands each received byte to the
//! line (flow control, overrun counting, time stamps, as a handler would)
//! and the line's bytes to the port. The bridge's loop reads and writes
//! the line's thread end and never waits on the port.
//!
//! The port's own receive buffer only has to cover the time until this
//! task runs: a byte it drops when full is not counted (embassy-stm32
//! 0.6's `BufferedUart` does not report it); the line's ring, with its
//! flow control, is where bytes wait for the bridge.

use embassy_futures::select::{select4, Either4};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use embassy_time::Timer;
use embedded_io_async::{Read, Write};

use crate::board::clock::now_us;
use crate::serial::{FlowControl, IsrEnd};

/// A wake-up between tasks: the line's thread end pends its task, a line's
/// task tells the bridge's loop that bytes moved.
pub type Wake = Signal<CriticalSectionRawMutex, ()>;

/// Bytes moved at a time each way. With the port's transmit buffer (8
/// bytes on these boards) it bounds how many bytes go out ahead of an XOFF
/// the line queues: 4 + 8 + the one in the shift register, within the
/// host latency the line's marks allow (`serial::HOST_LATENCY`, 17).
const CHUNK: usize = 4;

/// The RTS and CTS lines of a port that has them as GPIOs, for
/// [`FlowControl::RtsCts`].
pub trait Modem {
    /// Drives RTS (`true`: the peer may send).
    fn set_rts(&mut self, high: bool);
    /// Reads CTS (`true`: the peer may receive).
    fn cts(&mut self) -> bool;
}

/// A port without modem lines.
pub struct NoModem;

impl Modem for NoModem {
    fn set_rts(&mut self, _: bool) {}
    fn cts(&mut self) -> bool {
        true
    }
}

/// Modem lines where the configuration asks for them (`None`: none).
impl<M: Modem> Modem for Option<M> {
    fn set_rts(&mut self, high: bool) {
        if let Some(m) = self {
            m.set_rts(high);
        }
    }
    fn cts(&mut self) -> bool {
        self.as_mut().is_none_or(|m| m.cts())
    }
}

/// One serial line as its task serves it: the port's two halves, the
/// line's interrupt end, the modem lines, whether received bytes are
/// stamped (a Modbus RTU line), and what the line's thread end signals
/// (bytes queued, or the ring drained while paused).
pub struct LinePort<R, W, M> {
    /// The port's receiving half.
    pub rx: R,
    /// The port's transmitting half.
    pub tx: W,
    /// The line's interrupt end.
    pub end: IsrEnd<'static>,
    /// RTS and CTS.
    pub modem: M,
    /// Stamp each received byte with the microsecond clock.
    pub stamped: bool,
    /// Signalled by the line's thread end.
    pub pended: &'static Wake,
}

/// Serves `line` for ever: received bytes into the line, the line's bytes
/// out; `moved` is signalled whenever bytes moved.
pub async fn serve<R: Read, W: Write, M: Modem>(line: &mut LinePort<R, W, M>, moved: &Wake) -> ! {
    let mut received = [0u8; CHUNK];
    let mut out = [0u8; CHUNK];
    let mut out_len = 0;
    loop {
        let end = &mut line.end;
        end.service();
        let rts_cts = end.flow() == FlowControl::RtsCts;
        if rts_cts {
            line.modem.set_rts(end.rts());
        }
        if out_len == 0 {
            let cts = !rts_cts || line.modem.cts();
            for slot in out.iter_mut() {
                match end.next_tx(cts) {
                    Some(b) => {
                        *slot = b;
                        out_len += 1;
                    }
                    None => break,
                }
            }
        }
        // CTS has no interrupt here, and a port's write may wait for room
        // without a wake-up of its own: look again after a tick.
        let recheck = out_len > 0 || (rts_cts && end.wants_tx());
        let pending = out.get(..out_len).unwrap_or(&[]);
        let tx = &mut line.tx;
        let step = select4(
            line.rx.read(&mut received),
            async {
                if pending.is_empty() {
                    core::future::pending().await
                } else {
                    tx.write(pending).await
                }
            },
            line.pended.wait(),
            async {
                if recheck {
                    Timer::after_millis(1).await
                } else {
                    core::future::pending().await
                }
            },
        )
        .await;
        let end = &mut line.end;
        match step {
            Either4::First(Ok(n)) => {
                let at = if line.stamped { Some(now_us()) } else { None };
                for &b in received.get(..n).unwrap_or(&[]) {
                    match at {
                        Some(at) => end.on_receive_at(b, at),
                        None => end.on_receive(b),
                    }
                }
                moved.signal(());
            }
            // A receive error (framing, noise) loses what it was receiving.
            Either4::First(Err(_)) => end.on_hw_overrun(1),
            Either4::Second(Ok(n)) => {
                let n = n.min(out_len);
                out.copy_within(n..out_len, 0);
                out_len -= n;
                moved.signal(());
            }
            // The port refused the bytes: they are lost, as on a line
            // whose transmitter failed.
            Either4::Second(Err(_)) => out_len = 0,
            Either4::Third(()) | Either4::Fourth(()) => {}
        }
    }
}
