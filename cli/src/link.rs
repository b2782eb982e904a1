//! The line to a controller: a serial port or a TCP connection (a
//! serial-to-Ethernet adapter, or `iai simulate --tcp`) run by the core's
//! [`StdLink`]: its millisecond clock, its [`Line`] (what one command of
//! this process left in flight on it, the next one knows) and its turns
//! ([`Link::turn`]) that move bytes and time between one of the core's
//! engines and the line. What is the tool's own is the stream under it,
//! a [`Port`]: the serial port opened with the user's settings, XON/XOFF
//! over TCP, and the witness of what came back.
//!
//! Flow control: on a serial port the driver does it (`--flow xonxoff`:
//! IXON/IXOFF; `rtscts`: the modem lines). Over TCP (a serial server
//! that passes XON/XOFF through) `xonxoff` is done here: a received XOFF
//! stops the writing until XON, and both are taken out of the received
//! bytes. A [`Witness`] decodes every received byte again and counts what
//! came back, for [`Link::hint`].

mod witness;

pub use witness::Witness;

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use firmware_example::config::BAUD_RATES;
use firmware_example::serial::{XOFF, XON};
use iai_protocol_b::engine::Engine;
use iai_protocol_b::hosted::{StdLink, WaitRead};
use iai_protocol_b::{error::Failure, line::Line, line::LineConfig};

/// How long a write waits for XON after an XOFF before it fails.
const XOFF_PATIENCE: Duration = Duration::from_secs(10);

/// Bytes written between looks at the input for an XOFF.
const FLOW_CHUNK: usize = 64;

/// Flow control of a link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Flow {
    /// None: the other side must keep up.
    #[default]
    None,
    /// XON/XOFF (software).
    XonXoff,
    /// RTS/CTS (hardware; serial ports only).
    RtsCts,
}

/// Parity of a serial port.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Parity {
    /// None (8N1, the usual setting).
    #[default]
    None,
    /// Odd.
    Odd,
    /// Even.
    Even,
}

/// A serial port's framing and flow control (the controller's I/O
/// parameters Nos. 93-95 must match: 7 or 8 data bits, 1 or 2 stop bits,
/// none, odd or even parity; TTA p. 7, 2003 p. 6).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialSettings {
    /// 7 or 8.
    pub data_bits: u8,
    /// Parity.
    pub parity: Parity,
    /// 1 or 2.
    pub stop_bits: u8,
    /// Flow control.
    pub flow: Flow,
}

impl SerialSettings {
    /// 8 data bits, no parity, 1 stop bit (8N1), no flow control: what
    /// `iai` uses where nothing else is given.
    pub const DEFAULT: SerialSettings = SerialSettings {
        data_bits: 8,
        parity: Parity::None,
        stop_bits: 1,
        flow: Flow::None,
    };
}

impl Default for SerialSettings {
    fn default() -> Self {
        SerialSettings::DEFAULT
    }
}

/// Reads from a TCP stream what arrives within `wait`: `None` when nothing
/// did, `Some(0)` when the peer closed. The core's [`WaitRead`] for a TCP
/// stream, which keeps short waits by polling (a socket read timeout
/// overshoots a few milliseconds by several); a signal (Ctrl-C)
/// interrupting the read counts as nothing read.
pub fn tcp_read_for(
    s: &mut TcpStream,
    buf: &mut [u8],
    wait: Duration,
) -> io::Result<Option<usize>> {
    match s.read_within(buf, wait) {
        Ok(0) => Ok(None),
        Ok(n) => Ok(Some(n)),
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => Ok(Some(0)),
        Err(e) => Err(e),
    }
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
        /// Framing and flow control.
        settings: SerialSettings,
    },
    /// `HOST:PORT`, with XON/XOFF done here or not.
    Tcp {
        /// `HOST:PORT`.
        addr: String,
        /// [`Flow::XonXoff`] or [`Flow::None`].
        flow: Flow,
    },
}

impl std::fmt::Display for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Target::Serial { path, baud, .. } => write!(f, "serial port {path} at {baud} baud"),
            Target::Tcp { addr, .. } => write!(f, "tcp {addr}"),
        }
    }
}

enum Inner {
    Serial(Box<dyn serialport::SerialPort>),
    Tcp(TcpStream),
}

/// The stream of a [`Link`]: a serial port or a TCP connection, with
/// XON/XOFF done here over TCP and a [`Witness`] of every byte that went
/// by. Its reads wait a bounded time ([`WaitRead`]), so the core's
/// [`StdLink`] runs the engines over it.
pub struct Port {
    inner: Inner,
    /// XON/XOFF done here (TCP).
    soft_flow: bool,
    /// An XOFF came and no XON yet.
    stopped: bool,
    /// Data that came in while a write looked for XOFF or waited for XON:
    /// the next read returns it first.
    held: Vec<u8>,
    witness: Witness,
}

