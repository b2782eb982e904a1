//! The web page on the Ethernet build: HTTP/1.1 on port 80 (the web
//! block's `web.port`), one request per connection, on [`SOCKETS`] sockets
//! of the network runtime beside protocol B and Modbus TCP.
//!
//! - Reads: the status page (each axis's status, position and alarm from
//!   the Modbus gateway's polled cache, both lines, the counters, the
//!   firmware and its uptime; its live part again every 2 s), the
//!   configuration form (every setting of [`crate::config::settings`]),
//!   the last frames as text ([`pages`]). Open to anyone, or to whom gives
//!   the password by basic authentication (`web.reads`).
//! - Writes (the form, a restart): a POSTed form with the password; on a
//!   fresh gateway only with a new password. A form from another page (its
//!   `Origin`, else `Referer`, not this gateway's `Host`) is refused, and so
//!   is a second change while one is read.
//! - Limits, each a clear 4xx and nothing written: a head over [`RX`]
//!   bytes (431), a body over [`BODY_MAX`] (413), without a length (411) or
//!   not a form (415); a head or body that takes over [`REQUEST_MS`] (408);
//!   a value the settings refuse (400, naming the setting); a wrong
//!   password (403, then 429 for a second). A flood of connections: one
//!   socket always listens; when it is taken, the oldest connection that
//!   has sent nothing is dropped for it, or, if every one has, the new one
//!   is answered 429. A client that takes nothing for [`STALL_MS`] is
//!   reset.
//! - Bounded work per poll ([`PARTS_PER_ROUND`] parts sent,
//!   [`BODY_BYTES_PER_ROUND`] body bytes taken, per connection); nothing
//!   waits for the controller; pages are rendered part by part into the
//!   socket (no page buffer).

pub mod form;
pub mod pages;
pub mod request;
#[cfg(test)]
mod tests;

use heapless::Vec;
use smoltcp::iface::{SocketHandle, SocketSet};
use smoltcp::socket::tcp::{self, State};

use crate::bridge::Bridge;
use crate::config::access::{Check, PasswordError, Reads};
use crate::config::editor::Refusal as EditRefusal;
use crate::config::settings::Settings;
use crate::config::wire::PASSWORD_MAX;
use crate::modbus::Gateway;
use crate::net::NetView;
use crate::text::Buf;
use form::FormParser;
use pages::{Page, Refusal, View};
use request::{Head, Origin, Parsed, Route};

/// Sockets on the web port: two requests served at once and one always
/// listening.
pub const SOCKETS: usize = 3;
/// Receive buffer per socket: a request's head must fit in it.
pub const RX: usize = 1024;
/// Transmit buffer per socket: the longest part of a page fits in it (695
/// bytes: a configuration row with an allow-list of every other ID; see
/// the test `every_part_of_every_page_fits_the_transmit_buffer`).
pub const TX: usize = 768;
/// A form's body at most.
pub const BODY_MAX: u32 = 2048;
/// A request's head, or its body, must arrive within this.
pub const REQUEST_MS: u32 = 5_000;
/// A client that takes none of its answer for this long is reset.
pub const STALL_MS: u32 = 10_000;
/// A connection closing still open after this long is reset.
pub const CLOSE_LIMIT_MS: u32 = 2_000;
/// Parts of a page written per connection and round.
pub const PARTS_PER_ROUND: usize = 4;
/// Body bytes taken per connection and round.
pub const BODY_BYTES_PER_ROUND: usize = 512;

/// HTTP status codes this server answers with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// 200.
    Ok,
    /// 400.
    BadRequest,
    /// 401.
    Unauthorized,
    /// 403.
    Forbidden,
    /// 404.
    NotFound,
    /// 405.
    MethodNotAllowed,
    /// 408.
    RequestTimeout,
    /// 409.
    Conflict,
    /// 411.
    LengthRequired,
    /// 413.
    ContentTooLarge,
    /// 415.
    UnsupportedMediaType,
    /// 429.
    TooManyRequests,
    /// 431.
    HeadersTooLarge,
    /// 500.
    InternalError,
    /// 503.
    Unavailable,
}

