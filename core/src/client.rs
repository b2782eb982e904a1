//! The request engine: any command and its typed reply, over a [`Line`].
//!
//! ```
//! # use iai_protocol_b::{client::Client, io::Loopback, line::*, frame::Station, message::*};
//! # let mut uart = Loopback::default(); let mut t = 0u32; let mut now = move || { t += 1; t };
//! let mut line = Line::new(LineConfig::new(Station(0x99)), 7);
//! let mut client: Client = Client::new();
//! let go = AbsoluteMove::to(&[(1, 100_000), (2, -25_500)])?.with_speed(100);
//! let _reply: AbsoluteMoveResponse = client.call(&mut line, &mut uart, &mut now, &go)?;
//! let status = client.call(&mut line, &mut uart, &mut now, &AxisStatusQuery::of(&[1, 2])?)?;
//! assert_eq!(status.axes.len(), 2);
//! # Ok::<(), iai_protocol_b::error::Failure<core::convert::Infallible>>(())
//! ```
//!
//! (`uart` is any `embedded_io` port with [`embedded_io::ReadReady`]; here
//! the test double [`Loopback`](crate::io::Loopback) answers like a
//! controller.)
//!
//! Sans-IO at heart, in the shape of every engine ([`crate::engine`]):
//! [`Client::start`] a command, then [`Client::poll`], [`Client::sent`]
//! and [`Client::received`] until [`Step::Done`]; [`Client::response`]
//! then parses the reply as the command's typed response, the type
//! following from the [`Pending`] ticket that `start` gave. The timing,
//! resends and what may still arrive are the line's ([`crate::line`]).
//!
//! With [`Client::with_proof`] a reply counts only once a fence sent after
//! it proved the order ([`Line::start_proof`]): if the line heard a frame
//! it could not place meanwhile (it repeats frames), the reply may be a
//! copy of an earlier one; a query is asked again (the line now expects
//! copies), anything else ends [`Failure::Unconfirmed`].
//!
//! An error response becomes [`Failure::Controller`] with its code. With
//! [`Client::with_error_detail`] the client then asks 216H for the latest
//! system error and returns its detail with the code (**inferred**: that
//! the latest system error is the one the `&` reported;
//! [`ErrorDetail::matches_code`] says whether its number matches).
//!
//! RAM: a command buffer of `CMD` bytes and a reply buffer of `REPLY`
//! bytes (defaults: the TTA's 2,051 and 2,048). A client for small
//! commands and replies can be much smaller: `Client<64, 128>`.

use core::marker::PhantomData;

use crate::catalogue;
use crate::checksum::BypassPolicy;
use crate::clock::Clock;
use crate::decoder::Received;
use crate::engine::{self, Engine, Step};
use crate::error::{Error, ErrorDetail, Failure};
use crate::frame::{Frame, Header};
use crate::limits;
use crate::line::{Due, Heard, Judge, Line, Receiver, Span, Verdict};
use crate::message::{ErrorDetailQuery, ErrorDetailResponse, Message, Request, Response};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Idle,
    /// The command (or the 216H query for the detail of an `&` with this
    /// code) is on the line.
    Running {
        detail_for: Option<u16>,
    },
    /// The reply is taken; a fence proves no copy stood in for it.
    Proving {
        started: bool,
    },
    /// Over: `Ok(true)` with a reply, `Ok(false)` for a command without
    /// normal response.
    Done(Result<bool, Failure>),
}

/// Times a query is asked again when its reply could not be proved.
const PROOF_ASKS: u8 = 2;

/// Sends commands and matches their replies.
pub struct Client<
    const CMD: usize = { limits::TTA.command },
    const REPLY: usize = { limits::TTA.response },
> {
    command: [u8; CMD],
    command_len: usize,
    replies: Receiver<REPLY>,
    /// Ask 216H after an `&`, unless this says the code is not the
    /// controller's.
    fetch_error_detail: Option<fn(u16) -> bool>,
    phase: Phase,
    /// The ID of the command started last.
    id: u16,
    /// Prove each reply before it counts.
    prove: bool,
    /// The line's count of unplaced frames when the command started.
    unplaced_at_start: u32,
    /// Times the command was asked again for want of a proof.
    asked_again: u8,
    /// Requests started so far: which one a [`Pending`] is for.
    started: u32,
}

/// A request started on a [`Client`]: the ticket to its reply, whose type
/// follows from the request's ([`Client::response`]).
pub struct Pending<R> {
    started: u32,
    id: u16,
    request: PhantomData<fn() -> R>,
}

