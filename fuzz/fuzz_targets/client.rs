//! The request engine (`client::Client`) over a `line::Line`, on a virtual
//! clock, against a simulated controller that answers in order.
//!
//! Input: the line (`common/link.rs`), its flags' 0x20 bit for the 216H
//! detail (`with_error_detail`), 0x40 for skipping it on the bridge's codes
//! (`with_error_detail_except`), 0x80 for proofs (`with_proof`); a byte:
//! requests 1-4; then a script. A script byte picks each request: 212H,
//! 235H (unsafe), 25BH (no normal response), 216H through `start`, an ID
//! outside the catalogue or any catalogue command's default frame
//! (200H included) through `start_frame`. The controller echoes fences and
//! 200H texts and answers each send in order; per transmission an op byte
//! (bits 0-2 length ms, bits 3-4 = 2 lost, bits 5-7 the reply: 0 at once,
//! 1 lost, 2 corrupted, 3 copied later, 4 an `&`, 5 a body that does not
//! parse, 6 another station's or ID's frame first, 7 late with a copy;
//! then a byte and a delay); fences get an `&` for 4 and 5, 25BH (no
//! normal response) silence for 0, an `&` for 2-5 and 7. While it
//! waits (`% 6`): time, noise (raw with the link's bit), a copy of any
//! reply made (whole or broken), the next delivery, abandoning the request
//! for the next one, the deadline. Every byte is fed: the client takes all.
//!
//! A `Shadow` mirrors the client's decoders (its own, and the line's
//! while it keeps its reply) and tells which delivery made each frame.
//! Checked (beside no panic, a bounded end, waits never in the past, before
//! the first fence or beyond the longest hold):
//! - **a reply taken (`Answer` / `Rejected`) is one the controller made for
//!   a send of the command in flight** (or its 216H query) unless that
//!   delivery broke the contract (`Link::arrives`), came from raw noise,
//!   or an echo outside the contract settled what it answered (a command
//!   that took another's reply leaves its own adrift); taken only while
//!   awaited, from the station, with the ID in flight, never while the
//!   client keeps a reply; a 200H reply taken echoes the call's text;
//! - `Mismatch` only for a reply of the ID in flight that does not parse
//!   (200H: whose text is not the call's); `Fence` exactly for the echo of
//!   the fence in flight (its text, before its timeout was seen);
//!   `Foreign` exactly for another station's frame or a command;
//!   **`Unplaced` never for a reply within the contract** (an original in
//!   time, a copy in the window of a first arrival the line heard whole);
//! - what goes out: fences numbered from 1 with the seed's text (these
//!   engines never stir it), the command as started, the 216H query only
//!   with the option and not for a bridge code under the exception; sends
//!   within `max_sends`, once for unsafe commands and 25BH; resends,
//!   `Timeout` / `OutcomeUnknown` (by resend safety, with the sends) not
//!   before `sent + timeout` unless a broken frame came; `Done(Ok)` with
//!   the reply taken (`reply_frame`, typed `response` parse), for 25BH at
//!   its timeout; `Controller` with the detail of the 216H reply taken;
//! - proofs: `Ok` only after a fence echoed (or, without one, the replies
//!   waited out) with nothing unplaced since the command was asked; asked
//!   again only if something was, safe commands only, at most twice;
//!   `Unconfirmed` only then; the line's `stats()` agree.
#![no_main]

#[path = "common/link.rs"]
mod link;
#[path = "common/records.rs"]
mod records;

use firmware_example::codes;
use iai_protocol_b::catalogue::{self, Reply, Resend};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::client::{Client, Pending};
use iai_protocol_b::decoder::Status;
use iai_protocol_b::engine::Step;
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::line::{Heard, Line};
use iai_protocol_b::message::{
    AxisStatusQuery, Command, ErrorDetailQuery, ErrorDetailResponse, ErrorResponse, Message,
    RelativeMove, Response, SoftwareReset,
};
use libfuzzer_sys::fuzz_target;
use link::{Delivery, Kind, Link, Seen, Setup, Shadow, Source};
use records::Input;

const CMD: usize = iai_protocol_b::limits::TTA.command;
const REPLY: usize = iai_protocol_b::limits::TTA.response;

/// An ID outside the catalogue (a bridge passing on what it does not know).
const UNKNOWN_ID: u16 = 0x2FE;

/// Times a client with proofs asks a query again (its `PROOF_ASKS`).
const PROOF_ASKS: u8 = 2;

