//! The line to a controller: a serial port or a TCP connection (a
//! serial-to-Ethernet adapter, or `iai simulate --tcp`), with reads that
//! wait at most a given time, a millisecond clock, and the core's [`Line`]:
//! what one command of this process left in flight on it, the next one
//! knows. [`Link::turn`] moves bytes and time between one of the core's
//! engines and the line.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use iai_protocol_b::engine::{feed, Engine, Step};
use iai_protocol_b::{Failure, Line, LineConfig};

/// Reads from a TCP stream what arrives within `wait`: `None` when nothing
/// did, `Some(0)` when the peer closed. A socket read timeout overshoots a
/// few milliseconds by several; short waits (the 1 ms turnaround, the
/// controller's α) are kept by polling instead.
pub fn tcp_read_for(
    s: &mut TcpStream,
    buf: &mut [u8],
    wait: Duration,
) -> io::Result<Option<usize>> {
    // A signal (Ctrl-C) interrupting the read counts as nothing read: the
    // caller looks at its stop flag.
    let timed_out = |e: &io::Error| {
        matches!(
            e.kind(),
            io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
        )
    };
    if wait > Duration::from_millis(20) {
        s.set_read_timeout(Some(wait))?;
        return match s.read(buf) {
            Ok(n) => Ok(Some(n)),
            Err(e) if timed_out(&e) => Ok(None),
            Err(e) => Err(e),
        };
    }
    let end = Instant::now() + wait;
    s.set_nonblocking(true)?;
    let r = loop {
        match s.read(buf) {
            Ok(n) => break Ok(Some(n)),
            Err(e) if timed_out(&e) => {
                let now = Instant::now();
                if now >= end {
                    break Ok(None);
                }
                std::thread::sleep((end - now).min(Duration::from_micros(200)));
            }
            Err(e) => break Err(e),
        }
    };
    s.set_nonblocking(false)?;
    r
}

/// Where the controller is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// A serial device (`/dev/ttyUSB0`, `/dev/pts/3`, `COM3`) at this baud rate.
    Serial {
        /// Device path or name.
        path: String,
        /// Bits per second.
        baud: u32,
    },
    /// `HOST:PORT`.
    Tcp(String),
}

impl std::fmt::Display for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Target::Serial { path, baud } => write!(f, "serial port {path} at {baud} baud"),
            Target::Tcp(addr) => write!(f, "tcp {addr}"),
        }
    }
}

enum Inner {
    Serial(Box<dyn serialport::SerialPort>),
    Tcp(TcpStream),
}

/// An open line.
pub struct Link {
    inner: Inner,
    t0: Instant,
    line: Line,
    /// Bytes received that the engine of the moment did not take yet (it
    /// held a reply): they go to the next one.
    pending: Vec<u8>,
}

/// A seed for the line's fence texts: different at each start.
fn seed() -> u32 {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    (t ^ (t >> 32) ^ u64::from(std::process::id()).rotate_left(16)) as u32
}

/// Baud rates the controllers offer (TTA p. 7).
pub const BAUD_RATES: &[u32] = &[9600, 19200, 38400, 57600, 115_200];