impl<R> Clone for Pending<R> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<R> Copy for Pending<R> {}
impl<R> PartialEq for Pending<R> {
    fn eq(&self, other: &Self) -> bool {
        (self.started, self.id) == (other.started, other.id)
    }
}
impl<R> Eq for Pending<R> {}
impl<R> core::fmt::Debug for Pending<R> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Pending({:03X}H, #{})", self.id, self.started)
    }
}

impl<const CMD: usize, const REPLY: usize> Default for Client<CMD, REPLY> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CMD: usize, const REPLY: usize> Client<CMD, REPLY> {
    /// An idle client.
    pub const fn new() -> Self {
        Client {
            command: [0; CMD],
            command_len: 0,
            replies: Receiver::new(),
            fetch_error_detail: None,
            phase: Phase::Idle,
            id: 0,
            prove: false,
            unplaced_at_start: 0,
            asked_again: 0,
            started: 0,
        }
    }

    /// This client, proving each reply before it counts (see the module
    /// docs): one fence more per command.
    pub const fn with_proof(mut self) -> Self {
        self.prove = true;
        self
    }

    /// This client, asking 216H for the detail of every error response.
    pub const fn with_error_detail(self) -> Self {
        self.with_error_detail_except(|_| false)
    }

    /// This client, asking 216H for the detail of error responses except
    /// those whose code `not_the_controllers` picks (a bridge's own codes:
    /// the controller did not raise them and has no detail for them).
    pub const fn with_error_detail_except(mut self, not_the_controllers: fn(u16) -> bool) -> Self {
        self.fetch_error_detail = Some(not_the_controllers);
        self
    }

    /// Starts `req` on `line` at tick `now` (whatever the line was doing is
    /// abandoned: its replies are owed). Fails if `req` does not fit the
    /// command buffer.
    pub fn start<'a, R: Request<'a>>(
        &mut self,
        line: &mut Line,
        req: &R,
        now: u32,
    ) -> Result<Pending<R>, Error> {
        let cfg = line.config();
        self.phase = Phase::Idle;
        self.command_len = req.emit_with(cfg.station, cfg.checksum, &mut self.command)?;
        line.start(R::INFO, now);
        self.id = R::ID;
        Ok(self.began(line))
    }

    /// [`Client::start`], sent at most `max_sends` times (0 is read as 1)
    /// whatever the line's setting: a poll that the next round asks again
    /// anyway need not hold the line for three timeouts.
    pub fn start_with_sends<'a, R: Request<'a>>(
        &mut self,
        line: &mut Line,
        req: &R,
        max_sends: u8,
        now: u32,
    ) -> Result<Pending<R>, Error> {
        let cfg = line.config();
        self.phase = Phase::Idle;
        self.command_len = req.emit_with(cfg.station, cfg.checksum, &mut self.command)?;
        line.start_raw(R::ID, max_sends, now);
        self.id = R::ID;
        Ok(self.began(line))
    }

    /// Starts a command given as a complete frame (a tool sending what a
    /// user typed). The frame is checked; its ID's catalogue entry decides
    /// resend safety and reply kind; an ID outside the catalogue is sent
    /// once and any normal response with that ID is taken.
    pub fn start_frame(&mut self, line: &mut Line, frame: &[u8], now: u32) -> Result<(), Error> {
        let f = Frame::new_checked(frame, BypassPolicy::Accept)?;
        if f.header() != Header::Command {
            return Err(Error::UnexpectedHeader {
                expected: Header::Command,
                found: f.header(),
            });
        }
        self.phase = Phase::Idle;
        let dst = self
            .command
            .get_mut(..frame.len())
            .ok_or(Error::BufferTooSmall)?;
        dst.copy_from_slice(frame);
        self.command_len = frame.len();
        let max_sends = line.config().max_sends;
        line.start_raw(f.code(), max_sends, now);
        self.id = f.code();
        let _: Pending<()> = self.began(line);
        Ok(())
    }

    fn began<R>(&mut self, line: &Line) -> Pending<R> {
        self.unplaced_at_start = line.stats().unplaced;
        self.asked_again = 0;
        self.phase = Phase::Running { detail_for: None };
        self.started = self.started.wrapping_add(1);
        Pending {
            started: self.started,
            id: self.id,
            request: PhantomData,
        }
    }