/// Finding F18 (open, fuzz/README.md): bytes the client's decoder still
/// holds at a send (a late reply swallowed as a 200H's ten characters)
/// are dropped, and the line told (`unread`), only once the line has
/// decided to send: the send does not wait out the copy window, and a copy
/// of that reply (within the window) answers it. `false`: a copy of a
/// reply dropped so is not blamed.
const F18_FIXED: bool = false;

/// The request's kind, with the client's ticket to its typed reply.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Typed {
    Raw,
    AxisStatus(Pending<AxisStatusQuery>),
    RelativeMove(Pending<RelativeMove>),
    SoftwareReset(Pending<SoftwareReset>),
    ErrorDetail(Pending<ErrorDetailQuery>),
}

/// A request: its command (phase 0) and, after an `&`, its 216H query
/// (phase 1).
struct Req {
    serial: usize,
    id: u16,
    typed: Typed,
    bytes: Vec<u8>,
    phase: u8,
    sends: u8,
    rejected: Option<u16>,
    /// The frame taken as the reply of the phase in flight.
    taken: Option<Vec<u8>>,
    /// A fence's echo was heard since that reply was taken.
    echo_since_taken: bool,
    /// The 216H reply taken: its error number (`None` if forged).
    detail: Option<Option<u16>>,
    detail_failed: bool,
    /// A 216H query went out.
    asked_detail: bool,
    /// Times it was asked again for want of a proof, and the line's count
    /// of unplaced frames when it was last asked.
    asked_again: u8,
    unplaced_mark: u32,
}

/// Who a command frame is for: the request, its phase (1: the 216H
/// query), and the ask (a query asked again for a proof is a command of
/// its own).
type Owner = (usize, u8, u8);

struct H<'a> {
    input: Input<'a>,
    setup: Setup,
    link: Link,
    line: Line,
    client: Client<CMD, REPLY>,
    shadow: Shadow<REPLY>,
    clock: u64,
    req: Option<Req>,
    /// Who each command frame the controller received belongs to (`None`:
    /// a fence).
    owners: Vec<Option<Owner>>,
    /// The last fence sent (controller command index), and whether its
    /// echo is still awaited (sent, no echo, no timeout seen, not
    /// abandoned).
    last_fence: Option<usize>,
    fence_awaited: bool,
    /// A reply is awaited: `sent` was called and nothing sent since.
    awaiting: bool,
    last_sent: u64,
    broken_since_sent: bool,
    adrift: Vec<Owner>,
    /// Replies to commands before this one (controller command index) are
    /// not blamed: an echo outside the contract settled them.
    excused_before: usize,
    /// Replies (made indices) whose bytes the client dropped unread at a
    /// send (F18).
    dropped: Vec<usize>,
    prove: bool,
    transmitted: bool,
    commands: u32,
    sends: u32,
    fences: u32,
}

