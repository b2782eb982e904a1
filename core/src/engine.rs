//! The shape every engine has, and the one driver that moves its bytes.
//!
//! The engines ([`crate::client`], [`crate::transfer`], [`crate::readback`],
//! [`crate::relay`]) are sans-IO: [`Engine::poll`] says what to transmit
//! or until when to wait, [`Engine::received`] takes the bytes that arrive,
//! [`Engine::sent`] hears that a transmission ended. Each call borrows the
//! [`Line`] the engine talks over.
//!
//! [`Driver`] is the one loop body between an engine and a port: it feeds
//! what arrived, writes what is due as far as the port takes it, and says
//! what it waits for. [`Driver::turn`] does that over an `embedded-io` port
//! without ever blocking (the firmware's loops); [`run_blocking`],
//! [`poll_nb`], `run_async` (feature `async`) and `hosted::StdLink` are
//! thin shells around the same steps. They read the clock *after* a
//! transmission was written (and, where the shell may block, flushed), so
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

/// A sans-IO engine that the driver can run.
pub trait Engine {
    /// What it gives when it succeeds.
    type Output;
    /// What it wants at tick `now`.
    fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, Self::Output>;
    /// Bytes from the line at tick `now`: returns at the first frame (or
    /// broken frame), with the bytes it used ([`crate::decoder::Status::Partial`]
    /// once all are used and nothing more is complete).
    fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard>;
    /// The transmission ended at tick `now`.
    fn sent(&mut self, line: &mut Line, now: u32);
}

/// Feeds all of `bytes` to `engine`.
pub fn feed<G: Engine + ?Sized>(engine: &mut G, line: &mut Line, bytes: &[u8], now: u32) {
    let mut used = 0;
    loop {
        let r = engine.received(line, bytes.get(used..).unwrap_or(&[]), now);
        used += r.consumed;
        if r.status.is_partial() {
            return;
        }
    }
}

/// What the driver needs next: bytes written, or a wait.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next<'a, T> {
    /// Write these bytes (the rest of the transmission due), then report
    /// how many were taken ([`Driver::wrote`]).
    Write(&'a [u8]),
    /// Nothing to write before this tick, if any (read meanwhile).
    Wait(Option<u32>),
    /// The engine's result.
    Done(Result<T, Failure>),
}

/// What one [`Driver::turn`] achieved.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Turn<T> {
    /// Bytes moved: turn again.
    Busy,
    /// Nothing moves before `until` (if any), bytes to read, or, with
    /// `write`, room to write.
    Wait {
        /// The engine's next deadline.
        until: Option<u32>,
        /// A transmission waits for room in the port.
        write: bool,
    },
    /// The engine's result.
    Done(Result<T, Failure>),
}

/// Bytes read from a port per call.
const READ_CHUNK: usize = 32;

/// The one driver loop body between an engine and a port (see the module
/// docs): where a transmission stands between calls. Keep one per port;
/// it holds nothing of the engine, so engines can take turns on it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Driver {
    /// Bytes of the transmission due already written.
    written: usize,
}

impl Driver {
    /// A driver with nothing written.
    pub const fn new() -> Self {
        Driver { written: 0 }
    }

    /// Whether a transmission is half written.
    pub const fn writing(&self) -> bool {
        self.written > 0
    }

    /// While no engine runs: reads what `port` has ready and lets the line
    /// hear it (late replies, copies, noise), so that what arrives between
    /// engines is placed or noticed, never dropped unread. Whether
    /// anything came.
    pub fn listen<P, C>(
        &mut self,
        line: &mut Line,
        port: &mut P,
        clock: &mut C,
    ) -> Result<bool, P::Error>
    where
        P: embedded_io::Read + embedded_io::ReadReady,
        C: Clock,
    {
        let mut buf = [0u8; READ_CHUNK];
        let mut moved = false;
        while port.read_ready()? {
            let n = port.read(&mut buf)?;
            if n == 0 {
                break;
            }
            line.listen(buf.get(..n).unwrap_or(&[]), clock.now_ms());
            moved = true;
        }
        Ok(moved)
    }

