//! Test doubles shared by the host tests (`host-tests`) and the fuzz
//! targets (`fuzz/`, a workspace of its own built with nightly): one home
//! for each, so that a change to a trait they implement is made once.
//!
//! - [`VecPort`]: a firmware serial port over byte vectors.
//! - [`reference_decoder`]: the frame decoder without its short cuts, what
//!   the core's decoder is checked against.

use std::convert::Infallible;

pub mod reference_decoder;

use firmware_example::serial::Port;

/// A [`Port`] over byte vectors: reads drain `input`, writes append to
/// `output`. It is always ready to write and never loses a byte, so a test
/// sees exactly what the bridge sent and feeds it exactly what it chooses.
#[derive(Debug, Default)]
pub struct VecPort {
    /// Bytes still to be read, oldest first.
    pub input: Vec<u8>,
    /// Every byte written, in order.
    pub output: Vec<u8>,
}

impl embedded_io::ErrorType for VecPort {
    type Error = Infallible;
}

impl embedded_io::ReadReady for VecPort {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(!self.input.is_empty())
    }
}

impl embedded_io::Read for VecPort {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let n = buf.len().min(self.input.len());
        for (slot, byte) in buf.iter_mut().zip(self.input.drain(..n)) {
            *slot = byte;
        }
        Ok(n)
    }
}

impl embedded_io::WriteReady for VecPort {
    fn write_ready(&mut self) -> Result<bool, Infallible> {
        Ok(true)
    }
}

impl embedded_io::Write for VecPort {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.output.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

impl Port for VecPort {}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_io::{Read, ReadReady, Write};

    #[test]
    fn reads_what_it_was_given_and_keeps_what_was_written() {
        let mut port = VecPort {
            input: b"#99200".to_vec(),
            ..VecPort::default()
        };
        let mut buf = [0u8; 4];
        assert_eq!(port.read(&mut buf), Ok(4));
        assert_eq!(&buf, b"#992");
        assert_eq!(port.read(&mut buf), Ok(2));
        assert_eq!(&buf[..2], b"00");
        assert_eq!(port.read_ready(), Ok(false));
        assert_eq!(port.read(&mut buf), Ok(0));
        assert_eq!(port.write(b"!99"), Ok(3));
        assert_eq!(port.write(b"212"), Ok(3));
        assert_eq!(port.output, b"!99212");
        assert_eq!(port.take_overruns(), 0);
    }
}