impl Status {
    /// The number.
    pub const fn code(self) -> u16 {
        match self {
            Status::Ok => 200,
            Status::BadRequest => 400,
            Status::Unauthorized => 401,
            Status::Forbidden => 403,
            Status::NotFound => 404,
            Status::MethodNotAllowed => 405,
            Status::RequestTimeout => 408,
            Status::Conflict => 409,
            Status::LengthRequired => 411,
            Status::ContentTooLarge => 413,
            Status::UnsupportedMediaType => 415,
            Status::TooManyRequests => 429,
            Status::HeadersTooLarge => 431,
            Status::InternalError => 500,
            Status::Unavailable => 503,
        }
    }

    /// The reason phrase.
    pub const fn reason(self) -> &'static str {
        match self {
            Status::Ok => "OK",
            Status::BadRequest => "Bad Request",
            Status::Unauthorized => "Unauthorized",
            Status::Forbidden => "Forbidden",
            Status::NotFound => "Not Found",
            Status::MethodNotAllowed => "Method Not Allowed",
            Status::RequestTimeout => "Request Timeout",
            Status::Conflict => "Conflict",
            Status::LengthRequired => "Length Required",
            Status::ContentTooLarge => "Content Too Large",
            Status::UnsupportedMediaType => "Unsupported Media Type",
            Status::TooManyRequests => "Too Many Requests",
            Status::HeadersTooLarge => "Request Header Fields Too Large",
            Status::InternalError => "Internal Server Error",
            Status::Unavailable => "Service Unavailable",
        }
    }
}

/// The web sockets' buffers and the form being read, in a static of the
/// board (the form is kept there, not in the network side's state, which
/// the board builds on its stack at start).
pub struct HttpBuffers {
    rx: [[u8; RX]; SOCKETS],
    tx: [[u8; TX]; SOCKETS],
    /// At most one form. A `Vec` rather than an `Option`: empty, it is
    /// all zero bytes, so the static takes no flash (an `Option`'s `None`
    /// is not, and would put 6 KiB of zeros in `.data`).
    form: Vec<FormJob, 1>,
}

impl HttpBuffers {
    /// Zeroed buffers.
    pub const fn new() -> Self {
        HttpBuffers {
            rx: [[0; RX]; SOCKETS],
            tx: [[0; TX]; SOCKETS],
            form: Vec::new(),
        }
    }

    /// Adds a socket on each of these buffers to `set`, one at a time (as
    /// the Modbus sockets, to keep the stack small); their handles, and the
    /// form's place.
    pub(super) fn add_sockets<'a>(
        &'a mut self,
        set: &mut SocketSet<'a>,
    ) -> ([SocketHandle; SOCKETS], &'a mut Vec<FormJob, 1>) {
        let HttpBuffers { rx, tx, form } = self;
        let mut handles = [SocketHandle::default(); SOCKETS];
        for ((handle, rx), tx) in handles.iter_mut().zip(rx.iter_mut()).zip(tx.iter_mut()) {
            let mut socket = tcp::Socket::new(
                tcp::SocketBuffer::new(rx.as_mut_slice()),
                tcp::SocketBuffer::new(tx.as_mut_slice()),
            );
            super::host::configure(&mut socket);
            *handle = set.add(socket);
        }
        (handles, form)
    }
}

impl Default for HttpBuffers {
    fn default() -> Self {
        Self::new()
    }
}

