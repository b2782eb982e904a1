//! Host side of the bridge firmware under QEMU: the simulator served on the
//! downstream socket in a thread (real time), 26DH commands encoded whole,
//! and [`HostLink`], the host's serial port on the upstream socket: it
//! paces its writes to a line rate and honours XON/XOFF, as a PC's UART
//! driver does, since QEMU models neither.
//!
//! The virtual-time host model of the same bridge library is in [`model`].
//!
//! Used by `tests/qemu_*.rs` and the `demo` binary.

pub mod model;

use std::collections::{BTreeMap, VecDeque};
use std::io::{self, Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::PositionStreamEncoder;

use iai_simulator::Simulator;

/// The bridge's `&` codes and IDs, from the bridge library itself.
pub use firmware_example::codes;
use firmware_example::serial::{XOFF, XON};

/// A simulator running on a socket in its own thread, in real time.
pub struct SimThread {
    handle: JoinHandle<(Simulator, io::Result<()>)>,
    records: Arc<AtomicU64>,
    silent: Arc<AtomicBool>,
}

impl SimThread {
    /// Serve `sim` on `stream` (normally a clone of the session's
    /// downstream socket) until the peer closes it (QEMU exits), its
    /// replies paced to `baud` (see [`serve_paced`]).
    pub fn spawn(mut sim: Simulator, stream: UnixStream, baud: Option<u32>) -> Self {
        let records = Arc::new(AtomicU64::new(0));
        let shared = Arc::clone(&records);
        let silent = Arc::new(AtomicBool::new(false));
        let mute = Arc::clone(&silent);
        let handle = thread::spawn(move || {
            let result = serve_paced(&mut sim, stream, &shared, &mute, baud);
            (sim, result)
        });
        SimThread {
            handle,
            records,
            silent,
        }
    }

    /// Makes the controller stop answering (`true`: what reaches it is
    /// dropped unread, as by a controller switched off) or answer again.
    pub fn set_silent(&self, silent: bool) {
        self.silent.store(silent, Ordering::Relaxed);
    }

    /// Records the simulator has written so far.
    pub fn records(&self) -> u64 {
        self.records.load(Ordering::Relaxed)
    }

    /// Wait for the thread (after QEMU exited) and get the simulator back.
    pub fn join(self) -> io::Result<Simulator> {
        match self.handle.join() {
            Ok((sim, Ok(()))) => Ok(sim),
            Ok((_, Err(e))) => Err(io::Error::new(e.kind(), format!("simulator: {e}"))),
            Err(_) => Err(io::Error::other("simulator thread panicked")),
        }
    }
}

/// Serves `sim` on `stream` with its replies paced to `baud` (10 bits a
/// byte), as a controller's UART sends them, and a live count of the
/// records written. QEMU models no baud rate: unpaced, a 2 KB read-back
/// reply would reach the bridge's 128-byte receive ring as fast as its
/// interrupt can take bytes, a burst no controller sends, and overrun it.
/// Like [`HostLink`], the next bytes go only once QEMU has read the
/// previous ones, and the line restarts after QEMU stood still.
fn serve_paced(
    sim: &mut Simulator,
    mut stream: UnixStream,
    records: &AtomicU64,
    silent: &AtomicBool,
    baud: Option<u32>,
) -> io::Result<()> {
    let t0 = Instant::now();
    let now = || t0.elapsed().as_millis() as u32;
    let byte_time = baud.map(|b| Duration::from_secs_f64(10.0 / f64::from(b.max(1))));
    // Non-blocking, with short sleeps: a read timeout is rounded up to the
    // kernel's tick (4 ms), too coarse to pace 11.5 bytes a millisecond.
    stream.set_nonblocking(true)?;
    let mut buf = [0u8; 4096];
    let mut out: VecDeque<u8> = VecDeque::new();
    // When the line (re)started and how many bytes it has sent since.
    let mut base = Instant::now();
    let mut since_base = 0u32;
    loop {
        match stream.read(&mut buf) {
            Ok(0) => return Ok(()),
            Ok(_) if silent.load(Ordering::Relaxed) => {
                out.clear();
                continue;
            }
            Ok(n) => {
                sim.receive(&buf[..n], now());
                records.store(sim.stats().records_written, Ordering::Relaxed);
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                thread::sleep(Duration::from_micros(100));
            }
            Err(e) => return Err(e),
        }
        if silent.load(Ordering::Relaxed) {
            // Switched off: nothing it had to say goes out.
            out.clear();
            drop(sim.take_output(now()));
            continue;
        }
        if out.is_empty() {
            out.extend(sim.take_output(now()));
            // An idle line starts afresh.
            base = Instant::now();
            since_base = 0;
        } else {
            out.extend(sim.take_output(now()));
        }
        if out.is_empty() || unread(&stream, SIOCOUTQ)? > 0 {
            continue;
        }
        let n = match byte_time {
            None => out.len(),
            Some(bt) => {
                let due = (base.elapsed().as_secs_f64() / bt.as_secs_f64()) as u32;
                due.saturating_sub(since_base).min(HOST_CHUNK as u32) as usize
            }
        };
        if n == 0 {
            continue;
        }
        let chunk: Vec<u8> = out.drain(..n.min(out.len())).collect();
        match write_all_nonblocking(&mut stream, &chunk) {
            Ok(()) => {}
            // QEMU went while a reply was going out: the line's end, as
            // a read of 0 bytes is.
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::BrokenPipe | io::ErrorKind::ConnectionReset
                ) =>
            {
                return Ok(())
            }
            Err(e) => return Err(e),
        }
        since_base += chunk.len() as u32;
    }
}