impl Port {
    /// Sends all of `bytes`, honouring XON/XOFF done here; `progress` is
    /// told the bytes written so far. Bytes that arrive meanwhile are held
    /// for the next read.
    fn send(&mut self, bytes: &[u8], progress: &mut dyn FnMut(usize)) -> io::Result<()> {
        self.witness.sent(bytes);
        send(
            &mut self.inner,
            self.soft_flow,
            &mut self.stopped,
            &mut self.held,
            &mut self.witness,
            bytes,
            progress,
        )
    }
}

impl WaitRead for Port {
    /// What was held from a write first; otherwise what arrives within
    /// `wait` (at least 1 ms), XON/XOFF done here taken out (and obeyed).
    fn read_within(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<usize> {
        if !self.held.is_empty() {
            let n = self.held.len().min(buf.len());
            if let (Some(dst), Some(src)) = (buf.get_mut(..n), self.held.get(..n)) {
                dst.copy_from_slice(src);
            }
            self.held.drain(..n);
            return Ok(n);
        }
        let n = raw_read(&mut self.inner, buf, wait)?;
        let got = buf.get_mut(..n).unwrap_or(&mut []);
        let n = if self.soft_flow {
            strip_flow(got, &mut self.stopped)
        } else {
            n
        };
        self.witness.received(buf.get(..n).unwrap_or(&[]));
        Ok(n)
    }
}

impl Read for Port {
    /// Waits until something arrives (a closed TCP connection is an
    /// error, not the end of the stream).
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        loop {
            let n = self.read_within(buf, Duration::from_secs(1))?;
            if n > 0 || buf.is_empty() {
                return Ok(n);
            }
        }
    }
}

impl Write for Port {
    /// Writes all of `bytes` (see [`Link::write_all`]).
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        self.send(bytes, &mut |_| {})?;
        Ok(bytes.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        match &mut self.inner {
            Inner::Serial(p) => p.flush(),
            Inner::Tcp(s) => s.flush(),
        }
    }
}

/// An open line.
pub struct Link {
    link: StdLink<Port>,
    target: Target,
}

/// The baud rates the controllers offer ([`BAUD_RATES`]), listed: `9600,
/// 19200, ... 115200` with `last` before the last.
pub fn baud_rates_text(last: &str) -> String {
    let rates: Vec<String> = BAUD_RATES.iter().map(u32::to_string).collect();
    match rates.split_last() {
        Some((tail, [])) => tail.clone(),
        Some((tail, head)) => format!("{}{last}{tail}", head.join(", ")),
        None => String::new(),
    }
}

impl Link {
    /// Opens `target`, a line with the settings `cfg`. The error names what
    /// the user gave and what was expected.
    pub fn open(target: &Target, cfg: LineConfig) -> Result<Link, String> {
        let mut soft_flow = false;
        let inner = match target {
            Target::Serial {
                path,
                baud,
                settings,
            } => {
                if !BAUD_RATES.contains(baud) {
                    return Err(format!(
                        "--baud {baud}: the controllers use {}",
                        baud_rates_text(" or ")
                    ));
                }
                let port = serialport::new(path, *baud)
                    .data_bits(if settings.data_bits == 7 {
                        serialport::DataBits::Seven
                    } else {
                        serialport::DataBits::Eight
                    })
                    .parity(match settings.parity {
                        Parity::None => serialport::Parity::None,
                        Parity::Odd => serialport::Parity::Odd,
                        Parity::Even => serialport::Parity::Even,
                    })
                    .stop_bits(if settings.stop_bits == 2 {
                        serialport::StopBits::Two
                    } else {
                        serialport::StopBits::One
                    })
                    .flow_control(match settings.flow {
                        Flow::None => serialport::FlowControl::None,
                        Flow::XonXoff => serialport::FlowControl::Software,
                        Flow::RtsCts => serialport::FlowControl::Hardware,
                    })
                    .timeout(Duration::from_millis(10))
                    .open()
                    .map_err(|e| {
                        format!(
                            "--port {path:?}: cannot open it as a serial port ({e}); give a device such as /dev/ttyUSB0 or COM3 (`iai ports` lists them)"
                        )
                    })?;
                Inner::Serial(port)
            }
            Target::Tcp { addr, flow } => {
                let s = TcpStream::connect(addr.as_str()).map_err(|e| {
                    format!("--tcp {addr:?}: cannot connect ({e}); give HOST:PORT of a listening controller or adapter")
                })?;
                s.set_nodelay(true)
                    .map_err(|e| format!("--tcp {addr:?}: {e}"))?;
                soft_flow = *flow == Flow::XonXoff;
                Inner::Tcp(s)
            }
        };
        let port = Port {
            inner,
            soft_flow,
            stopped: false,
            held: Vec::new(),
            witness: Witness::new(cfg.station.0),
        };
        Ok(Link {
            link: StdLink::new(port, cfg),
            target: target.clone(),
        })
    }

