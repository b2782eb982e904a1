//! RTU framing: a frame is what arrives between two silences of 3.5
//! characters (Modbus over serial line, 2.5.1.1), 1.75 ms fixed above
//! 19,200 baud. A frame is checked before anything reads it: its CRC-16,
//! and its length against its function code. A frame that fails either, or
//! that is longer than 256 bytes, is dropped without an answer, and the
//! next silence starts the next frame: the bus never stalls.

/// Longest RTU frame (address, PDU of up to 253 bytes, CRC).
pub const MAX_FRAME: usize = 256;

/// The silence that ends a frame at `baud`, µs: 3.5 characters of 11 bits
/// (start, 8 data, parity or second stop, stop), and 1,750 µs above
/// 19,200 baud.
pub const fn silence_us(baud: u32) -> u32 {
    if baud > 19_200 || baud == 0 {
        1_750
    } else {
        38_500_000 / baud
    }
}

/// Collects bytes into a frame until the silence after it.
pub struct Framer {
    buf: [u8; MAX_FRAME],
    len: usize,
    /// More bytes came than a frame holds: the frame is dropped.
    overflow: bool,
    /// When the last byte arrived (µs), while a frame is open.
    last_us: Option<u32>,
    silence_us: u32,
}

/// Why a frame was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dropped {
    /// Longer than [`MAX_FRAME`].
    TooLong,
    /// CRC-16 wrong.
    Crc,
    /// Its length does not fit its function code.
    Length,
}

impl Framer {
    /// An empty framer for a line at `baud`.
    pub const fn new(baud: u32) -> Self {
        Framer {
            buf: [0; MAX_FRAME],
            len: 0,
            overflow: false,
            last_us: None,
            silence_us: silence_us(baud),
        }
    }

    /// One byte that arrived at `at_us`.
    pub fn push(&mut self, b: u8, at_us: u32) {
        match self.buf.get_mut(self.len) {
            Some(slot) => {
                *slot = b;
                self.len += 1;
            }
            None => self.overflow = true,
        }
        self.last_us = Some(at_us);
    }

    /// Whether a frame is being received.
    pub fn open(&self) -> bool {
        self.last_us.is_some()
    }

    /// When the open frame ends if nothing more arrives (µs).
    pub fn ends_at(&self) -> Option<u32> {
        self.last_us.map(|t| t.wrapping_add(self.silence_us))
    }

    /// At `now_us`, with nothing left to read: the frame, if the silence
    /// after it has passed (`Ok`), or why it was dropped (`Err`); `None`
    /// while a frame is still open or none is.
    pub fn take(&mut self, now_us: u32) -> Option<Result<&[u8], Dropped>> {
        let last = self.last_us?;
        let quiet = now_us.wrapping_sub(last);
        // A stamp ahead of `now_us` (a clock read before the byte's
        // interrupt) is no silence.
        if quiet < self.silence_us || quiet >= 0x8000_0000 {
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        self.last_us = None;
        if overflow {
            return Some(Err(Dropped::TooLong));
        }
        let frame = self.buf.get(..len).unwrap_or(&[]);
        Some(check(frame).map(|()| frame))
    }
}

/// Checks a whole frame: its length for its function code, then its CRC.
pub fn check(frame: &[u8]) -> Result<(), Dropped> {
    let n = frame.len();
    let fits = match frame.get(1) {
        Some(1..=6) => n == 8,
        Some(15 | 16) => frame.get(6).is_some_and(|&b| n == 9 + usize::from(b)),
        Some(_) => n >= 4,
        None => false,
    };
    if !fits {
        return Err(Dropped::Length);
    }
    // The CRC of a frame with its CRC appended (low byte first) is 0.
    if crc16(frame) != 0 {
        return Err(Dropped::Crc);
    }
    Ok(())
}

/// Modbus CRC-16 (polynomial A001H reflected, initial FFFFH), bit by bit.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc = 0xFFFFu16;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            let lsb = crc & 1;
            crc >>= 1;
            if lsb != 0 {
                crc ^= 0xA001;
            }
        }
    }
    crc
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Unit 1, read holding registers 9000H, 2 registers (PNOW of axis 1).
    const READ_PNOW: [u8; 8] = [0x01, 0x03, 0x90, 0x00, 0x00, 0x02, 0xE9, 0x0B];

    #[test]
    fn a_frame_ends_at_the_silence_after_it() {
        assert_eq!(crc16(&READ_PNOW[..6]), 0x0BE9);
        let mut f = Framer::new(115_200);
        for (i, &b) in READ_PNOW.iter().enumerate() {
            f.push(b, 1_000 + 87 * i as u32);
        }
        let last = 1_000 + 87 * 7;
        assert_eq!(f.take(last + 1_749), None);
        assert_eq!(f.take(last + 1_750), Some(Ok(&READ_PNOW[..])));
        assert_eq!(f.take(last + 5_000), None);
        // 3.5 characters of 11 bits at 9,600 baud.
        assert_eq!(silence_us(9_600), 4_010);
    }

    #[test]
    fn broken_frames_are_dropped_and_the_next_one_is_read() {
        let mut f = Framer::new(19_200);
        let mut bad = READ_PNOW;
        bad[7] ^= 1;
        for b in bad {
            f.push(b, 0);
        }
        assert_eq!(f.take(10_000), Some(Err(Dropped::Crc)));
        for _ in 0..300 {
            f.push(0x55, 20_000);
        }
        assert_eq!(f.take(30_000), Some(Err(Dropped::TooLong)));
        // Function 16 whose byte count disagrees with the frame's length.
        assert_eq!(
            check(&[1, 16, 0, 0, 0, 1, 2, 0, 5, 0, 0, 0]),
            Err(Dropped::Length)
        );
        for b in READ_PNOW {
            f.push(b, 40_000);
        }
        assert_eq!(f.take(50_000), Some(Ok(&READ_PNOW[..])));
    }
}
