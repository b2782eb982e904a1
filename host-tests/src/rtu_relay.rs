//! The gateway's Modbus RTU port: a TCP port of 127.0.0.1 relayed to the
//! third UART of the board under QEMU (the gateway's Modbus port), paced
//! as an RTU line would carry it. A Modbus client speaks RTU frames over
//! the TCP connection (pymodbus's `framer=FramerType.RTU`, or a serial
//! program through a pty bridged to the port).
//!
//! QEMU models no baud rate: a UART is fed as fast as the firmware drains
//! its FIFO. The firmware finds RTU frames by silence (3.5 characters,
//! 1.75 ms above 19,200 baud), so the relay keeps the framing of what the
//! client sent:
//!
//! - **A frame is a request.** A request whose function gives its length
//!   (1 to 6, 15, 16) is one frame however TCP or a pty bridged to it
//!   delivers it (in pieces, or with the next request behind it); other
//!   bytes the client sends with gaps shorter than the silence are one
//!   frame. Each is written to QEMU in one piece, so that no gap opens
//!   inside it.
//! - **Silence between frames.** The next frame goes only once QEMU has
//!   taken the previous one (the Unix socket's `SIOCOUTQ` is 0), the
//!   previous frame's time on the wire at the line rate has passed, and
//!   then the silence (3.5 characters), so two frames never run together.
//! - **Replies** go back to the client as they come; what the firmware
//!   sends while no client is connected is dropped.
//!
//! One client at a time, as on a serial line: a connection made while a
//! client is connected waits, unanswered, until that client leaves (a
//! client that disconnects and reconnects at once is served whatever the
//! order in which the relay sees the two). The relay ends when asked
//! (`stop`) or when QEMU's side closes.

use std::io::{self, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use crate::bridge::unsent;

/// How often the loops look at their stop flag.
const POLL: Duration = Duration::from_millis(20);
/// Longest burst forwarded as one frame (an RTU frame is at most 256
/// bytes; more is forwarded as it is, and the firmware drops it).
const MAX_BURST: usize = 512;
/// How long a client may take to accept a reply.
const CLIENT_WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// Bits per character on the line: start, 8 data, parity, stop.
const CHAR_BITS: u64 = 11;

/// The silence that ends an RTU frame at `baud` (3.5 characters; 1.75 ms
/// above 19,200 baud).
pub fn silence(baud: u32) -> Duration {
    if baud > 19_200 || baud == 0 {
        Duration::from_micros(1_750)
    } else {
        Duration::from_micros(CHAR_BITS * 3_500_000 / u64::from(baud))
    }
}

/// Time of `n` characters on the line at `baud`.
fn wire_time(n: usize, baud: u32) -> Duration {
    Duration::from_micros(n as u64 * CHAR_BITS * 1_000_000 / u64::from(baud.max(1)))
}

/// What the relay counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RelayStats {
    /// Clients served.
    pub clients: u64,
    /// Frames (bursts) forwarded to the firmware.
    pub frames: u64,
    /// Bytes forwarded to the firmware.
    pub bytes_in: u64,
    /// Bytes of replies sent to clients.
    pub bytes_out: u64,
}

/// The running relay: two threads, ended by `stop` or QEMU's end.
pub struct RtuRelay {
    up: JoinHandle<RelayStats>,
    down: JoinHandle<()>,
    bytes_out: Arc<AtomicU64>,
}

impl RtuRelay {
    /// Serves `listener`'s clients to `uart` (QEMU's socket of the
    /// board's Modbus UART) at `baud`, until `stop` is set or QEMU closes
    /// its side.
    pub fn spawn(
        listener: TcpListener,
        uart: &UnixStream,
        baud: u32,
        stop: Arc<AtomicBool>,
    ) -> io::Result<RtuRelay> {
        listener.set_nonblocking(true)?;
        let to_uart = uart.try_clone()?;
        let from_uart = uart.try_clone()?;
        from_uart.set_read_timeout(Some(POLL))?;
        let client: Arc<Mutex<Option<TcpStream>>> = Arc::default();
        let bytes_out = Arc::new(AtomicU64::new(0));
        let down = {
            let (client, stop, out) = (
                Arc::clone(&client),
                Arc::clone(&stop),
                Arc::clone(&bytes_out),
            );
            thread::spawn(move || replies(from_uart, &client, &stop, &out))
        };
        let up = thread::spawn(move || serve(&listener, to_uart, &client, baud, &stop));
        Ok(RtuRelay {
            up,
            down,
            bytes_out,
        })
    }