    /// Decides the next step at tick `now`.
    pub fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, ()> {
        loop {
            let detail_for = match self.phase {
                Phase::Idle => return Step::Idle,
                Phase::Done(r) => return Step::Done(r.map(|_| ())),
                Phase::Proving { started: false } => {
                    line.start_proof(now);
                    self.phase = Phase::Proving { started: true };
                    continue;
                }
                Phase::Proving { started: true } => {
                    match line.poll(now) {
                        Due::Fence => return Step::Transmit(line.fence_bytes()),
                        Due::WaitUntil(t) => return Step::WaitUntil(t),
                        Due::Done(Ok(())) => self.proved(line, now),
                        Due::Done(Err(e)) => self.phase = Phase::Done(Err(e)),
                        Due::Send { .. } | Due::Idle => {
                            self.phase = Phase::Proving { started: false }
                        }
                    }
                    continue;
                }
                Phase::Running { detail_for } => detail_for,
            };
            match line.poll(now) {
                Due::Idle => self.phase = Phase::Idle,
                Due::Fence => return Step::Transmit(line.fence_bytes()),
                Due::Send { fresh } => {
                    if fresh {
                        // Bytes from before the send cannot answer it.
                        self.replies.clear(line, now);
                    }
                    return Step::Transmit(self.command.get(..self.command_len).unwrap_or(&[]));
                }
                Due::WaitUntil(t) => return Step::WaitUntil(t),
                Due::Done(r) => self.finished(line, r, detail_for, now),
            }
        }
    }

    fn finished(
        &mut self,
        line: &mut Line,
        r: Result<(), Failure>,
        detail_for: Option<u16>,
        now: u32,
    ) {
        let replied = self.has_normal_response(line);
        let result = match (r, detail_for) {
            (Ok(()), None) => Ok(replied),
            (Ok(()), Some(code)) => Err(Failure::Controller {
                code,
                detail: self
                    .replies
                    .reply()
                    .and_then(|fr| ErrorDetailResponse::parse(&fr).ok())
                    .map(|r| detail(&r, code)),
            }),
            // The detail query itself failed: report the first code.
            (Err(_), Some(code)) => Err(Failure::Controller { code, detail: None }),
            (Err(Failure::Controller { code, .. }), None)
                if self.fetch_error_detail.is_some_and(|skip| !skip(code)) =>
            {
                if self.fetch_detail(line, code, now) {
                    return;
                }
                Err(Failure::Controller { code, detail: None })
            }
            (Err(e), None) => Err(e),
        };
        self.phase = if self.prove && result == Ok(true) && detail_for.is_none() {
            Phase::Proving { started: false }
        } else {
            Phase::Done(result)
        };
    }

    /// The proof's echo is back: the reply counts if nothing unplaced came
    /// since the command started; else a query is asked again.
    fn proved(&mut self, line: &mut Line, now: u32) {
        let unplaced = line.stats().unplaced;
        if unplaced == self.unplaced_at_start {
            self.phase = Phase::Done(Ok(true));
            return;
        }
        let safe = catalogue::request_rules(self.id)
            .is_some_and(|(resend, _)| resend == catalogue::Resend::Safe);
        if safe && self.asked_again < PROOF_ASKS {
            self.asked_again += 1;
            self.unplaced_at_start = unplaced;
            let max_sends = line.config().max_sends;
            line.start_raw(self.id, max_sends, now);
            self.phase = Phase::Running { detail_for: None };
        } else {
            self.phase = Phase::Done(Err(Failure::Unconfirmed { unplaced }));
        }
    }

    fn has_normal_response(&self, line: &Line) -> bool {
        catalogue::request_rules(line.id())
            .is_none_or(|(_, reply)| reply == catalogue::Reply::Normal)
    }

    /// Starts the 216H query for the latest system error; `false` if it
    /// cannot be emitted.
    fn fetch_detail(&mut self, line: &mut Line, code: u16, now: u32) -> bool {
        let cfg = line.config();
        let q = ErrorDetailQuery::latest_system_error();
        match q.emit_with(cfg.station, cfg.checksum, &mut self.command) {
            Ok(n) => {
                self.command_len = n;
                line.start(ErrorDetailQuery::INFO, now);
                self.phase = Phase::Running {
                    detail_for: Some(code),
                };
                true
            }
            Err(_) => false,
        }
    }

    /// The command was completely transmitted at tick `now`.
    pub fn sent(&mut self, line: &mut Line, now: u32) {
        line.sent(now);
    }