impl Link {
    /// Opens `target`, a line with the settings `cfg`. The error names what
    /// the user gave and what was expected.
    pub fn open(target: &Target, cfg: LineConfig) -> Result<Link, String> {
        let inner = match target {
            Target::Serial { path, baud } => {
                if !BAUD_RATES.contains(baud) {
                    return Err(format!(
                        "--baud {baud}: the controllers use 9600, 19200, 38400, 57600 or 115200"
                    ));
                }
                // 8 data bits, no parity, 1 stop bit: the controllers'
                // parameters Nos. 93-95 must match.
                let port = serialport::new(path, *baud)
                    .data_bits(serialport::DataBits::Eight)
                    .parity(serialport::Parity::None)
                    .stop_bits(serialport::StopBits::One)
                    .flow_control(serialport::FlowControl::None)
                    .timeout(Duration::from_millis(10))
                    .open()
                    .map_err(|e| {
                        format!(
                            "--port {path:?}: cannot open it as a serial port ({e}); give a device such as /dev/ttyUSB0 or COM3"
                        )
                    })?;
                Inner::Serial(port)
            }
            Target::Tcp(addr) => {
                let s = TcpStream::connect(addr.as_str()).map_err(|e| {
                    format!("--tcp {addr:?}: cannot connect ({e}); give HOST:PORT of a listening controller or adapter")
                })?;
                s.set_nodelay(true)
                    .map_err(|e| format!("--tcp {addr:?}: {e}"))?;
                Inner::Tcp(s)
            }
        };
        Ok(Link {
            inner,
            t0: Instant::now(),
            line: Line::new(cfg, seed()),
            pending: Vec::new(),
        })
    }

    /// The core's memory of this line.
    pub fn line(&self) -> &Line {
        &self.line
    }

    /// The core's memory of this line, to start a command on it.
    pub fn line_mut(&mut self) -> &mut Line {
        &mut self.line
    }

    /// One turn of `engine` on this line: the bytes held back from the
    /// last turn first, then what is due (a transmission, or a wait of at
    /// most `cap` reading what arrives). `Some` with the engine's result
    /// once it has one.
    pub fn turn<G: Engine>(
        &mut self,
        engine: &mut G,
        cap: Duration,
    ) -> io::Result<Option<Result<G::Output, Failure>>> {
        self.feed_pending(engine);
        let now = self.now();
        match engine.poll(&mut self.line, now) {
            Step::Transmit(bytes) => {
                write_all(&mut self.inner, bytes)?;
                let end = self.now();
                engine.sent(&mut self.line, end);
            }
            Step::WaitUntil(until) => {
                let left = Duration::from_millis(u64::from(until.saturating_sub(now)));
                let mut buf = [0u8; 4096];
                let n = self.read_for(&mut buf, left.min(cap))?;
                self.pending.extend_from_slice(buf.get(..n).unwrap_or(&[]));
                self.feed_pending(engine);
            }
            Step::Idle => std::thread::sleep(Duration::from_millis(1)),
            Step::Done(r) => return Ok(Some(r)),
        }
        Ok(None)
    }

    fn feed_pending<G: Engine>(&mut self, engine: &mut G) {
        if !self.pending.is_empty() {
            let now = self.now();
            let used = feed(engine, &mut self.line, &self.pending, now);
            self.pending.drain(..used.min(self.pending.len()));
        }
    }

    /// Milliseconds since the link was opened (the engines' clock).
    pub fn now(&self) -> u32 {
        u32::try_from(self.t0.elapsed().as_millis()).unwrap_or(u32::MAX)
    }

    /// Reads what arrives within `wait` (at least 1 ms); `Ok(0)` when
    /// nothing did. A closed TCP connection is an error.
    pub fn read_for(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<usize> {
        let wait = wait.max(Duration::from_millis(1));
        let r = match &mut self.inner {
            Inner::Serial(p) => {
                p.set_timeout(wait)?;
                p.read(buf)
            }
            Inner::Tcp(s) => match tcp_read_for(s, buf, wait)? {
                None => Ok(0),
                Some(0) => Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the connection was closed by the other side",
                )),
                Some(n) => Ok(n),
            },
        };
        match r {
            // A signal (Ctrl-C) interrupts a read: the caller looks at its stop flag.
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut
                        | io::ErrorKind::WouldBlock
                        | io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            r => r,
        }
    }

    /// Sends all of `bytes`.
    pub fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        write_all(&mut self.inner, bytes)
    }
}

fn write_all(inner: &mut Inner, bytes: &[u8]) -> io::Result<()> {
    match inner {
        Inner::Serial(p) => {
            p.write_all(bytes)?;
            p.flush()
        }
        Inner::Tcp(s) => s.write_all(bytes),
    }
}