/// Writes all of `bytes` to a non-blocking socket, waiting while it is full.
fn write_all_nonblocking(stream: &mut UnixStream, mut bytes: &[u8]) -> io::Result<()> {
    while !bytes.is_empty() {
        match stream.write(bytes) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => bytes = bytes.get(n..).unwrap_or(&[]),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                thread::sleep(Duration::from_micros(100));
            }
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Bytes written to the Unix socket `fd` that its peer (QEMU) has not
/// read yet.
pub(crate) fn unsent(fd: &impl AsRawFd) -> io::Result<i32> {
    unread(fd, SIOCOUTQ)
}

/// `ioctl` count `request` of the socket `fd` (see [`SIOCOUTQ`],
/// [`FIONREAD`]).
fn unread(fd: &impl AsRawFd, request: u64) -> io::Result<i32> {
    let mut count: i32 = 0;
    // SAFETY: both requests write one int through the pointer; the fd is an
    // open socket.
    let rc = unsafe { ioctl(fd.as_raw_fd(), request, &mut count) };
    if rc != 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(count)
}

/// One whole 26DH command (header through LF) carrying `records`.
pub fn command_26dh(station: Station, records: &[PositionRecord]) -> Vec<u8> {
    let count = u16::try_from(records.len()).expect("at most 20,000 records");
    let mut enc = PositionStreamEncoder::new(
        PositionStream::CHANGE_2,
        station,
        0,
        count,
        records.iter().cloned(),
    )
    .expect("26DH envelope");
    let mut out = Vec::with_capacity(PositionStream::CHANGE_2.overhead() + 82 * records.len());
    let mut chunk = [0u8; 4096];
    loop {
        let n = enc.read(&mut chunk).expect("valid records");
        if n == 0 {
            return out;
        }
        out.extend_from_slice(&chunk[..n]);
    }
}

/// The `#` reply the bridge sends for a 26DH of `count` records.
pub fn reply_26dh(station: Station, count: u16) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = iai_protocol_b::frame::emit_frame(
        &mut buf,
        iai_protocol_b::frame::Header::Response,
        station,
        0x26D,
        Default::default(),
        |w| PositionStream::CHANGE_2.write_prefix(w, 0, count),
    )
    .expect("fits");
    buf[..n].to_vec()
}

/// The `&` reply with `code`.
pub fn error_reply(station: Station, code: u16) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = iai_protocol_b::frame::emit_frame(
        &mut buf,
        iai_protocol_b::frame::Header::Error,
        station,
        code,
        Default::default(),
        |_| Ok(()),
    )
    .expect("fits");
    buf[..n].to_vec()
}

/// Bytes the host writes at once: small, so that an XOFF stops it within a
/// few bytes.
const HOST_CHUNK: usize = 8;

/// `ioctl` request: bytes written to a socket that its peer has not read
/// yet (for a Unix stream socket: the memory they take, 0 once all are
/// read).
const SIOCOUTQ: u64 = 0x5411;
/// `ioctl` request: bytes received on a socket and not read yet.
const FIONREAD: u64 = 0x541B;

