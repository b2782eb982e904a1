//! The shape every engine has, and the loops that drive one over a UART.
//!
//! The engines ([`crate::client`], [`crate::transfer`], [`crate::readback`])
//! are sans-IO: [`Engine::poll`] says what to transmit or until when to
//! wait, [`Engine::received`] takes the bytes that arrive, [`Engine::sent`]
//! hears that a transmission ended. Each call borrows the [`Line`] the
//! engine talks over. [`run_blocking`], [`poll_nb`] and (with the `async`
//! feature) `run_async` move bytes and time between an engine and a UART;
//! they read the clock *after* a transmission was written and flushed, so
//! that the reply timeout starts at its end.

use crate::clock::Clock;
use crate::decoder::Received;
use crate::error::Failure;
use crate::line::{Heard, Line};

/// What an engine wants next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step<'a, T> {
    /// Transmit these bytes, then report `sent`.
    Transmit(&'a [u8]),
    /// Nothing before this tick (feed received bytes meanwhile).
    WaitUntil(u32),
    /// Nothing until something outside changes (records to send).
    Idle,
    /// A result: the engine's last (a client's reply, a transfer's
    /// guarantee), or, for a read-back, one window's records (poll again
    /// for the next). A failed transfer or read-back can be resumed.
    Done(Result<T, Failure>),
}

/// A sans-IO engine that the loops can drive.
pub trait Engine {
    /// What it gives when it succeeds.
    type Output;
    /// What it wants at tick `now`.
    fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, Self::Output>;
    /// Bytes from the line at tick `now`: returns at the first frame (or
    /// broken frame), with the bytes it used. An engine that holds a result
    /// the next bytes would overwrite takes none (`consumed` 0,
    /// [`Heard::NeedMore`]) until it was polled.
    fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard>;
    /// The transmission ended at tick `now`.
    fn sent(&mut self, line: &mut Line, now: u32);
}

/// Feeds `bytes` to `engine` until it used them all or takes no more;
/// returns the bytes used.
pub fn feed<G: Engine + ?Sized>(engine: &mut G, line: &mut Line, bytes: &[u8], now: u32) -> usize {
    let mut used = 0;
    loop {
        let r = engine.received(line, bytes.get(used..).unwrap_or(&[]), now);
        used += r.consumed;
        if r.event == Heard::NeedMore {
            return used;
        }
    }
}

/// Makes what progress is possible without waiting: reads what arrived,
/// transmits what is due, checks the deadline. `WouldBlock` means "call
/// again later".
///
/// Bytes read in the same chunk after a result the engine still holds are
/// dropped: they came after the reply and before the next command, so they
/// answer nothing, but they may hold a reply whose copy is still to come,
/// so the line hears that bytes went unread ([`Line::unread`]). A driver
/// that can keep them for the next engine should (`hosted::StdLink` does).
pub fn poll_nb<G, U, C>(
    engine: &mut G,
    line: &mut Line,
    uart: &mut U,
    clock: &mut C,
) -> nb::Result<G::Output, Failure<U::Error>>
where
    G: Engine,
    U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
    C: Clock,
{
    let io = |e| nb::Error::Other(Failure::Io(e));
    let mut buf = [0u8; 32];
    while uart.read_ready().map_err(io)? {
        let n = uart.read(&mut buf).map_err(io)?;
        if n == 0 {
            return Err(nb::Error::Other(Failure::Closed));
        }
        let chunk = buf.get(..n).unwrap_or(&[]);
        let now = clock.now_ms();
        if feed(engine, line, chunk, now) < n {
            line.unread(now);
            break;
        }
    }
    match engine.poll(line, clock.now_ms()) {
        Step::Transmit(bytes) => {
            uart.write_all(bytes).map_err(io)?;
            uart.flush().map_err(io)?;
            let end = clock.now_ms();
            engine.sent(line, end);
            Err(nb::Error::WouldBlock)
        }
        Step::WaitUntil(_) | Step::Idle => Err(nb::Error::WouldBlock),
        Step::Done(Ok(out)) => Ok(out),
        Step::Done(Err(e)) => Err(nb::Error::Other(e.widen())),
    }
}

/// Runs the engine to its result, blocking; `clock.idle()` while waiting.
pub fn run_blocking<G, U, C>(
    engine: &mut G,
    line: &mut Line,
    uart: &mut U,
    clock: &mut C,
) -> Result<G::Output, Failure<U::Error>>
where
    G: Engine,
    U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
    C: Clock,
{
    loop {
        match poll_nb(engine, line, uart, clock) {
            Ok(out) => return Ok(out),
            Err(nb::Error::Other(e)) => return Err(e),
            Err(nb::Error::WouldBlock) => clock.idle(),
        }
    }
}

