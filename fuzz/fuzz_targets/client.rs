//! The request engine (`client::Client`) over a `line::Line`, on a virtual
//! clock, against a simulated controller that answers in order.
//!
//! Input layout: the line (`common/link.rs`: station, timeout, flags with
//! sends 1-4, `resend_unsafe`, fences off, raw noise, turnaround, late and
//! duplicate windows, fence seed, start tick), with the flags' 0x20 bit
//! for the 216H detail (`with_error_detail`) and 0x40 for skipping it on
//! the bridge's codes (`with_error_detail_except(codes::is_bridge_code)`);
//! one byte: requests 1-4; then a script. Each request is picked by a
//! script byte: a typed request through `Client::start` (212H axis status,
//! 235H relative move: unsafe to resend, 25BH software reset: no normal
//! response, 216H error detail), a command outside the catalogue, or any
//! catalogue command's default frame through `start_frame`.
//!
//! The controller receives each transmission at its end (`sent`) and
//! answers in order: the fences it echoes, each command with its normal
//! reply (the response's default frame; for 216H an error detail whose
//! number is the `&` code or not; 25BH none). Per transmission the script
//! picks its length (replies due meanwhile arrive before `sent`), whether
//! the controller gets it (op bits 0-2: length, ms; bits 3-4 = 2: lost),
//! and what becomes of the reply (op bits 5-7):
//! 0 at once, 1 lost, 2 a corrupted byte, 3 a copy later, 4 an `&` (a
//! controller or bridge code), 5 a body that does not parse, 6 another
//! station's or another ID's frame first, 7 a delay with a copy; with a
//! fault, a byte and a delay (up to three timeouts and the late window).
//! A command without normal response (25BH) gets an `&` for faults 2, 3
//! and 7. Fences are echoed (4 and 5: an `&` instead). While the client
//! waits, a script byte (`% 6`): 0 advances the clock (u16 ms) delivering
//! what is due, 1 injects noise (a byte `k`, `k % 64` bytes, no LF unless
//! raw noise is on: then a frame in it is forged; with `k & 0x40` the next
//! delivery follows with no poll between), 2 sends a copy of any reply
//! made before (a byte: which, `& 0x80` broken), 3 delivers the next
//! delivery, 4 abandons the request for the next one (its pick follows),
//! 5 waits until the deadline; when the script ends, the deadline or the
//! next delivery, whichever comes first.
//!
//! A delivery keeps the contract (`Link::arrives`) when an original reply
//! comes within `timeout + late_window` of the send it answers (in order:
//! the controller never lets a reply overtake an earlier one) and a copy
//! within `duplicate_window` of the first arrival, if that kept the
//! contract; a copy before its original, a stale answer and raw noise
//! never do. A plain `FrameDecoder` beside the client's (reset with it: at
//! each send, and when the client drops bytes held from before a first
//! send) tells which delivery made each frame the client heard.
//!
//! Checked:
//! - no panic; it ends within a bounded number of steps; no wait before
//!   the first transmission of a line with fences (the first command is
//!   fenced), none in the past or beyond the longest hold;
//! - what goes out: fences (200H with the seed's text), or the command in
//!   flight as started, or after an `&` the 216H query for the detail,
//!   only with the option on and, with the bridge exception, never for a
//!   code in `codes::RANGE`; sends of a command <= `max_sends`, one for a
//!   command the catalogue marks unsafe (and one outside it) unless
//!   `resend_unsafe`, one for 25BH, nothing resent after an `&`; a resend
//!   not before `sent + timeout` unless a broken frame came after `sent`;
//! - **a reply taken (`Answer` / `Rejected`) is one the controller made for
//!   a send of the command in flight** (the request, or its 216H query),
//!   whatever came before: earlier requests' late replies and copies, the
//!   fences' echoes, abandoned requests; unless the delivery broke the
//!   contract, or came from raw noise (and a command that took another's
//!   reply leaves its own replies adrift: whoever takes them later is not
//!   blamed); taken only while awaited (after `sent`); the frame is the
//!   station's, with the ID in flight (`&`: its code);
//! - `Mismatch` only for a reply with the ID in flight whose body does not
//!   parse; `Fence` only for the echo of the last fence sent;
//! - `Done(Ok)`: for a command with a normal response, after its reply was
//!   taken; `reply_frame()` is that frame and the typed `response::<R>()`
//!   parses; for 25BH only at `sent + timeout` or later, with no reply;
//! - `Timeout { sends }` / `OutcomeUnknown { sends }` by the command's
//!   resend safety with the sends made, not before `sent + timeout` unless
//!   a broken frame came after it (25BH: `OutcomeUnknown` only then);
//!   `Controller { code, detail }` only after an `&` with that code was
//!   taken, with the detail of the 216H reply taken (`matches_code`
//!   right), `None` if the query failed or was not to be asked;
//! - `stats()` of the line: commands started, sends, fences.
#![no_main]

