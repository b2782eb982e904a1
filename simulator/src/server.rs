//! The simulator served: one controller on a TCP port of this machine,
//! on a pseudo-terminal (which serial tools open like a port), or on one
//! TCP connection it makes itself to a listening port ([`connect`]: the
//! controller side of the bridge under QEMU, for instance). This is what
//! `iai simulate` runs.
//!
//! One [`Controller`] is shared by every connection: its position table
//! and axes persist, as a real controller's memory does. Each connection
//! has its own [`Session`] (partial frames, pending replies, fault draws)
//! and its own thread, so an idle client blocks nobody.
//!
//! Connection summaries (and, with [`ServeOptions::log_frames`], the
//! frames) go to stdout. Frames are shown as their text by default;
//! [`Shared::with_frame_log`] puts a decoder of one's own in its place
//! (`iai simulate` shows every field).

use std::io::{self, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use iai_protocol_b::hosted::WaitRead;

use crate::{Controller, Faults, Session};

/// How to serve (`iai simulate`'s options other than where to listen).
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// Faults to inject.
    pub faults: Faults,
    /// Seed of the fault draws (connection k uses `seed + k`).
    pub seed: u64,
    /// Print every frame (otherwise only connection summaries).
    pub log_frames: bool,
}

/// Parses `corrupt=P,swap=P,drop=P,late=P:MS,dup=P:MS,error=P`.
pub fn parse_faults(spec: &str) -> Result<Faults, String> {
    let mut f = Faults::default();
    let mut seen = Vec::new();
    for part in spec.split(',').filter(|p| !p.is_empty()) {
        let (key, val) = part
            .split_once('=')
            .ok_or_else(|| format!("--faults {part:?}: expected NAME=P (or NAME=P:MS)"))?;
        if seen.contains(&key) {
            return Err(format!("--faults: {key} is given twice"));
        }
        seen.push(key);
        let prob = |s: &str| -> Result<f64, String> {
            let ok = !s.is_empty()
                && s.bytes().all(|b| b.is_ascii_digit() || b == b'.')
                && s.bytes().filter(|b| *b == b'.').count() <= 1;
            match s.parse::<f64>() {
                Ok(p) if ok && (0.0..=1.0).contains(&p) => Ok(p),
                _ => Err(format!(
                    "--faults {key}={val}: {s:?} is not a probability (0 to 1, such as 0.01)"
                )),
            }
        };
        let timed = || -> Result<Option<(f64, u32)>, String> {
            let (p, ms) = val.split_once(':').ok_or_else(|| {
                format!("--faults {key}={val}: expected {key}=P:MS (chance, then delay in ms)")
            })?;
            let ms = ms
                .parse::<u32>()
                .ok()
                .filter(|_| ms.bytes().all(|b| b.is_ascii_digit()))
                .ok_or_else(|| {
                    format!("--faults {key}={val}: {ms:?} is not a delay in ms (0 to 4294967295)")
                })?;
            Ok(Some((prob(p)?, ms)))
        };
        match key {
            "corrupt" => {
                let p = prob(val)?;
                f.flip_bit_in = p;
                f.flip_bit_out = p;
            }
            "swap" => f.swap_record = prob(val)?,
            "drop" => f.drop_reply = prob(val)?,
            "error" => f.error_reply = prob(val)?,
            "late" => f.late_reply = timed()?,
            "dup" => f.dup_reply = timed()?,
            other => {
                return Err(format!(
                    "--faults: unknown fault {other:?} (corrupt, swap, drop, late, dup, error)"
                ))
            }
        }
    }
    Ok(f)
}

/// A byte stream to serve: reads wait at most a given time.
pub trait Conn {
    /// Reads what arrives within `wait`; `Ok(None)` on timeout,
    /// `Ok(Some(0))` when the peer is gone.
    fn read_for(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<Option<usize>>;
    /// Sends all of `bytes`.
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
}

impl Conn for TcpStream {
    fn read_for(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<Option<usize>> {
        match self.read_within(buf, wait) {
            Ok(0) => Ok(None),
            Ok(n) => Ok(Some(n)),
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => Ok(Some(0)),
            Err(e) => Err(e),
        }
    }
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.write_all(bytes)
    }
}

/// Which way frames went on a served connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// From the host to the simulator (`<` in the log).
    Received,
    /// From the simulator to the host (`>` in the log).
    Sent,
}

