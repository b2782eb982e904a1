//! The request engine (`client::Client`, on `exchange::Exchange`) driven
//! by a virtual clock against a scripted controller.
//!
//! Input layout: a config (station, timeout, sends 1-4, turnaround, late
//! and duplicate windows, resend of unsafe commands, 216H detail fetch,
//! start tick, number of requests 1-4), then a script. Each request is
//! picked by a script byte: any catalogue command as a raw frame
//! (`Command::default_for(id)` through `Client::start_frame`), a command
//! outside the catalogue (raw), or a typed request through `Client::start`
//! (212H axis status, 235H relative move: unsafe to resend, 25BH software
//! reset: no normal response, 216H error detail).
//!
//! For every send the script picks how long the transmission takes
//! (replies due meanwhile arrive *before* `sent`) and what the controller
//! answers: the normal reply (the response's default frame; for 216H an
//! error detail with a chosen number), nothing, an `&` (controller or
//! bridge code), a reply with a corrupted byte (the SC fails), a reply
//! with the right station and ID but a body that does not parse, a reply
//! from another station or with another ID followed by the right one; and
//! when: at once, late (up to far past the timeout), duplicated later, or
//! both. While the client waits the script advances the clock, delivers
//! what is due, injects noise (never a LF, so noise cannot complete a
//! frame; with the raw-noise bit of the config any bytes, a frame in them
//! counting as an unsolicited one), replays an earlier reply (stale or duplicated), or abandons the
//! request by starting the next one. When the script ends the controller
//! answers at once.
//!
//! Checked:
//! - no panic; it ends within a bounded number of steps;
//! - `Offer::Accepted` only while a reply is awaited (after `sent`, before
//!   the next transmission), never for bytes that arrived before `sent`,
//!   and only for a normal response from the station with the ID of the
//!   command in flight; a reply the controller made for an *earlier*
//!   request (or for the other phase of this one: the command or its 216H
//!   detail query) is taken only outside the engine's contract: later than
//!   `timeout + late_window` after the send it answered and, for a copy,
//!   later than `duplicate_window` after the original was taken (or after
//!   an original that arrived in time but was dropped: finding F6, fixed).
//!   So a request never gets a
//!   reply that belongs to an earlier request. (A command that took another
//!   command's reply outside the contract leaves its own replies adrift:
//!   whoever takes them later is not blamed.) Which delivery made a frame
//!   is known from a plain `FrameDecoder` fed beside the client's, which
//!   must decode the same events;
//! - `Done(Ok(Replied))` only after such an acceptance; the reply frame is
//!   readable and, for a catalogue ID, parses as its response (typed
//!   requests: `Client::response` succeeds); `Done(Ok(NoReplyExpected))`
//!   only for 25BH, not before `sent + timeout` (finding F3, fixed: a
//!   broken `&` ended it early; now `OutcomeUnknown`, only after a broken
//!   frame), and the next command waits for the controller's restart (10 s
//!   after that `sent`);
//! - sends per command <= `max_sends`; a command the catalogue marks unsafe
//!   (and one outside the catalogue) is sent once unless `resend_unsafe`;
//!   25BH once; nothing is resent after an `&`;
//! - timeouts run from `sent`: a resend, `Timeout` or `OutcomeUnknown`
//!   comes no earlier than `sent + timeout`, unless a broken frame arrived
//!   after that `sent` (a reply that arrived broken is resent after the
//!   turnaround); every first send of a command waits for the turnaround
//!   after the reply that ended the previous one (two ticks at least), its
//!   duplicate window, and the late window of sends whose replies are still
//!   owed (a timeout, an abandon, a reply after resends); no wait before the
//!   first send or longer than the longest hold (finding F1, fixed: a first
//!   command past tick 2^31 waited until the clock wrapped);
//! - `Timeout { sends }` for a safe command and `OutcomeUnknown { sends }`
//!   for an unsafe one, with the sends made; `Controller { code, detail }`
//!   only after an `&` with that code was taken, and `detail` only when the
//!   216H fetch is on and a detail reply was taken (`matches_code` tells
//!   whether its number is the code); `Bridge { code }` for codes in
//!   `BRIDGE_CODES`, never followed by a 216H query; `Protocol` never;
//! - `stats()` agree: requests started, frames sent, resends.
#![no_main]

#[path = "common/records.rs"]
mod records;

use iai_protocol_b::catalogue::{self, Resend};
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::client::{CallError, Client, ClientConfig, ClientStep, Heard, Outcome};
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::error::BRIDGE_CODES;
use iai_protocol_b::exchange::{ExchangeConfig, Offer};
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::message::{
    AxisStatusQuery, Command, ErrorDetailQuery, ErrorDetailResponse, ErrorResponse, Message,
    RelativeMove, Response, SoftwareReset,
};
use libfuzzer_sys::fuzz_target;
use records::Input;

const CMD: usize = iai_protocol_b::limits::TTA.command;
const REPLY: usize = iai_protocol_b::limits::TTA.response;