/// What one web socket is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Conn {
    /// Listening.
    Listen,
    /// Connected since `since`; the request's head not whole yet.
    Reading {
        /// Tick of the connection.
        since: u32,
    },
    /// A form's body coming in: `left` bytes more, the head came at `since`.
    Body {
        /// Tick of the head.
        since: u32,
        /// Bytes still to come.
        left: u32,
    },
    /// Answering `page`, its part `part` next; the last part went at
    /// `since`.
    Reply {
        /// The page.
        page: Page,
        /// The next part.
        part: u16,
        /// Tick of the last progress.
        since: u32,
    },
    /// Closing our side since `since`.
    Closing {
        /// Tick when the close began.
        since: u32,
    },
    /// Aborted: its reset goes out at the next poll, then it listens.
    Reset,
}

/// Counters of the web side.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HttpStats {
    /// Requests whose head was read.
    pub requests: u32,
    /// Answers other than 200.
    pub refused: u32,
    /// Changes written.
    pub saved: u32,
    /// Connections dropped or refused (429) to keep a socket listening.
    pub flood: u32,
    /// Connections reset for a client that took nothing.
    pub stalled: u32,
}

/// A form being read: the parser and what it said so far.
pub struct FormJob {
    parser: FormParser,
    fields: Fields,
}

/// What a form said so far: its settings, its passwords, its first error.
struct Fields {
    route: Route,
    settings: Settings,
    password: Vec<u8, PASSWORD_MAX>,
    new1: Vec<u8, PASSWORD_MAX>,
    new2: Vec<u8, PASSWORD_MAX>,
    error: Option<Refusal>,
}

impl Fields {
    /// Takes what the parser handed out.
    fn took(&mut self, pair: form::Pair<'_>) {
        match pair {
            Some(Ok((key, value))) => self.take(key, value),
            Some(Err(e)) if self.error.is_none() => self.error = Some(bad(e.reason(), None)),
            _ => {}
        }
    }

    /// Takes one field.
    fn take(&mut self, key: &[u8], value: &[u8]) {
        if self.error.is_some() {
            return;
        }
        let slot = match key {
            b"password" => Some(&mut self.password),
            b"new_password" => Some(&mut self.new1),
            b"new_password2" => Some(&mut self.new2),
            _ => None,
        };
        if let Some(slot) = slot {
            if let Ok(v) = Vec::from_slice(value) {
                *slot = v;
            } else {
                self.error = Some(bad("a password is 64 characters at most", None));
            }
            return;
        }
        if self.route != Route::SaveConfig {
            return;
        }
        let (Ok(key), Ok(value)) = (core::str::from_utf8(key), core::str::from_utf8(value)) else {
            self.error = Some(bad("a field that is not UTF-8 text", None));
            return;
        };
        if key == "access.password" {
            self.error = Some(bad("the password is set with new_password", None));
            return;
        }
        if let Err(e) = self.settings.set(key, value) {
            self.error = Some(bad(e.reason, e.key));
        }
    }
}

fn bad(reason: &'static str, key: Option<&'static str>) -> Refusal {
    Refusal {
        status: Status::BadRequest,
        reason,
        key,
    }
}

/// The web side: its sockets and the form being read.
pub struct Http<'a> {
    handles: [SocketHandle; SOCKETS],
    conns: [Conn; SOCKETS],
    port: u16,
    /// The page's sequence number when the port was last read from it.
    seen: Option<Option<u32>>,
    /// The form being read (its place is the board's static: a form is
    /// over 700 bytes).
    form: &'a mut Vec<FormJob, 1>,
    /// The socket reading it.
    form_socket: Option<usize>,
    stats: HttpStats,
}

impl<'a> Http<'a> {
    /// The sockets `handles` and the form's place `form` (from
    /// [`HttpBuffers`]) on `port`; they listen from the first
    /// [`Http::service`].
    pub fn new(handles: [SocketHandle; SOCKETS], form: &'a mut Vec<FormJob, 1>, port: u16) -> Self {
        Http {
            handles,
            conns: [Conn::Reset; SOCKETS],
            port,
            seen: None,
            form,
            form_socket: None,
            stats: HttpStats::default(),
        }
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.port
    }

    /// Counters.
    pub fn stats(&self) -> HttpStats {
        self.stats
    }

