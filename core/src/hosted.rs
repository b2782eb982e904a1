//! The engines from `std` (feature `std`): a line over a TCP socket, a
//! serial port or any byte stream that can wait for input with a timeout,
//! with a clock that sleeps instead of spinning.
//!
//! [`StdLink`] owns the stream, the [`Line`] and the bytes one engine did
//! not take (a copy that came in the same read as a reply): the next
//! engine gets them first, so nothing that arrived is lost between calls.
//! While an engine waits, the link blocks in a read that ends at the
//! engine's deadline, so a call costs no CPU while the controller thinks.
//!
//! ```no_run
//! use std::net::TcpStream;
//! use iai_protocol_b::hosted::StdLink;
//! use iai_protocol_b::message::AxisStatusQuery;
//! use iai_protocol_b::{client::Client, line::LineConfig, frame::Station};
//!
//! let stream = TcpStream::connect("127.0.0.1:5021")?;
//! let mut link = StdLink::new(stream, LineConfig::new(Station(0x99)));
//! let mut client: Client = Client::new();
//! let status = link.call(&mut client, &AxisStatusQuery::of(&[1])?)?;
//! println!("axis 1 at {} um, homed: {:?}", status.axes[0].current_position, status.axes[0].homing());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! A serial port (the `serialport` crate, say) plugs in by implementing
//! [`WaitRead`] with its `set_timeout`.

extern crate std;

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};
use std::vec::Vec;

use crate::client::Client;
use crate::clock::reached;
use crate::engine::{feed, Driver, Engine, Next};
use crate::error::Failure;
use crate::line::{Line, LineConfig};
use crate::message::Request;