    /// Waits for both threads (after `stop`, or once QEMU is gone).
    pub fn join(self) -> RelayStats {
        let mut stats = self.up.join().unwrap_or_default();
        let _ = self.down.join();
        stats.bytes_out = self.bytes_out.load(Ordering::Relaxed);
        stats
    }
}

fn log(line: &str) {
    let mut err = io::stderr().lock();
    let _ = writeln!(err, "gateway: modbus-rtu: {line}");
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Accepts one client at a time and forwards its frames.
fn serve(
    listener: &TcpListener,
    mut uart: UnixStream,
    client: &Mutex<Option<TcpStream>>,
    baud: u32,
    stop: &AtomicBool,
) -> RelayStats {
    let mut stats = RelayStats::default();
    let mut reader: Option<TcpStream> = None;
    // Bytes of the next frame that came with the previous one.
    let mut pending = Vec::new();
    let mut pacer = Pacer::new(baud);
    while !stop.load(Ordering::Relaxed) {
        // The next client is taken only once the current one has left:
        // until then its connection waits in the listen backlog.
        if reader.is_none() {
            match listener.accept() {
                Ok((conn, peer)) => match admit(&conn) {
                    Ok(r) => {
                        log(&format!("{peer} connected"));
                        stats.clients += 1;
                        *lock(client) = Some(conn);
                        reader = Some(r);
                    }
                    Err(e) => log(&format!("{peer}: {e}")),
                },
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) => log(&format!("accept: {e}")),
            }
        }
        let Some(r) = reader.as_mut() else {
            thread::sleep(POLL);
            continue;
        };
        let (frame, open) = read_frame(r, &mut pending, silence(baud));
        if !frame.is_empty() {
            if let Err(e) = pacer.forward(&mut uart, &frame, stop) {
                log(&format!("the board's Modbus UART took no more: {e}"));
                break;
            }
            stats.frames += 1;
            stats.bytes_in += frame.len() as u64;
        }
        if !open {
            if let Some(conn) = lock(client).take() {
                let _ = conn.shutdown(Shutdown::Both);
            }
            reader = None;
            pending.clear();
            log("client left");
        }
    }
    if let Some(conn) = lock(client).take() {
        let _ = conn.shutdown(Shutdown::Both);
    }
    stats
}

/// The reading end of a new client.
fn admit(conn: &TcpStream) -> io::Result<TcpStream> {
    conn.set_nonblocking(false)?;
    conn.set_nodelay(true)?;
    conn.set_write_timeout(Some(CLIENT_WRITE_TIMEOUT))?;
    conn.try_clone()
}

/// How long the rest of a request whose length is known may take to come:
/// TCP (and a pty bridged to it) may deliver one frame in pieces with gaps
/// longer than the line's silence, which no RTU line would show.
const PIECES_PATIENCE: Duration = Duration::from_millis(100);

/// The length of the RTU request that `frame` starts, from its function
/// code (unit, function, fields, CRC), when the function has a fixed
/// layout and enough of it is there to tell: 8 bytes for functions 1 to 6,
/// 9 plus the byte count for 15 and 16. `None`: not known (yet).
pub fn request_len(frame: &[u8]) -> Option<usize> {
    match frame.get(1)? {
        1..=6 => Some(8),
        15 | 16 => frame.get(6).map(|&count| 9 + usize::from(count)),
        _ => None,
    }
}