impl H<'_> {
    fn now(&self) -> u32 {
        self.setup.base.wrapping_add(self.clock as u32)
    }

    fn id_in_flight(&self) -> u16 {
        let r = self.req.as_ref().expect("a request");
        if r.phase == 1 {
            ErrorDetailQuery::ID
        } else {
            r.id
        }
    }

    fn owner(&self) -> Owner {
        let r = self.req.as_ref().expect("a request");
        (r.serial, r.phase, r.asked_again)
    }

    fn start(&mut self, serial: usize, pick: u8) {
        let now = self.now();
        let station = self.setup.line.station;
        let checksum = self.setup.line.checksum;
        let emit = |r: &dyn Fn(&mut [u8]) -> usize| {
            let mut buf = vec![0u8; 128];
            let n = r(&mut buf);
            buf.truncate(n);
            buf
        };
        if self.fence_awaited {
            // Starting abandons what the line was doing, a fence too.
            self.fence_awaited = false;
        }
        let (id, typed, bytes) = match pick % 8 {
            0 => {
                let q = AxisStatusQuery::default();
                let p = self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (AxisStatusQuery::ID, Typed::AxisStatus(p), b)
            }
            1 => {
                let q = RelativeMove::default();
                let p = self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (RelativeMove::ID, Typed::RelativeMove(p), b)
            }
            2 => {
                let q = SoftwareReset::default();
                let p = self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (SoftwareReset::ID, Typed::SoftwareReset(p), b)
            }
            3 => {
                let q = ErrorDetailQuery::latest_system_error();
                let p = self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (ErrorDetailQuery::ID, Typed::ErrorDetail(p), b)
            }
            4 => {
                let b = link::frame(Header::Command, station, UNKNOWN_ID, &[]);
                self.client
                    .start_frame(&mut self.line, &b, now)
                    .expect("starts");
                (UNKNOWN_ID, Typed::Raw, b)
            }
            _ => {
                let all = catalogue::ALL;
                let info = all[usize::from(self.input.u8()) % all.len()];
                let cmd = Command::default_for(info.id).expect("every catalogue ID has a command");
                let mut b = vec![0u8; cmd.emit_len()];
                let n = cmd.emit_with(station, checksum, &mut b).expect("emits");
                assert_eq!(n, b.len(), "emit_len");
                self.client
                    .start_frame(&mut self.line, &b, now)
                    .expect("starts");
                (info.id, Typed::Raw, b)
            }
        };
        trace!("t={} START request {serial}: {id:03X}", self.clock);
        self.commands += 1;
        self.awaiting = false;
        self.req = Some(Req {
            serial,
            id,
            typed,
            bytes,
            phase: 0,
            sends: 0,
            rejected: None,
            taken: None,
            echo_since_taken: false,
            detail: None,
            detail_failed: false,
            asked_detail: false,
            asked_again: 0,
            unplaced_mark: self.line.stats().unplaced,
        });
    }

    /// Delivers what is due by `to`, moving the clock.
    fn deliver_until(&mut self, to: u64) {
        while let Some(d) = self.link.due(to) {
            self.clock = self.clock.max(d.at);
            self.feed(d);
        }
    }

    /// Feeds one delivery, checking what each frame did.
    fn feed(&mut self, mut d: Delivery) {
        d.at = self.clock;
        self.link.arrives(&mut d, self.clock);
        self.shadow.begin(&d);
        let mut rest = &d.bytes[..];
        let now = self.now();
        loop {
            let errors = self.line.stats().line_errors;
            let r = self.client.received(&mut self.line, rest, now);
            if self.line.stats().line_errors > errors {
                self.broken_since_sent = true;
            }
            trace!(
                "t={} RX {:?} -> {:?} ({:?}{})",
                self.clock,
                String::from_utf8_lossy(&rest[..r.consumed]),
                r.status,
                d.kind,
                if self.shadow.holding() { ", held" } else { "" }
            );
            assert!(r.consumed <= rest.len());
            let seen = self.shadow.decoded(rest, &r);
            rest = &rest[r.consumed..];
            let heard = match r.status {
                Status::Partial => {
                    assert!(rest.is_empty(), "Partial with bytes left");
                    return;
                }
                Status::Complete(h) => h,
            };
            if let Heard::Broken(_) = heard {
                self.broken_since_sent = true;
            }
            if let Some(seen) = seen {
                self.heard(heard, seen);
            }
            if heard == Heard::Answer {
                // The client keeps its reply until its next send.
                self.shadow.hold();
            }
        }
    }

    fn heard(&mut self, heard: Heard, seen: Seen) {
        let station = self.setup.line.station;
        let (header, from, _) = seen.envelope;
        let ours = from == station && header != Header::Command;
        assert_eq!(
            heard == Heard::Foreign,
            !ours,
            "{heard:?} for a frame from {from:?} ({header:?})"
        );
        if let Source::Delivery(d) = &seen.source {
            self.link.heard_whole(d);
        }
        let d = match &seen.source {
            Source::Forged => None,
            Source::Delivery(d) => Some(d.clone()),
        };
        link::check_fence_echo(
            &self.setup,
            &seen,
            ours,
            heard,
            self.fences,
            self.fence_awaited,
        );
        if seen.held {
            assert!(
                !matches!(heard, Heard::Answer | Heard::Rejected(_) | Heard::Mismatch),
                "{heard:?} while the client keeps its reply"
            );
        }
        match heard {
            Heard::Answer | Heard::Rejected(_) => {
                assert!(self.awaiting, "{heard:?} while no reply was awaited");
                let f = seen.frame();
                let id = self.id_in_flight();
                assert_eq!(f.station(), station, "a reply from another station taken");
                let me = self.owner();
                if d.is_none() {
                    // Raw noise taken: this command's own replies are adrift.
                    self.adrift.push(me);
                }
                if let Some(d) = &d {
                    let cmd = self
                        .link
                        .origin(d)
                        .expect("a frame the controller never made");
                    let owner = self.owners[cmd];
                    let ok = d.ok();
                    let dropped =
                        matches!(d.kind, Kind::Reply { made, .. } if self.dropped.contains(&made));
                    let excused = cmd < self.excused_before || (!F18_FIXED && dropped);
                    if owner != Some(me) && ok && !excused {
                        assert!(
                            owner.is_some_and(|o| self.adrift.contains(&o)),
                            "request {me:?} took a reply made for {owner:?} (command {cmd} sent at {}, now {}, {:?})",
                            self.link.cmds[cmd].at,
                            self.clock,
                            d.kind
                        );
                    }
                    if owner != Some(me) || !ok {
                        // Something else stood in for its reply: its own
                        // replies are adrift now.
                        self.adrift.push(me);
                    }
                }
                let req = self.req.as_mut().expect("a request");
                match heard {
                    Heard::Answer => {
                        assert_eq!((f.header(), f.code()), (Header::Response, id));
                        if catalogue::lookup(id).is_some() {
                            Response::parse(&f).expect("a reply taken parses");
                        }
                        if id == 0x200 {
                            assert_eq!(f.body(), &req.bytes[6..16], "a 200H reply of another text");
                        }
                        if req.phase == 1 {
                            let r = ErrorDetailResponse::parse(&f).expect("a 216H reply");
                            req.detail = Some(Some(r.error_number));
                        }
                        req.taken = Some(seen.bytes.clone());
                        req.echo_since_taken = false;
                    }
                    Heard::Rejected(code) => {
                        assert_eq!((f.header(), f.code()), (Header::Error, code));
                        if req.phase == 0 {
                            req.rejected = Some(code);
                        } else {
                            req.detail_failed = true;
                        }
                    }
                    _ => unreachable!(),
                }
                self.awaiting = false;
            }
            Heard::Mismatch => {
                assert!(self.awaiting, "a mismatch while no reply was awaited");
                let f = seen.frame();
                let id = self.id_in_flight();
                assert_eq!(
                    (f.header(), f.station(), f.code()),
                    (Header::Response, station, id)
                );
                let req = self.req.as_ref().expect("a request");
                let parses = catalogue::lookup(id).is_none() || Response::parse(&f).is_ok();
                let echoes = id != 0x200 || f.body() == &req.bytes[6..16];
                assert!(
                    !(parses && echoes),
                    "a reply that parses (and echoes the call) called a mismatch"
                );
            }
            Heard::Fence => {
                let in_order = match &d {
                    Some(d) => {
                        let cmd = self
                            .link
                            .origin(d)
                            .expect("an echo the controller never made");
                        assert_eq!(Some(cmd), self.last_fence, "the echo of another fence");
                        d.ok()
                    }
                    None => false,
                };
                if !in_order {
                    // An echo outside the contract (a copy before the
                    // original, forged) settles what is still owed: replies
                    // to the commands before it are no longer in order.
                    self.excused_before = self.link.cmds.len();
                }
                self.fence_awaited = false;
                if let Some(req) = self.req.as_mut() {
                    req.echo_since_taken = true;
                }
            }
            Heard::Unplaced => {
                if let Some(d) = &d {
                    if let Some(cmd) = self.link.placeable(d) {
                        let owner = self.owners[cmd];
                        let excused = cmd < self.excused_before
                            || owner.is_some_and(|o| self.adrift.contains(&o));
                        assert!(
                            excused,
                            "a reply within the contract heard Unplaced: command {cmd} of {owner:?} \
                             sent at {}, now {} ({:?})",
                            self.link.cmds[cmd].at, self.clock, d.kind
                        );
                    }
                }
            }
            Heard::Stale | Heard::Foreign | Heard::Broken(_) => {}
        }
    }

    /// The controller's normal reply to the command in flight (`cmd`:
    /// the frame it received).
    fn normal(&self, cmd: &[u8], extra: u8) -> Option<Vec<u8>> {
        let id = self.id_in_flight();
        let station = self.setup.line.station;
        if id == ErrorDetailQuery::ID {
            let code = self.req.as_ref().and_then(|r| r.rejected).unwrap_or(0x0A0);
            let r = ErrorDetailResponse {
                error_number: if extra & 2 == 0 {
                    code & 0xFFF
                } else {
                    u16::from(extra)
                },
                ..Default::default()
            };
            let mut buf = vec![0u8; r.emit_len()];
            let n = r.emit(station, &mut buf).expect("216H reply");
            buf.truncate(n);
            return Some(buf);
        }
        if id == UNKNOWN_ID {
            return Some(link::frame(Header::Response, station, id, b"00"));
        }
        if id == 0x200 {
            // 200H: the call's ten characters echoed (2003 p. 15).
            return Some(link::frame(Header::Response, station, id, &cmd[6..16]));
        }
        let r = Response::default_for(id)?;
        let mut buf = vec![0u8; r.emit_len()];
        let n = r.emit(station, &mut buf).expect("a default response emits");
        buf.truncate(n);
        Some(buf)
    }
    fn error(&self, extra: u8) -> Vec<u8> {
        let code = if extra & 1 == 0 {
            *codes::RANGE.start() + u16::from(extra >> 1) % 0x20
        } else {
            0x0A0 + u16::from(extra)
        };
        let mut buf = [0u8; 16];
        let n = ErrorResponse { code: code & 0xFFF }
            .emit(self.setup.line.station, &mut buf)
            .expect("fits");
        buf[..n].to_vec()
    }

    /// The controller got command `cmd` (a fence if `fence`) at the clock.
    fn answer(&mut self, cmd: usize, fence: bool, f: &link::Fate, bytes: &[u8]) {
        let at = self.clock + f.delay;
        let station = self.setup.line.station;
        if fence {
            let echo = self.link.echo(bytes);
            match f.fault {
                4 | 5 => {
                    // A controller that refuses 200H.
                    let e = self.error(f.extra);
                    self.link.reply(e, cmd, at, false);
                }
                _ => self.link.answer(echo, cmd, at, f, false),
            }
            return;
        }
        let normal = self.normal(bytes, f.extra);
        match f.fault {
            4 => {
                let e = self.error(f.extra);
                self.link.reply(e, cmd, at, false);
            }
            5 if normal.is_none() => {
                // Nothing but an `&` answers a command without normal
                // response (25BH).
                let e = self.error(f.extra);
                self.link.reply(e, cmd, at, false);
            }
            5 => {
                // One digit too many: no catalogue response parses.
                let Some(mut b) = normal.clone() else {
                    return;
                };
                let body_end = b.len() - 4;
                b.insert(body_end, b'0');
                let f2 = Frame::new_checked(&b, BypassPolicy::Accept);
                let fixed = match f2 {
                    Ok(_) => b,
                    Err(_) => {
                        let body = b[6..body_end + 1].to_vec();
                        link::frame(Header::Response, station, self.id_in_flight(), &body)
                    }
                };
                self.link.reply(fixed, cmd, at, false);
            }
            6 => {
                // Another station's frame, or another ID's reply, first:
                // frames the controller did not make for this command
                // (kept as lies: taking one is a fault of the engine only
                // if it broke the station or ID rule, checked above).
                let other = if f.extra & 1 == 0 {
                    let mut b = normal.clone().unwrap_or_else(|| self.error(f.extra));
                    let st = format!("{:02X}", station.0.wrapping_add(1 + f.extra % 200));
                    b[1..3].copy_from_slice(st.as_bytes());
                    let body = b[6..b.len() - 4].to_vec();
                    let (h, code) = (Header::from_byte(b[0]).expect("header"), {
                        let s = std::str::from_utf8(&b[3..6]).expect("ascii");
                        u16::from_str_radix(s, 16).expect("hex")
                    });
                    link::frame(
                        h,
                        Station(station.0.wrapping_add(1 + f.extra % 200)),
                        code,
                        &body,
                    )
                } else {
                    let all = catalogue::ALL;
                    let id = all[usize::from(f.extra) % all.len()].id;
                    match Response::default_for(id) {
                        Some(r) => {
                            let mut buf = vec![0u8; r.emit_len()];
                            let n = r.emit(station, &mut buf).expect("emits");
                            buf.truncate(n);
                            buf
                        }
                        None => self.error(f.extra),
                    }
                };
                self.link.reply(other, cmd, at, true);
                if let Some(b) = normal {
                    self.link.reply(b, cmd, at, false);
                }
            }
            _ => {
                let at = if f.fault == 0 { self.clock + 1 } else { at };
                match normal {
                    Some(b) => self.link.answer(b, cmd, at, f, false),
                    // Without a normal response (25BH) the faults that
                    // alter a reply (corrupted, copied, late) hit an `&`.
                    None if f.fault != 0 => {
                        let e = self.error(f.extra);
                        self.link.answer(e, cmd, at, f, false);
                    }
                    None => {}
                }
            }
        }
    }
}

