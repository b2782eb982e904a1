//! Pass-through: the host's checked command goes down, the controller's
//! checked reply comes up, unchanged. The line decides when the command
//! may go (after a fence, when something may still arrive from an earlier
//! command) and which frame is its reply; the bridge relays the reply as
//! it is, so it judges nothing beyond the envelope and its host checks the
//! body ([`Line::offer`] with `content_ok`).
//!
//! With XON/XOFF on, a reply whose text holds 0x11 or 0x13 is not relayed
//! (it would stop or start the host's transmitter): the host gets `&`
//! [`codes::XON_XOFF_IN_TEXT`] instead.

use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::line::{Due, Heard, Line};

use super::history::Dir::ToHost;
use super::{write_some, Bridge, Error, Mode, Port};
use crate::codes;
use crate::log;
use crate::serial::{FlowControl, XOFF, XON};

impl Bridge {
    /// The pass-through modes: send the command when the line says so (a
    /// fence first, if it asks for one), offer what the controller sends to
    /// the line, relay the reply.
    pub(super) fn poll_passthrough<U: Port, D: Port>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<bool, Error<U::Error, D::Error>> {
        match self.mode {
            Mode::SendCommand if self.guest_holds => Ok(false),
            Mode::SendCommand => {
                if let Some(id) = self.forward_pending.take() {
                    super::upstream::start_forward(&mut self.line, id, now);
                }
                self.send_command(down, now).map_err(Error::Downstream)
            }
            Mode::AwaitReply => self.await_reply(down, now).map_err(Error::Downstream),
            Mode::RelayReply => {
                let bytes = self
                    .job
                    .idle_decoder()
                    .last_frame()
                    .map_or(&[][..], |f| f.as_bytes());
                let out = &mut self.stats.upstream_out;
                let n = write_some(up, bytes, &mut self.out_off, out).map_err(Error::Upstream)?;
                if self.out_off >= bytes.len() {
                    self.history.record(ToHost, bytes, bytes.len(), now);
                    self.stats.relayed += 1;
                    self.go_idle();
                    return Ok(true);
                }
                Ok(n > 0)
            }
            _ => Ok(false),
        }
    }

    /// Writes the fence or the command, as the line asks; reads what comes
    /// meanwhile (the fence's echo, late replies) into the small decoder.
    fn send_command<D: Port>(&mut self, down: &mut D, now: u32) -> Result<bool, D::Error> {
        let mut moved = self.hear_meanwhile(down, now)?;
        match self.line.poll(now) {
            Due::Fence => {
                let bytes = self.line.fence_bytes();
                let out = &mut self.stats.downstream_out;
                moved |= write_some(down, bytes, &mut self.out_off, out)? > 0;
                if self.out_off >= bytes.len() {
                    self.out_off = 0;
                    self.fence_replies.reset();
                    self.line.sent(now);
                    moved = true;
                }
            }
            Due::Send { .. } => {
                let frames = self.job.idle_decoder();
                let bytes = frames.last_frame().map_or(&[][..], |f| f.as_bytes());
                let len = bytes.len();
                let out = &mut self.stats.downstream_out;
                moved |= write_some(down, bytes, &mut self.out_off, out)? > 0;
                if self.out_off >= len {
                    // All in the transmit ring: the reply clock starts; the
                    // reply is decoded where the command was.
                    self.out_off = 0;
                    self.stats.forwarded += 1;
                    frames.reset();
                    frames.set_policy(iai_protocol_b::checksum::BypassPolicy::Reject);
                    self.line.sent(now);
                    self.mode = Mode::AwaitReply;
                    moved = true;
                }
            }
            Due::WaitUntil(_) => {}
            Due::Done(_) | Due::Idle => {
                // The line dropped the command (it cannot happen while the
                // bridge holds it): the host times out and resends.
                self.go_idle();
                moved = true;
            }
        }
        Ok(moved)
    }

    /// Bytes from the controller before the command went out: the fence's
    /// echo, or replies to earlier commands (never relayed).
    fn hear_meanwhile<D: Port>(&mut self, down: &mut D, now: u32) -> Result<bool, D::Error> {
        let mut buf = [0u8; 1];
        let mut moved = false;
        while down.read_ready()? {
            if down.read(&mut buf)? == 0 {
                break;
            }
            self.stats.downstream_in += 1;
            moved = true;
            hear(&mut self.line, &mut self.fence_replies, buf[0], now);
        }
        Ok(moved)
    }

    /// Waits for the reply: every frame goes to the line, which takes the
    /// command's reply (or gives up after the timeout).
    fn await_reply<D: Port>(&mut self, down: &mut D, now: u32) -> Result<bool, D::Error> {
        let mut buf = [0u8; 1];
        let mut moved = false;
        let mut reply = None;
        while down.read_ready()? {
            if down.read(&mut buf)? == 0 {
                break;
            }
            self.stats.downstream_in += 1;
            moved = true;
            let (heard, xchar) = hear(&mut self.line, self.job.idle_decoder(), buf[0], now);
            if let Heard::Answer | Heard::Rejected(_) = heard {
                reply = Some(xchar);
                break;
            }
        }
        match (self.line.poll(now), reply) {
            (Due::Done(_), Some(xchar)) => {
                let station = self.cfg.controller_station;
                if xchar && self.cfg.flow == FlowControl::XonXoff {
                    self.respond_error(station, codes::XON_XOFF_IN_TEXT, now);
                } else {
                    self.mode = Mode::RelayReply;
                    self.out_off = 0;
                }
                moved = true;
            }
            (Due::Done(_), None) => {
                // No valid reply (or none expected, 25BH): the host times
                // out and decides, as without a bridge.
                log::warning!("no reply from the controller within 3 s");
                self.stats.reply_timeouts += 1;
                self.go_idle();
                moved = true;
            }
            _ => {}
        }
        Ok(moved)
    }
}

/// Decodes byte `b` and offers what it completes to the line: a frame as
/// it is (the bridge relays, so `content_ok`), a broken one by what could
/// be read of it. Also says whether the frame holds XON or XOFF.
fn hear<const N: usize>(
    line: &mut Line,
    frames: &mut FrameDecoder<N>,
    b: u8,
    now: u32,
) -> (Heard, bool) {
    match frames.push(b) {
        Event::NeedMore => (Heard::NeedMore, false),
        Event::Frame(f) => {
            let xchar = f.as_bytes().iter().any(|&b| b == XON || b == XOFF);
            (line.offer(&f, true, now), xchar)
        }
        Event::Error(e) => {
            line.broken(frames.failed_envelope(), now);
            (Heard::Broken(e), false)
        }
    }
}