/// One frame from the client: waits up to [`POLL`] for its first byte,
/// then takes bytes until the request is complete by its length
/// ([`request_len`]; the rest may take up to [`PIECES_PATIENCE`]) or, when
/// that is not known, until the client is silent for `gap`. Bytes past the
/// end of a request stay in `pending`, the start of the next frame.
/// `(bytes, open)`: `open` is false once the client closed its side (or
/// failed).
fn read_frame(conn: &mut TcpStream, pending: &mut Vec<u8>, gap: Duration) -> (Vec<u8>, bool) {
    let mut frame = std::mem::take(pending);
    let mut buf = [0u8; 512];
    loop {
        let known = request_len(&frame);
        if let Some(n) = known.filter(|&n| frame.len() >= n) {
            *pending = frame.split_off(n);
            return (frame, true);
        }
        let wait = match (frame.is_empty(), known) {
            (true, _) => POLL,
            (false, Some(_)) => PIECES_PATIENCE,
            (false, None)
                if frame.len() < 2 || frame.get(1).is_some_and(|f| *f == 15 || *f == 16) =>
            {
                PIECES_PATIENCE
            }
            (false, None) => gap,
        };
        if conn.set_read_timeout(Some(wait)).is_err() {
            return (frame, false);
        }
        match conn.read(&mut buf) {
            Ok(0) => return (frame, false),
            Ok(n) => {
                frame.extend_from_slice(buf.get(..n).unwrap_or_default());
                if frame.len() >= MAX_BURST {
                    return (frame, true);
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                return (frame, true)
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(_) => return (frame, false),
        }
    }
}

/// Keeps the frames apart on the line.
struct Pacer {
    baud: u32,
    /// Before this, the previous frame is still on the wire.
    free_at: Instant,
}

impl Pacer {
    fn new(baud: u32) -> Self {
        Pacer {
            baud,
            free_at: Instant::now(),
        }
    }

    /// Writes `frame` in one piece once the previous one is taken, its
    /// time on the wire over, and the silence after it kept.
    fn forward(
        &mut self,
        uart: &mut UnixStream,
        frame: &[u8],
        stop: &AtomicBool,
    ) -> io::Result<()> {
        while unsent(uart)? > 0 {
            if stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            thread::sleep(Duration::from_micros(200));
        }
        let quiet = silence(self.baud);
        let after_taken = Instant::now() + quiet;
        let start = after_taken.max(self.free_at + quiet);
        let now = Instant::now();
        if start > now {
            thread::sleep(start - now);
        }
        uart.write_all(frame)?;
        self.free_at = Instant::now() + wire_time(frame.len(), self.baud);
        Ok(())
    }
}

/// Firmware → client: the replies as they come; dropped while no client
/// is connected.
fn replies(
    mut uart: UnixStream,
    client: &Mutex<Option<TcpStream>>,
    stop: &AtomicBool,
    out: &AtomicU64,
) {
    let mut buf = [0u8; 512];
    while !stop.load(Ordering::Relaxed) {
        match uart.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                let bytes = buf.get(..n).unwrap_or_default();
                let mut c = lock(client);
                if let Some(conn) = c.as_mut() {
                    if conn.write_all(bytes).is_ok() {
                        out.fetch_add(n as u64, Ordering::Relaxed);
                    } else if let Some(conn) = c.take() {
                        let _ = conn.shutdown(Shutdown::Both);
                    }
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock
                        | io::ErrorKind::TimedOut
                        | io::ErrorKind::Interrupted
                ) => {}
            Err(_) => break,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_silence_follows_the_baud_rate() {
        assert_eq!(silence(115_200), Duration::from_micros(1_750));
        assert_eq!(silence(9_600), Duration::from_micros(4_010));
        assert_eq!(wire_time(8, 115_200), Duration::from_micros(763));
    }

    #[test]
    fn a_request_is_as_long_as_its_function_says() {
        // 03: read 6 registers from 9000H, unit 1.
        assert_eq!(request_len(&[0x01, 0x03, 0x90, 0x00, 0x00, 0x06]), Some(8));
        // 16: write 2 registers (4 bytes) at 0D00H: 9 + 4.
        assert_eq!(
            request_len(&[0x01, 0x10, 0x0D, 0x00, 0x00, 0x02, 0x04]),
            Some(13)
        );
        // 16 before its byte count, an unknown function, a lone unit byte.
        assert_eq!(request_len(&[0x01, 0x10, 0x0D, 0x00]), None);
        assert_eq!(request_len(&[0x01, 0x2B, 0x0E]), None);
        assert_eq!(request_len(&[0x01]), None);
    }

    #[test]
    fn a_frame_in_pieces_is_one_frame_and_the_next_stays_apart() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let mut client = TcpStream::connect(listener.local_addr().unwrap()).unwrap();
        let (mut conn, _) = listener.accept().unwrap();
        let write = [
            0x01, 0x10, 0x0D, 0x00, 0x00, 0x01, 0x02, 0x10, 0x00, 0xAA, 0xBB,
        ];
        let read = [0x01, 0x03, 0x90, 0x00, 0x00, 0x06, 0xCC, 0xDD];
        // The write in two pieces 20 ms apart (far more than the 1.75 ms
        // silence), then the read right behind it.
        client.write_all(&write[..5]).unwrap();
        thread::sleep(Duration::from_millis(20));
        let mut rest = write[5..].to_vec();
        rest.extend_from_slice(&read);
        client.write_all(&rest).unwrap();
        let mut pending = Vec::new();
        let (first, open) = read_frame(&mut conn, &mut pending, silence(115_200));
        assert!(open);
        assert_eq!(first, write);
        let (second, open) = read_frame(&mut conn, &mut pending, silence(115_200));
        assert!(open);
        assert_eq!(second, read);
        assert!(pending.is_empty());
    }
}
