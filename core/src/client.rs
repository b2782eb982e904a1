//! The request engine: send any command and get its typed reply, under the
//! timeout-and-retry rules of chapter 5 (see [`crate::exchange`]).
//!
//! ```
//! # use iai_protocol_b::{client::*, frame::Station, message::*};
//! # let mut uart = Loopback::default(); let mut t = 0u32; let mut now = move || { t += 1; t };
//! let mut client: Client = Client::new(ClientConfig::new(Station(0x99)));
//! let go = AbsoluteMove::to(&[(1, 100_000), (2, -25_500)])?.with_speed(100);
//! let _reply: AbsoluteMoveResponse = client.call(&mut uart, &mut now, &go)?;
//! let status = client.call(&mut uart, &mut now, &AxisStatusQuery::of(&[1, 2])?)?;
//! assert_eq!(status.axes.len(), 2);
//! # Ok::<(), CallError<core::convert::Infallible>>(())
//! ```
//!
//! (`uart` is any `embedded_io` port with [`embedded_io::ReadReady`]; here
//! a loopback test double, [`Loopback`], answers like a controller.)
//!
//! [`Client`] is sans-IO at heart: [`Client::start`] a command, then
//! [`Client::poll`] for what to do ([`ClientStep::Transmit`] these bytes and
//! report [`Client::sent`]; feed received bytes to [`Client::received`];
//! [`ClientStep::WaitUntil`] a tick), until [`ClientStep::Done`]; then
//! [`Client::response`] parses the reply as the command's typed response.
//! [`Client::call`] (blocking, `embedded-io` and a [`Clock`]),
//! [`Client::poll_nb`] and, with the `async` feature, `Client::call_async`
//! run that loop over a UART.
//!
//! An error response becomes [`CallError::Controller`] with its code, and
//! is not sent again. With [`ClientConfig::fetch_error_detail`] the client
//! then asks 216H for the latest system error and returns its detail with
//! the code (**inferred**: that the latest system error is the one the
//! `&` reported; the client says whether its number matches). Codes in
//! [`BRIDGE_CODES`] come from a bridge, not the controller: they become
//! [`CallError::Bridge`] and no detail is asked for.
//!
//! Replies to earlier commands (late ones, and copies of any reply within
//! the duplicate window) never answer a later command: the exchange holds
//! the next first send until none can come. Bytes the reply decoder still
//! holds when a command is about to go out (a frame in progress, or a
//! 200H whose ten text bytes took in another frame) came before it: they
//! are dropped, and with a duplicate window the send waits it out, since a
//! late reply may have been among them.
//!
//! RAM: a command buffer of `CMD` bytes, a reply buffer of `REPLY` bytes
//! (defaults: the TTA's 2,051 and 2,048), and a few counters. A client for
//! small commands and replies can be much smaller: `Client<64, 128>`.

use crate::catalogue::{self, Reply, Resend};
use crate::checksum::{BypassPolicy, ChecksumMode};
use crate::clock::Clock;
use crate::decoder::{Event, FrameDecoder};
use crate::drive::{self, Engine, Stop, Want};
use crate::error::{Error, BRIDGE_CODES};
use crate::exchange::{Due, Exchange, ExchangeConfig, Finish, Offer, Quarantine};
use crate::frame::{Frame, Header, Station};
use crate::limits;
use crate::message::{ErrorDetailQuery, ErrorDetailResponse, Message, Request, Response};

/// Settings of a [`Client`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClientConfig {
    /// Station, timeout, sends, turnaround, late and duplicate windows.
    pub exchange: ExchangeConfig,
    /// Checksum or `@@` on commands.
    pub checksum: ChecksumMode,
    /// After an error response from the controller, fetch the 216H detail.
    pub fetch_error_detail: bool,
}

impl ClientConfig {
    /// The spec's settings for `station` (see [`ExchangeConfig::new`]),
    /// computed checksums, no 216H fetch.
    pub const fn new(station: Station) -> Self {
        ClientConfig {
            exchange: ExchangeConfig::new(station),
            checksum: ChecksumMode::Compute,
            fetch_error_detail: false,
        }
    }

    /// With the 216H detail fetched after an error response.
    pub const fn with_error_detail(mut self) -> Self {
        self.fetch_error_detail = true;
        self
    }
}