    /// Bytes from the controller at tick `now`. Returns at the first frame
    /// (or broken one), with the bytes used; call again with the rest. The
    /// reply taken stays readable ([`Client::response`]) until the next
    /// start; bytes after it answer nothing.
    pub fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        let command = self.command.get(..self.command_len).unwrap_or(&[]);
        let mut judge = ReplyCheck { command };
        self.replies.receive(line, &mut judge, bytes, now)
    }

    /// The raw reply frame of the finished request, if it was answered.
    pub fn reply_frame(&self) -> Option<Frame<'_>> {
        match self.phase {
            Phase::Done(Ok(true)) => self.replies.reply(),
            _ => None,
        }
    }

    /// The reply to the request `pending` stands for, as its response type
    /// (for a command without normal response, 25BH, the default value):
    /// [`Error::NoReply`] if it took none (it failed or is not over),
    /// [`Error::UnexpectedMessageId`] if another request was started
    /// since.
    pub fn response<'c, 'a, R>(&'c self, pending: &Pending<R>) -> Result<R::Response<'c>, Error>
    where
        R: Request<'a>,
        R::Response<'c>: Default,
    {
        if pending.started != self.started {
            return Err(Error::UnexpectedMessageId {
                expected: pending.id,
                found: self.id,
            });
        }
        match self.phase {
            Phase::Done(Ok(false)) => Ok(Default::default()),
            _ => {
                let frame = self.reply_frame().ok_or(Error::NoReply { id: R::ID })?;
                <R::Response<'c> as Message<'c>>::parse(&frame)
            }
        }
    }

    /// Sends `req` over `uart` and waits for its typed reply, blocking.
    /// The timeout starts when `write_all` and `flush` return.
    pub fn call<'c, 'a, R, U, C>(
        &'c mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
        req: &R,
    ) -> Result<R::Response<'c>, Failure<U::Error>>
    where
        R: Request<'a>,
        R::Response<'c>: Default,
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        let pending = self.start(line, req, clock.now_ms())?;
        engine::run_blocking(self, line, uart, clock)?;
        Ok(self.response(&pending)?)
    }

    /// Makes what progress is possible without waiting for the started
    /// request (see [`engine::poll_nb`]). `Ok` once it is over; then
    /// [`Client::response`] parses the reply.
    pub fn poll_nb<U, C>(
        &mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
    ) -> nb::Result<(), Failure<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        engine::poll_nb(self, line, uart, clock)
    }

    /// [`Client::call`] over an `embedded-io-async` UART, sleeping at most
    /// `poll_ms` between checks while it waits.
    #[cfg(feature = "async")]
    pub async fn call_async<'c, 'a, R, U, C>(
        &'c mut self,
        line: &mut Line,
        uart: &mut U,
        clock: &mut C,
        poll_ms: u32,
        req: &R,
    ) -> Result<R::Response<'c>, Failure<U::Error>>
    where
        R: Request<'a>,
        R::Response<'c>: Default,
        U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
        C: crate::clock::AsyncClock,
    {
        let pending = self.start(line, req, clock.now_ms())?;
        engine::run_async(self, line, uart, clock, poll_ms).await?;
        Ok(self.response(&pending)?)
    }
}

impl<const CMD: usize, const REPLY: usize> Engine for Client<CMD, REPLY> {
    type Output = ();
    fn poll<'a>(&'a mut self, line: &'a mut Line, now: u32) -> Step<'a, ()> {
        match Client::poll(self, line, now) {
            // Nothing was started: nothing will ever finish.
            Step::Idle => Step::Done(Err(Failure::Protocol(Error::NotStarted))),
            step => step,
        }
    }
    fn received(&mut self, line: &mut Line, bytes: &[u8], now: u32) -> Received<Heard> {
        Client::received(self, line, bytes, now)
    }
    fn sent(&mut self, line: &mut Line, now: u32) {
        Client::sent(self, line, now);
    }
}

/// A client's check of a reply: chapter 5 condition 1, a normal response
/// has its message's layout; a 200H reply echoes the call's text exactly.
struct ReplyCheck<'c> {
    command: &'c [u8],
}

impl Judge for ReplyCheck<'_> {
    fn judge(&mut self, f: &Frame<'_>) -> Verdict {
        let layout_ok = catalogue::lookup(f.code()).is_none() || Response::parse(f).is_ok();
        let echo_ok = f.code() != catalogue::TEST_CALL.id || echoes(self.command, f);
        Verdict {
            fits: layout_ok && echo_ok,
            values: Span::UNKNOWN,
            keep: true,
        }
    }
}

/// Whether `reply` (a 200H response) carries exactly the text of
/// `command` (the 200H sent): the controller echoes it (2003 p. 15).
pub(crate) fn echoes(command: &[u8], reply: &Frame<'_>) -> bool {
    Frame::new_checked(command, BypassPolicy::Accept)
        .is_ok_and(|c| c.code() == catalogue::TEST_CALL.id && c.body() == reply.body())
}

/// The numbers of a 216H reply, for the `&` with `code`.
fn detail(r: &ErrorDetailResponse<'_>, code: u16) -> ErrorDetail {
    ErrorDetail {
        error_number: r.error_number,
        detail_1: r.detail_1,
        detail_2: r.detail_2,
        detail_3: r.detail_3,
        detail_4: r.detail_4,
        detail_5_to_8: [r.detail_5, r.detail_6, r.detail_7, r.detail_8],
        matches_code: r.error_number == code,
    }
}

#[cfg(test)]
mod tests;