    /// What socket `n` is doing.
    pub fn conn(&self, n: usize) -> Option<Conn> {
        self.conns.get(n).copied()
    }

    /// Looks at every socket after the interface was polled: reads heads
    /// and forms, writes answers, closes, listens again.
    pub fn service(
        &mut self,
        sockets: &mut SocketSet<'_>,
        bridge: &mut Bridge,
        gateway: Option<&mut Gateway>,
        net: NetView,
        now: u32,
    ) {
        self.follow_web_port(bridge, sockets);
        let mut view = View {
            bridge,
            gateway,
            net,
            now,
        };
        for n in 0..SOCKETS {
            let (Some(&handle), Some(conn)) = (self.handles.get(n), self.conns.get(n).copied())
            else {
                continue;
            };
            let next = match conn {
                Conn::Reset => Conn::Listen,
                Conn::Listen => match sockets.get::<tcp::Socket>(handle).state() {
                    State::Established | State::CloseWait => self.accept(n, sockets, now),
                    State::Closed | State::TimeWait => {
                        sockets.get_mut::<tcp::Socket>(handle).abort();
                        Conn::Reset
                    }
                    _ => Conn::Listen,
                },
                Conn::Reading { since } => {
                    let socket = sockets.get_mut::<tcp::Socket>(handle);
                    self.read_head(n, socket, &mut view, since, now)
                }
                Conn::Body { since, left } => {
                    let socket = sockets.get_mut::<tcp::Socket>(handle);
                    self.read_body(n, socket, &mut view, since, left, now)
                }
                Conn::Reply { page, part, since } => {
                    let socket = sockets.get_mut::<tcp::Socket>(handle);
                    self.reply(socket, &mut view, page, part, since, now)
                }
                Conn::Closing { since } => {
                    settle(sockets.get_mut::<tcp::Socket>(handle), since, now)
                }
            };
            if self.form_socket == Some(n) && !matches!(next, Conn::Body { .. }) {
                self.form_socket = None;
            }
            let socket = sockets.get_mut::<tcp::Socket>(handle);
            if next == Conn::Listen && !socket.is_open() {
                // Cannot fail: the socket is closed and the port not 0.
                let _ = socket.listen(self.port);
            }
            if let Some(c) = self.conns.get_mut(n) {
                *c = next;
            }
        }
    }

    /// Listens on the web block's port once it changed (sockets busy
    /// finish on the old one).
    fn follow_web_port(&mut self, bridge: &mut Bridge, sockets: &mut SocketSet<'_>) {
        let Some(editor) = bridge.editor() else {
            return;
        };
        let seq = editor.sequence();
        if self.seen == Some(seq) {
            return;
        }
        self.seen = Some(seq);
        let port = editor.web().port;
        if port == self.port {
            return;
        }
        self.port = port;
        for (handle, conn) in self.handles.iter().zip(self.conns.iter_mut()) {
            if *conn == Conn::Listen {
                sockets.get_mut::<tcp::Socket>(*handle).abort();
                *conn = Conn::Reset;
            }
        }
    }

    /// A connection on socket `n`: read, unless it takes the last listening
    /// socket: then a silent older one is dropped, or it is answered 429.
    fn accept(&mut self, n: usize, sockets: &mut SocketSet<'_>, now: u32) -> Conn {
        let listening = self
            .conns
            .iter()
            .enumerate()
            .filter(|(i, c)| *i != n && **c == Conn::Listen)
            .count();
        if listening > 0 {
            return Conn::Reading { since: now };
        }
        self.stats.flood = self.stats.flood.wrapping_add(1);
        let silent = self
            .conns
            .iter()
            .enumerate()
            .filter_map(|(i, c)| match c {
                Conn::Reading { since } if i != n => Some((i, *since)),
                _ => None,
            })
            .filter(|&(i, _)| {
                self.handles
                    .get(i)
                    .is_some_and(|h| sockets.get::<tcp::Socket>(*h).recv_queue() == 0)
            })
            .max_by_key(|&(_, since)| now.wrapping_sub(since));
        match silent {
            Some((i, _)) => {
                if let (Some(h), Some(c)) = (self.handles.get(i), self.conns.get_mut(i)) {
                    sockets.get_mut::<tcp::Socket>(*h).abort();
                    *c = Conn::Reset;
                }
                Conn::Reading { since: now }
            }
            None => self.refuse(
                Status::TooManyRequests,
                "too many connections at once: try again in a second",
                now,
            ),
        }
    }

