//! Host side of the bridge firmware under QEMU: the simulator served on the
//! downstream socket in a thread (real time), 26DH commands encoded whole,
//! and a client that sends a command upstream and reads the one reply.
//!
//! Used by `tests/qemu_bridge.rs` and the `demo` binary.

use std::collections::BTreeMap;
use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::stream::{PositionStream, PositionStreamEncoder};

use crate::sim::{serve_tcp, Simulator};

/// The bridge's `&` codes (see `firmware-example/src/bridge.rs`).
pub mod codes {
    /// The upstream 26DH was malformed (checksum, format).
    pub const UPSTREAM_FRAME: u16 = 0xB01;
    /// The controller did not confirm a chunk (3 timeouts).
    pub const CONTROLLER_TIMEOUT: u16 = 0xB02;
    /// The controller kept answering a chunk with `&`.
    pub const CONTROLLER_ERROR: u16 = 0xB03;
    /// The upstream 26DH stopped in its middle.
    pub const UPSTREAM_STALLED: u16 = 0xB04;
    /// The transfer could not be set up.
    pub const INTERNAL: u16 = 0xB05;
}

/// A simulator running on a socket in its own thread, in real time.
pub struct SimThread {
    handle: JoinHandle<(Simulator, io::Result<()>)>,
    records: Arc<AtomicU64>,
}

impl SimThread {
    /// Serve `sim` on `stream` (normally a clone of the session's
    /// downstream socket) until the peer closes it (QEMU exits).
    pub fn spawn(sim: Simulator, stream: TcpStream) -> Self {
        Self::spawn_with(sim, stream, false)
    }

    /// Like [`SimThread::spawn`]; with `live`, keep [`SimThread::records`]
    /// up to date (serving in small steps instead of `serve_tcp`).
    pub fn spawn_with(mut sim: Simulator, stream: TcpStream, live: bool) -> Self {
        let records = Arc::new(AtomicU64::new(0));
        let shared = Arc::clone(&records);
        let handle = thread::spawn(move || {
            let result = if live {
                serve_live(&mut sim, stream, &shared)
            } else {
                serve_tcp(&mut sim, stream)
            };
            (sim, result)
        });
        SimThread { handle, records }
    }

    /// Records the simulator has written so far (live mode only).
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

/// `serve_tcp` with a live count of the records written.
fn serve_live(sim: &mut Simulator, mut stream: TcpStream, records: &AtomicU64) -> io::Result<()> {
    let t0 = Instant::now();
    let now = || t0.elapsed().as_millis() as u32;
    stream.set_read_timeout(Some(Duration::from_millis(1)))?;
    stream.set_nodelay(true)?;
    let mut buf = [0u8; 4096];
    loop {
        match stream.read(&mut buf) {
            Ok(0) => return Ok(()),
            Ok(n) => {
                sim.receive(&buf[..n], now());
                records.store(sim.stats().records_written, Ordering::Relaxed);
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(e) => return Err(e),
        }
        let out = sim.take_output(now());
        if !out.is_empty() {
            stream.write_all(&out)?;
        }
    }
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

/// Write `bytes` upstream in chunks, calling `progress` with the bytes
/// written so far. Blocks while the bridge holds the line back (flow
/// control); the socket's write timeout bounds each wait.
pub fn send(up: &mut TcpStream, bytes: &[u8], mut progress: impl FnMut(usize)) -> io::Result<()> {
    let mut done = 0;
    for chunk in bytes.chunks(4096) {
        up.write_all(chunk).map_err(|e| {
            io::Error::new(
                e.kind(),
                format!("writing upstream at byte {done} of {}: {e}", bytes.len()),
            )
        })?;
        done += chunk.len();
        progress(done);
    }
    up.flush()
}

/// Read from the upstream until one valid frame arrives (`Some`) or
/// `timeout` passes (`None`). Noise and broken frames are skipped.
pub fn read_frame(up: &mut TcpStream, timeout: Duration) -> io::Result<Option<Vec<u8>>> {
    let deadline = Instant::now() + timeout;
    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Reject);
    let saved = up.read_timeout()?;
    let mut buf = [0u8; 256];
    let result = loop {
        let now = Instant::now();
        if now >= deadline {
            break Ok(None);
        }
        up.set_read_timeout(Some((deadline - now).min(Duration::from_millis(100))))?;
        match up.read(&mut buf) {
            Ok(0) => {
                break Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "upstream closed",
                ))
            }
            Ok(n) => {
                let mut input = &buf[..n];
                let mut found = None;
                while !input.is_empty() {
                    let d = dec.decode(input);
                    input = &input[d.consumed..];
                    if let Event::Frame(f) = d.event {
                        found = Some(f.as_bytes().to_vec());
                        break;
                    }
                }
                if let Some(f) = found {
                    break Ok(Some(f));
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) => {}
            Err(e) => break Err(e),
        }
    };
    up.set_read_timeout(saved)?;
    result
}

/// Send `command` upstream and wait up to `timeout` (after the last byte)
/// for the bridge's reply.
pub fn exchange(
    up: &mut TcpStream,
    command: &[u8],
    timeout: Duration,
    progress: impl FnMut(usize),
) -> io::Result<Option<Vec<u8>>> {
    send(up, command, progress)?;
    read_frame(up, timeout)
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