/// Describes the frames of one direction of one connection for the log
/// ([`ServeOptions::log_frames`]).
pub trait FrameLog: Send {
    /// Takes the bytes that went by and returns one entry (its lines) per
    /// frame they completed; a partial frame waits for the next bytes.
    fn entries(&mut self, bytes: &[u8]) -> Vec<Vec<String>>;
}

/// Makes the [`FrameLog`] of each direction of each connection.
pub type FrameLogMaker = Arc<dyn Fn(Direction) -> Box<dyn FrameLog> + Send + Sync>;

/// The default [`FrameLog`]: each frame (up to its CR LF) as one line of
/// text, control and non-ASCII bytes escaped (`\r`, `\n`, `\xNN`); a frame
/// longer than 160 bytes is cut there (`…`).
#[derive(Debug, Default)]
pub struct TextFrames {
    partial: Vec<u8>,
    cut: bool,
}

/// The longest frame [`TextFrames`] shows whole; longer ones are cut.
const SHOWN_FRAME: usize = 160;

impl FrameLog for TextFrames {
    fn entries(&mut self, bytes: &[u8]) -> Vec<Vec<String>> {
        let mut out = Vec::new();
        for &b in bytes {
            if self.partial.len() < SHOWN_FRAME {
                self.partial.push(b);
            } else {
                self.cut = true;
            }
            if b == b'\n' {
                let mut line = escape(&std::mem::take(&mut self.partial));
                if std::mem::take(&mut self.cut) {
                    line.push('…');
                }
                out.push(vec![line]);
            }
        }
        out
    }
}

/// `bytes` as text: printable ASCII as is, `\r`, `\n`, `\t`, `\\` and
/// `\xNN` for the rest.
fn escape(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len());
    for &b in bytes {
        match b {
            b'\r' => s.push_str("\\r"),
            b'\n' => s.push_str("\\n"),
            b'\t' => s.push_str("\\t"),
            b'\\' => s.push_str("\\\\"),
            0x20..=0x7E => s.push(char::from(b)),
            _ => s.push_str(&format!("\\x{b:02X}")),
        }
    }
    s
}

/// Log lines go to stdout, one connection's entry at a time; a closed
/// stdout is ignored (the simulator keeps serving).
fn log_lines(lines: &[String]) {
    let mut out = io::stdout().lock();
    for l in lines {
        let _ = writeln!(out, "{l}");
    }
    let _ = out.flush();
}

/// Appends `entries` to `out`, each line after `arrow`.
fn entry_lines(arrow: &str, entries: Vec<Vec<String>>, out: &mut Vec<String>) {
    for entry in entries {
        for (i, line) in entry.into_iter().enumerate() {
            // Position-stream fields would flood the log: the header line
            // and a few field lines per frame are enough.
            if i > 6 {
                out.push(format!("  {arrow}     …"));
                break;
            }
            out.push(format!("  {arrow} {line}"));
        }
    }
}

/// The shared controller, the clock all connections use and how their
/// frames are logged.
#[derive(Clone)]
pub struct Shared {
    /// The controller.
    pub ctl: Arc<Mutex<Controller>>,
    t0: Instant,
    frame_log: Option<FrameLogMaker>,
}

impl Shared {
    /// Shares `ctl`; time starts now.
    pub fn new(ctl: Controller) -> Self {
        Shared {
            ctl: Arc::new(Mutex::new(ctl)),
            t0: Instant::now(),
            frame_log: None,
        }
    }

    /// Logs frames ([`ServeOptions::log_frames`]) with what `make` gives
    /// for each direction of each connection instead of [`TextFrames`].
    pub fn with_frame_log(mut self, make: FrameLogMaker) -> Self {
        self.frame_log = Some(make);
        self
    }