#[path = "common/link.rs"]
mod link;
#[path = "common/records.rs"]
mod records;

use firmware_example::codes;
use iai_protocol_b::catalogue::{self, Reply, Resend};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::client::Client;
use iai_protocol_b::engine::Step;
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::line::{Heard, Line};
use iai_protocol_b::message::{
    AxisStatusQuery, Command, ErrorDetailQuery, ErrorDetailResponse, ErrorResponse, Message,
    RelativeMove, Response, SoftwareReset,
};
use libfuzzer_sys::fuzz_target;
use link::{Delivery, Link, Setup, Shadow, Source};
use records::Input;

const CMD: usize = iai_protocol_b::limits::TTA.command;
const REPLY: usize = iai_protocol_b::limits::TTA.response;

/// An ID outside the catalogue (a bridge passing on what it does not know).
const UNKNOWN_ID: u16 = 0x2FE;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Typed {
    Raw,
    AxisStatus,
    RelativeMove,
    SoftwareReset,
    ErrorDetail,
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
    /// The 216H reply taken: its error number (`None` if forged).
    detail: Option<Option<u16>>,
    detail_failed: bool,
    /// A 216H query went out.
    asked_detail: bool,
}

type Owner = (usize, u8);

struct H<'a> {
    input: Input<'a>,
    setup: Setup,
    link: Link,
    line: Line,
    client: Client<CMD, REPLY>,
    shadow: Shadow,
    clock: u64,
    req: Option<Req>,
    /// Who each command frame the controller received belongs to (`None`:
    /// a fence).
    owners: Vec<Option<Owner>>,
    /// The last fence sent (controller command index).
    last_fence: Option<usize>,
    /// A reply is awaited: `sent` was called and nothing sent since.
    awaiting: bool,
    last_sent: u64,
    broken_since_sent: bool,
    /// The client holds a reply: nothing more is fed until the next poll.
    holding: bool,
    adrift: Vec<Owner>,
    /// Replies to commands before this one (controller command index) are
    /// not blamed: an echo outside the contract settled them.
    excused_before: usize,
    fetch: bool,
    except_bridge: bool,
    transmitted: bool,
    commands: u32,
    sends: u32,
    fences: u32,
    next_id: usize,
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
        (r.serial, r.phase)
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
        let (id, typed, bytes) = match pick % 8 {
            0 => {
                let q = AxisStatusQuery::default();
                self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (AxisStatusQuery::ID, Typed::AxisStatus, b)
            }
            1 => {
                let q = RelativeMove::default();
                self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (RelativeMove::ID, Typed::RelativeMove, b)
            }
            2 => {
                let q = SoftwareReset::default();
                self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (SoftwareReset::ID, Typed::SoftwareReset, b)
            }
            3 => {
                let q = ErrorDetailQuery::latest_system_error();
                self.client.start(&mut self.line, &q, now).expect("starts");
                let b = emit(&|b| q.emit_with(station, checksum, b).expect("emits"));
                (ErrorDetailQuery::ID, Typed::ErrorDetail, b)
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
        self.holding = false;
        self.req = Some(Req {
            serial,
            id,
            typed,
            bytes,
            phase: 0,
            sends: 0,
            rejected: None,
            taken: None,
            detail: None,
            detail_failed: false,
            asked_detail: false,
        });
    }

    /// Delivers what is due by `to`, moving the clock (not while the
    /// client holds a reply).
    fn deliver_until(&mut self, to: u64) {
        while !self.holding {
            let Some(d) = self.link.due(to) else { break };
            self.clock = self.clock.max(d.at);
            self.feed(d);
        }
    }

    /// Feeds one delivery, checking what each frame did.
    fn feed(&mut self, mut d: Delivery) {
        if self.holding {
            self.link.put_back(d);
            return;
        }
        if d.ok.is_none() {
            d.at = self.clock;
        }
        self.link.arrives(&mut d, self.clock);
        self.shadow.begin(&d);
        let mut rest = &d.bytes[..];
        let now = self.now();
        loop {
            let errors = self.line.stats().line_errors;
            let r = self.client.received(&mut self.line, rest, now);
            if self.line.stats().line_errors > errors {
                // A broken frame (the read-back path reports none).
                self.broken_since_sent = true;
            }
            trace!(
                "t={} RX {:?} -> {:?} ({:?})",
                self.clock,
                String::from_utf8_lossy(&rest[..r.consumed]),
                r.event,
                d.kind
            );
            assert!(r.consumed <= rest.len());
            assert!(
                r.consumed > 0 || r.event != Heard::NeedMore || rest.is_empty(),
                "the client refused bytes while it held no reply"
            );
            let heard = self.shadow.decoded(rest, r.consumed, &r.event);
            rest = &rest[r.consumed..];
            if let Heard::Broken(_) = r.event {
                self.broken_since_sent = true;
            }
            if let Some((frame, src)) = heard {
                self.heard(r.event, &frame, src);
            }
            if r.event == Heard::Answer {
                // The client holds its reply until the next start: the
                // rest waits.
                self.holding = true;
                if !rest.is_empty() {
                    let mut tail = d.clone();
                    tail.bytes = rest.to_vec();
                    self.link.put_back(tail);
                }
                return;
            }
            if r.event == Heard::NeedMore {
                assert!(rest.is_empty(), "NeedMore with bytes left");
                return;
            }
        }
    }

    fn heard(&mut self, heard: Heard, frame: &[u8], src: Source) {
        let f = Frame::new_checked(frame, BypassPolicy::Reject).expect("a frame");
        let station = self.setup.line.station;
        let d = match src {
            Source::Forged => None,
            Source::Delivery(d) => Some(d),
        };
        match heard {
            Heard::Answer | Heard::Rejected(_) => {
                assert!(self.awaiting, "{heard:?} while no reply was awaited");
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
                    let excused = cmd < self.excused_before;
                    if owner != Some(me) && ok && !excused {
                        assert!(
                            owner.is_some_and(|o| self.adrift.contains(&o)),
                            "request {me:?} took a reply made for {owner:?} (command {cmd} sent at {}, now {}, {:?})",
                            self.link.cmds[cmd].at,
                            self.clock,
                            d.kind
                        );
                    }
                    if owner != Some(me) {
                        // Its own replies are adrift now.
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
                        if req.phase == 1 {
                            let r = ErrorDetailResponse::parse(&f).expect("a 216H reply");
                            req.detail = Some(Some(r.error_number));
                        }
                        req.taken = Some(frame.to_vec());
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
                let id = self.id_in_flight();
                assert_eq!(
                    (f.header(), f.station(), f.code()),
                    (Header::Response, station, id)
                );
                assert!(
                    catalogue::lookup(id).is_some() && Response::parse(&f).is_err(),
                    "a reply that parses called a mismatch"
                );
            }
            Heard::Fence => {
                assert_eq!((f.header(), f.code()), (Header::Response, 0x200));
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
            }
            Heard::Stale | Heard::Foreign | Heard::NeedMore | Heard::Broken(_) => {}
        }
    }

    /// The controller's normal reply to the command in flight.
    fn normal(&self, extra: u8) -> Option<Vec<u8>> {
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
        let normal = self.normal(f.extra);
        match f.fault {
            4 => {
                let e = self.error(f.extra);
                self.link.reply(e, cmd, at, false);
            }
            5 => {
                // One digit too many: no catalogue response parses.
                let Some(mut b) = normal.clone().or_else(|| {
                    let id = self.id_in_flight();
                    Some(link::frame(Header::Response, station, id, b""))
                }) else {
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
    let requests = 1 + usize::from(input.u8() % 4);
    let mut client: Client<CMD, REPLY> = Client::new();
    if fetch {
        client = if except_bridge {
            client.with_error_detail_except(codes::is_bridge_code)
        } else {
            client.with_error_detail()
        };
    }
    trace!("{:?} fetch {fetch} except {except_bridge}", setup.line);
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
        awaiting: false,
        last_sent: 0,
        broken_since_sent: false,
        holding: false,
        adrift: Vec::new(),
        excused_before: 0,
        fetch,
        except_bridge,
        transmitted: false,
        commands: 0,
        sends: 0,
        fences: 0,
        next_id: 0,
    };
    let _ = h.next_id;
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
        // The 216H query after an `&` is a command of its own.
        h.commands += after.commands - before.commands;
        if after.sends > before.sends || after.line_errors > before.line_errors {
            // The client reset its reply decoder (a send; bytes held from
            // before a first send dropped): so does the shadow.
            h.shadow.reset();
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
                let fence = setup.is_fence(&bytes);
                if fence {
                    link::check_fence(&setup, &bytes);
                    assert_eq!(after.fences, before.fences + 1, "a fence not counted");
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
                if !fence {
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
                } else if fence {
                    h.last_fence = None;
                }
            }
            S::Wait(t) => {
                let nothing_sent = !h.transmitted && ex.fences;
                let ahead = records::check_wait(now, t, setup.horizon(), nothing_sent);
                trace!("t={} WAIT {ahead}", h.clock);
                let until = h.clock + u64::from(ahead);
                match h.input.next() {
                    None => {
                        let next = h.link.outbox.first().map_or(until, |d| d.at.min(until));
                        h.deliver_until(next);
                        if !h.holding {
                            h.clock = h.clock.max(next);
                        }
                    }
                    Some(op) => match op % 6 {
                        0 => {
                            let to = h.clock + u64::from(h.input.u16());
                            h.deliver_until(to);
                            if !h.holding {
                                h.clock = to;
                            }
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
                            if !h.holding {
                                h.clock = h.clock.max(until);
                            }
                        }
                    },
                }
            }
            S::Done(result) => {
                trace!("t={} DONE {result:?}", h.clock);
                // The client takes no bytes until the next start.
                h.holding = true;
                let req = h.req.take().expect("done without a request");
                let normal_reply =
                    catalogue::request_rules(req.id).is_none_or(|(_, r)| r == Reply::Normal);
                let late_enough = h.clock >= h.last_sent + u64::from(ex.timeout_ms);
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
                                Typed::AxisStatus => {
                                    h.client.response::<AxisStatusQuery>().expect("typed reply");
                                }
                                Typed::RelativeMove => {
                                    h.client.response::<RelativeMove>().expect("typed reply");
                                }
                                Typed::ErrorDetail => {
                                    h.client
                                        .response::<ErrorDetailQuery>()
                                        .expect("typed reply");
                                }
                                Typed::SoftwareReset => panic!("25BH has no normal reply"),
                                Typed::Raw => {}
                            }
                        } else {
                            assert_eq!(req.id, SoftwareReset::ID);
                            assert!(req.taken.is_none(), "a normal reply taken for 25BH");
                            assert!(late_enough, "25BH done before its timeout");
                            if req.typed == Typed::SoftwareReset {
                                h.client.response::<SoftwareReset>().expect("the default");
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
    let _ = (h.fetch, h.except_bridge);
});