/// Runs the engine to its result over an `embedded-io-async` UART. While
/// it waits it checks [`embedded_io_async::ReadReady`] and sleeps at most
/// `poll_ms` between checks, so a deadline is seen even if no byte comes.
#[cfg(feature = "async")]
pub async fn run_async<G, U, C>(
    engine: &mut G,
    line: &mut Line,
    uart: &mut U,
    clock: &mut C,
    poll_ms: u32,
) -> Result<G::Output, Failure<U::Error>>
where
    G: Engine,
    U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
    C: crate::clock::AsyncClock,
{
    let mut buf = [0u8; 32];
    loop {
        while uart.read_ready().map_err(Failure::Io)? {
            let n = uart.read(&mut buf).await.map_err(Failure::Io)?;
            if n == 0 {
                return Err(Failure::Closed);
            }
            let chunk = buf.get(..n).unwrap_or(&[]);
            let now = clock.now_ms();
            if feed(engine, line, chunk, now) < n {
                line.unread(now);
                break;
            }
        }
        let now = clock.now_ms();
        match engine.poll(line, now) {
            Step::Transmit(bytes) => {
                uart.write_all(bytes).await.map_err(Failure::Io)?;
                uart.flush().await.map_err(Failure::Io)?;
                let end = clock.now_ms();
                engine.sent(line, end);
            }
            Step::WaitUntil(t) => {
                clock
                    .sleep_ms(t.wrapping_sub(now).clamp(1, poll_ms.max(1)))
                    .await
            }
            Step::Idle => clock.sleep_ms(poll_ms.max(1)).await,
            Step::Done(Ok(out)) => return Ok(out),
            Step::Done(Err(e)) => return Err(e.widen()),
        }
    }
}

#[cfg(test)]
mod tests {
    //! The blocking driver over a scripted UART on a virtual clock.

    extern crate std;
    use core::cell::Cell;
    use std::collections::VecDeque;
    use std::rc::Rc;
    use std::vec::Vec;

    use crate::checksum::Checksum;
    use crate::client::Client;
    use crate::frame::Station;
    use crate::line::{Line, LineConfig};
    use crate::message::{AxisStatusQuery, SystemStatusQuery};

    /// `body` with its SC, CR and LF.
    fn framed(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(std::format!("{:02X}\r\n", Checksum::of(body)).as_bytes());
        f
    }

    /// A converter that repeats frames, in front of a controller that
    /// answered a 212H's two sends in one burst: the late reply to the
    /// first and `&` C74 to the second. Each command written schedules
    /// what comes back.
    struct Scripted {
        now: Rc<Cell<u32>>,
        written: Vec<u8>,
        due: Vec<(u32, Vec<u8>)>,
        rx: VecDeque<u8>,
        sends_212: u32,
    }

    impl Scripted {
        fn command(&mut self, frame: &[u8]) {
            let t = self.now.get();
            let body = frame.get(..frame.len() - 4).unwrap_or(&[]);
            match body.get(3..6) {
                Some(b"200") => {
                    let mut echo = body.to_vec();
                    echo[0] = b'#';
                    self.due.push((t + 5, framed(&echo)));
                }
                Some(b"212") => {
                    self.sends_212 += 1;
                    if self.sends_212 == 2 {
                        let mut burst = framed(b"#9921200");
                        burst.extend_from_slice(&framed(b"&99C74"));
                        self.due.push((t + 10, burst));
                        self.due.push((t + 2_010, framed(b"&99C74")));
                    }
                }
                Some(b"215") => self.due.push((t + 2_500, framed(b"#99215100000000000000"))),
                _ => {}
            }
        }
    }

    impl embedded_io::ErrorType for Scripted {
        type Error = core::convert::Infallible;
    }
    impl embedded_io::ReadReady for Scripted {
        fn read_ready(&mut self) -> Result<bool, Self::Error> {
            let now = self.now.get();
            let (ready, later): (Vec<_>, Vec<_>) = self.due.drain(..).partition(|(t, _)| *t <= now);
            self.due = later;
            for (_, bytes) in ready {
                self.rx.extend(bytes);
            }
            Ok(!self.rx.is_empty())
        }
    }
    impl embedded_io::Read for Scripted {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
            let n = buf.len().min(self.rx.len());
            for (b, v) in buf.iter_mut().zip(self.rx.drain(..n)) {
                *b = v;
            }
            Ok(n)
        }
    }
    impl embedded_io::Write for Scripted {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            for &b in buf {
                self.written.push(b);
                if b == b'\n' {
                    let frame = core::mem::take(&mut self.written);
                    self.command(&frame);
                }
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    /// Fuzz finding F16: bytes the driver reads after the reply it hands
    /// back (here an `&` to a later send of the same command) answer
    /// nothing, but their copy may still come. The line hears that they
    /// went unread, so the next command waits out the copy window and
    /// gets its own reply instead of the copy of the `&`.
    #[test]
    fn bytes_read_after_a_held_reply_still_hold_back_their_copies() {
        let now = Rc::new(Cell::new(0u32));
        let mut uart = Scripted {
            now: now.clone(),
            written: Vec::new(),
            due: Vec::new(),
            rx: VecDeque::new(),
            sends_212: 0,
        };
        let tick = now.clone();
        let mut clock = move || {
            tick.set(tick.get() + 1);
            tick.get()
        };
        let cfg = LineConfig::new(Station(0x99)).with_duplicate_window(3_000);
        let mut line = Line::new(cfg, 7);
        let mut c: Client<64, 128> = Client::new();
        let q = AxisStatusQuery::of(&[1]).unwrap();
        assert!(c.call(&mut line, &mut uart, &mut clock, &q).is_ok());
        let r = c.call(&mut line, &mut uart, &mut clock, &SystemStatusQuery {});
        assert_eq!(r.map(|s| s.system_mode), Ok(1));
    }
}