/// Finding F9 (fixed in the core; the check is strict) (fuzz/README.md): a late reply to a command given up
/// (abandoned, or timed out) that arrives while a command with another ID
/// is in progress is `Foreign` to the exchange, which then starts no
/// duplicate window for it: a copy of it within `duplicate_window` is
/// taken by the next command with the first one's ID. Before the fix the
/// copy check tolerated exactly a copy of a reply that was heard as
/// `Foreign` before.
const F9_FIXED: bool = true;

/// An ID outside the catalogue (a bridge passing on what it does not know).
const UNKNOWN_ID: u16 = 0x2FE;

/// Who made a reply: (request serial, phase: 0 command / 1 its 216H query).
type Origin = (usize, u8);

#[derive(Debug, Clone)]
struct Delivery {
    at: u64,
    bytes: Vec<u8>,
    /// For a reply to a send: who it answers, when that send ended, and
    /// the index of the original in `history` if this is a copy.
    origin: Option<(Origin, u64)>,
    copy_of: Option<usize>,
    /// Index in `history` (replies only).
    id: Option<usize>,
    /// A frame that answers nothing the client sent (another ID): taking
    /// it is wrong only if station or ID differ.
    unsolicited: bool,
}

/// A delivery fed since the client's decoder was last reset: where its
/// bytes start in `H::stream`, and when a copy of it first arrived before.
#[derive(Debug, Clone)]
struct Fed {
    start: usize,
    d: Delivery,
    prior: Option<u64>,
}

/// What the current command is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Typed {
    Raw,
    AxisStatus,
    RelativeMove,
    SoftwareReset,
    ErrorDetail,
}

struct Req {
    serial: usize,
    id: u16,
    typed: Typed,
    /// 0: the command; 1: the 216H detail query after an `&`.
    phase: u8,
    /// Sends of the command in flight.
    sends: u8,
    /// The `&` taken for the command (phase 0).
    rejected: Option<u16>,
    /// The detail reply taken (phase 1): its error number.
    detail: Option<u16>,
    /// An `&` taken in phase 1.
    detail_rejected: bool,
    /// A detail reply taken from raw noise (its number unread here).
    detail_unread: bool,
}

struct H<'a> {
    input: Input<'a>,
    cfg: ClientConfig,
    client: Client<CMD, REPLY>,
    clock: u64,
    base: u32,
    outbox: Vec<Delivery>,
    history: Vec<Delivery>,
    /// When each history entry was first taken (accepted) by the client,
    /// and when a copy of it first arrived; for the delivery being fed, the
    /// first arrival of an earlier copy.
    taken_at: Vec<Option<u64>>,
    arrived_at: Vec<Option<u64>>,
    /// Whether a copy of the reply was heard as `Foreign` (open finding F9).
    heard_foreign: Vec<bool>,
    /// Beside the client's reply decoder: a plain one fed the same bytes
    /// (reset with it at every send), the bytes since that reset, the
    /// deliveries they came from, and where the last frame ended.
    shadow: FrameDecoder<REPLY>,
    /// The client's `line_errors` after the last bytes it was fed: more at
    /// the next feed means it dropped the bytes its decoder held (before a
    /// first send), and the shadow decoder must too.
    line_errors_seen: u32,
    stream: Vec<u8>,
    fed: Vec<Fed>,
    cursor: usize,
    req: Option<Req>,
    /// A reply is awaited: `sent` was called and no transmission since.
    awaiting: bool,
    /// The end of the last send.
    last_sent: u64,
    /// A broken frame was heard since the last `sent`.
    broken_since_sent: bool,
    /// An acceptance happened for the command in flight (until poll).
    accepted: Option<usize>,
    /// Earliest tick of the next first send: two ticks after the reply
    /// that ended the previous command; 10 s after a 25BH was sent.
    not_before: u64,
    /// Frames sent in all.
    sends: u32,
    resends: u32,
    requests: u32,
    /// Bytes held back after an acceptance until the next poll.
    held: Vec<Delivery>,
    /// Commands that took a reply not their own (outside the contract).
    adrift: Vec<Origin>,
}

fn now_of(base: u32, clock: u64) -> u32 {
    base.wrapping_add(clock as u32)
}