extern "C" {
    fn ioctl(fd: i32, request: u64, ...) -> i32;
}

/// What the host's receive thread shares with the writer.
#[derive(Default)]
struct LinkRx {
    data: VecDeque<u8>,
    /// XOFF received and no XON since.
    stopped: bool,
    xoffs: u32,
    closed: bool,
}

/// Counters of a [`HostLink`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LinkStats {
    /// Bytes written upstream.
    pub bytes_sent: u64,
    /// XOFF bytes received (times the bridge stopped the host).
    pub xoffs: u32,
    /// Time spent stopped by XOFF.
    pub paused: Duration,
    /// Time spent writing (pacing and pauses included).
    pub sending: Duration,
}

/// The host's serial port on the upstream socket.
///
/// Writes are paced to `baud` (10 bits a byte, 8N1) when a rate is given;
/// with `xon_xoff`, received XOFF/XON bytes stop and restart the writer and
/// never reach the reader (a UART driver with IXON on). Methods take
/// `&self`: one thread may send while another reads.
///
/// A wire holds no bytes: what a host sends reaches the UART one byte time
/// later. QEMU is not real time: when the machine is busy it may not run
/// for milliseconds, and would then take in at once all a paced writer
/// sent meanwhile, a burst no UART sees. So the link writes its next few
/// bytes only once QEMU has read the previous ones (the socket's unread
/// count, `SIOCOUTQ`): while QEMU stands still, so does the line.
pub struct HostLink {
    writer: UnixStream,
    rx: Arc<(Mutex<LinkRx>, Condvar)>,
    baud: Option<u32>,
    xon_xoff: bool,
    stats: Mutex<LinkStats>,
}

impl HostLink {
    /// A link on `stream` (the session's upstream socket).
    pub fn new(stream: &UnixStream, baud: Option<u32>, xon_xoff: bool) -> io::Result<Self> {
        let writer = stream.try_clone()?;
        let mut reader = stream.try_clone()?;
        reader.set_read_timeout(None)?;
        let rx: Arc<(Mutex<LinkRx>, Condvar)> = Arc::default();
        let shared = Arc::clone(&rx);
        thread::spawn(move || {
            let mut buf = [0u8; 512];
            loop {
                let n = reader.read(&mut buf).unwrap_or(0);
                let (state, changed) = &*shared;
                let mut st = state.lock().unwrap_or_else(PoisonError::into_inner);
                if n == 0 {
                    st.closed = true;
                    changed.notify_all();
                    return;
                }
                for &b in &buf[..n] {
                    match b {
                        XOFF if xon_xoff => {
                            st.stopped = true;
                            st.xoffs += 1;
                        }
                        XON if xon_xoff => st.stopped = false,
                        _ => st.data.push_back(b),
                    }
                }
                changed.notify_all();
            }
        });
        Ok(HostLink {
            writer,
            rx,
            baud,
            xon_xoff,
            stats: Mutex::new(LinkStats::default()),
        })
    }

    /// Counters so far.
    pub fn stats(&self) -> LinkStats {
        let mut s = *self.stats.lock().unwrap_or_else(PoisonError::into_inner);
        let (state, _) = &*self.rx;
        s.xoffs = state.lock().unwrap_or_else(PoisonError::into_inner).xoffs;
        s
    }

    /// Whether XON/XOFF is honoured.
    pub fn xon_xoff(&self) -> bool {
        self.xon_xoff
    }

