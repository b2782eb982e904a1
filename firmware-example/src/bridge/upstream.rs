//! Frames from the host, sorted by their envelope (header, station, ID):
//! the bridge's own station, other stations, refused commands, 26DH, and
//! the pass-through; and the bridge's own answers going up: the status
//! query, and the configuration messages ([`crate::config::wire`]) answered
//! through the board's [`Editor`], whose granted restart goes when due.

use iai_protocol_b::catalogue;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameSkipper, Skipped, Status};
use iai_protocol_b::frame::{emit_frame, read_envelope, Frame, Header, Station, ENVELOPE_LEN};

use super::history::Dir::{FromHost, ToHost};
use super::{write_some, Bridge, Error, Mode, Port, STREAM};
use crate::codes;
use crate::config::editor::Editor;
use crate::config::page::{ACCESS_AT, WINDOW};
use crate::config::wire::{self, PageInfo, Request};
use crate::config::Policy;
use crate::log;
use crate::status::{self, LastError};

/// Upstream bytes read per call (a staging chunk, not a message buffer).
const IN_CHUNK: usize = 16;

/// One step of reading the upstream.
pub(super) enum Up {
    Byte(u8),
    /// Bytes were lost before the next one.
    Lost,
    Empty,
}

/// What reading the host did.
pub(super) enum Read {
    /// Whether bytes moved.
    Moved(bool),
    /// The quit sequence arrived.
    Quit,
}

/// The upstream side: the envelope being read, a staging chunk, the
/// skipper of a refused command, the quit detector.
pub(super) struct Upstream {
    pub(super) head: [u8; ENVELOPE_LEN],
    pub(super) head_len: usize,
    inbuf: [u8; IN_CHUNK],
    in_pos: usize,
    in_len: usize,
    skipper: Option<FrameSkipper>,
    quit: QuitDetector,
}

impl Upstream {
    /// Host bytes read from the port and not yet sorted.
    pub(super) fn staged(&self) -> usize {
        self.in_len.saturating_sub(self.in_pos)
    }

    #[inline(always)]
    pub(super) const fn new() -> Self {
        Upstream {
            head: [0; ENVELOPE_LEN],
            head_len: 0,
            inbuf: [0; IN_CHUNK],
            in_pos: 0,
            in_len: 0,
            skipper: None,
            quit: QuitDetector::new(),
        }
    }
}

impl Bridge {
    /// The modes that read the host (idle, envelope, command, skip): read
    /// and sort bytes until the mode changes or none is left.
    pub(super) fn poll_upstream<U: Port, D: Port>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<Read, Error<U::Error, D::Error>> {
        if let Some(editor) = self.editor.as_deref_mut() {
            editor.poll(now);
        }
        let mut moved = self
            .drain_downstream(down, now)
            .map_err(Error::Downstream)?;
        while matches!(
            self.mode,
            Mode::Idle | Mode::Head | Mode::Command | Mode::Skip { .. }
        ) {
            let b = match self.next_up(up).map_err(Error::Upstream)? {
                Up::Empty => break,
                Up::Lost => {
                    moved = true;
                    if self.mode != Mode::Idle {
                        self.stats.rejected += 1;
                    }
                    self.go_idle();
                    continue;
                }
                Up::Byte(b) => b,
            };
            moved = true;
            if self.cfg.quit_sequence && self.up.quit.feed(b, now) && self.mode == Mode::Idle {
                return Ok(Read::Quit);
            }
            self.on_upstream_byte(b, now);
        }
        Ok(Read::Moved(moved))
    }

    /// The next upstream byte. Checks the overrun count each time it reads
    /// a new chunk from the port, so every byte handed out before
    /// [`Up::Lost`] was received before the loss.
    pub(super) fn next_up<U: Port>(&mut self, up: &mut U) -> Result<Up, U::Error> {
        let u = &mut self.up;
        if u.in_pos >= u.in_len {
            let lost = up.take_overruns();
            if lost > 0 {
                self.stats.upstream_overruns = self.stats.upstream_overruns.wrapping_add(lost);
                return Ok(Up::Lost);
            }
            if !up.read_ready()? {
                return Ok(Up::Empty);
            }
            let n = up.read(&mut u.inbuf)?;
            self.stats.upstream_in += n as u64;
            u.in_pos = 0;
            u.in_len = n.min(IN_CHUNK);
        }
        match u.inbuf.get(u.in_pos).copied() {
            Some(b) if u.in_pos < u.in_len => {
                u.in_pos += 1;
                Ok(Up::Byte(b))
            }
            _ => Ok(Up::Empty),
        }
    }