    fn refuse(&mut self, status: Status, reason: &'static str, now: u32) -> Conn {
        self.answer(Page::refused(status, reason), now)
    }

    fn answer(&mut self, page: Page, now: u32) -> Conn {
        if let Page::Refused(_) = page {
            self.stats.refused = self.stats.refused.wrapping_add(1);
        }
        Conn::Reply {
            page,
            part: 0,
            since: now,
        }
    }

    /// Reads the head (it starts at the receive buffer's start: one
    /// request per connection) and answers or starts the form.
    fn read_head(
        &mut self,
        n: usize,
        socket: &mut tcp::Socket<'_>,
        view: &mut View<'_>,
        since: u32,
        now: u32,
    ) -> Conn {
        if !matches!(socket.state(), State::Established | State::CloseWait) {
            socket.abort();
            return Conn::Reset;
        }
        let queued = socket.recv_queue();
        let parsed = match socket.peek(queued) {
            Ok(bytes) => request::parse(bytes),
            Err(_) => Parsed::Partial,
        };
        let head = match parsed {
            Parsed::Head(h) => h,
            Parsed::Bad(reason) => return self.refuse(Status::BadRequest, reason, now),
            Parsed::Partial if queued >= RX => {
                return self.refuse(
                    Status::HeadersTooLarge,
                    "the request's head is over 1,024 bytes",
                    now,
                )
            }
            Parsed::Partial if !socket.may_recv() && queued > 0 => {
                return self.refuse(Status::BadRequest, "the request ended within its head", now)
            }
            Parsed::Partial if !socket.may_recv() => {
                socket.close();
                return Conn::Closing { since: now };
            }
            Parsed::Partial if now.wrapping_sub(since) >= REQUEST_MS => {
                return self.refuse(
                    Status::RequestTimeout,
                    "the request did not arrive within 5 s",
                    now,
                )
            }
            Parsed::Partial => return Conn::Reading { since },
        };
        self.stats.requests = self.stats.requests.wrapping_add(1);
        let _ = socket.recv(|b| (head.len.min(b.len()), ()));
        self.route(n, head, view, now)
    }

    fn route(&mut self, n: usize, head: Head, view: &mut View<'_>, now: u32) -> Conn {
        let page = match head.route {
            Route::BadMethod => {
                return self.refuse(
                    Status::MethodNotAllowed,
                    "this page takes GET (forms POST)",
                    now,
                )
            }
            Route::NotFound => return self.refuse(Status::NotFound, "no such page here", now),
            Route::Status => Page::Status,
            Route::Live => Page::Live,
            Route::Config => Page::Config,
            Route::Frames => Page::Frames,
            Route::SaveConfig | Route::Restart => return self.start_form(n, head, view, now),
        };
        if let Some(e) = view.bridge.editor() {
            if e.web().reads == Reads::Password && e.verifier().is_some() {
                let password = head.password.as_deref().unwrap_or(&[]);
                match e.check(password, now) {
                    Check::Granted | Check::NoPassword => {}
                    Check::Shut => {
                        return self.refuse(
                            Status::TooManyRequests,
                            "a wrong password came less than a second ago: wait, then try again",
                            now,
                        )
                    }
                    Check::Wrong => {
                        return self.refuse(
                            Status::Unauthorized,
                            "reading this gateway needs its password",
                            now,
                        )
                    }
                }
            }
        }
        self.answer(page, now)
    }