    /// Wait while stopped by XOFF (at most `limit`); returns the time
    /// waited.
    fn wait_until_allowed(&self, limit: Duration) -> io::Result<Duration> {
        let start = Instant::now();
        let (state, changed) = &*self.rx;
        let mut st = state.lock().unwrap_or_else(PoisonError::into_inner);
        if !st.stopped {
            return Ok(Duration::ZERO);
        }
        while st.stopped && !st.closed {
            let left = limit.saturating_sub(start.elapsed());
            if left.is_zero() {
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!("stopped by XOFF for more than {limit:?}"),
                ));
            }
            st = changed
                .wait_timeout(st, left)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
        Ok(start.elapsed())
    }

    /// Wait (at most `limit`) until `request` (an `ioctl` count on the
    /// socket) reads 0; returns the time waited.
    fn wait_for_zero(&self, request: u64, what: &str, limit: Duration) -> io::Result<Duration> {
        let start = Instant::now();
        loop {
            if unread(&self.writer, request)? == 0 {
                return Ok(start.elapsed());
            }
            if start.elapsed() >= limit {
                return Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!("{what} for {limit:?}"),
                ));
            }
            thread::sleep(Duration::from_micros(50));
        }
    }

    /// Write `bytes` upstream at the link's rate, honouring XOFF; calls
    /// `progress` with the bytes written so far.
    pub fn send(&self, bytes: &[u8], mut progress: impl FnMut(usize)) -> io::Result<()> {
        let start = Instant::now();
        let byte_time = self
            .baud
            .map(|b| Duration::from_secs_f64(10.0 / f64::from(b.max(1))));
        // The pacing schedule restarts after every pause (a UART does not
        // catch up on lost time).
        let mut base = Instant::now();
        let mut since_base = 0u32;
        let mut paused = Duration::ZERO;
        let mut done = 0;
        let limit = Duration::from_secs(60);
        for chunk in bytes.chunks(HOST_CHUNK) {
            // QEMU has taken what was written before (see the type's docs).
            let stood = self.wait_for_zero(SIOCOUTQ, "QEMU read nothing", limit)?;
            if stood > Duration::from_millis(1) {
                // QEMU stood still: the line restarts from now.
                base = Instant::now();
                since_base = 0;
            }
            if let Some(bt) = byte_time {
                let due = base + bt * since_base;
                let now = Instant::now();
                if due > now {
                    thread::sleep(due - now);
                }
            }
            // What the bridge sent is read before the next bytes go (it may
            // be an XOFF: a UART driver sees it before it queues more).
            self.wait_for_zero(FIONREAD, "the reader took nothing", limit)?;
            if self.xon_xoff {
                let waited = self.wait_until_allowed(limit)?;
                if !waited.is_zero() {
                    paused += waited;
                    base = Instant::now();
                    since_base = 0;
                }
            }
            (&self.writer).write_all(chunk).map_err(|e| {
                io::Error::new(
                    e.kind(),
                    format!("writing upstream at byte {done} of {}: {e}", bytes.len()),
                )
            })?;
            done += chunk.len();
            since_base += chunk.len() as u32;
            progress(done);
        }
        (&self.writer).flush()?;
        let mut s = self.stats.lock().unwrap_or_else(PoisonError::into_inner);
        s.bytes_sent += bytes.len() as u64;
        s.paused += paused;
        s.sending += start.elapsed();
        Ok(())
    }

    /// Read until one valid frame arrives (`Some`) or `timeout` passes
    /// (`None`). Noise and broken frames are skipped.
    pub fn read_frame(&self, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        let deadline = Instant::now() + timeout;
        let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Reject);
        let (state, changed) = &*self.rx;
        let mut st = state.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            while let Some(b) = st.data.pop_front() {
                if let Status::Complete(Event::Frame(f)) = dec.push(b) {
                    return Ok(Some(f.as_bytes().to_vec()));
                }
            }
            if st.closed {
                return Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "upstream closed",
                ));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            st = changed
                .wait_timeout(st, deadline - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Waits up to `timeout` for received bytes and takes all there are
    /// (without XON/XOFF when they are honoured); empty when none came.
    /// `UnexpectedEof` once the upstream closed and all was taken.
    pub fn read_some(&self, timeout: Duration) -> io::Result<Vec<u8>> {
        let deadline = Instant::now() + timeout;
        let (state, changed) = &*self.rx;
        let mut st = state.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            if !st.data.is_empty() {
                return Ok(st.data.drain(..).collect());
            }
            if st.closed {
                return Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "upstream closed",
                ));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(Vec::new());
            }
            st = changed
                .wait_timeout(st, deadline - now)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }

    /// Drops the bytes received and not taken yet.
    pub fn discard_received(&self) {
        let (state, _) = &*self.rx;
        state
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .data
            .clear();
    }

    /// Send `command` and wait up to `timeout` (after the last byte) for
    /// the bridge's reply.
    pub fn exchange(&self, command: &[u8], timeout: Duration) -> io::Result<Option<Vec<u8>>> {
        self.send(command, |_| {})?;
        self.read_frame(timeout)
    }

    /// Write raw bytes now, unpaced (the quit sequence).
    pub fn write_raw(&self, bytes: &[u8]) -> io::Result<()> {
        (&self.writer).write_all(bytes)?;
        (&self.writer).flush()
    }
}