    /// Where this line goes.
    pub fn target(&self) -> &Target {
        &self.target
    }

    /// What came back on this line so far.
    pub fn witness(&self) -> &Witness {
        &self.link.stream_ref().witness
    }

    /// The likely cause of a line that gave no valid reply, from what came
    /// back (see [`Witness::hint`]).
    pub fn hint(&self) -> Option<String> {
        self.witness().hint()
    }

    /// The core's memory of this line.
    pub fn line(&self) -> &Line {
        self.link.line()
    }

    /// What the user should know when the line showed that it repeats
    /// frames (it heard frames it could not place): every reply taken was
    /// proved or asked again, but the line is slow until its duplicate
    /// window is declared.
    pub fn repeats_note(&self) -> Option<String> {
        let line = self.line();
        line.repeats().then(|| {
            format!(
                "this line repeats frames: {} frame(s) could not be placed (copies of earlier replies, or replies out of order); every reply counted was proved by a fence or asked again, expecting copies up to {} ms after a reply; declare it with --duplicate-window-ms {} to work faster",
                line.stats().unplaced,
                line.copy_window(),
                line.copy_window()
            )
        })
    }

    /// Runs `f` with a line of its own to `cfg.station` over this link (a
    /// bridge's own station), then puts this link's line back (see
    /// `hosted::StdLink::replace_line`).
    pub fn with_line<T>(&mut self, cfg: LineConfig, f: impl FnOnce(&mut Link) -> T) -> T {
        let own = self.link.replace_line(cfg);
        let r = f(self);
        self.link.put_back_line(own);
        r
    }

    /// The core's memory of this line, to start a command on it.
    pub fn line_mut(&mut self) -> &mut Line {
        self.link.line_mut()
    }

    /// One turn of `engine` on this line ([`StdLink::turn`]): the bytes
    /// held back from the last turn first, then what is due (a
    /// transmission, or a wait of at most `cap` reading what arrives).
    /// `Some` with the engine's result once it has one.
    pub fn turn<G: Engine>(
        &mut self,
        engine: &mut G,
        cap: Duration,
    ) -> io::Result<Option<Result<G::Output, Failure>>> {
        self.link.turn(engine, cap)
    }

    /// Milliseconds since the link was opened (the engines' clock).
    pub fn now(&self) -> u32 {
        self.link.now()
    }

    /// Reads what arrives within `wait` (at least 1 ms); `Ok(0)` when
    /// nothing did. A closed TCP connection is an error. XON/XOFF done
    /// here are taken out (and obeyed). Bytes an engine left are not
    /// read again: [`Link::take_pending`] has them.
    pub fn read_for(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<usize> {
        self.link.stream().read_within(buf, wait)
    }

    /// Sends all of `bytes`, honouring XON/XOFF done here. Bytes that
    /// arrive meanwhile are kept for the next engine (or
    /// [`Link::take_pending`]).
    pub fn write_all(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.write_with(bytes, &mut |_| {})
    }

    /// [`Link::write_all`] with progress: `progress` is told the bytes
    /// written so far.
    pub fn write_with(&mut self, bytes: &[u8], progress: &mut dyn FnMut(usize)) -> io::Result<()> {
        self.link.stream().send(bytes, progress)
    }

    /// The bytes received and not given to an engine yet: what the last
    /// engine left, then what came in during a write.
    pub fn take_pending(&mut self) -> Vec<u8> {
        let mut got = self.link.take_pending();
        got.append(&mut self.link.stream().held);
        got
    }
}

/// Reads what arrives within `wait` (at least 1 ms): `Ok(0)` when nothing
/// did; a closed TCP connection is an error.
fn raw_read(inner: &mut Inner, buf: &mut [u8], wait: Duration) -> io::Result<usize> {
    let wait = wait.max(Duration::from_millis(1));
    let r = match inner {
        Inner::Serial(p) => {
            p.set_timeout(wait)?;
            p.read(buf)
        }
        Inner::Tcp(s) => s.read_within(buf, wait),
    };
    match r {
        // A signal (Ctrl-C) interrupts a read: the caller looks at its stop flag.
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
            ) =>
        {
            Ok(0)
        }
        r => r,
    }
}