    /// One upstream byte in the Idle, Head, Command or Skip mode.
    fn on_upstream_byte(&mut self, b: u8, now: u32) {
        let is_header = Header::from_byte(b).is_some();
        match self.mode {
            Mode::Idle | Mode::Head if is_header => {
                // When a host's frame starts varies from boot to boot (a
                // QEMU run's RAM starts zeroed, a board's may not be
                // random): the fences to come take it in.
                self.line
                    .stir(now ^ (self.stats.upstream_in as u32).rotate_left(16));
                self.up.head[0] = b;
                self.up.head_len = 1;
                self.mode = Mode::Head;
            }
            Mode::Idle => {}
            Mode::Head => {
                if let Some(slot) = self.up.head.get_mut(self.up.head_len) {
                    *slot = b;
                    self.up.head_len += 1;
                }
                if self.up.head_len == ENVELOPE_LEN {
                    self.classify(now);
                }
            }
            Mode::Command => self.command_byte(b, now),
            Mode::Skip { answer } => self.skip_byte(b, answer, now),
            _ => {}
        }
    }

    /// The envelope is complete: decide what to do with the frame.
    fn classify(&mut self, now: u32) {
        let head = self.up.head;
        if let Some((Header::Command, station, id)) = read_envelope(&head) {
            if station == self.cfg.bridge_station {
                self.start_command(now);
                return;
            }
            if station != self.cfg.controller_station {
                self.stats.other_station += 1;
                self.start_skip(None);
                return;
            }
            if !self.cfg.policy.allows(id) {
                log::warning!("command {=u16:X}H refused by the policy", id);
                self.start_skip(Some(codes::REFUSED));
                return;
            }
            if id == STREAM.id {
                // Its records are not kept: the envelope says what it was.
                self.history.record(FromHost, &head, head.len(), now);
                self.start_stream(station, now);
                return;
            }
        }
        self.start_command(now);
    }

    /// Pass-through (or own query): the envelope goes to the frame decoder.
    fn start_command(&mut self, now: u32) {
        let frames = self.job.idle_decoder();
        frames.reset();
        frames.set_policy(BypassPolicy::CommandsOnly);
        self.mode = Mode::Command;
        let head = self.up.head;
        for &b in &head {
            self.command_byte(b, now);
            if self.mode != Mode::Command {
                break;
            }
        }
    }

    /// Skip the rest of the frame, summing its checksum.
    fn start_skip(&mut self, answer: Option<u16>) {
        self.up.skipper = Some(FrameSkipper::new(
            Header::Command,
            &self.up.head,
            BypassPolicy::CommandsOnly,
        ));
        self.mode = Mode::Skip { answer };
    }

    /// One byte of a skipped command.
    fn skip_byte(&mut self, b: u8, answer: Option<u16>, now: u32) {
        let Some(skipper) = self.up.skipper.as_mut() else {
            self.go_idle();
            return;
        };
        let Status::Complete(end) = skipper.push(b) else {
            return;
        };
        match (end, answer) {
            (Skipped::End { checksum_ok: true }, Some(code)) => {
                self.stats.refused += 1;
                let station = self.cfg.controller_station;
                self.respond_error(station, code, now);
            }
            (Skipped::End { checksum_ok: true }, None) => self.go_idle(),
            (Skipped::End { checksum_ok: false }, _) => {
                self.stats.rejected += 1;
                self.go_idle();
            }
            (Skipped::Broken, _) => {
                // The frame was cut: this byte may start the next one.
                self.stats.rejected += 1;
                self.go_idle();
                self.on_upstream_byte(b, now);
            }
        }
    }

    /// One byte of a pass-through command (or an own query).
    fn command_byte(&mut self, b: u8, now: u32) {
        let bridge_station = self.cfg.bridge_station;
        let policy = self.cfg.policy;
        // What a checked frame asks for: decided while it is borrowed.
        let Status::Complete(event) = self.job.idle_decoder().push(b) else {
            return;
        };
        let decided = match event {
            Event::Frame(f) if f.header() == Header::Command => {
                let bytes = f.as_bytes();
                self.history.record(FromHost, bytes, bytes.len(), now);
                let (station, id) = (f.station(), f.code());
                if station == bridge_station {
                    Next::Own {
                        station,
                        id,
                        body_empty: f.body().is_empty(),
                    }
                } else if carries_a_frame_in_its_text(&f, policy) {
                    Next::Refuse(station)
                } else {
                    Next::Forward(id)
                }
            }
            // Only commands go downstream.
            Event::Frame(_) => Next::Drop(false),
            Event::Error(_e) => {
                log::warning!("malformed upstream command dropped: {}", _e);
                Next::Drop(Header::from_byte(b).is_some())
            }
        };
        match decided {
            Next::Own {
                station,
                id,
                body_empty,
            } => {
                self.stats.own_queries += 1;
                self.own_query(station, id, body_empty, now);
            }
            Next::Refuse(station) => {
                log::warning!("200H with a frame in its text refused");
                self.stats.refused += 1;
                self.respond_error(station, codes::REFUSED, now);
            }
            Next::Forward(id) => {
                // Started on the line once the guest (if any) let go of
                // it; sent once: the host resends after its own timeout.
                self.forward_pending = Some(id);
                self.mode = Mode::Forward;
                self.out_off = 0;
            }
            Next::Drop(restart) => {
                self.stats.rejected += 1;
                self.go_idle();
                if restart {
                    // The header byte that cut the frame starts the next one.
                    self.on_upstream_byte(b, now);
                }
            }
        }
    }