    fn start_form(&mut self, n: usize, head: Head, view: &mut View<'_>, now: u32) -> Conn {
        let Some(editor) = view.bridge.editor() else {
            return self.refuse(
                Status::Unavailable,
                "this gateway keeps no configuration it can write",
                now,
            );
        };
        if head.origin == Origin::Other {
            return self.refuse(
                Status::Forbidden,
                "a form from another page is refused: nothing was written",
                now,
            );
        }
        if !head.form {
            return self.refuse(
                Status::UnsupportedMediaType,
                "a change is a form (application/x-www-form-urlencoded)",
                now,
            );
        }
        let Some(len) = head.content_length else {
            return self.refuse(
                Status::LengthRequired,
                "a form needs its Content-Length",
                now,
            );
        };
        if len > BODY_MAX {
            return self.refuse(
                Status::ContentTooLarge,
                "the form is over 2,048 bytes: nothing was written",
                now,
            );
        }
        if self.form_socket.is_some() {
            return self.refuse(
                Status::Conflict,
                "another change is being read: try again in a moment",
                now,
            );
        }
        self.form.clear();
        // Cannot fail: the vector was just emptied.
        let _ = self.form.push(FormJob {
            parser: FormParser::new(),
            fields: Fields {
                route: head.route,
                settings: editor.settings(),
                password: Vec::new(),
                new1: Vec::new(),
                new2: Vec::new(),
                error: None,
            },
        });
        self.form_socket = Some(n);
        if len == 0 {
            return self.finish_form(view, now);
        }
        Conn::Body {
            since: now,
            left: len,
        }
    }

    fn read_body(
        &mut self,
        n: usize,
        socket: &mut tcp::Socket<'_>,
        view: &mut View<'_>,
        since: u32,
        left: u32,
        now: u32,
    ) -> Conn {
        let job = match self.form.first_mut() {
            Some(job) if self.form_socket == Some(n) => job,
            _ => {
                socket.abort();
                return Conn::Reset;
            }
        };
        let want = (left as usize).min(BODY_BYTES_PER_ROUND);
        let FormJob { parser, fields, .. } = job;
        let took = socket
            .recv(|b| {
                let k = b.len().min(want);
                for &byte in b.get(..k).unwrap_or(&[]) {
                    fields.took(parser.push(byte));
                }
                (k, k)
            })
            .unwrap_or(0);
        let left = left.saturating_sub(took as u32);
        if left == 0 {
            fields.took(parser.end());
            return self.finish_form(view, now);
        }
        if !socket.may_recv() && !socket.can_recv() {
            return self.refuse(
                Status::BadRequest,
                "the form ended short of its length",
                now,
            );
        }
        if now.wrapping_sub(since) >= REQUEST_MS {
            return self.refuse(
                Status::RequestTimeout,
                "the form did not arrive within 5 s: nothing was written",
                now,
            );
        }
        Conn::Body { since, left }
    }

    /// The whole form came: check and carry it out.
    fn finish_form(&mut self, view: &mut View<'_>, now: u32) -> Conn {
        self.form_socket = None;
        let Some(FormJob { fields: job, .. }) = self.form.first() else {
            return self.refuse(Status::InternalError, "the form was lost", now);
        };
        if let Some(r) = job.error {
            return self.answer(Page::Refused(r), now);
        }
        let Some(editor) = view.bridge.editor() else {
            return self.refuse(Status::Unavailable, "no configuration to write", now);
        };
        let page = if job.route == Route::Restart {
            match editor.request_restart(&job.password, now) {
                Ok(()) => Page::Restarting,
                Err(e) => refusal_page(e),
            }
        } else if job.new1 != job.new2 {
            Page::Refused(bad(
                "the two new passwords differ: nothing was written",
                None,
            ))
        } else {
            let new = (!job.new1.is_empty()).then_some(&job.new1[..]);
            if !job.settings.any_changed() && new.is_none() {
                match editor.check(&job.password, now) {
                    Check::Granted => Page::Unchanged,
                    Check::NoPassword => refusal_page(EditRefusal::NoPassword),
                    Check::Wrong => refusal_page(EditRefusal::WrongPassword),
                    Check::Shut => refusal_page(EditRefusal::Shut),
                }
            } else {
                match editor.commit_settings(&job.settings, &job.password, new, now) {
                    Ok(a) => Page::Saved(a),
                    Err(e) => refusal_page(e),
                }
            }
        };
        if let Page::Saved(_) = page {
            self.stats.saved = self.stats.saved.wrapping_add(1);
        }
        self.answer(page, now)
    }