/// A byte stream whose reads can wait a bounded time.
pub trait WaitRead: Read + Write {
    /// Reads what arrives within `wait` (at least 1 ms): `Ok(0)` when
    /// nothing did. A stream the other side closed is an error
    /// ([`io::ErrorKind::UnexpectedEof`]).
    fn read_within(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<usize>;
}

/// Whether `e` only says that no byte came in time (or that a signal cut
/// the wait short).
fn nothing_came(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

/// Waits longer than this are one read with a socket timeout; shorter
/// ones poll, as a socket timeout overshoots a few milliseconds by several
/// (a timer tick) and the short waits are the ones that must be kept (the
/// 1 ms turnaround, a controller's reply delay).
const POLLED_WAIT: Duration = Duration::from_millis(20);

impl WaitRead for TcpStream {
    fn read_within(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<usize> {
        let wait = wait.max(Duration::from_millis(1));
        let got = if wait > POLLED_WAIT {
            self.set_read_timeout(Some(wait))?;
            self.read(buf)
        } else {
            let end = Instant::now() + wait;
            self.set_nonblocking(true)?;
            let r = loop {
                match self.read(buf) {
                    Err(e) if nothing_came(&e) => {
                        let now = Instant::now();
                        if now >= end {
                            break Ok(None);
                        }
                        std::thread::sleep((end - now).min(Duration::from_micros(200)));
                    }
                    r => break r.map(Some),
                }
            };
            self.set_nonblocking(false)?;
            match r {
                Ok(None) => return Ok(0),
                Ok(Some(n)) => Ok(n),
                Err(e) => Err(e),
            }
        };
        match got {
            Ok(0) if !buf.is_empty() => Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the connection was closed by the other side",
            )),
            Ok(n) => Ok(n),
            Err(e) if nothing_came(&e) => Ok(0),
            Err(e) => Err(e),
        }
    }
}

/// A clock for the engines: milliseconds since it was made.
#[derive(Debug, Clone, Copy)]
pub struct SystemClock {
    start: Instant,
}

impl Default for SystemClock {
    fn default() -> Self {
        Self::new()
    }
}

impl SystemClock {
    /// A clock at 0 now.
    pub fn new() -> Self {
        SystemClock {
            start: Instant::now(),
        }
    }
    /// The engines' tick: ms since [`SystemClock::new`], wrapping.
    pub fn now_ms(&self) -> u32 {
        self.start.elapsed().as_millis() as u32
    }
}

impl crate::clock::Clock for SystemClock {
    fn now_ms(&mut self) -> u32 {
        SystemClock::now_ms(self)
    }
    fn idle(&mut self) {
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// One line to a controller over a `std` stream: the stream, the core's
/// [`Line`], and the bytes the last engine left.
#[derive(Debug)]
pub struct StdLink<S> {
    stream: S,
    line: Line,
    clock: SystemClock,
    driver: Driver,
    pending: Vec<u8>,
}

/// A seed for the line's fence texts that differs between processes and
/// starts.
fn seed() -> u32 {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    (t ^ (t >> 32) ^ u64::from(std::process::id()).rotate_left(16)) as u32
}

impl<S: WaitRead> StdLink<S> {
    /// A link over `stream` with the line settings `cfg`. The line is new:
    /// its first command is preceded by a fence.
    pub fn new(stream: S, cfg: LineConfig) -> Self {
        StdLink {
            stream,
            line: Line::new(cfg, seed()),
            clock: SystemClock::new(),
            driver: Driver::new(),
            pending: Vec::new(),
        }
    }

    /// The line's memory (statistics, what may still arrive).
    pub fn line(&self) -> &Line {
        &self.line
    }

    /// The line, to start an engine on it.
    pub fn line_mut(&mut self) -> &mut Line {
        &mut self.line
    }

    /// Puts a new line with settings `cfg` in place of this link's, seeded
    /// as at start, and returns the one it replaces (to put back with
    /// [`StdLink::put_back_line`]): another responder on the same wire
    /// (a bridge's own station) gets a line of its own. What arrives for
    /// the first line meanwhile is heard by the other, so do this before
    /// the first line owes anything.
    pub fn replace_line(&mut self, cfg: LineConfig) -> Line {
        core::mem::replace(&mut self.line, Line::new(cfg, seed()))
    }

    /// Puts back a line that [`StdLink::replace_line`] returned.
    pub fn put_back_line(&mut self, line: Line) {
        self.line = line;
    }

    /// The stream.
    pub fn stream(&mut self) -> &mut S {
        &mut self.stream
    }

    /// The stream, to look at.
    pub fn stream_ref(&self) -> &S {
        &self.stream
    }

    /// Takes the bytes received that no engine took yet (what came after
    /// the last engine's reply), for a caller reading the stream itself.
    pub fn take_pending(&mut self) -> Vec<u8> {
        core::mem::take(&mut self.pending)
    }

    /// The link's clock, ms: the `now` to start engines with.
    pub fn now(&self) -> u32 {
        self.clock.now_ms()
    }

    /// Sends `req` and returns its typed reply.
    pub fn call<'c, 'a, R, const CMD: usize, const REPLY: usize>(
        &mut self,
        client: &'c mut Client<CMD, REPLY>,
        req: &R,
    ) -> Result<R::Response<'c>, Failure<io::Error>>
    where
        R: Request<'a>,
        R::Response<'c>: Default,
    {
        let now = self.now();
        let pending = client.start(&mut self.line, req, now)?;
        self.run(client)?;
        Ok(client.response(&pending)?)
    }

    /// Runs a started engine to its result.
    pub fn run<G: Engine>(&mut self, engine: &mut G) -> Result<G::Output, Failure<io::Error>> {
        loop {
            if let Some(r) = self
                .turn(engine, Duration::from_secs(1))
                .map_err(Failure::Io)?
            {
                return r.map_err(Failure::widen);
            }
        }
    }

    /// One turn of `engine`: the bytes held from the last turn first, then
    /// what is due (a transmission, or a wait of at most `cap` reading what
    /// arrives). `Some` with the engine's result once it has one; between
    /// turns a caller may look at a stop flag or draw progress.
    pub fn turn<G: Engine>(
        &mut self,
        engine: &mut G,
        cap: Duration,
    ) -> io::Result<Option<Result<G::Output, Failure>>> {
        self.feed_pending(engine);
        let now = self.now();
        match self.driver.next(engine, &mut self.line, now) {
            Next::Write(bytes) => {
                self.stream.write_all(bytes)?;
                self.stream.flush()?;
                let end = self.now();
                self.driver.wrote(engine, &mut self.line, 0, true, end);
            }
            Next::Wait(until) => {
                let left = match until {
                    Some(t) if !reached(now, t) => t.wrapping_sub(now),
                    Some(_) => 0,
                    None => 1,
                };
                let left = Duration::from_millis(u64::from(left));
                let mut buf = [0u8; 4096];
                let n = self.stream.read_within(&mut buf, left.min(cap))?;
                self.pending.extend_from_slice(buf.get(..n).unwrap_or(&[]));
                self.feed_pending(engine);
            }
            Next::Done(r) => return Ok(Some(r)),
        }
        Ok(None)
    }

    fn feed_pending<G: Engine>(&mut self, engine: &mut G) {
        if !self.pending.is_empty() {
            let now = self.now();
            feed(engine, &mut self.line, &self.pending, now);
            self.pending.clear();
        }
    }
}