    /// A command to the bridge's own station. Not inlined: the
    /// configuration messages' buffers (passwords, a window) stay off the
    /// stack of every other command.
    #[inline(never)]
    fn own_query(&mut self, station: Station, id: u16, body_empty: bool, now: u32) {
        if id == codes::STATUS_QUERY && body_empty {
            self.status_reply(station, now);
            return;
        }
        if id == catalogue::TEST_CALL.id {
            // The echo, as a controller gives it (2003 p. 15): a host can
            // fence its line to the bridge's own station.
            let frames = self.job.idle_decoder();
            let text = frames.last_frame().map_or(&[][..], |f| f.body());
            self.resp_len = emit_frame(
                &mut self.resp,
                Header::Response,
                station,
                catalogue::TEST_CALL.id,
                Default::default(),
                |w| w.put(text),
            )
            .unwrap_or(0);
            self.out_off = 0;
            self.mode = Mode::Respond;
            return;
        }
        let Bridge {
            job, editor, resp, ..
        } = self;
        let request = job
            .idle_decoder()
            .last_frame()
            .and_then(|f| Request::parse(id, f.body()));
        let answered = match (request, editor.as_deref_mut()) {
            (None, _) => Err(codes::UNKNOWN_QUERY),
            (Some(Err(())), _) => Err(codes::MALFORMED),
            (Some(Ok(_)), None) => Err(codes::STORE_FAILED),
            (Some(Ok(r)), Some(e)) => config_answer(e, r, station, resp, now),
        };
        match answered {
            Ok(len) => {
                self.resp_len = len;
                self.out_off = 0;
                self.mode = Mode::Respond;
            }
            Err(code) => self.respond_error(station, code, now),
        }
    }

    /// The status reply goes up next.
    #[inline(never)]
    fn status_reply(&mut self, station: Station, now: u32) {
        let report = status::Report {
            now_ms: now,
            config: &self.cfg,
            source: self.source,
            stats: &self.stats,
            last_error: self.last_error,
        };
        self.resp_len = report.emit(station, &mut self.resp).unwrap_or(0);
        self.out_off = 0;
        self.mode = Mode::Respond;
    }

    /// The Respond mode: the bridge's own reply goes up.
    pub(super) fn poll_respond<U: Port>(&mut self, up: &mut U, now: u32) -> Result<bool, U::Error> {
        let resp = self.resp.get(..self.resp_len).unwrap_or(&[]);
        let out = &mut self.stats.upstream_out;
        let n = write_some(up, resp, &mut self.out_off, out)?;
        if self.out_off >= self.resp_len {
            self.history.record(ToHost, resp, resp.len(), now);
            self.go_idle();
        }
        Ok(n > 0)
    }

    /// Queue the 26DH's `#` reply with the count.
    pub(super) fn respond_count(&mut self, station: Station, count: u16) {
        self.go_idle();
        self.resp_len = emit_frame(
            &mut self.resp,
            Header::Response,
            station,
            STREAM.id,
            Default::default(),
            |w| STREAM.write_prefix(w, 0, count),
        )
        .unwrap_or(0);
        self.mode = Mode::Respond;
    }

    /// Queue an `&` reply with one of the bridge's codes.
    pub(super) fn respond_error(&mut self, station: Station, code: u16, now: u32) {
        self.go_idle();
        self.last_error = Some(LastError { code, at_ms: now });
        self.resp_len = emit_frame(
            &mut self.resp,
            Header::Error,
            station,
            code,
            Default::default(),
            |_| Ok(()),
        )
        .unwrap_or(0);
        self.mode = Mode::Respond;
    }
}