/// The numbers of a 216H error detail (its message string, always empty on
/// the TTA, is not kept; read 216H yourself for it).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ErrorDetail {
    /// The error number the controller reports.
    pub error_number: u16,
    /// Detail 1: program number (system-down errors: type).
    pub detail_1: u32,
    /// Detail 2: step number (system-down: error code).
    pub detail_2: u32,
    /// Detail 3: axis number (system-down: information 1).
    pub detail_3: u32,
    /// Detail 4: position number, negative for an interpolation point
    /// (system-down: information 2).
    pub detail_4: i32,
    /// Details 5 to 8 (meanings undocumented).
    pub detail_5_to_8: [u32; 4],
    /// Whether `error_number` equals the code of the error response.
    pub matches_code: bool,
}

impl ErrorDetail {
    fn from_response(r: &ErrorDetailResponse<'_>, code: u16) -> Self {
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
}

/// Why a request did not produce its normal response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CallError<E = core::convert::Infallible> {
    /// No valid reply after this many sends of a command that is safe to
    /// repeat.
    Timeout {
        /// Sends made.
        sends: u8,
    },
    /// No valid reply to a command that is unsafe to repeat (a relative
    /// move): it may have run. Check the controller's state (212H) before
    /// doing anything else.
    OutcomeUnknown {
        /// Sends made (1 unless resending unsafe commands was allowed).
        sends: u8,
    },
    /// The controller answered with an error response.
    Controller {
        /// Its code (the meaning is in the controller's manual).
        code: u16,
        /// The 216H detail, if it was asked for and came.
        detail: Option<ErrorDetail>,
    },
    /// A bridge between host and controller answered with one of its own
    /// codes ([`BRIDGE_CODES`]).
    Bridge {
        /// The bridge's code.
        code: u16,
    },
    /// The command could not be emitted, or the reply not parsed as the
    /// type asked for.
    Protocol(Error),
    /// The driver failed.
    Io(E),
}

impl<E> From<Error> for CallError<E> {
    fn from(e: Error) -> Self {
        CallError::Protocol(e)
    }
}

impl CallError {
    fn widen<E>(self) -> CallError<E> {
        match self {
            CallError::Timeout { sends } => CallError::Timeout { sends },
            CallError::OutcomeUnknown { sends } => CallError::OutcomeUnknown { sends },
            CallError::Controller { code, detail } => CallError::Controller { code, detail },
            CallError::Bridge { code } => CallError::Bridge { code },
            CallError::Protocol(e) => CallError::Protocol(e),
            CallError::Io(never) => match never {},
        }
    }
}

/// How a request succeeded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Outcome {
    /// The normal response came; [`Client::response`] parses it.
    Replied,
    /// The command has no normal response (25BH) and no error response came.
    NoReplyExpected,
}

/// What the caller should do next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClientStep<'a> {
    /// No request.
    Idle,
    /// Send these bytes, then call [`Client::sent`].
    Transmit(&'a [u8]),
    /// Feed received bytes to [`Client::received`]; poll again by this tick.
    WaitUntil(u32),
    /// The request is over.
    Done(Result<Outcome, CallError>),
}

/// What one call of [`Client::received`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Heard {
    /// All bytes used; nothing complete.
    NeedMore,
    /// A complete frame, and what it meant for the request.
    Frame(Offer),
    /// A broken frame or noise was dropped.
    Broken(Error),
}

/// The answer of a `received` call: how many bytes it used, and what it
/// found (the same shape as [`crate::decoder::Decoded`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Received<E> {
    /// Bytes of the input used; feed the rest in the next call.
    pub consumed: usize,
    /// What they completed.
    pub event: E,
}

/// Counters of a client.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClientStats {
    /// Requests started.
    pub requests: u32,
    /// Frames sent, resends included.
    pub sends: u32,
    /// Frames sent again after a timeout.
    pub resends: u32,
    /// Timeouts.
    pub timeouts: u32,
    /// Error responses received.
    pub error_replies: u32,
    /// Replies that came when none was awaited, and were dropped.
    pub stale_frames: u32,
    /// Frames for another station or command.
    pub foreign_frames: u32,
    /// Replies whose body did not fit the response's layout.
    pub malformed_replies: u32,
    /// Broken frames and noise, and bytes held by the reply decoder that
    /// were dropped before a first send.
    pub line_errors: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Idle,
    /// The command (or the 216H detail query after an error response with
    /// this code) is in the exchange.
    Running {
        detail_for: Option<u16>,
    },
    Done(Result<Outcome, CallError>),
}

/// Sends commands and matches their replies.
pub struct Client<
    const CMD: usize = { limits::TTA.command },
    const REPLY: usize = { limits::TTA.response },
> {
    cfg: ClientConfig,
    exchange: Exchange,
    command: [u8; CMD],
    command_len: usize,
    replies: FrameDecoder<REPLY>,
    phase: Phase,
    stats: ClientStats,
}

