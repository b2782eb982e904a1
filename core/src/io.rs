//! Glue to UART drivers: `embedded-io` (blocking) and `nb` (byte at a time).
//!
//! ```
//! use iai_protocol_b::io::{send, receive};
//! use iai_protocol_b::decoder::FrameDecoder;
//! use iai_protocol_b::message::{Message, SystemStatusQuery};
//! use iai_protocol_b::frame::Station;
//! // Send a command into any embedded_io::Write (here a byte slice)...
//! let mut wire = [0u8; 16];
//! let n = send(&mut &mut wire[..], &SystemStatusQuery {}, Station(0x99), &mut [0u8; 16]).unwrap();
//! assert_eq!(&wire[..n], b"!992152B\r\n");
//! // ...and receive a frame from any embedded_io::Read.
//! let mut dec: FrameDecoder = FrameDecoder::new();
//! let frame = receive(&mut &b"junk#992322C\r\n"[..], &mut dec).unwrap();
//! assert_eq!(frame.code(), 0x232);
//! ```

use crate::decoder::{Event, FrameDecoder, Status};
use crate::error::Failure;
use crate::frame::{Frame, Station};
use crate::message::Message;

/// Emits `msg` into `scratch` and writes it to `w`; returns the frame length.
pub fn send<'a, W: embedded_io::Write, M: Message<'a>>(
    w: &mut W,
    msg: &M,
    station: Station,
    scratch: &mut [u8],
) -> Result<usize, Failure<W::Error>> {
    let n = msg.emit(station, scratch)?;
    w.write_all(scratch.get(..n).unwrap_or(&[]))
        .map_err(Failure::Io)?;
    w.flush().map_err(Failure::Io)?;
    Ok(n)
}

/// Reads from `r` one byte at a time until `dec` has a complete frame.
/// Broken frames are skipped (and counted in the decoder's stats); a read
/// of 0 bytes ends with [`Failure::Closed`].
///
/// Reading byte by byte keeps bytes after the frame in the driver for the
/// next call.
pub fn receive<'d, R: embedded_io::Read, const N: usize>(
    r: &mut R,
    dec: &'d mut FrameDecoder<N>,
) -> Result<Frame<'d>, Failure<R::Error>> {
    loop {
        let mut b = [0u8; 1];
        if r.read(&mut b).map_err(Failure::Io)? == 0 {
            return Err(Failure::Closed);
        }
        if let Status::Complete(Event::Frame(_)) = dec.push(b[0]) {
            break;
        }
    }
    dec.last_frame().ok_or(Failure::Closed)
}

/// Feeds the decoder from an `nb` byte source (e.g. an `embedded-hal-nb`
/// serial `read`) until a frame is complete or the source would block.
///
/// Returns `Err(nb::Error::WouldBlock)` when no more bytes are available
/// yet; call again later. Broken frames are skipped and counted.
pub fn poll_frame<'d, E, const N: usize>(
    mut read_byte: impl FnMut() -> nb::Result<u8, E>,
    dec: &'d mut FrameDecoder<N>,
) -> nb::Result<Frame<'d>, E> {
    loop {
        let b = read_byte()?;
        if let Status::Complete(Event::Frame(_)) = dec.push(b) {
            break;
        }
    }
    dec.last_frame().ok_or(nb::Error::WouldBlock)
}

/// A test double for examples and tests: a UART whose "controller" answers
/// every well-formed command with its default normal response (an axis
/// status query with one status block per axis asked, a 200H with its own
/// text), a 25BH with nothing, and anything else with nothing.
#[derive(Debug, Default)]
pub struct Loopback {
    rx: heapless::Deque<u8, 512>,
    cmd: FrameDecoder<64>,
}

impl embedded_io::ErrorType for Loopback {
    type Error = core::convert::Infallible;
}

impl embedded_io::Read for Loopback {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let mut n = 0;
        for slot in buf.iter_mut() {
            match self.rx.pop_front() {
                Some(b) => {
                    *slot = b;
                    n += 1;
                }
                None => break,
            }
        }
        Ok(n)
    }
}

impl embedded_io::ReadReady for Loopback {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(!self.rx.is_empty())
    }
}

impl embedded_io::Write for Loopback {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        for &b in buf {
            if let Status::Complete(Event::Frame(f)) = self.cmd.push(b) {
                let mut out = [0u8; 256];
                let n = loopback_reply(&f, &mut out);
                for &o in out.get(..n).unwrap_or(&[]) {
                    let _ = self.rx.push_back(o);
                }
            }
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

fn loopback_reply(cmd: &Frame<'_>, out: &mut [u8]) -> usize {
    use crate::message::{
        AxisStatus, AxisStatusQuery, AxisStatusResponse, Command, Response, TestCall,
        TestCallResponse,
    };
    if let Ok(q) = AxisStatusQuery::parse(cmd) {
        let mut r = AxisStatusResponse {
            axis_pattern: q.query_axis_pattern,
            ..Default::default()
        };
        for _ in q.query_axis_pattern.iter() {
            let _ = r.axes.push(AxisStatus::default());
        }
        return r.emit(cmd.station(), out).unwrap_or(0);
    }
    if let Ok(q) = TestCall::parse(cmd) {
        let r = TestCallResponse {
            test_string: q.test_string,
        };
        return r.emit(cmd.station(), out).unwrap_or(0);
    }
    match Response::default_for(cmd.code()) {
        Some(r) if Command::parse(cmd).is_ok() => r.emit(cmd.station(), out).unwrap_or(0),
        _ => 0,
    }
}