/// Carries out configuration request `r` with `e` and writes its reply
/// into `resp`: the reply's length, or the `&` code.
#[inline(never)]
fn config_answer(
    e: &mut Editor<'static>,
    r: Request<'_>,
    station: Station,
    resp: &mut [u8],
    now: u32,
) -> Result<usize, u16> {
    let refused = |r: crate::config::editor::Refusal| wire::refusal_code(&r);
    let mut password = [0u8; wire::PASSWORD_MAX];
    let mut new = [0u8; wire::PASSWORD_MAX];
    let emitted = match r {
        Request::Read { at, password: p } => {
            let len = wire::window_at(at).ok_or(codes::MALFORMED)?;
            let mut window = [0u8; WINDOW];
            if at == ACCESS_AT {
                let p = wire::unhex(p, &mut password).ok_or(codes::MALFORMED)?;
                e.read_verifier(p, now, &mut window).map_err(refused)?;
            } else {
                let bytes = window.get_mut(..len).ok_or(codes::MALFORMED)?;
                e.read_host(at, bytes).map_err(refused)?;
            }
            let bytes = window.get(..len).ok_or(codes::MALFORMED)?;
            let info = PageInfo {
                seq: e.sequence(),
                password_set: e.verifier().is_some(),
                restart_pending: e.restart_pending(),
            };
            wire::emit_read_reply(resp, station, at, info, bytes)
        }
        Request::Stage { at, digits } => {
            let mut window = [0u8; WINDOW];
            let bytes = wire::unhex(digits, &mut window).ok_or(codes::MALFORMED)?;
            let next = e.stage(at, bytes).map_err(refused)?;
            wire::emit_reply(resp, station, codes::CONFIG_STAGE, &[(next as u64, 3)])
        }
        Request::Apply { crc, password: p } => {
            let p = wire::unhex(p, &mut password).ok_or(codes::MALFORMED)?;
            let a = e.apply(p, crc, now).map_err(refused)?;
            let fields = [(u64::from(a.seq), 8), (u64::from(a.restart_needed), 1)];
            wire::emit_reply(resp, station, codes::CONFIG_APPLY, &fields)
        }
        Request::Restart { password: p } => {
            let p = wire::unhex(p, &mut password).ok_or(codes::MALFORMED)?;
            e.request_restart(p, now).map_err(refused)?;
            wire::emit_reply(resp, station, codes::RESTART, &[])
        }
        Request::Password { current, new: n } => {
            let current = wire::unhex(current, &mut password).ok_or(codes::MALFORMED)?;
            let n = wire::unhex(n, &mut new).ok_or(codes::MALFORMED)?;
            let a = e.set_password(current, n, now).map_err(refused)?;
            wire::emit_reply(
                resp,
                station,
                codes::CONFIG_PASSWORD,
                &[(u64::from(a.seq), 8)],
            )
        }
    };
    emitted.map_err(|_| codes::INTERNAL)
}

/// What a complete upstream command asks of the bridge.
enum Next {
    Own {
        station: Station,
        id: u16,
        body_empty: bool,
    },
    Refuse(Station),
    Forward(u16),
    /// Dropped; `true` if the byte that broke it starts the next frame.
    Drop(bool),
}

/// Whether a command may carry a frame in its free text under `policy`: a
/// 200H whose ten characters hold a header byte, CR or LF. A controller
/// that decodes again inside a broken 200H (as the project's own decoder
/// does) could run that frame, after one line error, although the policy
/// refuses it; so under a restricting policy such a 200H is refused.
fn carries_a_frame_in_its_text(f: &Frame<'_>, policy: Policy) -> bool {
    if policy == Policy::ForwardAll || f.code() != iai_protocol_b::catalogue::TEST_CALL.id {
        return false;
    }
    f.body()
        .iter()
        .any(|&b| Header::from_byte(b).is_some() || b == b'\r' || b == b'\n')
}

/// Recognises [`codes::QUIT`] after [`super::QUIT_GUARD_MS`] of silence.
pub(super) struct QuitDetector {
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

    /// Feed one byte read at `now_ms`; `true` once the sequence is complete.
    fn feed(&mut self, byte: u8, now_ms: u32) -> bool {
        let quiet_before = self
            .last_byte_ms
            .is_none_or(|last| now_ms.wrapping_sub(last) >= super::QUIT_GUARD_MS);
        self.last_byte_ms = Some(now_ms);
        if self.matched > 0 && codes::QUIT.get(self.matched) == Some(&byte) {
            self.matched += 1;
            if self.matched == codes::QUIT.len() {
                self.matched = 0;
                return true;
            }
        } else if byte == codes::QUIT[0] && quiet_before {
            self.matched = 1;
        } else {
            self.matched = 0;
        }
        false
    }
}