impl<const CMD: usize, const REPLY: usize> Client<CMD, REPLY> {
    /// An idle client.
    pub const fn new(cfg: ClientConfig) -> Self {
        Client {
            cfg,
            exchange: Exchange::new(cfg.exchange, Quarantine::Wait),
            command: [0; CMD],
            command_len: 0,
            replies: FrameDecoder::with_policy(BypassPolicy::Reject),
            phase: Phase::Idle,
            stats: ClientStats {
                requests: 0,
                sends: 0,
                resends: 0,
                timeouts: 0,
                error_replies: 0,
                stale_frames: 0,
                foreign_frames: 0,
                malformed_replies: 0,
                line_errors: 0,
            },
        }
    }

    /// The settings.
    pub const fn config(&self) -> &ClientConfig {
        &self.cfg
    }

    /// Counters so far.
    pub const fn stats(&self) -> ClientStats {
        self.stats
    }

    /// Starts `req` at tick `now` (a request still running is abandoned:
    /// its replies are treated as stale). Fails if it cannot be emitted
    /// into the command buffer.
    pub fn start<'a, R: Request<'a>>(&mut self, req: &R, now: u32) -> Result<(), Error> {
        self.exchange.abandon(now);
        self.phase = Phase::Idle;
        self.command_len = req.emit_with(
            self.cfg.exchange.station,
            self.cfg.checksum,
            &mut self.command,
        )?;
        self.exchange.start(R::INFO, now);
        self.begin();
        Ok(())
    }

    /// Starts a command given as a complete frame (a bridge passing on what
    /// a host sent). The frame is checked; its ID's catalogue entry decides
    /// resend safety and reply kind. An ID outside the catalogue is sent
    /// once and any normal response with that ID is taken.
    pub fn start_frame(&mut self, frame: &[u8], now: u32) -> Result<(), Error> {
        let f = Frame::new_checked(frame, BypassPolicy::Accept)?;
        if f.header() != Header::Command {
            return Err(Error::UnexpectedHeader {
                expected: Header::Command,
                found: f.header(),
            });
        }
        self.exchange.abandon(now);
        self.phase = Phase::Idle;
        let dst = self
            .command
            .get_mut(..frame.len())
            .ok_or(Error::BufferTooSmall)?;
        dst.copy_from_slice(frame);
        self.command_len = frame.len();
        match catalogue::lookup(f.code()) {
            Some(info) => self.exchange.start(info, now),
            None => self
                .exchange
                .start_raw(f.code(), Resend::Unsafe, Reply::Normal, now),
        }
        self.begin();
        Ok(())
    }

    fn begin(&mut self) {
        self.stats.requests += 1;
        self.phase = Phase::Running { detail_for: None };
    }