    fn frame_log(&self, dir: Direction) -> Box<dyn FrameLog> {
        match &self.frame_log {
            Some(make) => make(dir),
            None => Box::new(TextFrames::default()),
        }
    }

    /// Milliseconds since the simulator started.
    pub fn now(&self) -> u32 {
        u32::try_from(self.t0.elapsed().as_millis()).unwrap_or(u32::MAX)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Controller> {
        self.ctl.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Serves one connection until the peer goes; returns its summary line.
pub fn serve(
    shared: &Shared,
    conn: &mut dyn Conn,
    name: &str,
    opts: &ServeOptions,
    seed: u64,
) -> String {
    let mut session = Session::new(seed);
    let mut rx = shared.frame_log(Direction::Received);
    let mut tx = shared.frame_log(Direction::Sent);
    let mut buf = [0u8; 4096];
    let end = loop {
        let now = shared.now();
        // Sleep until the next reply is due, at most 50 ms.
        let wait = session
            .next_output_at()
            .map_or(50, |t| t.saturating_sub(now).min(50));
        match conn.read_for(&mut buf, Duration::from_millis(u64::from(wait))) {
            Ok(Some(0)) => break "closed".to_string(),
            Ok(Some(n)) => {
                let bytes = buf.get(..n).unwrap_or(&[]);
                {
                    let mut ctl = shared.lock();
                    session.receive(&mut ctl, &opts.faults, bytes, shared.now());
                }
                if opts.log_frames {
                    let mut lines = Vec::new();
                    entry_lines("<", rx.entries(bytes), &mut lines);
                    log_lines(&lines);
                }
            }
            Ok(None) => {}
            Err(e) => break format!("failed: {e}"),
        }
        let out = session.take_output(shared.now());
        if !out.is_empty() {
            if let Err(e) = conn.send(&out) {
                break format!("failed: {e}");
            }
            if opts.log_frames {
                let mut lines = Vec::new();
                entry_lines(">", tx.entries(&out), &mut lines);
                log_lines(&lines);
            }
        }
    };
    let s = session.stats();
    let held = shared.lock().table.len();
    let faults = s.dropped_replies
        + s.late_replies
        + s.duplicated_replies
        + s.injected_errors
        + s.swapped_records;
    format!(
        "connection {name} {end}: {} command(s), {} reply(ies), {} broken frame(s), {} position record(s) written, table holds {held}; {faults} fault(s) injected ({} dropped, {} late, {} duplicated, {} error replies, {} swapped records)",
        s.commands, s.replies, s.broken_frames, s.records_written,
        s.dropped_replies, s.late_replies, s.duplicated_replies, s.injected_errors, s.swapped_records
    )
}

/// Serves TCP connections on `listener` forever, each on its own thread.
pub fn serve_tcp(listener: TcpListener, shared: Shared, opts: ServeOptions) -> io::Result<()> {
    for (k, conn) in listener.incoming().enumerate() {
        let mut conn = match conn {
            Ok(c) => c,
            Err(e) => {
                log_lines(&[format!("accept failed: {e}")]);
                continue;
            }
        };
        let _ = conn.set_nodelay(true);
        let name = conn
            .peer_addr()
            .map_or_else(|_| format!("#{k}"), |a| a.to_string());
        log_lines(&[format!("connection {name} opened")]);
        let (shared, opts) = (shared.clone(), opts.clone());
        std::thread::spawn(move || {
            let seed = opts.seed.wrapping_add(k as u64);
            let line = serve(&shared, &mut conn, &name, &opts, seed);
            log_lines(&[line]);
        });
    }
    Ok(())
}

/// How long [`connect`] keeps trying by default: long enough for QEMU to
/// boot and open its port.
pub const CONNECT_PATIENCE: Duration = Duration::from_secs(10);

/// Connects to the listening `addr` (`HOST:PORT`), trying again every
/// 100 ms for up to `patience` while nothing listens there yet (a port
/// that is still starting up). An address that does not resolve fails at
/// once.
pub fn connect(addr: &str, patience: Duration) -> Result<TcpStream, String> {
    let targets: Vec<SocketAddr> = addr
        .to_socket_addrs()
        .map_err(|e| format!("--connect {addr:?}: not an address ({e}); give HOST:PORT"))?
        .collect();
    let deadline = Instant::now() + patience;
    let mut last = format!("{addr:?} resolves to no address");
    loop {
        for target in &targets {
            let left = deadline.saturating_duration_since(Instant::now());
            match TcpStream::connect_timeout(target, left.max(Duration::from_millis(100))) {
                Ok(conn) => {
                    let _ = conn.set_nodelay(true);
                    return Ok(conn);
                }
                Err(e) => last = format!("{target}: {e}"),
            }
        }
        let now = Instant::now();
        if now >= deadline || targets.is_empty() {
            return Err(format!(
                "--connect {addr}: nothing accepted a connection within {:.1} s (last attempt: {last})",
                patience.as_secs_f64()
            ));
        }
        std::thread::sleep((deadline - now).min(Duration::from_millis(100)));
    }
}

/// Serves the one connection [`connect`] made until the peer closes it,
/// logging like [`serve_tcp`]; returns when it is gone.
pub fn serve_connected(mut conn: TcpStream, shared: &Shared, opts: &ServeOptions) {
    let name = conn
        .peer_addr()
        .map_or_else(|_| "#0".to_string(), |a| a.to_string());
    log_lines(&[format!("connection {name} opened")]);
    let line = serve(shared, &mut conn, &name, opts, opts.seed);
    log_lines(&[line]);
}

/// A pseudo-terminal: the simulator holds the master side, serial tools
/// open the slave path (`/dev/pts/N`).
#[cfg(unix)]
pub mod pty {
    use super::*;
    use std::io::Read;
    use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};

    /// The master side of a pseudo-terminal.
    pub struct Pty {
        master: std::fs::File,
        /// The slave's path.
        pub path: String,
    }

    fn last_error(what: &str) -> io::Error {
        let e = io::Error::last_os_error();
        io::Error::new(e.kind(), format!("{what}: {e}"))
    }

    impl Pty {
        /// Opens a new pseudo-terminal in raw mode (no echo, no CR/LF
        /// translation).
        pub fn open() -> io::Result<Pty> {
            // SAFETY: plain libc calls on a descriptor this function owns;
            // ptsname is read before any other call could overwrite its
            // static buffer (only this thread opens terminals).
            unsafe {
                let fd = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY);
                if fd < 0 {
                    return Err(last_error("posix_openpt"));
                }
                let owned = OwnedFd::from_raw_fd(fd);
                if libc::grantpt(fd) != 0 || libc::unlockpt(fd) != 0 {
                    return Err(last_error("grantpt/unlockpt"));
                }
                let name = libc::ptsname(fd);
                if name.is_null() {
                    return Err(last_error("ptsname"));
                }
                let path = std::ffi::CStr::from_ptr(name)
                    .to_string_lossy()
                    .into_owned();
                let mut t: libc::termios = std::mem::zeroed();
                if libc::tcgetattr(fd, &mut t) == 0 {
                    libc::cfmakeraw(&mut t);
                    libc::tcsetattr(fd, libc::TCSANOW, &t);
                }
                Ok(Pty {
                    master: std::fs::File::from(owned),
                    path,
                })
            }
        }
    }

    impl Conn for Pty {
        fn read_for(&mut self, buf: &mut [u8], wait: Duration) -> io::Result<Option<usize>> {
            let mut p = libc::pollfd {
                fd: self.master.as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            };
            let ms = i32::try_from(wait.as_millis()).unwrap_or(i32::MAX).max(1);
            // SAFETY: one valid pollfd for the duration of the call.
            let r = unsafe { libc::poll(&mut p, 1, ms) };
            if r < 0 {
                let e = io::Error::last_os_error();
                return if e.kind() == io::ErrorKind::Interrupted {
                    Ok(None)
                } else {
                    Err(e)
                };
            }
            if r == 0 {
                return Ok(None);
            }
            if p.revents & libc::POLLHUP != 0 && p.revents & libc::POLLIN == 0 {
                return Ok(Some(0));
            }
            match self.master.read(buf) {
                Ok(n) => Ok(Some(n)),
                // EIO: no process has the slave open.
                Err(e) if e.raw_os_error() == Some(libc::EIO) => Ok(Some(0)),
                Err(e) => Err(e),
            }
        }
        fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
            self.master.write_all(bytes)
        }
    }

