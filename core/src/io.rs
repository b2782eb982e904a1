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

use crate::decoder::{Event, FrameDecoder};
use crate::error::Error;
use crate::frame::{Frame, Station};
use crate::message::Message;

/// An I/O error of the driver, or a protocol error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IoError<E> {
    /// The driver failed.
    Io(E),
    /// The bytes were not a valid frame / message.
    Protocol(Error),
    /// The stream ended (read returned 0) before a frame was complete.
    EndOfStream,
}

impl<E> From<Error> for IoError<E> {
    fn from(e: Error) -> Self {
        IoError::Protocol(e)
    }
}

/// Emits `msg` into `scratch` and writes it to `w`; returns the frame length.
pub fn send<'a, W: embedded_io::Write, M: Message<'a>>(
    w: &mut W,
    msg: &M,
    station: Station,
    scratch: &mut [u8],
) -> Result<usize, IoError<W::Error>> {
    let n = msg.emit(station, scratch)?;
    w.write_all(scratch.get(..n).unwrap_or(&[]))
        .map_err(IoError::Io)?;
    w.flush().map_err(IoError::Io)?;
    Ok(n)
}

/// Reads from `r` one byte at a time until `dec` has a complete frame.
/// Broken frames are skipped (and counted in the decoder's stats); a read
/// of 0 bytes ends with [`IoError::EndOfStream`].
///
/// Reading byte by byte keeps bytes after the frame in the driver for the
/// next call.
pub fn receive<'d, R: embedded_io::Read, const N: usize>(
    r: &mut R,
    dec: &'d mut FrameDecoder<N>,
) -> Result<Frame<'d>, IoError<R::Error>> {
    loop {
        let mut b = [0u8; 1];
        if r.read(&mut b).map_err(IoError::Io)? == 0 {
            return Err(IoError::EndOfStream);
        }
        if let Event::Frame(_) = dec.push(b[0]) {
            break;
        }
    }
    dec.last_frame().ok_or(IoError::EndOfStream)
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
        if let Event::Frame(_) = dec.push(b) {
            break;
        }
    }
    dec.last_frame().ok_or(nb::Error::WouldBlock)
}