    /// Decides the next step at tick `now`.
    pub fn poll(&mut self, now: u32) -> ClientStep<'_> {
        loop {
            let detail_for = match self.phase {
                Phase::Idle => return ClientStep::Idle,
                Phase::Done(r) => return ClientStep::Done(r),
                Phase::Running { detail_for } => detail_for,
            };
            if self.exchange.busy() && !self.exchange.awaiting() && self.exchange.sends() == 0 {
                self.drop_held_bytes(now);
            }
            match self.exchange.poll(now) {
                Due::Idle => self.phase = Phase::Idle,
                Due::Transmit { fresh } => {
                    if fresh {
                        self.stats.sends += 1;
                        if self.exchange.sends() > 1 {
                            self.stats.resends += 1;
                        }
                        self.replies.reset();
                    }
                    return ClientStep::Transmit(
                        self.command.get(..self.command_len).unwrap_or(&[]),
                    );
                }
                Due::WaitUntil(t) => return ClientStep::WaitUntil(t),
                Due::Done(f) => self.finished(f, detail_for, now),
            }
        }
    }

    /// Before a first send: bytes the decoder still holds (a frame in
    /// progress, or those of a failed text frame waiting to be decoded
    /// again) came before the command, so they cannot be its reply, but a
    /// late reply to an earlier command may be among them (a 200H's text
    /// takes in any ten bytes), and a copy of it may follow. They are
    /// dropped, and the send waits out the duplicate window.
    fn drop_held_bytes(&mut self, now: u32) {
        if self.replies.pending() > 0 {
            self.stats.line_errors += 1;
            self.replies.reset();
            let dup = self.cfg.exchange.duplicate_window_ms;
            if dup > 0 {
                self.exchange.defer(now.wrapping_add(dup));
            }
        }
    }

    fn finished(&mut self, f: Finish, detail_for: Option<u16>, now: u32) {
        let result = match (f, detail_for) {
            (Finish::Replied, None) => Ok(Outcome::Replied),
            (Finish::NoReplyExpected, _) => Ok(Outcome::NoReplyExpected),
            (Finish::Replied, Some(code)) => {
                let detail = self
                    .replies
                    .last_frame()
                    .and_then(|fr| ErrorDetailResponse::parse(&fr).ok())
                    .map(|r| ErrorDetail::from_response(&r, code));
                Err(CallError::Controller { code, detail })
            }
            (Finish::ErrorReply(code), Some(first)) => {
                // The detail query itself was refused: report the first code.
                let _ = code;
                Err(CallError::Controller {
                    code: first,
                    detail: None,
                })
            }
            (Finish::TimedOut { .. } | Finish::OutcomeUnknown { .. }, Some(code)) => {
                self.stats.timeouts += 1;
                Err(CallError::Controller { code, detail: None })
            }
            (Finish::ErrorReply(code), None) => {
                self.stats.error_replies += 1;
                if BRIDGE_CODES.contains(&code) {
                    Err(CallError::Bridge { code })
                } else if self.cfg.fetch_error_detail && self.fetch_detail(code, now) {
                    return;
                } else {
                    Err(CallError::Controller { code, detail: None })
                }
            }
            (Finish::TimedOut { sends }, None) => {
                self.stats.timeouts += 1;
                Err(CallError::Timeout { sends })
            }
            (Finish::OutcomeUnknown { sends }, None) => {
                self.stats.timeouts += 1;
                Err(CallError::OutcomeUnknown { sends })
            }
        };
        self.phase = Phase::Done(result);
    }

    /// Starts the 216H query for the latest system error; `false` if it
    /// cannot be emitted.
    fn fetch_detail(&mut self, code: u16, now: u32) -> bool {
        let q = ErrorDetailQuery::latest_system_error();
        match q.emit_with(
            self.cfg.exchange.station,
            self.cfg.checksum,
            &mut self.command,
        ) {
            Ok(n) => {
                self.command_len = n;
                self.exchange.start(ErrorDetailQuery::INFO, now);
                self.phase = Phase::Running {
                    detail_for: Some(code),
                };
                true
            }
            Err(_) => false,
        }
    }

    /// The command was completely transmitted at tick `now`.
    pub fn sent(&mut self, now: u32) {
        self.exchange.sent(now);
    }

    /// Bytes from the controller at tick `now`. Stops at the end of the
    /// awaited reply, so that it stays readable ([`Client::response`]);
    /// call again with the rest of the input until it answers
    /// [`Heard::NeedMore`].
    pub fn received(&mut self, bytes: &[u8], now: u32) -> Received<Heard> {
        let running = matches!(self.phase, Phase::Running { .. });
        let d = self.replies.decode(bytes);
        let consumed = d.consumed;
        let event = match d.event {
            Event::NeedMore => Heard::NeedMore,
            Event::Error(e) => Heard::Broken(e),
            Event::Frame(f) => {
                // Chapter 5 condition 1: a normal response must have its
                // message's layout.
                let layout_ok = f.header() != Header::Response
                    || catalogue::lookup(f.code()).is_none()
                    || Response::parse(&f).is_ok();
                let offer = if running {
                    self.exchange.offer(&f, layout_ok, now)
                } else {
                    Offer::Stale
                };
                match offer {
                    Offer::Stale => self.stats.stale_frames += 1,
                    Offer::Foreign => self.stats.foreign_frames += 1,
                    Offer::Mismatch => self.stats.malformed_replies += 1,
                    Offer::Accepted | Offer::Rejected(_) => {}
                }
                Heard::Frame(offer)
            }
        };
        if let Heard::Broken(_) = event {
            self.stats.line_errors += 1;
            if running {
                self.exchange
                    .broken_frame(self.replies.failed_envelope(), now);
            }
        }
        Received { consumed, event }
    }

    /// Feeds all of `bytes` ([`Client::received`] in a loop), ignoring what
    /// follows the awaited reply.
    pub fn received_all(&mut self, mut bytes: &[u8], now: u32) {
        loop {
            let r = self.received(bytes, now);
            bytes = bytes.get(r.consumed..).unwrap_or(&[]);
            match r.event {
                Heard::NeedMore => return,
                Heard::Frame(Offer::Accepted) => return,
                _ => {}
            }
        }
    }

    /// The raw reply frame of the finished request, if it was answered.
    pub fn reply_frame(&self) -> Option<Frame<'_>> {
        match self.phase {
            Phase::Done(Ok(Outcome::Replied)) => self.replies.last_frame(),
            _ => None,
        }
    }

    /// The finished request's reply, as `R`'s response type. For a command
    /// without normal response (25BH) that is the default value.
    pub fn response<'c, 'a, R>(&'c self) -> Result<R::Response<'c>, Error>
    where
        R: Request<'a>,
        R::Response<'c>: Default,
    {
        match self.phase {
            Phase::Done(Ok(Outcome::NoReplyExpected)) => Ok(Default::default()),
            _ => {
                let frame = self
                    .reply_frame()
                    .ok_or(Error::UnknownMessageId { id: R::ID })?;
                <R::Response<'c> as Message<'c>>::parse(&frame)
            }
        }
    }

    /// Sends `req` over `uart` and waits for its typed reply, blocking.
    /// The timeout starts when `write_all` and `flush` return.
    pub fn call<'c, 'a, R, U, C>(
        &'c mut self,
        uart: &mut U,
        clock: &mut C,
        req: &R,
    ) -> Result<R::Response<'c>, CallError<U::Error>>
    where
        R: Request<'a>,
        R::Response<'c>: Default,
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        self.start(req, clock.now_ms())?;
        drive::run_blocking(self, uart, clock).map_err(CallError::from_stop)?;
        Ok(self.response::<R>()?)
    }

    /// Makes what progress is possible without waiting for the started
    /// request: reads what arrived, sends what is due (taking the time
    /// after the write), checks the deadline. `Ok` once it is over; then
    /// [`Client::response`] parses the reply.
    pub fn poll_nb<U, C>(
        &mut self,
        uart: &mut U,
        clock: &mut C,
    ) -> nb::Result<Outcome, CallError<U::Error>>
    where
        U: embedded_io::Read + embedded_io::ReadReady + embedded_io::Write,
        C: Clock,
    {
        drive::poll_nb(self, uart, clock).map_err(|e| e.map(CallError::from_stop))
    }
}