/// The bridge's status query: `!`, the bridge's station, `B00`, SC, CR LF.
pub fn status_query_frame(bridge_station: Station) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = iai_protocol_b::frame::emit_frame(
        &mut buf,
        iai_protocol_b::frame::Header::Command,
        bridge_station,
        codes::STATUS_QUERY,
        Default::default(),
        |_| Ok(()),
    )
    .expect("fits");
    buf[..n].to_vec()
}

/// Asks the bridge at `bridge_station` for its status and waits up to
/// `timeout` for the reply, skipping the frames that come before it (the
/// bridge answers in order: what it still owed comes first); returns the
/// named fields.
pub fn status_query(
    link: &HostLink,
    bridge_station: Station,
    timeout: Duration,
) -> Result<Vec<(&'static str, u64)>, String> {
    link.send(&status_query_frame(bridge_station), |_| {})
        .map_err(|e| format!("status query: {e}"))?;
    let deadline = Instant::now() + timeout;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let reply = link
            .read_frame(left)
            .map_err(|e| format!("status query: {e}"))?
            .ok_or_else(|| format!("no reply to the status query within {timeout:?}"))?;
        let Ok(frame) = Frame::new_checked(&reply, Default::default()) else {
            continue;
        };
        if frame.header() != Header::Response
            || frame.station() != bridge_station
            || frame.code() != codes::STATUS_QUERY
        {
            continue;
        }
        return firmware_example::status::parse(frame.body())
            .map(|f| f.to_vec())
            .ok_or_else(|| format!("bad status reply {:?}", String::from_utf8_lossy(&reply)));
    }
}

/// Compare the simulator's table with the source records: `Ok` when every
/// record is there, equal, and nothing else is.
pub fn check_table(
    table: &BTreeMap<u16, PositionRecord>,
    source: &[PositionRecord],
) -> Result<(), String> {
    let mut expected = BTreeMap::new();
    for r in source {
        expected.insert(r.number, r.clone());
    }
    if table.len() != expected.len() {
        return Err(format!(
            "simulator holds {} records, the source has {}",
            table.len(),
            expected.len()
        ));
    }
    for (n, want) in &expected {
        match table.get(n) {
            Some(got) if got == want => {}
            Some(got) => return Err(format!("record {n} differs: {got:?} != {want:?}")),
            None => return Err(format!("record {n} missing")),
        }
    }
    Ok(())
}

/// A host's 26DH rate through the bridge against the limit the downstream
/// line sets: every record crosses it twice (its chunk, then the 21FH
/// read-back), and every command costs the controller's processing time
/// and the line's turnaround. The limit is the host's rate if the
/// downstream line never stood idle.
#[derive(Debug, Clone, Copy)]
pub struct Throughput {
    /// Line rate, baud (8N1), both sides.
    pub baud: u32,
    /// Bytes of the host's message.
    pub host_bytes: u64,
    /// From the host's first byte to the bridge's reply, seconds.
    pub seconds: f64,
    /// Bytes that take line time on the downstream line (both directions
    /// in the host model; under QEMU only the simulator's paced replies).
    pub downstream_bytes: u64,
    /// Commands the controller answered.
    pub commands: u32,
    /// Controller time per command plus the line's turnaround, ms.
    pub per_command_ms: u32,
}

impl Throughput {
    fn line_rate(&self) -> f64 {
        f64::from(self.baud) / 10.0
    }
    /// The host's rate, percent of the line rate.
    pub fn percent(&self) -> f64 {
        self.host_bytes as f64 / self.seconds / self.line_rate() * 100.0
    }
    /// The downstream line's limit for it, percent of the line rate.
    pub fn limit_percent(&self) -> f64 {
        let busy = self.downstream_bytes as f64 / self.line_rate()
            + f64::from(self.commands) * f64::from(self.per_command_ms) / 1_000.0;
        self.host_bytes as f64 / busy / self.line_rate() * 100.0
    }
    /// `throughput BAUD FLOW N% of line rate, limit M%`.
    pub fn line(&self, flow: &str) -> String {
        format!(
            "throughput {} {flow} {:.0}% of line rate, limit {:.0}%",
            self.baud,
            self.percent(),
            self.limit_percent()
        )
    }
}