    /// What `engine` needs at `now` (sans-IO: the caller moves the bytes).
    pub fn next<'a, G: Engine>(
        &mut self,
        engine: &'a mut G,
        line: &'a mut Line,
        now: u32,
    ) -> Next<'a, G::Output> {
        match engine.poll(line, now) {
            Step::Transmit(bytes) => Next::Write(bytes.get(self.written..).unwrap_or(&[])),
            Step::WaitUntil(t) => {
                self.written = 0;
                Next::Wait(Some(t))
            }
            Step::Idle => {
                self.written = 0;
                Next::Wait(None)
            }
            Step::Done(r) => {
                self.written = 0;
                Next::Done(r)
            }
        }
    }

    /// `n` bytes of what [`Driver::next`] gave were written; `done` once
    /// they were its last (and, where the port can say, have left it), at
    /// tick `now`: the engine hears the transmission ended.
    pub fn wrote<G: Engine>(
        &mut self,
        engine: &mut G,
        line: &mut Line,
        n: usize,
        done: bool,
        now: u32,
    ) {
        self.written += n;
        if done {
            self.written = 0;
            engine.sent(line, now);
        }
    }

    /// One turn over a port that never blocks: reads what is ready,
    /// writes what the port takes of the transmission due (reporting it
    /// sent once all is taken), polls the engine. Never waits. A port
    /// that reads nothing while ready was closed: [`Failure::Closed`].
    pub fn turn<G, P, C>(
        &mut self,
        engine: &mut G,
        line: &mut Line,
        port: &mut P,
        clock: &mut C,
    ) -> Result<Turn<G::Output>, P::Error>
    where
        G: Engine,
        P: embedded_io::Read
            + embedded_io::ReadReady
            + embedded_io::Write
            + embedded_io::WriteReady,
        C: Clock,
    {
        let mut moved = match read_ready(engine, line, port, clock) {
            Ok(moved) => moved,
            Err(Failure::Io(e)) => return Err(e),
            Err(_) => return Ok(Turn::Done(Err(Failure::Closed))),
        };
        // Rounds of an engine that asks to be polled again at once (a
        // read-back delivering window after window), bounded.
        let mut rounds = 0u8;
        loop {
            let now = clock.now_ms();
            match self.next(engine, line, now) {
                Next::Write(bytes) => {
                    let len = bytes.len();
                    if len > 0 && !port.write_ready()? {
                        return Ok(if moved {
                            Turn::Busy
                        } else {
                            Turn::Wait {
                                until: None,
                                write: true,
                            }
                        });
                    }
                    let n = if len > 0 { port.write(bytes)? } else { 0 };
                    let now = clock.now_ms();
                    self.wrote(engine, line, n, n >= len, now);
                    if n < len {
                        return Ok(if n > 0 || moved {
                            Turn::Busy
                        } else {
                            Turn::Wait {
                                until: None,
                                write: true,
                            }
                        });
                    }
                    moved = true;
                }
                Next::Wait(Some(t)) if crate::clock::reached(now, t) && rounds < 4 => {
                    rounds += 1;
                    moved = true;
                }
                Next::Wait(until) => {
                    return Ok(if moved {
                        Turn::Busy
                    } else {
                        Turn::Wait {
                            until,
                            write: false,
                        }
                    })
                }
                Next::Done(r) => return Ok(Turn::Done(r)),
            }
        }
    }
}

/// Feeds `engine` what `port` has ready; whether anything came. A port
/// that reads 0 bytes while ready was closed.
fn read_ready<G, P, C>(
    engine: &mut G,
    line: &mut Line,
    port: &mut P,
    clock: &mut C,
) -> Result<bool, Failure<P::Error>>
where
    G: Engine,
    P: embedded_io::Read + embedded_io::ReadReady,
    C: Clock,
{
    let mut buf = [0u8; READ_CHUNK];
    let mut moved = false;
    while port.read_ready().map_err(Failure::Io)? {
        let n = port.read(&mut buf).map_err(Failure::Io)?;
        if n == 0 {
            return Err(Failure::Closed);
        }
        feed(engine, line, buf.get(..n).unwrap_or(&[]), clock.now_ms());
        moved = true;
    }
    Ok(moved)
}

/// Makes what progress is possible without waiting: reads what arrived,
/// transmits what is due (a blocking write, flushed, so the timeout starts
/// when the last byte left), checks the deadline. `WouldBlock` means "call
/// again later".
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
    read_ready(engine, line, uart, clock).map_err(nb::Error::Other)?;
    let mut driver = Driver::new();
    let now = clock.now_ms();
    match driver.next(engine, line, now) {
        Next::Write(bytes) => {
            uart.write_all(bytes).map_err(io)?;
            uart.flush().map_err(io)?;
            let end = clock.now_ms();
            driver.wrote(engine, line, 0, true, end);
            Err(nb::Error::WouldBlock)
        }
        Next::Wait(_) => Err(nb::Error::WouldBlock),
        Next::Done(Ok(out)) => Ok(out),
        Next::Done(Err(e)) => Err(nb::Error::Other(e.widen())),
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
    let mut buf = [0u8; READ_CHUNK];
    let mut driver = Driver::new();
    loop {
        while uart.read_ready().map_err(Failure::Io)? {
            let n = uart.read(&mut buf).await.map_err(Failure::Io)?;
            if n == 0 {
                return Err(Failure::Closed);
            }
            feed(engine, line, buf.get(..n).unwrap_or(&[]), clock.now_ms());
        }
        let now = clock.now_ms();
        match driver.next(engine, line, now) {
            Next::Write(bytes) => {
                uart.write_all(bytes).await.map_err(Failure::Io)?;
                uart.flush().await.map_err(Failure::Io)?;
                let end = clock.now_ms();
                driver.wrote(engine, line, 0, true, end);
            }
            Next::Wait(Some(t)) => {
                clock
                    .sleep_ms(t.wrapping_sub(now).clamp(1, poll_ms.max(1)))
                    .await
            }
            Next::Wait(None) => clock.sleep_ms(poll_ms.max(1)).await,
            Next::Done(Ok(out)) => return Ok(out),
            Next::Done(Err(e)) => return Err(e.widen()),
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
