//! Board-independent bridging between the upstream (host) and downstream
//! (controller) serial ports.
//!
//! For now a transparent byte pump: every byte read on one side is written
//! to the other. It only uses `embedded-io` traits, a millisecond clock and
//! a sleep function, so it knows nothing about registers and can be
//! replaced by protocol-aware bridging without touching the board layer.
//!
//! The pump also watches the upstream for the quit sequence [`QUIT`]
//! (ESC 'Q' '!'), accepted only outside a transfer: its ESC must follow at
//! least [`QUIT_GUARD_MS`] of upstream silence. The sequence's bytes are
//! forwarded downstream like any others before the pump stops.

use embedded_io::{Read, ReadReady, Write, WriteReady};

/// Upstream byte sequence that ends the run.
pub const QUIT: [u8; 3] = [0x1B, b'Q', b'!'];

/// Upstream silence required before the quit sequence.
pub const QUIT_GUARD_MS: u32 = 20;

/// Bytes moved per read / write call.
const CHUNK: usize = 64;

/// Why [`run`] stopped with an error.
#[derive(Debug)]
pub enum Error<U, D> {
    /// The upstream port failed.
    Upstream(U),
    /// The downstream port failed.
    Downstream(D),
}

/// Which end of a lane failed.
enum LaneError<R, W> {
    Source(R),
    Sink(W),
}

/// One direction of the pump: bytes read from the source and not yet
/// accepted by the sink.
struct Lane {
    buf: [u8; CHUNK],
    start: usize,
    end: usize,
}

impl Lane {
    const fn new() -> Self {
        Self {
            buf: [0; CHUNK],
            start: 0,
            end: 0,
        }
    }

    fn is_empty(&self) -> bool {
        self.start == self.end
    }

    /// Whether [`Lane::step`] would make progress now (errors count as
    /// progress, so that `step` reports them).
    fn can_progress<R, W>(&self, src: &mut R, dst: &mut W) -> bool
    where
        R: ReadReady,
        W: WriteReady,
    {
        if self.is_empty() {
            src.read_ready().unwrap_or(true)
        } else {
            dst.write_ready().unwrap_or(true)
        }
    }

    /// Move bytes without waiting: read from the source when the lane is
    /// empty, then write to the sink what it accepts.
    fn step<R, W>(
        &mut self,
        src: &mut R,
        dst: &mut W,
    ) -> Result<Step, LaneError<R::Error, W::Error>>
    where
        R: Read + ReadReady,
        W: Write + WriteReady,
    {
        let mut step = Step {
            read: 0,
            moved: false,
        };
        if self.is_empty() && src.read_ready().map_err(LaneError::Source)? {
            let n = src.read(&mut self.buf).map_err(LaneError::Source)?;
            self.start = 0;
            self.end = n;
            step.read = n;
            step.moved = n > 0;
        }
        if !self.is_empty() && dst.write_ready().map_err(LaneError::Sink)? {
            let n = dst
                .write(&self.buf[self.start..self.end])
                .map_err(LaneError::Sink)?;
            self.start += n;
            step.moved |= n > 0;
        }
        Ok(step)
    }

    /// The bytes the last [`Lane::step`] read, given its [`Step::read`].
    fn fresh(&self, read: usize) -> &[u8] {
        &self.buf[..read]
    }
}

/// What one [`Lane::step`] did.
struct Step {
    /// Bytes read from the source (they start the lane's buffer).
    read: usize,
    /// Whether any byte was read or written.
    moved: bool,
}

/// Recognises [`QUIT`] after [`QUIT_GUARD_MS`] of silence.
struct QuitDetector {
    matched: usize,
    last_byte_ms: Option<u32>,
}

impl QuitDetector {
    const fn new() -> Self {
        Self {
            matched: 0,
            last_byte_ms: None,
        }
    }

    /// Feed bytes read at `now_ms`; `true` once the sequence is complete.
    fn feed(&mut self, bytes: &[u8], now_ms: u32) -> bool {
        for &byte in bytes {
            let quiet_before = self
                .last_byte_ms
                .is_none_or(|last| now_ms.wrapping_sub(last) >= QUIT_GUARD_MS);
            self.last_byte_ms = Some(now_ms);
            if self.matched > 0 && byte == QUIT[self.matched] {
                self.matched += 1;
                if self.matched == QUIT.len() {
                    self.matched = 0;
                    return true;
                }
            } else if byte == QUIT[0] && quiet_before {
                self.matched = 1;
            } else {
                self.matched = 0;
            }
        }
        false
    }
}

/// Pump bytes both ways until the upstream sends the quit sequence
/// (`Ok(())`) or a port fails.
///
/// Never waits inside a port call: it checks `read_ready` / `write_ready`
/// first, and when neither direction can move calls `sleep` with a
/// readiness check, which should sleep (e.g. WFI) unless that check says
/// there is work. `now_ms` is a millisecond clock for the quit guard time.
pub fn run<U, D>(
    upstream: &mut U,
    downstream: &mut D,
    now_ms: impl Fn() -> u32,
    mut sleep: impl FnMut(&mut dyn FnMut() -> bool),
) -> Result<(), Error<U::Error, D::Error>>
where
    U: Read + ReadReady + Write + WriteReady,
    D: Read + ReadReady + Write + WriteReady,
{
    let mut up_to_down = Lane::new();
    let mut down_to_up = Lane::new();
    let mut quit = QuitDetector::new();
    loop {
        let down = up_to_down.step(upstream, downstream).map_err(|e| match e {
            LaneError::Source(e) => Error::Upstream(e),
            LaneError::Sink(e) => Error::Downstream(e),
        })?;
        if down.read > 0 && quit.feed(up_to_down.fresh(down.read), now_ms()) {
            return Ok(());
        }
        let up = down_to_up.step(downstream, upstream).map_err(|e| match e {
            LaneError::Source(e) => Error::Downstream(e),
            LaneError::Sink(e) => Error::Upstream(e),
        })?;
        if !down.moved && !up.moved {
            sleep(&mut || {
                up_to_down.can_progress(upstream, downstream)
                    || down_to_up.can_progress(downstream, upstream)
            });
        }
    }
}