impl H<'_> {
    fn now(&self) -> u32 {
        now_of(self.base, self.clock)
    }

    fn ex(&self) -> &ExchangeConfig {
        &self.cfg.exchange
    }

    /// The ID of the command in flight.
    fn id_in_flight(&self) -> Option<u16> {
        self.req.as_ref().map(|r| {
            if r.phase == 1 {
                ErrorDetailQuery::ID
            } else {
                r.id
            }
        })
    }

    /// Starts request number `serial` picked by `pick`.
    fn start(&mut self, serial: usize, pick: u8) {
        // A request still running is abandoned: the replies its sends may
        // still get are stale, and the next command waits them out.
        if let Some(r) = &self.req {
            if r.sends > 0 {
                let ex = *self.ex();
                self.not_before = self
                    .not_before
                    .max(self.last_sent + u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms));
            }
        }
        let now = self.now();
        let (id, typed, res) = match pick % 8 {
            0 => (
                AxisStatusQuery::ID,
                Typed::AxisStatus,
                self.client.start(&AxisStatusQuery::default(), now),
            ),
            1 => (
                RelativeMove::ID,
                Typed::RelativeMove,
                self.client.start(&RelativeMove::default(), now),
            ),
            2 => (
                SoftwareReset::ID,
                Typed::SoftwareReset,
                self.client.start(&SoftwareReset::default(), now),
            ),
            3 => (
                ErrorDetailQuery::ID,
                Typed::ErrorDetail,
                self.client
                    .start(&ErrorDetailQuery::latest_system_error(), now),
            ),
            4 => {
                let mut buf = [0u8; 16];
                let n = emit_frame(
                    &mut buf,
                    Header::Command,
                    self.cfg.exchange.station,
                    UNKNOWN_ID,
                    ChecksumMode::Compute,
                    |_| Ok(()),
                )
                .expect("a bare command fits");
                (
                    UNKNOWN_ID,
                    Typed::Raw,
                    self.client.start_frame(&buf[..n], now),
                )
            }
            _ => {
                let all = catalogue::ALL;
                let info = all[usize::from(self.input.u8()) % all.len()];
                let cmd = Command::default_for(info.id).expect("every catalogue ID has a command");
                let mut buf = vec![0u8; cmd.emit_len()];
                let n = cmd
                    .emit_with(self.cfg.exchange.station, self.cfg.checksum, &mut buf)
                    .expect("a default command emits");
                assert_eq!(n, buf.len(), "emit_len");
                (info.id, Typed::Raw, self.client.start_frame(&buf, now))
            }
        };
        res.expect("a valid command must start");
        trace!("t={} START request {serial}: {id:03X}", self.clock);
        self.requests += 1;
        self.awaiting = false;
        self.accepted = None;
        self.req = Some(Req {
            serial,
            id,
            typed,
            phase: 0,
            sends: 0,
            rejected: None,
            detail: None,
            detail_rejected: false,
            detail_unread: false,
        });
    }

    fn schedule(&mut self, d: Delivery) {
        let i = self.outbox.partition_point(|e| e.at <= d.at);
        self.outbox.insert(i, d);
    }

    /// Delivers everything due up to `to`, moving the clock.
    fn deliver_until(&mut self, to: u64) {
        while self.accepted.is_none() && self.outbox.first().is_some_and(|d| d.at <= to) {
            let d = self.outbox.remove(0);
            self.clock = self.clock.max(d.at);
            self.feed(d);
        }
    }

    /// Feeds one delivery, checking what each frame did.
    fn feed(&mut self, d: Delivery) {
        if self.accepted.is_some() {
            // The reply taken stays readable until the next poll.
            self.held.push(d);
            return;
        }
        if self.client.stats().line_errors > self.line_errors_seen {
            // Before a first send the client dropped the bytes its decoder
            // held (they came before the command): so does the shadow.
            trace!("t={} the client dropped the bytes it held", self.clock);
            self.shadow.reset();
            self.stream.clear();
            self.fed.clear();
            self.cursor = 0;
        }
        let now = self.now();
        let mut prior = None;
        if let Some(i) = d.copy_of.or(d.id) {
            // When a copy of this reply first arrived (before this one).
            prior = self.arrived_at[i];
            if self.arrived_at[i].is_none() {
                self.arrived_at[i] = Some(self.clock);
            }
        }
        let index = self.fed.len();
        self.fed.push(Fed {
            start: self.stream.len(),
            d: d.clone(),
            prior,
        });
        let mut rest = &d.bytes[..];
        loop {
            let r = self.client.received(rest, now);
            self.line_errors_seen = self.client.stats().line_errors;
            // The plain decoder beside the client's: the same events from
            // the same bytes, and the frame's bytes, which the client keeps
            // to itself.
            let shadow = self.shadow.decode(rest);
            trace!(
                "t={} RX {:?} -> {:?} (origin {:?} copy_of {:?} id {:?})",
                self.clock,
                String::from_utf8_lossy(&rest[..r.consumed]),
                r.event,
                d.origin,
                d.copy_of,
                d.id
            );
            assert!(r.consumed <= rest.len());
            assert_eq!(r.consumed, shadow.consumed, "the client decodes otherwise");
            self.stream.extend_from_slice(&rest[..r.consumed]);
            rest = &rest[r.consumed..];
            let frame = match (&r.event, shadow.event) {
                (Heard::NeedMore, Event::NeedMore) => {
                    assert!(rest.is_empty());
                    return;
                }
                (Heard::Broken(a), Event::Error(b)) => {
                    assert_eq!(*a, b, "the client decodes otherwise");
                    self.broken_since_sent = true;
                    None
                }
                (Heard::Frame(_), Event::Frame(f)) => Some(f.as_bytes().to_vec()),
                (a, b) => panic!("the client heard {a:?}, the decoder {b:?}"),
            };
            if let (Heard::Frame(offer), Some(frame)) = (r.event, frame) {
                // Which delivery made the frame: frames come out in stream
                // order (bytes of a failed text frame are decoded again, so
                // a frame may come from an earlier delivery).
                let at = self.stream[self.cursor..]
                    .windows(frame.len())
                    .position(|w| w == frame)
                    .expect("a frame that is not in the bytes fed")
                    + self.cursor;
                let end = at + frame.len();
                self.cursor = end;
                // The delivery that completed it, unless it began in raw
                // noise: then it is the noise's (forged, unsolicited).
                let last = self
                    .fed
                    .iter()
                    .rposition(|f| f.start < end)
                    .unwrap_or(index);
                let first = self
                    .fed
                    .iter()
                    .rposition(|f| f.start <= at)
                    .unwrap_or(index);
                let first_raw = self.fed[first].d.origin.is_none() && self.fed[first].d.unsolicited;
                let src = self.fed[if first_raw { first } else { last }].clone();
                self.offered(offer, &src, &frame);
            }
            if self.accepted.is_some() {
                if !rest.is_empty() {
                    let mut tail = d.clone();
                    tail.bytes = rest.to_vec();
                    tail.origin = None;
                    tail.id = None;
                    tail.copy_of = None;
                    self.held.push(tail);
                }
                return;
            }
        }
    }

    fn offered(&mut self, offer: Offer, src: &Fed, frame: &[u8]) {
        let clock = self.clock;
        let d = &src.d;
        if let (Offer::Foreign, Some(i)) = (offer, d.copy_of.or(d.id)) {
            self.heard_foreign[i] = true;
        }
        match offer {
            Offer::Accepted | Offer::Rejected(_) => {
                assert!(
                    self.awaiting,
                    "{offer:?} while no reply was awaited (before sent?)"
                );
                let id = self.id_in_flight().expect("a reply with no request");
                // The frame taken: the whole delivery, except for raw noise,
                // where only the client's reply frame (after the poll) and
                // the offer's code tell.
                let f = Some(Frame::new_checked(frame, BypassPolicy::Reject).expect("a frame"));
                if let Some(f) = &f {
                    assert_eq!(
                        f.station(),
                        self.cfg.exchange.station,
                        "a reply from another station taken"
                    );
                }
                let req = self.req.as_ref().expect("request");
                let (origin, sent_at) = match d.origin {
                    Some(o) => o,
                    None => {
                        assert!(d.unsolicited, "a frame the controller never made was taken");
                        ((req.serial, req.phase), 0)
                    }
                };
                if origin != (req.serial, req.phase) && !self.adrift.contains(&origin) {
                    // A reply made for something else: only outside the
                    // contract. A copy of a reply the client took may come
                    // `duplicate_window` after it was taken; any other reply
                    // `timeout + late_window` after the send it answers.
                    // (Whichever copy comes second is the duplicate.)
                    let ex = self.ex();
                    let hist = d.copy_of.or(d.id);
                    let taken = hist.and_then(|i| self.taken_at[i]);
                    let dup = u64::from(ex.duplicate_window_ms);
                    let late =
                        clock >= sent_at + u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms);
                    let out = match taken {
                        Some(t) => clock >= t + dup,
                        None => late,
                    };
                    // A copy of a reply that arrived in time but was not
                    // taken (it came while the client held the next command
                    // back) may still come `duplicate_window` after it: the
                    // client holds it back too (finding F6, fixed), but for
                    // open finding F9: not if the original was heard as
                    // `Foreign` (a command with another ID was in progress).
                    let in_time = sent_at + u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms);
                    let f6 = src.prior.is_some_and(|a| a < in_time && clock < a + dup);
                    let f9 = !F9_FIXED && hist.is_some_and(|i| self.heard_foreign[i]);
                    assert!(
                        out && !(f6 && !f9),
                        "request {:?} took a reply made for {origin:?} (sent at {sent_at}, now {clock}, \
                         taken before at {taken:?}, arrived before at {:?})",
                        (req.serial, req.phase),
                        src.prior
                    );
                }
                if d.origin.map(|o| o.0) != Some((req.serial, req.phase)) {
                    // This command took another's reply (outside the
                    // contract): its own replies are adrift, and whoever
                    // takes them later is not at fault.
                    self.adrift.push((req.serial, req.phase));
                }
                let hist = d.copy_of.or(d.id);
                if let Some(i) = hist {
                    if self.taken_at[i].is_none() {
                        self.taken_at[i] = Some(clock);
                    }
                }
                // The next command waits for the turnaround (two ticks at
                // least), for duplicates of this reply, and for the replies
                // of this command's other sends.
                let ex = *self.ex();
                let sends = self.req.as_ref().map_or(0, |r| r.sends);
                let mut nb = clock + u64::from(ex.turnaround_ms) + 1;
                if ex.duplicate_window_ms > 0 {
                    nb = nb.max(clock + u64::from(ex.duplicate_window_ms));
                }
                if sends > 1 {
                    nb = nb.max(
                        self.last_sent + u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms),
                    );
                }
                self.not_before = self.not_before.max(nb);
                let req = self.req.as_mut().expect("request");
                // The exchange is over: an abandon or a 216H fetch starts
                // from no sends.
                req.sends = 0;
                match offer {
                    Offer::Accepted => {
                        match &f {
                            Some(f) => {
                                assert_eq!(
                                    (f.header(), f.code()),
                                    (Header::Response, id),
                                    "accepted another ID"
                                );
                                if catalogue::lookup(id).is_some() {
                                    Response::parse(f).expect("an accepted reply parses");
                                }
                                if req.phase == 1 {
                                    let r = ErrorDetailResponse::parse(f).expect("a 216H reply");
                                    req.detail = Some(r.error_number);
                                }
                            }
                            None if req.phase == 1 => req.detail_unread = true,
                            None => {}
                        }
                        self.accepted = Some(req.serial);
                    }
                    Offer::Rejected(code) => {
                        if let Some(f) = &f {
                            assert_eq!((f.header(), f.code()), (Header::Error, code));
                        }
                        if req.phase == 0 {
                            req.rejected = Some(code);
                        } else {
                            req.detail_rejected = true;
                        }
                    }
                    _ => unreachable!(),
                }
                self.awaiting = false;
            }
            Offer::Mismatch => {
                // Right station and ID, a body that does not parse.
                if let Ok(f) = Frame::new_checked(frame, BypassPolicy::Reject) {
                    assert_eq!(f.header(), Header::Response);
                    assert!(
                        Response::parse(&f).is_err(),
                        "a reply that parses called malformed"
                    );
                } else {
                    assert!(
                        d.unsolicited && d.origin.is_none(),
                        "a mismatch from no frame"
                    );
                }
            }
            Offer::Stale | Offer::Foreign => {}
        }
    }

    /// The controller answers the send that just ended.
    fn answer(&mut self, op: Option<u8>) {
        let op = op.unwrap_or(0);
        let req = self.req.as_ref().expect("a send without a request");
        let origin = (req.serial, req.phase);
        let id = self.id_in_flight().expect("id");
        let station = self.cfg.exchange.station;
        let fate = (op >> 3) & 7;
        let timing = op >> 6;
        let extra = if op != 0 { self.input.u8() } else { 0 };
        let code = if extra & 1 == 0 {
            *BRIDGE_CODES.start() + u16::from(extra >> 1) % 0x20
        } else {
            0x0A0 + u16::from(extra)
        };
        let normal = || -> Option<Vec<u8>> {
            if id == ErrorDetailQuery::ID {
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
                let mut buf = [0u8; 16];
                let n = emit_frame(
                    &mut buf,
                    Header::Response,
                    station,
                    id,
                    ChecksumMode::Compute,
                    |w| w.put(b"00"),
                )
                .expect("fits");
                return Some(buf[..n].to_vec());
            }
            let r = Response::default_for(id)?;
            let mut buf = vec![0u8; r.emit_len()];
            let n = r.emit(station, &mut buf).expect("a default response emits");
            buf.truncate(n);
            Some(buf)
        };
        let error = |code: u16| {
            let mut buf = [0u8; 16];
            let n = ErrorResponse { code }
                .emit(station, &mut buf)
                .expect("fits");
            buf[..n].to_vec()
        };
        // (bytes, is a reply to this send); unsolicited frames are marked
        // by `false` with a catalogue ID of their own.
        let mut frames: Vec<(Vec<u8>, bool)> = Vec::new();
        match fate {
            2 => {}
            3 => frames.push((error(code & 0xFFF), true)),
            4 => {
                // The reply (or, with bit 2 of the extra byte or for a
                // command without one, an `&`) with one byte changed.
                let mut b = match normal() {
                    Some(b) if extra & 4 == 0 => b,
                    _ => error(code & 0xFFF),
                };
                let at = 1 + usize::from(extra) % (b.len() - 3);
                b[at] = if b[at] == b'0' { b'1' } else { b'0' };
                frames.push((b, false));
            }
            5 => {
                // One digit too many: no catalogue response parses; an ID
                // outside the catalogue has no layout to check, so for it
                // this is the reply.
                let mut b = match normal() {
                    Some(b) => b,
                    None => {
                        let mut buf = [0u8; 16];
                        let n = emit_frame(
                            &mut buf,
                            Header::Response,
                            station,
                            id,
                            ChecksumMode::Compute,
                            |_| Ok(()),
                        )
                        .expect("fits");
                        buf[..n].to_vec()
                    }
                };
                let sc_at = b.len() - 4;
                b.insert(sc_at, b'0');
                retarget(&mut b, None, None);
                frames.push((b, id == UNKNOWN_ID));
            }
            6 => {
                let other = Station(station.0.wrapping_add(1 + extra % 200));
                let mut b = normal().unwrap_or_else(|| error(code & 0xFFF));
                retarget(&mut b, Some(other), None);
                frames.push((b, false));
                if let Some(b) = normal() {
                    frames.push((b, true));
                }
            }
            7 => {
                let all = catalogue::ALL;
                let other = all[usize::from(extra) % all.len()].id;
                if other != id {
                    if let Some(r) = Response::default_for(other) {
                        let mut buf = vec![0u8; r.emit_len()];
                        let n = r.emit(station, &mut buf).expect("emits");
                        frames.push((buf[..n].to_vec(), false));
                    }
                }
                if let Some(b) = normal() {
                    frames.push((b, true));
                }
            }
            _ => {
                if let Some(b) = normal() {
                    frames.push((b, true));
                }
            }
        }
        let delay = match timing {
            0 | 2 => 1,
            _ => {
                let span =
                    3 * u64::from(self.ex().timeout_ms) + u64::from(self.ex().late_window_ms) + 2;
                u64::from(self.input.u16()) % span
            }
        };
        let at = self.clock + delay;
        for (bytes, reply) in frames {
            let unsolicited = !reply && bytes[0] == b'#' && bytes.get(3..6) != Some(&hex3(id)[..]);
            let mut d = Delivery {
                at,
                bytes,
                origin: reply.then_some((origin, self.clock)),
                copy_of: None,
                id: None,
                unsolicited,
            };
            if reply {
                d.id = Some(self.history.len());
                self.history.push(d.clone());
                self.taken_at.push(None);
                self.arrived_at.push(None);
                self.heard_foreign.push(false);
            }
            if timing >= 2 {
                let mut dup = d.clone();
                dup.at += u64::from(extra) * 50;
                dup.copy_of = d.id;
                dup.id = None;
                self.schedule(dup);
            }
            self.schedule(d);
        }
    }
}

