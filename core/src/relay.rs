//! A command passed on as it came, and its reply taken as it comes: what a
//! bridge does with a host's command. The host judges the reply's content;
//! the line takes the first reply with the command's station, header and
//! ID after the command was sent ([`crate::line`]), with one rule of
//! content: a 200H reply must carry exactly the command's text (the
//! controller echoes it, 2003 p. 15), so a fence's echo, or any other
//! 200H, never answers a host's 200H.
//!
//! One buffer serves the whole exchange (a bridge has one of 2,051 bytes):
//! it holds the command until it is sent, then the reply. Meanwhile the
//! line's own small decoder reads what arrives (a fence's echo, late
//! replies). The command goes out once: a host resends after its own
//! timeout, as without a bridge.

use crate::catalogue;
use crate::checksum::BypassPolicy;
use crate::decoder::{FrameDecoder, Received};
use crate::engine::{Engine, Step};
use crate::error::{Error, Failure};
use crate::frame::{Frame, Header};
use crate::line::{receive, Due, Heard, Judge, Line, Span, Verdict};

/// Characters of a 200H's text (2003 p. 15).
const TEXT_LEN: usize = 10;

/// The state of one relayed exchange, kept beside the buffer it runs in
/// ([`Relay::over`]).
#[derive(Debug, Clone, Default)]
pub struct Relay {
    /// The buffer holds the command (until it is sent) or the reply taken.
    held: bool,
    /// The transmission in progress is the command (not a fence).
    sending: bool,
    /// The text of a 200H relayed, which its reply must echo.
    text: Option<[u8; TEXT_LEN]>,
    /// The command went out.
    sent: bool,
}

impl Relay {
    /// No exchange.
    pub const fn new() -> Self {
        Relay {
            held: false,
            sending: false,
            text: None,
            sent: false,
        }
    }

    /// Whether the command of the exchange went out (completely written).
    pub const fn command_sent(&self) -> bool {
        self.sent
    }

    /// Starts passing on `command` (a checked command frame that the
    /// buffer of [`Relay::over`] holds) at `now`; sent once.
    pub fn start(&mut self, line: &mut Line, command: &Frame<'_>, now: u32) -> Result<(), Error> {
        if command.header() != Header::Command {
            return Err(Error::UnexpectedHeader {
                expected: Header::Command,
                found: command.header(),
            });
        }
        self.text = None;
        if command.code() == catalogue::TEST_CALL.id {
            let mut t = [0u8; TEXT_LEN];
            let body = command.body();
            let dst = t.get_mut(..body.len()).ok_or(Error::BufferTooSmall)?;
            dst.copy_from_slice(body);
            self.text = Some(t);
        }
        line.start_raw(command.code(), 1, now);
        self.held = true;
        self.sending = false;
        self.sent = false;
        Ok(())
    }

    /// The exchange as an engine over `frames`, the buffer that holds the
    /// command and then takes the reply (its last frame once done).
    pub fn over<'a, const N: usize>(
        &'a mut self,
        frames: &'a mut FrameDecoder<N>,
    ) -> Relaying<'a, N> {
        Relaying {
            relay: self,
            frames,
        }
    }
}

/// A [`Relay`] with its buffer: an [`Engine`] whose result is the reply,
/// left in the buffer ([`FrameDecoder::last_frame`]).
pub struct Relaying<'a, const N: usize> {
    relay: &'a mut Relay,
    frames: &'a mut FrameDecoder<N>,
}

/// The one check of a relayed reply's content.
struct EchoCheck<'t> {
    text: Option<&'t [u8; TEXT_LEN]>,
}

impl Judge for EchoCheck<'_> {
    fn judge(&mut self, f: &Frame<'_>) -> Verdict {
        let fits = match self.text {
            Some(t) if f.code() == catalogue::TEST_CALL.id => f.body() == t.as_slice(),
            None if f.code() == catalogue::TEST_CALL.id => false,
            _ => true,
        };
        Verdict {
            fits,
            values: Span::UNKNOWN,
            keep: true,
        }
    }
    fn keeps_errors(&self) -> bool {
        true
    }
}

impl<const N: usize> Engine for Relaying<'_, N> {
    type Output = ();

    fn poll<'b>(&'b mut self, line: &'b mut Line, now: u32) -> Step<'b, ()> {
        match line.poll(now) {
            Due::Fence => {
                self.relay.sending = false;
                Step::Transmit(line.fence_bytes())
            }
            Due::Send { .. } if self.relay.held => {
                self.relay.sending = true;
                let bytes = self.frames.last_frame().map_or(&[][..], |f| f.as_bytes());
                Step::Transmit(bytes)
            }
            // Sent once: what is due again cannot be sent (the buffer
            // holds the reply's bytes by now).
            Due::Send { .. } => {
                line.abandon(now);
                Step::Done(Err(Failure::Timeout { sends: 1 }))
            }
            Due::WaitUntil(t) => Step::WaitUntil(t),
            Due::Done(r) => Step::Done(r),
            Due::Idle => Step::Done(Err(Failure::Timeout { sends: 0 })),
        }
    }

    fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        let mut judge = EchoCheck {
            text: self.relay.text.as_ref(),
        };
        receive(
            self.frames,
            &mut self.relay.held,
            line,
            &mut judge,
            bytes,
            now,
        )
    }

    fn sent(&mut self, line: &mut Line, now: u32) {
        if core::mem::take(&mut self.relay.sending) {
            // The reply is decoded where the command was.
            self.frames.reset();
            self.frames.set_policy(BypassPolicy::Reject);
            self.relay.held = false;
            self.relay.sent = true;
        }
        line.sent(now);
    }
}