/// Takes XON and XOFF out of `bytes` (in place), noting the last one in
/// `stopped`; returns the length left.
fn strip_flow(bytes: &mut [u8], stopped: &mut bool) -> usize {
    let mut n = 0;
    for i in 0..bytes.len() {
        let b = bytes.get(i).copied().unwrap_or(0);
        match b {
            XOFF => *stopped = true,
            XON => *stopped = false,
            _ => {
                if let Some(slot) = bytes.get_mut(n) {
                    *slot = b;
                }
                n += 1;
            }
        }
    }
    n
}

/// Writes `bytes`; with `soft_flow`, in chunks, looking at the input for
/// XOFF between them and waiting for XON (received data goes to
/// `held`).
fn send(
    inner: &mut Inner,
    soft_flow: bool,
    stopped: &mut bool,
    held: &mut Vec<u8>,
    witness: &mut Witness,
    bytes: &[u8],
    progress: &mut dyn FnMut(usize),
) -> io::Result<()> {
    if !soft_flow {
        write_all(inner, bytes)?;
        progress(bytes.len());
        return Ok(());
    }
    let mut done = 0;
    let mut buf = [0u8; 4096];
    for chunk in bytes.chunks(FLOW_CHUNK) {
        let mut since = Instant::now();
        loop {
            let wait = if *stopped {
                Duration::from_millis(50)
            } else {
                Duration::from_millis(1)
            };
            let n = raw_read(inner, &mut buf, wait)?;
            if n > 0 {
                let got = buf.get_mut(..n).unwrap_or(&mut []);
                let was = *stopped;
                let k = strip_flow(got, stopped);
                let data = buf.get(..k).unwrap_or(&[]);
                witness.received(data);
                held.extend_from_slice(data);
                if was && !*stopped {
                    since = Instant::now();
                }
            }
            if !*stopped {
                break;
            }
            if since.elapsed() > XOFF_PATIENCE {
                return Err(io::Error::other(format!(
                    "the other side sent XOFF and no XON for {} s",
                    XOFF_PATIENCE.as_secs()
                )));
            }
        }
        write_all(inner, chunk)?;
        done += chunk.len();
        progress(done);
    }
    Ok(())
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use iai_protocol_b::frame::Station;
    use std::net::TcpListener;

    /// Over TCP with `--flow xonxoff`, an XOFF stops the writing until XON
    /// (a chunk may be under way), and neither reaches the received data.
    #[test]
    fn an_xoff_over_tcp_stops_the_writing_until_xon() {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap().to_string();
        let peer = std::thread::spawn(move || {
            let (mut c, _) = l.accept().unwrap();
            c.write_all(&[XOFF]).unwrap();
            std::thread::sleep(Duration::from_millis(400));
            c.set_nonblocking(true).unwrap();
            let mut buf = vec![0u8; 65536];
            let during = c.read(&mut buf).unwrap_or(0);
            c.set_nonblocking(false).unwrap();
            c.write_all(&[XON, b'#', XOFF, XON]).unwrap();
            let mut all = buf[..during].to_vec();
            while all.len() < 10_000 {
                let n = c.read(&mut buf).unwrap();
                assert!(n > 0);
                all.extend_from_slice(&buf[..n]);
            }
            (during, all)
        });
        let target = Target::Tcp {
            addr,
            flow: Flow::XonXoff,
        };
        let mut link = Link::open(&target, LineConfig::new(Station(0x99))).unwrap();
        // The XOFF is there before the first chunk goes.
        std::thread::sleep(Duration::from_millis(100));
        let data: Vec<u8> = (0..10_000u32).map(|i| b'0' + (i % 10) as u8).collect();
        let t0 = Instant::now();
        link.write_all(&data).unwrap();
        assert!(
            t0.elapsed() >= Duration::from_millis(250),
            "{:?}",
            t0.elapsed()
        );
        let (during, all) = peer.join().unwrap();
        assert!(
            during <= FLOW_CHUNK,
            "{during} bytes went out during the XOFF"
        );
        assert_eq!(all, data);
        // The data byte between the flow-control bytes is kept, alone.
        let mut got = link.take_pending();
        let mut buf = [0u8; 16];
        let end = Instant::now() + Duration::from_millis(300);
        while got.is_empty() && Instant::now() < end {
            let n = link.read_for(&mut buf, Duration::from_millis(50)).unwrap();
            got.extend_from_slice(&buf[..n]);
        }
        assert_eq!(got, b"#");
    }
}
