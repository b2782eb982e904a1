//! Pass-through: the host's checked command goes down, the controller's
//! checked reply comes up, unchanged, by the core's relay engine
//! ([`iai_protocol_b::relay`]) on the bridge's one line and driver. The
//! line decides when the command may go (after a fence, when something
//! may still arrive from an earlier command) and which frame is its reply;
//! the host judges the reply's content, except that a 200H reply must echo
//! the host's own text (a fence's echo is never relayed).
//!
//! With XON/XOFF on, a reply whose text holds 0x11 or 0x13 is not relayed
//! (it would stop or start the host's transmitter): the host gets `&`
//! [`codes::XON_XOFF_IN_TEXT`] instead.

use iai_protocol_b::engine::Turn;
use iai_protocol_b::error::Failure;

use super::history::Dir::ToHost;
use super::{write_some, Bridge, Error, Mode, Port};
use crate::codes;
use crate::log;
use crate::serial::{Counted, FlowControl, XOFF, XON};

impl Bridge {
    /// The pass-through modes: forward the command and take its reply (the
    /// relay engine), then write the reply upstream.
    pub(super) fn poll_passthrough<U: Port, D: Port>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<bool, Error<U::Error, D::Error>> {
        match self.mode {
            Mode::Forward if self.guest_holds => Ok(false),
            Mode::Forward => self.forward(down, now).map_err(Error::Downstream),
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

    /// Starts the relay once the guest let go of the line, and turns it.
    fn forward<D: Port>(&mut self, down: &mut D, now: u32) -> Result<bool, D::Error> {
        let mut moved = false;
        if self.forward_pending.take().is_some() {
            let frames = self.job.idle_decoder();
            let started = match frames.last_frame() {
                Some(f) => self.relay.start(&mut self.line, &f, now).is_ok(),
                None => false,
            };
            if !started {
                // Cannot happen: the decoder holds the checked command.
                self.go_idle();
                return Ok(true);
            }
            moved = true;
        }
        let mut port = Counted::new(
            down,
            &mut self.stats.downstream_in,
            &mut self.stats.downstream_out,
        );
        let mut engine = self.relay.over(self.job.idle_decoder());
        let mut clock = || now;
        let turn = self
            .driver
            .turn(&mut engine, &mut self.line, &mut port, &mut clock);
        self.stream_deadline = None;
        self.tx_blocked = false;
        match turn {
            Err(e) => return Err(e),
            Ok(Turn::Busy) => moved = true,
            Ok(Turn::Wait { until, write }) => {
                self.stream_deadline = until;
                self.tx_blocked = write;
            }
            Ok(Turn::Done(r)) => {
                if self.relay.command_sent() {
                    self.stats.forwarded += 1;
                }
                match r {
                    Ok(()) | Err(Failure::Controller { .. }) => self.relay_reply(now),
                    Err(_) => {
                        // No valid reply (or none expected, 25BH): the host
                        // times out and decides, as without a bridge.
                        log::warning!("no reply from the controller in time");
                        self.stats.reply_timeouts += 1;
                        self.go_idle();
                    }
                }
                moved = true;
            }
        }
        Ok(moved)
    }

    /// The controller's reply (or `&`) is in the decoder: relay it, unless
    /// its text holds XON or XOFF on a line that uses them.
    fn relay_reply(&mut self, now: u32) {
        let xchar = self
            .job
            .idle_decoder()
            .last_frame()
            .is_some_and(|f| f.as_bytes().iter().any(|&b| b == XON || b == XOFF));
        if xchar && self.cfg.flow == FlowControl::XonXoff {
            let station = self.cfg.controller_station;
            self.respond_error(station, codes::XON_XOFF_IN_TEXT, now);
        } else {
            self.mode = Mode::RelayReply;
            self.out_off = 0;
        }
    }
}