    /// Serves the pseudo-terminal forever: one session from each opening
    /// of the slave to its last close.
    pub fn serve_pty(mut pty: Pty, shared: Shared, opts: ServeOptions) -> io::Result<()> {
        let mut k = 0u64;
        loop {
            // Wait for a client: while nobody has the slave open, the
            // master reports a hang-up.
            let mut p = libc::pollfd {
                fd: pty.master.as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one valid pollfd for the duration of the call.
            unsafe { libc::poll(&mut p, 1, 50) };
            if p.revents & libc::POLLHUP != 0 {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
            let name = format!("{} #{k}", pty.path);
            log_lines(&[format!("connection {name} opened")]);
            let line = serve(&shared, &mut pty, &name, &opts, opts.seed.wrapping_add(k));
            log_lines(&[line]);
            k += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn text_frames_show_each_frame_once_complete_escaped_and_cut() {
        let mut log = TextFrames::default();
        assert!(log.entries(b"!99212").is_empty(), "half a frame waits");
        assert_eq!(
            log.entries(b"01\x7F89\r\n#99"),
            vec![vec!["!9921201\\x7F89\\r\\n".to_string()]]
        );
        let long = [b"#99".as_slice(), &[b'0'; 300], b"\r\n"].concat();
        let entries = log.entries(&long);
        assert_eq!(entries.len(), 1);
        let line = &entries[0][0];
        // The "#99" of the previous call, then the new frame's first bytes.
        assert!(line.starts_with("#99#99000"), "{line}");
        assert!(line.ends_with('…'), "{line}");
        assert_eq!(line.chars().count(), SHOWN_FRAME + 1);
        // The next frame is whole again.
        assert_eq!(
            log.entries(b"&99E1\r\n"),
            vec![vec!["&99E1\\r\\n".to_string()]]
        );
    }

    #[test]
    fn the_log_prefixes_entries_and_cuts_long_ones() {
        let mut out = Vec::new();
        let entry: Vec<String> = (0..10).map(|i| format!("line {i}")).collect();
        entry_lines("<", vec![vec!["one".into()], entry], &mut out);
        assert_eq!(out.first().map(String::as_str), Some("  < one"));
        assert_eq!(out.len(), 1 + 7 + 1);
        assert_eq!(out.get(7).map(String::as_str), Some("  < line 6"));
        assert_eq!(out.last().map(String::as_str), Some("  <     …"));
    }

    #[test]
    fn a_tcp_connection_reads_nothing_data_then_closed() {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let mut c = TcpStream::connect(l.local_addr().unwrap()).unwrap();
        let (mut s, _) = l.accept().unwrap();
        let mut buf = [0u8; 16];
        // Short waits poll, long ones use a socket timeout: both report
        // nothing as `None`.
        for ms in [2, 30] {
            assert_eq!(
                Conn::read_for(&mut s, &mut buf, Duration::from_millis(ms)).unwrap(),
                None
            );
        }
        c.write_all(b"!99").unwrap();
        let mut got = Vec::new();
        while got.len() < 3 {
            if let Some(n) = Conn::read_for(&mut s, &mut buf, Duration::from_millis(5)).unwrap() {
                assert!(n > 0);
                got.extend_from_slice(&buf[..n]);
            }
        }
        assert_eq!(got, b"!99");
        drop(c);
        let end = Instant::now() + Duration::from_secs(5);
        let closed = loop {
            match Conn::read_for(&mut s, &mut buf, Duration::from_millis(5)).unwrap() {
                Some(0) => break true,
                _ if Instant::now() > end => break false,
                _ => {}
            }
        };
        assert!(closed, "the closed connection was not seen");
    }
}