/// The 3 hex digits of an ID as on the wire.
fn hex3(id: u16) -> [u8; 3] {
    let d = |n: u16| b"0123456789ABCDEF"[usize::from(n & 0xF)];
    [d(id >> 8), d(id >> 4), d(id)]
}

/// Rewrites a frame's station (if given) and its SC in place.
fn retarget(b: &mut [u8], station: Option<Station>, _id: Option<u16>) {
    if let Some(s) = station {
        let hex = b"0123456789ABCDEF";
        b[1] = hex[usize::from(s.0 >> 4)];
        b[2] = hex[usize::from(s.0 & 0xF)];
    }
    let sc_at = b.len() - 4;
    let sum = b[..sc_at].iter().fold(0u8, |a, &x| a.wrapping_add(x));
    let hex = b"0123456789ABCDEF";
    b[sc_at] = hex[usize::from(sum >> 4)];
    b[sc_at + 1] = hex[usize::from(sum & 0xF)];
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let station = Station(input.u8());
    let mut ex = ExchangeConfig::new(station);
    ex.timeout_ms = 1 + u32::from(input.u8()) * 20;
    let b = input.u8();
    ex.max_sends = b % 5; // 0 is read as 1
    ex.resend_unsafe = b & 0x08 != 0;
    let fetch = b & 0x10 != 0;
    let raw_noise = b & 0x80 != 0;
    let requests = 1 + usize::from(b >> 5 & 3);
    ex.turnaround_ms = 1 + u32::from(input.u8() % 4);
    ex.late_window_ms = u32::from(input.u16());
    ex.duplicate_window_ms = u32::from(input.u16());
    let base = input.u32();
    let mut cfg = ClientConfig::new(station);
    cfg.exchange = ex;
    cfg.fetch_error_detail = fetch;
    let mut h = H {
        input,
        cfg,
        client: Client::new(cfg),
        clock: 0,
        base,
        outbox: Vec::new(),
        history: Vec::new(),
        taken_at: Vec::new(),
        arrived_at: Vec::new(),
        heard_foreign: Vec::new(),
        shadow: FrameDecoder::with_policy(BypassPolicy::Reject),
        line_errors_seen: 0,
        stream: Vec::new(),
        fed: Vec::new(),
        cursor: 0,
        req: None,
        awaiting: false,
        last_sent: 0,
        broken_since_sent: false,
        accepted: None,
        not_before: 0,
        sends: 0,
        resends: 0,
        requests: 0,
        held: Vec::new(),
        adrift: Vec::new(),
    };
    let max_sends = ex.max_sends.max(1);
    let max_steps = 64 + 16 * data.len() + 64 * requests * usize::from(max_sends);
    let mut steps = 0usize;
    let mut serial = 0usize;
    let p = h.input.u8();
    h.start(serial, p);

    loop {
        steps += 1;
        assert!(steps <= max_steps, "no end after {steps} steps");
        let now = h.now();
        // After an acceptance the reply is read in the poll below; what
        // came after it is fed once it was.
        let held = std::mem::take(&mut h.held);
        let step = h.client.poll(now);
        match step {
            ClientStep::Idle => panic!("idle with a request started"),
            ClientStep::Transmit(bytes) => {
                let bytes = bytes.to_vec();
                trace!(
                    "t={} TX {}",
                    h.clock,
                    String::from_utf8_lossy(&bytes).trim_end()
                );
                let req = h.req.as_mut().expect("a transmission without a request");
                let f = Frame::new_checked(&bytes, BypassPolicy::Accept)
                    .expect("an invalid command sent");
                assert_eq!((f.header(), f.station()), (Header::Command, station));
                let phase = u8::from(f.code() == ErrorDetailQuery::ID && req.rejected.is_some());
                if phase == 1 && req.phase == 0 {
                    // The 216H detail fetch after an `&` from the controller.
                    let code = req.rejected.expect("rejected");
                    assert!(fetch, "a 216H query without the detail option");
                    assert!(
                        !BRIDGE_CODES.contains(&code),
                        "216H asked for a bridge code"
                    );
                    assert_eq!(
                        ErrorDetailQuery::parse(&f).expect("a 216H query"),
                        ErrorDetailQuery::latest_system_error()
                    );
                    req.phase = 1;
                    req.sends = 0;
                } else {
                    assert_eq!(
                        f.code(),
                        if req.phase == 1 {
                            ErrorDetailQuery::ID
                        } else {
                            req.id
                        }
                    );
                    assert!(
                        req.rejected.is_none() || req.phase == 1,
                        "resent after an &"
                    );
                }
                req.sends += 1;
                let id = if req.phase == 1 {
                    ErrorDetailQuery::ID
                } else {
                    req.id
                };
                let info = catalogue::lookup(id);
                let unsafe_ = info.is_none_or(|i| i.resend == Resend::Unsafe);
                let no_reply = info.is_some_and(|i| !i.has_normal_response());
                let limit = if no_reply || (unsafe_ && !ex.resend_unsafe) {
                    1
                } else {
                    max_sends
                };
                assert!(
                    req.sends <= limit,
                    "{} sends of {id:03X} (limit {limit})",
                    req.sends
                );
                if req.sends > 1 {
                    // A resend: only after the timeout, or a broken reply.
                    assert!(
                        h.clock >= h.last_sent + u64::from(ex.timeout_ms) || h.broken_since_sent,
                        "resent at {} after a send that ended at {}",
                        h.clock,
                        h.last_sent
                    );
                    h.resends += 1;
                } else {
                    assert!(
                        h.clock >= h.not_before,
                        "sent at {} before {}",
                        h.clock,
                        h.not_before
                    );
                }
                h.sends += 1;
                h.awaiting = false;
                // The client reset its reply decoder for this send.
                h.shadow.reset();
                h.stream.clear();
                h.fed.clear();
                h.cursor = 0;
                let op = h.input.next();
                let dur = u64::from(op.map_or(1, |o| o & 7));
                // Replies due while the command goes out arrive before `sent`.
                for d in held {
                    h.feed(d);
                }
                let to = h.clock + dur;
                h.deliver_until(to);
                h.clock = to;
                h.client.sent(h.now());
                h.awaiting = true;
                h.last_sent = h.clock;
                h.broken_since_sent = false;
                let is_reset = h
                    .req
                    .as_ref()
                    .is_some_and(|r| r.phase == 0 && r.id == SoftwareReset::ID);
                if is_reset {
                    h.not_before = h.not_before.max(h.clock + 10_000);
                }
                h.answer(op);
            }
            ClientStep::WaitUntil(deadline) => {
                trace!("t={} WAIT {}", h.clock, deadline.wrapping_sub(now));
                // The longest hold: the quarantine after a send (timeout +
                // late window), a duplicate window, the restart after 25BH.
                let bound = u64::from(ex.timeout_ms)
                    + u64::from(ex.late_window_ms)
                    + u64::from(ex.duplicate_window_ms)
                    + u64::from(ex.turnaround_ms)
                    + 10_002;
                let ahead = records::check_wait(now, deadline, bound, h.sends == 0);
                let until = h.clock + u64::from(ahead);
                for d in held {
                    h.feed(d);
                }
                match h.input.next() {
                    None => {
                        let next = h.outbox.first().map_or(until, |d| d.at.min(until));
                        h.deliver_until(next);
                        if h.accepted.is_none() {
                            h.clock = h.clock.max(next);
                        }
                    }
                    Some(op) => match op % 6 {
                        0 => {
                            let to = h.clock + u64::from(h.input.u16());
                            h.deliver_until(to);
                            if h.accepted.is_none() {
                                h.clock = to;
                            }
                        }
                        1 => {
                            // Noise: anything but LF (so it cannot complete a
                            // frame), or with the raw-noise bit anything at
                            // all, a frame in it being an unsolicited one.
                            let n = usize::from(h.input.u8() % 64);
                            let bytes: Vec<u8> = h
                                .input
                                .take(n)
                                .iter()
                                .map(|&b| if b == b'\n' && !raw_noise { b'?' } else { b })
                                .collect();
                            h.feed(Delivery {
                                at: h.clock,
                                bytes,
                                origin: None,
                                copy_of: None,
                                id: None,
                                unsolicited: raw_noise,
                            });
                        }
                        2 => {
                            if !h.history.is_empty() {
                                let i = usize::from(h.input.u8()) % h.history.len();
                                let mut d = h.history[i].clone();
                                d.copy_of = Some(i);
                                d.id = None;
                                d.at = h.clock;
                                h.feed(d);
                            }
                        }
                        3 => {
                            if let Some(at) = h.outbox.first().map(|d| d.at) {
                                h.deliver_until(at);
                            }
                        }
                        4 if serial + 1 < requests => {
                            // Abandon: the next request starts now.
                            serial += 1;
                            let p = h.input.u8();
                            h.start(serial, p);
                        }
                        _ => {
                            h.deliver_until(until);
                            if h.accepted.is_none() {
                                h.clock = h.clock.max(until);
                            }
                        }
                    },
                }
            }
            ClientStep::Done(result) => {
                trace!("t={} DONE {result:?}", h.clock);
                let req = h.req.take().expect("done without a request");
                let ended_by_reply = matches!(result, Ok(Outcome::Replied))
                    || req.detail_rejected
                    || (req.rejected.is_some() && req.phase == 0)
                    || (req.phase == 1 && (req.detail.is_some() || req.detail_unread));
                match result {
                    Ok(Outcome::Replied) => {
                        assert_eq!(
                            h.accepted,
                            Some(req.serial),
                            "Replied without an accepted reply"
                        );
                        assert_eq!(req.phase, 0);
                        let f = h.client.reply_frame().expect("the reply is readable");
                        assert_eq!(
                            (f.header(), f.station(), f.code()),
                            (Header::Response, station, req.id)
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
                            Typed::SoftwareReset => panic!("a normal reply to 25BH"),
                            Typed::Raw => {}
                        }
                    }
                    Ok(Outcome::NoReplyExpected) => {
                        assert_eq!(
                            req.id,
                            SoftwareReset::ID,
                            "no reply expected for {:03X}",
                            req.id
                        );
                        assert_eq!(req.sends, 1);
                        // (Finding F3, fixed: an `&` to 25BH that arrived
                        // broken ended it at once as NoReplyExpected.)
                        assert!(
                            h.clock >= h.last_sent + u64::from(ex.timeout_ms),
                            "25BH reported done at {} after a send that ended at {} (timeout {})",
                            h.clock,
                            h.last_sent,
                            ex.timeout_ms
                        );
                        if req.typed == Typed::SoftwareReset {
                            h.client.response::<SoftwareReset>().expect("the default");
                        }
                    }
                    Err(CallError::Timeout { sends })
                    | Err(CallError::OutcomeUnknown { sends }) => {
                        assert!(req.rejected.is_none());
                        assert_eq!(sends, req.sends);
                        let unsafe_ =
                            catalogue::lookup(req.id).is_none_or(|i| i.resend == Resend::Unsafe);
                        assert_eq!(
                            matches!(result, Err(CallError::OutcomeUnknown { .. })),
                            unsafe_
                        );
                        assert!(
                            h.clock >= h.last_sent + u64::from(ex.timeout_ms)
                                || h.broken_since_sent,
                            "gave up at {} after a send that ended at {}",
                            h.clock,
                            h.last_sent
                        );
                        // 25BH ends unknown only on a broken frame after its
                        // send: its `&`, unreadable (finding F3).
                        if req.id == SoftwareReset::ID && req.phase == 0 {
                            assert!(h.broken_since_sent, "25BH unknown without a broken reply");
                        }
                    }
                    Err(CallError::Controller { code, detail }) => {
                        assert_eq!(req.rejected, Some(code));
                        assert!(!BRIDGE_CODES.contains(&code));
                        match detail {
                            Some(d) => {
                                assert!(fetch);
                                if !req.detail_unread {
                                    assert_eq!(Some(d.error_number), req.detail);
                                }
                                assert_eq!(d.matches_code, d.error_number == code);
                            }
                            None => assert!(!fetch || (req.detail.is_none() && !req.detail_unread)),
                        }
                        if fetch {
                            assert_eq!(req.phase, 1, "no 216H query after an & with the option on");
                        }
                    }
                    Err(CallError::Bridge { code }) => {
                        assert_eq!(req.rejected, Some(code));
                        assert!(BRIDGE_CODES.contains(&code));
                        assert_eq!(req.phase, 0);
                    }
                    Err(e) => panic!("unexpected {e:?}"),
                }
                if !ended_by_reply
                    && req.sends > 0
                    && !matches!(result, Ok(Outcome::NoReplyExpected))
                    && !(req.id == SoftwareReset::ID && req.phase == 0)
                {
                    // Given up: every send's reply may still come. (A 25BH
                    // ends unknown only on a broken frame: its answer.)
                    h.not_before = h
                        .not_before
                        .max(h.last_sent + u64::from(ex.timeout_ms) + u64::from(ex.late_window_ms));
                }
                // Later bytes go to the client as stale frames.
                h.accepted = None;
                for d in held {
                    h.feed(d);
                }
                let s = h.client.stats();
                assert_eq!(
                    (s.requests, s.sends, s.resends),
                    (h.requests, h.sends, h.resends)
                );
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