#[cfg(feature = "async")]
impl<const CMD: usize, const REPLY: usize> Client<CMD, REPLY> {
    /// [`Client::call`] over an `embedded-io-async` UART. While a reply is
    /// awaited it checks [`embedded_io_async::ReadReady`] and sleeps at
    /// most `poll_ms` between checks, so the deadline is seen even if no
    /// byte ever comes.
    pub async fn call_async<'c, 'a, R, U, C>(
        &'c mut self,
        uart: &mut U,
        clock: &mut C,
        poll_ms: u32,
        req: &R,
    ) -> Result<R::Response<'c>, CallError<U::Error>>
    where
        R: Request<'a>,
        R::Response<'c>: Default,
        U: embedded_io_async::Read + embedded_io_async::ReadReady + embedded_io_async::Write,
        C: crate::clock::AsyncClock,
    {
        self.start(req, clock.now_ms())?;
        drive::run_async(self, uart, clock, poll_ms)
            .await
            .map_err(CallError::from_stop)?;
        Ok(self.response::<R>()?)
    }
}

impl<const CMD: usize, const REPLY: usize> Engine for Client<CMD, REPLY> {
    type Output = Outcome;
    type Error = CallError;
    fn feed(&mut self, bytes: &[u8], now: u32) {
        self.received_all(bytes, now);
    }
    fn want(&mut self, now: u32) -> Want<'_, Result<Outcome, CallError>> {
        let id = self.exchange.id();
        match self.poll(now) {
            ClientStep::Transmit(bytes) => Want::Transmit(bytes),
            ClientStep::WaitUntil(t) => Want::WaitUntil(t),
            ClientStep::Done(r) => Want::Done(r),
            // Nothing was started: nothing will ever finish.
            ClientStep::Idle => {
                Want::Done(Err(CallError::Protocol(Error::UnknownMessageId { id })))
            }
        }
    }
    fn sent(&mut self, now: u32) {
        Client::sent(self, now);
    }
}

impl<E> CallError<E> {
    fn from_stop(stop: Stop<CallError, E>) -> Self {
        match stop {
            Stop::Engine(e) => e.widen(),
            Stop::Io(e) => CallError::Io(e),
        }
    }
}

/// A test double for examples and tests: a UART whose "controller" answers
/// every well-formed command with its default normal response (an axis
/// status query with one status block per axis asked), a 25BH with
/// nothing, and anything else with nothing.
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
            if let Event::Frame(f) = self.cmd.push(b) {
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
    use crate::message::{AxisStatus, AxisStatusQuery, AxisStatusResponse};
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
    match Response::default_for(cmd.code()) {
        Some(r) if crate::message::Command::parse(cmd).is_ok() => {
            r.emit(cmd.station(), out).unwrap_or(0)
        }
        _ => 0,
    }
}