enum S {
    Transmit(Vec<u8>),
    Wait(u32),
    Idle,
    Done(Result<(), Failure>),
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let setup = link::setup(&mut input);
    let fetch = setup.flags & link::FLAG_A != 0;
    let except_bridge = setup.flags & link::FLAG_B != 0;
    let prove = setup.flags & link::FLAG_C != 0;
    let requests = 1 + usize::from(input.u8() % 4);
    let mut client: Client<CMD, REPLY> = Client::new();
    if fetch {
        client = if except_bridge {
            client.with_error_detail_except(codes::is_bridge_code)
        } else {
            client.with_error_detail()
        };
    }
    if prove {
        client = client.with_proof();
    }
    trace!(
        "{:?} fetch {fetch} except {except_bridge} prove {prove}",
        setup.line
    );
    let mut h = H {
        input,
        setup,
        link: Link::new(setup),
        line: Line::new(setup.line, setup.seed),
        client,
        shadow: Shadow::default(),
        clock: 0,
        req: None,
        owners: Vec::new(),
        last_fence: None,
        fence_awaited: false,
        awaiting: false,
        last_sent: 0,
        broken_since_sent: false,
        adrift: Vec::new(),
        excused_before: 0,
        dropped: Vec::new(),
        prove,
        transmitted: false,
        commands: 0,
        sends: 0,
        fences: 0,
    };
    let mut serial = 0usize;
    let p = h.input.u8();
    h.start(serial, p);
    let max_steps = 400 + 16 * data.len();
    let mut steps = 0usize;
    let ex = setup.line;
    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        let now = h.now();
        let before = h.line.stats();
        let step = match h.client.poll(&mut h.line, now) {
            Step::Transmit(b) => S::Transmit(b.to_vec()),
            Step::WaitUntil(t) => S::Wait(t),
            Step::Idle => S::Idle,
            Step::Done(r) => S::Done(r),
        };
        let after = h.line.stats();
        if after.fences_failed > before.fences_failed {
            // The fence's timeout was seen: its echo settles nothing now.
            h.fence_awaited = false;
        }
        let asked = after.commands - before.commands;
        if asked > 0 {
            // A command of its own: the 216H query after an `&`, or the
            // query asked again for want of a proof.
            h.commands += asked;
            let req = h.req.as_mut().expect("a request");
            if req.rejected.is_none() && req.phase == 0 {
                assert!(h.prove, "asked again without proofs");
                assert_eq!(asked, 1);
                let safe = catalogue::request_rules(req.id).is_some_and(|(r, _)| r == Resend::Safe);
                assert!(safe, "{:03X} asked again: not safe to repeat", req.id);
                assert!(
                    after.unplaced != req.unplaced_mark,
                    "asked again with nothing unplaced since it was asked"
                );
                assert!(req.taken.is_some(), "asked again with no reply taken");
                req.asked_again += 1;
                assert!(
                    req.asked_again <= PROOF_ASKS,
                    "asked again {} times",
                    req.asked_again
                );
                req.unplaced_mark = after.unplaced;
                req.sends = 0;
                req.taken = None;
            }
        }
        if after.sends > before.sends {
            // The client cleared its receiver for the send.
            for d in h.shadow.release() {
                if let Kind::Reply { made, .. } | Kind::Broken { made, .. } = d.kind {
                    h.dropped.push(made);
                }
            }
        }
        match step {
            S::Idle => panic!("idle with a request started"),
            S::Transmit(bytes) => {
                trace!(
                    "t={} TX {}",
                    h.clock,
                    String::from_utf8_lossy(&bytes).trim_end()
                );
                h.transmitted = true;
                let fence = after.fences > before.fences;
                assert_eq!(
                    fence,
                    setup.is_fence(&bytes),
                    "a fence not counted, or counted and not sent"
                );
                if fence {
                    assert_eq!(after.fences, before.fences + 1, "two fences at once");
                    link::check_fence(&setup, &bytes, after.fences);
                    h.fences += 1;
                } else {
                    assert_eq!(after.sends, before.sends + 1, "a send not counted");
                    let f = Frame::new_checked(&bytes, BypassPolicy::Accept)
                        .expect("an invalid command sent");
                    assert_eq!((f.header(), f.station()), (Header::Command, ex.station));
                    let req = h.req.as_mut().expect("a request");
                    if req.rejected.is_some() && req.phase == 0 {
                        // The 216H query for the detail of the `&`.
                        let code = req.rejected.expect("rejected");
                        assert!(fetch, "a command after an & without the detail option");
                        assert!(
                            !(except_bridge && codes::is_bridge_code(code)),
                            "216H asked for a bridge code"
                        );
                        assert_eq!(
                            ErrorDetailQuery::parse(&f).expect("a 216H query"),
                            ErrorDetailQuery::latest_system_error()
                        );
                        req.phase = 1;
                        req.sends = 0;
                        req.taken = None;
                        req.asked_detail = true;
                    } else if req.phase == 0 {
                        assert_eq!(bytes, req.bytes, "another command than the one started");
                    } else {
                        assert_eq!(f.code(), ErrorDetailQuery::ID);
                        assert!(!req.detail_failed, "216H resent after an &");
                    }
                    req.sends += 1;
                    let id = if req.phase == 1 {
                        ErrorDetailQuery::ID
                    } else {
                        req.id
                    };
                    let (resend, reply) =
                        catalogue::request_rules(id).unwrap_or((Resend::Unsafe, Reply::Normal));
                    let limit = match (resend, reply) {
                        (_, Reply::None { .. }) => 1,
                        (Resend::Unsafe, _) if !ex.resend_unsafe => 1,
                        _ => ex.max_sends,
                    };
                    assert!(
                        req.sends <= limit,
                        "{} sends of {id:03X} (limit {limit})",
                        req.sends
                    );
                    if req.sends > 1 {
                        assert!(
                            h.clock >= h.last_sent + u64::from(ex.timeout_ms)
                                || h.broken_since_sent,
                            "resent at {} after a send that ended at {}",
                            h.clock,
                            h.last_sent
                        );
                    }
                    h.sends += 1;
                }
                h.awaiting = false;
                let op = h.input.next();
                let fate = h.link.fate(&mut h.input, op);
                // Replies due while it goes out arrive before `sent`.
                let to = h.clock + fate.dur;
                h.deliver_until(to);
                h.clock = to;
                let now = h.now();
                h.client.sent(&mut h.line, now);
                if fence {
                    h.fence_awaited = true;
                    h.last_fence = None;
                } else {
                    h.awaiting = true;
                    h.last_sent = h.clock;
                    h.broken_since_sent = false;
                }
                if !fate.lost {
                    let cmd = h.link.received(&bytes, h.clock);
                    h.owners.push(if fence { None } else { Some(h.owner()) });
                    if fence {
                        h.last_fence = Some(cmd);
                    }
                    h.answer(cmd, fence, &fate, &bytes);
                }
            }
            S::Wait(t) => {
                let nothing_sent = !h.transmitted && ex.fences;
                let ahead =
                    records::check_wait(now, t, setup.horizon(h.line.copy_window()), nothing_sent);
                trace!("t={} WAIT {ahead}", h.clock);
                let until = h.clock + u64::from(ahead);
                match h.input.next() {
                    None => {
                        let next = h.link.outbox.first().map_or(until, |d| d.at.min(until));
                        h.deliver_until(next);
                        h.clock = h.clock.max(next);
                    }
                    Some(op) => match op % 6 {
                        0 => {
                            let to = h.clock + u64::from(h.input.u16());
                            h.deliver_until(to);
                            h.clock = h.clock.max(to);
                        }
                        1 => {
                            let (d, then_next) = h.link.noise(&mut h.input, h.clock);
                            h.feed(d);
                            if then_next {
                                if let Some(at) = h.link.outbox.first().map(|d| d.at) {
                                    h.deliver_until(at);
                                }
                            }
                        }
                        2 => {
                            // A copy of any reply made before.
                            if let Some(d) = h.link.copy(&mut h.input, h.clock) {
                                h.feed(d);
                            }
                        }
                        3 => {
                            if let Some(at) = h.link.outbox.first().map(|d| d.at) {
                                h.deliver_until(at);
                            }
                        }
                        4 if serial + 1 < requests => {
                            serial += 1;
                            let p = h.input.u8();
                            h.start(serial, p);
                        }
                        _ => {
                            h.deliver_until(until);
                            h.clock = h.clock.max(until);
                        }
                    },
                }
            }
            S::Done(result) => {
                trace!("t={} DONE {result:?}", h.clock);
                let req = h.req.take().expect("done without a request");
                let normal_reply =
                    catalogue::request_rules(req.id).is_none_or(|(_, r)| r == Reply::Normal);
                let late_enough = h.clock >= h.last_sent + u64::from(ex.timeout_ms);
                let unplaced = h.line.stats().unplaced;
                match result {
                    Ok(()) => {
                        assert_eq!(req.phase, 0, "Ok after an &");
                        if normal_reply {
                            let taken = req.taken.as_ref().expect("Ok without a reply taken");
                            let f = h.client.reply_frame().expect("the reply is readable");
                            assert_eq!(
                                f.as_bytes(),
                                &taken[..],
                                "reply_frame is not the reply taken"
                            );
                            match req.typed {
                                Typed::AxisStatus(p) => {
                                    h.client.response(&p).expect("typed reply");
                                }
                                Typed::RelativeMove(p) => {
                                    h.client.response(&p).expect("typed reply");
                                }
                                Typed::ErrorDetail(p) => {
                                    h.client.response(&p).expect("typed reply");
                                }
                                Typed::SoftwareReset(_) => panic!("25BH has no normal reply"),
                                Typed::Raw => {}
                            }
                            if prove {
                                let waited =
                                    u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms);
                                assert!(
                                    req.echo_since_taken || h.clock > h.last_sent + waited,
                                    "Ok without a proof: no echo since the reply and its \
                                     replies not waited out (sent {}, now {})",
                                    h.last_sent,
                                    h.clock
                                );
                                assert_eq!(
                                    unplaced, req.unplaced_mark,
                                    "Ok with frames unplaced since it was asked"
                                );
                            }
                        } else {
                            assert_eq!(req.id, SoftwareReset::ID);
                            assert!(req.taken.is_none(), "a normal reply taken for 25BH");
                            assert!(late_enough, "25BH done before its timeout");
                            if let Typed::SoftwareReset(p) = req.typed {
                                h.client.response(&p).expect("the default");
                            }
                        }
                    }
                    Err(Failure::Timeout { sends }) | Err(Failure::OutcomeUnknown { sends }) => {
                        assert_eq!(req.phase, 0, "{result:?} for the 216H query");
                        assert!(req.rejected.is_none());
                        assert_eq!(sends, req.sends);
                        let unsafe_ = catalogue::request_rules(req.id)
                            .is_none_or(|(r, _)| r == Resend::Unsafe);
                        assert_eq!(
                            matches!(result, Err(Failure::OutcomeUnknown { .. })),
                            unsafe_
                        );
                        assert!(
                            late_enough || h.broken_since_sent,
                            "gave up at {} after a send that ended at {}",
                            h.clock,
                            h.last_sent
                        );
                        if !normal_reply {
                            assert!(h.broken_since_sent, "25BH unknown without a broken reply");
                            // The broken frame that ended it may have been
                            // anything: its own reply is adrift.
                            h.adrift.push((req.serial, 0, 0));
                        }
                    }
                    Err(Failure::Controller { code, detail }) => {
                        assert_eq!(req.rejected, Some(code), "Controller without that &");
                        let eligible = fetch && !(except_bridge && codes::is_bridge_code(code));
                        match detail {
                            Some(d) => {
                                assert!(eligible && req.asked_detail, "a detail never asked");
                                match req.detail {
                                    Some(Some(n)) => assert_eq!(d.error_number, n),
                                    Some(None) => {}
                                    None => panic!("a detail without a 216H reply"),
                                }
                                assert_eq!(d.matches_code, d.error_number == code);
                            }
                            None => assert!(
                                !eligible || req.detail_failed || req.detail.is_none(),
                                "the detail taken was not reported"
                            ),
                        }
                        if eligible {
                            assert!(req.asked_detail, "no 216H query after an &");
                        }
                    }
                    Err(Failure::Unconfirmed { unplaced: n }) => {
                        assert!(prove, "Unconfirmed without proofs");
                        assert_eq!(n, unplaced, "Unconfirmed names another count");
                        assert!(req.taken.is_some(), "Unconfirmed with no reply taken");
                        assert_ne!(n, req.unplaced_mark, "Unconfirmed with nothing unplaced");
                        let safe = catalogue::request_rules(req.id)
                            .is_some_and(|(r, _)| r == Resend::Safe);
                        assert!(
                            !safe || req.asked_again == PROOF_ASKS,
                            "Unconfirmed after {} asks of a query",
                            req.asked_again
                        );
                    }
                    Err(e) => panic!("unexpected {e:?}"),
                }
                let s = h.line.stats();
                assert_eq!(
                    (s.commands, s.sends, s.fences),
                    (h.commands, h.sends, h.fences),
                    "line stats"
                );
                h.awaiting = false;
                serial += 1;
                if serial >= requests {
                    break;
                }
                let p = h.input.u8();
                h.start(serial, p);
            }
        }
    }
});