    /// Writes what fits of `page` from part `part`.
    fn reply(
        &mut self,
        socket: &mut tcp::Socket<'_>,
        view: &mut View<'_>,
        page: Page,
        mut part: u16,
        mut since: u32,
        now: u32,
    ) -> Conn {
        if !socket.may_send() {
            socket.abort();
            return Conn::Reset;
        }
        for _ in 0..PARTS_PER_ROUND {
            let empty = socket.send_queue() == 0;
            let sent = socket.send(|buf| {
                let mut out = Buf::new(buf);
                if !pages::part(page, usize::from(part), view, &mut out) {
                    (0, Some(false))
                } else if out.lost > 0 {
                    (0, None)
                } else {
                    (out.len(), Some(true))
                }
            });
            match sent {
                Ok(Some(true)) => {
                    part = part.wrapping_add(1);
                    since = now;
                }
                Ok(Some(false)) => {
                    socket.close();
                    return Conn::Closing { since: now };
                }
                // A part larger than the whole buffer: cannot be sent.
                Ok(None) if empty => {
                    socket.abort();
                    return Conn::Reset;
                }
                Ok(None) | Err(_) => break,
            }
        }
        if now.wrapping_sub(since) >= STALL_MS {
            self.stats.stalled = self.stats.stalled.wrapping_add(1);
            socket.abort();
            return Conn::Reset;
        }
        Conn::Reply { page, part, since }
    }
}

/// The page for a refused change.
fn refusal_page(e: EditRefusal) -> Page {
    let r = |status, reason| Page::refused(status, reason);
    match e {
        EditRefusal::WrongPassword => r(Status::Forbidden, "wrong password: nothing was written"),
        EditRefusal::Shut => r(
            Status::TooManyRequests,
            "a wrong password came less than a second ago: wait, then try again; nothing was written",
        ),
        EditRefusal::NoPassword => r(
            Status::Forbidden,
            "no password is set yet: choose one (new password) first; nothing was written",
        ),
        EditRefusal::Setting(s) => Page::Refused(bad(s.reason, s.key)),
        EditRefusal::BadPassword(PasswordError::Length) => {
            r(Status::BadRequest, "the new password must be 8 to 64 characters")
        }
        EditRefusal::BadPassword(PasswordError::Control) => r(
            Status::BadRequest,
            "the new password must hold no control characters",
        ),
        EditRefusal::Invalid(_) => r(Status::BadRequest, "a block of the new page does not check"),
        EditRefusal::Staging => r(Status::Conflict, "another change came in between"),
        EditRefusal::Store(_) => r(
            Status::InternalError,
            "the configuration could not be written",
        ),
    }
}

/// A closing socket: listens again once closed, is reset if it lingers.
fn settle(socket: &mut tcp::Socket<'_>, since: u32, now: u32) -> Conn {
    while socket.can_recv() {
        if socket.recv(|b| (b.len(), ())).is_err() {
            break;
        }
    }
    match socket.state() {
        State::Closed => Conn::Listen,
        State::TimeWait => {
            socket.abort();
            Conn::Reset
        }
        _ if now.wrapping_sub(since) >= CLOSE_LIMIT_MS => {
            socket.abort();
            Conn::Reset
        }
        _ => Conn::Closing { since },
    }
}
