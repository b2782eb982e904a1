//! The blocking, `nb` and async flavours, written once for every engine.
//!
//! The engines ([`crate::client`], [`crate::transfer`], [`crate::readback`])
//! are sans-IO: they say what to transmit and until when to wait, and take
//! the bytes that arrive. [`Engine`] is that shape; [`poll_nb`] and
//! (with the `async` feature) `run_async` move bytes and time between an
//! engine and a UART. Both
//! read the clock *after* a transmission has been written and flushed, so
//! that a reply timeout starts at the end of the transmission.

use crate::clock::Clock;

/// What an engine wants next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Want<'a, T> {
    /// Transmit these bytes, then report [`Engine::sent`].
    Transmit(&'a [u8]),
    /// Nothing before this tick (feed received bytes meanwhile).
    WaitUntil(u32),
    /// Nothing until something outside changes (records to send).
    Idle,
    /// Finished, with this result.
    Done(T),
}

/// A sans-IO engine that the flavours can drive.
pub trait Engine {
    /// What it gives when it succeeds.
    type Output;
    /// Why it fails (without I/O errors).
    type Error;
    /// Bytes from the line at tick `now`.
    fn feed(&mut self, bytes: &[u8], now: u32);
    /// What it wants at tick `now`.
    fn want(&mut self, now: u32) -> Want<'_, Result<Self::Output, Self::Error>>;
    /// The transmission ended at tick `now`.
    fn sent(&mut self, now: u32);
}

/// Why a driven engine stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop<E, Io> {
    /// The engine failed.
    Engine(E),
    /// The UART failed.
    Io(Io),
}

/// Makes what progress is possible without waiting: reads what arrived,
/// transmits what is due, checks the deadline. `WouldBlock` means "call
/// again later".
pub fn poll_nb<G, U, C>(
    engine: &mut G,
    uart: &mut U,
    clock: &mut C,
) -> nb::Result<G::Output, Stop<G::Error, U::Error>>
where
    G: Engine,
    U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
    C: Clock,
{
    let io = |e| nb::Error::Other(Stop::Io(e));
    let mut buf = [0u8; 32];
    while uart.read_ready().map_err(io)? {
        let n = uart.read(&mut buf).map_err(io)?;
        if n == 0 {
            break;
        }
        engine.feed(buf.get(..n).unwrap_or(&[]), clock.now_ms());
    }
    match engine.want(clock.now_ms()) {
        Want::Transmit(bytes) => {
            uart.write_all(bytes).map_err(io)?;
            uart.flush().map_err(io)?;
            let end = clock.now_ms();
            engine.sent(end);
            Err(nb::Error::WouldBlock)
        }
        Want::WaitUntil(_) | Want::Idle => Err(nb::Error::WouldBlock),
        Want::Done(Ok(out)) => Ok(out),
        Want::Done(Err(e)) => Err(nb::Error::Other(Stop::Engine(e))),
    }
}

/// Runs the engine to the end, blocking; `clock.idle()` while waiting.
pub fn run_blocking<G, U, C>(
    engine: &mut G,
    uart: &mut U,
    clock: &mut C,
) -> Result<G::Output, Stop<G::Error, U::Error>>
where
    G: Engine,
    U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
    C: Clock,
{
    loop {
        match poll_nb(engine, uart, clock) {
            Ok(out) => return Ok(out),
            Err(nb::Error::Other(e)) => return Err(e),
            Err(nb::Error::WouldBlock) => clock.idle(),
        }
    }
}

/// Runs the engine to the end over an `embedded-io-async` UART. While it
/// waits it checks [`embedded_io_async::ReadReady`] and sleeps at most
/// `poll_ms` between checks, so a deadline is seen even if no byte comes.
#[cfg(feature = "async")]
pub async fn run_async<G, U, C>(
    engine: &mut G,
    uart: &mut U,
    clock: &mut C,
    poll_ms: u32,
) -> Result<G::Output, Stop<G::Error, U::Error>>
where
    G: Engine,
    U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
    C: crate::clock::AsyncClock,
{
    let mut buf = [0u8; 32];
    loop {
        while uart.read_ready().map_err(Stop::Io)? {
            let n = uart.read(&mut buf).await.map_err(Stop::Io)?;
            if n == 0 {
                break;
            }
            let now = clock.now_ms();
            engine.feed(buf.get(..n).unwrap_or(&[]), now);
        }
        let now = clock.now_ms();
        match engine.want(now) {
            Want::Transmit(bytes) => {
                uart.write_all(bytes).await.map_err(Stop::Io)?;
                uart.flush().await.map_err(Stop::Io)?;
                let end = clock.now_ms();
                engine.sent(end);
            }
            Want::WaitUntil(t) => {
                clock
                    .sleep_ms(t.wrapping_sub(now).clamp(1, poll_ms.max(1)))
                    .await
            }
            Want::Idle => clock.sleep_ms(poll_ms.max(1)).await,
            Want::Done(Ok(out)) => return Ok(out),
            Want::Done(Err(e)) => return Err(Stop::Engine(e)),
        }
    }
}
