//! The line between an engine and a simulated controller, for the
//! `client`, `readback` and `transfer` targets: the line's settings from
//! the input, the controller's replies scheduled in order (a reply never
//! overtakes one made before it; copies may, within the duplicate
//! window), the fences echoed, and the contract each delivery keeps or
//! breaks (see [`Link::arrives`]).
//!
//! Also [`Shadow`]: the engine's decoders mirrored (its receiver's
//! `FrameDecoder`, and the line's decoder of frames heard while the
//! engine keeps a reply), fed the same bytes, which tells which delivery
//! made each frame the engine heard.
#![allow(dead_code)]

use iai_protocol_b::catalogue::LONGEST_RESTART_MS;
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::decoder::{Event, FrameDecoder, FrameSkipper, Received, Skipped, Status};
use iai_protocol_b::error::Error;
use iai_protocol_b::frame::{emit_frame, read_envelope, Frame, Header, Station, ENVELOPE_LEN};
use iai_protocol_b::line::{Heard, LineConfig};
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::{PositionStreamDecoder, StreamEvent};

use crate::records::Input;

/// Flag bits of the link's config byte that the engine targets use for
/// their own settings.
pub const FLAG_A: u8 = 0x20;
pub const FLAG_B: u8 = 0x40;
pub const FLAG_C: u8 = 0x80;

/// The line's settings, read from the input.
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    pub line: LineConfig,
    pub seed: u32,
    pub base: u32,
    /// Noise may hold any byte (so a frame that passes for a reply).
    pub raw_noise: bool,
    pub flags: u8,
}

/// Reads station; timeout byte (1 + 20 x b ms); flags (bits 0-1 sends
/// 1-4, 0x04 `resend_unsafe`, 0x08 fences off, 0x10 raw noise, 0x20-0x80
/// the target's); turnaround byte (`% 16` ms); late window u16; duplicate
/// window u16; fence seed u16; start tick u32.
pub fn setup(input: &mut Input<'_>) -> Setup {
    let mut line = LineConfig::new(Station(input.u8()));
    line.timeout_ms = 1 + u32::from(input.u8()) * 20;
    let flags = input.u8();
    line.max_sends = 1 + flags % 4;
    line.resend_unsafe = flags & 0x04 != 0;
    line.fences = flags & 0x08 == 0;
    line.turnaround_ms = u32::from(input.u8() % 16);
    line.late_window_ms = u32::from(input.u16());
    line.duplicate_window_ms = u32::from(input.u16());
    let seed = u32::from(input.u16()) << 4 | 0x00C0_0000;
    let base = input.u32();
    Setup {
        line,
        seed,
        base,
        raw_noise: flags & 0x10 != 0,
        flags,
    }
}

impl Setup {
    /// The longest hold the line may place (`WaitUntil` bound), with
    /// copies expected for `copy_window` ms (`Line::copy_window`: the
    /// declared window, or the one the line learned from frames it could
    /// not place).
    pub fn horizon(&self, copy_window: u32) -> u64 {
        let c = &self.line;
        let dup = c.duplicate_window_ms.max(copy_window);
        let sum = u64::from(c.timeout_ms)
            + u64::from(c.late_window_ms)
            + u64::from(dup)
            + u64::from(c.turnaround_ms)
            + 2;
        sum.max(u64::from(LONGEST_RESTART_MS))
    }

    /// Whether `bytes` is the line's fence: a 200H command for the station
    /// whose text begins with the six hex digits of the seed.
    pub fn is_fence(&self, bytes: &[u8]) -> bool {
        let head = format!(
            "!{:02X}200{:06X}",
            self.line.station.0,
            self.seed & 0xFF_FFFF
        );
        bytes.starts_with(head.as_bytes())
    }
}

/// What a delivery is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A reply the controller made (index into `Link::made`), or a copy.
    Reply { made: usize, copy: bool },
    /// The same with a byte changed (its SC fails; its envelope is intact).
    Broken { made: usize, copy: bool },
    /// Bytes that cannot complete a frame.
    Noise,
    /// Arbitrary bytes: a frame in them passes for anything.
    Forged,
}

#[derive(Debug, Clone)]
pub struct Delivery {
    pub at: u64,
    pub bytes: Vec<u8>,
    pub kind: Kind,
    /// Whether it kept the contract, judged when it first reached the
    /// engine (`Link::arrives`).
    pub ok: Option<bool>,
    /// It was the first arrival of its reply (whole or broken, the
    /// original or a copy).
    pub first: bool,
}

impl Delivery {
    pub fn new(at: u64, bytes: Vec<u8>, kind: Kind) -> Self {
        Delivery {
            at,
            bytes,
            kind,
            ok: None,
            first: false,
        }
    }

    /// Whether it kept the contract (see `Link::arrives`).
    pub fn ok(&self) -> bool {
        self.ok.expect("judged when it arrived")
    }
}

/// A reply the controller made.
#[derive(Debug, Clone)]
pub struct Made {
    pub bytes: Vec<u8>,
    /// The command frame it answers (index into `Link::cmds`).
    pub cmd: usize,
    /// The end of that command's transmission.
    pub sent_at: u64,
    /// When it first reached the engine (whole or broken, the original or
    /// a copy), and whether that first arrival kept the contract.
    pub arrived: Option<u64>,
    pub first_ok: bool,
    /// Not the controller's answer to that command (an earlier reply sent
    /// again, ...): outside the contract whenever it comes.
    pub lie: bool,
    /// Its first arrival was heard as a whole frame of that delivery alone
    /// (so the line knows of it: its copies are expected).
    pub first_heard: bool,
}

/// A command frame the controller received.
#[derive(Debug, Clone)]
pub struct Cmd {
    pub bytes: Vec<u8>,
    pub at: u64,
    pub fence: bool,
}

pub struct Link {
    pub setup: Setup,
    /// Deliveries in time order (originals in the order they were made).
    pub outbox: Vec<Delivery>,
    pub made: Vec<Made>,
    pub cmds: Vec<Cmd>,
    last_original: u64,
}

/// What the script says about one transmission: its length, whether the
/// controller gets it, and what happens to the reply.
#[derive(Debug, Clone, Copy, Default)]
pub struct Fate {
    /// Transmission time, ms (0-7).
    pub dur: u64,
    /// The command is lost (or arrives broken): no reply, nothing done.
    pub lost: bool,
    /// The target's own command fault (bit 4 of the op with bit 3 set).
    pub special: bool,
    /// Reply fault 0-7 (see each target), and its byte.
    pub fault: u8,
    pub extra: u8,
    /// When the reply comes after the end of the transmission.
    pub delay: u64,
}

impl Link {
    pub fn new(setup: Setup) -> Self {
        Link {
            setup,
            outbox: Vec::new(),
            made: Vec::new(),
            cmds: Vec::new(),
            last_original: 0,
        }
    }

    pub fn station(&self) -> Station {
        self.setup.line.station
    }

    /// Op byte of a transmission: bits 0-2 its duration, bits 3-4 the
    /// command's fate (2: lost, 3: special), bits 5-7 the reply's fault;
    /// with a fault, one more byte and a delay (u16, up to three timeouts
    /// and the late window past the end of the transmission).
    pub fn fate(&self, input: &mut Input<'_>, op: Option<u8>) -> Fate {
        let op = op.unwrap_or(0);
        let fault = op >> 5;
        let (extra, delay) = if fault == 0 {
            (0, 1)
        } else {
            let c = &self.setup.line;
            let span = 3 * u64::from(c.timeout_ms) + u64::from(c.late_window_ms) + 2;
            (input.u8(), u64::from(input.u16()) % span)
        };
        Fate {
            dur: u64::from(op & 7),
            lost: (op >> 3) & 3 == 2,
            special: (op >> 3) & 3 == 3,
            fault,
            extra,
            delay,
        }
    }

    /// The controller received command frame `bytes` at `at` (the end of
    /// its transmission).
    pub fn received(&mut self, bytes: &[u8], at: u64) -> usize {
        let fence = self.setup.is_fence(bytes);
        self.cmds.push(Cmd {
            bytes: bytes.to_vec(),
            at,
            fence,
        });
        self.cmds.len() - 1
    }

    /// The echo of fence `bytes`.
    pub fn echo(&self, bytes: &[u8]) -> Vec<u8> {
        let f = Frame::new_checked(bytes, BypassPolicy::Accept).expect("a valid fence");
        assert_eq!(f.body().len(), 10, "a fence of ten characters");
        frame(Header::Response, self.station(), 0x200, f.body())
    }

    /// Schedules reply `bytes` to command `cmd` at `at` or later (after
    /// every original made before it); returns its index.
    pub fn reply(&mut self, bytes: Vec<u8>, cmd: usize, at: u64, lie: bool) -> usize {
        let at = at.max(self.last_original);
        self.last_original = at;
        let sent_at = self.cmds[cmd].at;
        self.made.push(Made {
            bytes: bytes.clone(),
            cmd,
            sent_at,
            arrived: None,
            first_ok: false,
            lie,
            first_heard: false,
        });
        let made = self.made.len() - 1;
        self.schedule(Delivery::new(at, bytes, Kind::Reply { made, copy: false }));
        made
    }

    /// The common reply faults: 1 lost, 2 a corrupted byte, 3 a copy
    /// `extra x 50` ms later, 7 a copy `extra x 20` ms later; the target
    /// handles the others (and 0: at once) by calling `reply` itself.
    /// Schedules `bytes` as the reply to `cmd` under `f`.
    pub fn answer(&mut self, bytes: Vec<u8>, cmd: usize, at: u64, f: &Fate, lie: bool) {
        match f.fault {
            1 => {
                // Lost: made, never delivered.
                self.made.push(Made {
                    bytes,
                    cmd,
                    sent_at: self.cmds[cmd].at,
                    arrived: None,
                    first_ok: false,
                    lie,
                    first_heard: false,
                });
            }
            2 => {
                let made = self.reply(bytes, cmd, at, lie);
                let d = self
                    .outbox
                    .iter_mut()
                    .rev()
                    .find(|d| d.kind == Kind::Reply { made, copy: false });
                if let Some(d) = d {
                    corrupt_body(&mut d.bytes, u32::from(f.extra) * 977 + f.delay as u32);
                    d.kind = Kind::Broken { made, copy: false };
                }
            }
            3 | 7 => {
                let made = self.reply(bytes.clone(), cmd, at, lie);
                let step = if f.fault == 3 { 50 } else { 20 };
                let first = self.outbox_at(made);
                self.schedule(Delivery::new(
                    first + u64::from(f.extra) * step,
                    bytes,
                    Kind::Reply { made, copy: true },
                ));
            }
            _ => {
                self.reply(bytes, cmd, at, lie);
            }
        }
    }

    fn outbox_at(&self, made: usize) -> u64 {
        self.outbox
            .iter()
            .find(|d| d.kind == Kind::Reply { made, copy: false })
            .map_or(0, |d| d.at)
    }

    pub fn schedule(&mut self, d: Delivery) {
        let i = self.outbox.partition_point(|e| e.at <= d.at);
        self.outbox.insert(i, d);
    }

    /// The next delivery due by `to`.
    pub fn due(&mut self, to: u64) -> Option<Delivery> {
        if self.outbox.first().is_some_and(|d| d.at <= to) {
            Some(self.outbox.remove(0))
        } else {
            None
        }
    }

    /// Puts the rest of a delivery the engine did not take back in front.
    pub fn put_back(&mut self, d: Delivery) {
        self.outbox.insert(0, d);
    }

    /// Delivery `d` reaches the engine at `clock` (the first time: a
    /// delivery put back keeps its verdict). Whether it keeps the contract
    /// of the line's settings: the first arrival of a reply is the
    /// original, within `timeout + late_window` of the end of the send it
    /// answers (in order: the schedule keeps that; a copy that came first
    /// breaks it); every later arrival (a copy) within `duplicate_window`
    /// of the first, if that one kept the contract (none with a window of
    /// 0); noise always (it cannot complete a frame); raw bytes
    /// and lies never.
    pub fn arrives(&mut self, d: &mut Delivery, clock: u64) -> bool {
        if let Some(ok) = d.ok {
            return ok;
        }
        let c = self.setup.line;
        let ok = match d.kind {
            Kind::Reply { made, copy } | Kind::Broken { made, copy } => {
                let m = &mut self.made[made];
                let ok = match m.arrived {
                    None => {
                        let ok = !copy
                            && !m.lie
                            && clock
                                <= m.sent_at
                                    + u64::from(c.timeout_ms)
                                    + u64::from(c.late_window_ms);
                        m.arrived = Some(clock);
                        m.first_ok = ok;
                        d.first = true;
                        ok
                    }
                    // A line with no duplicate window never repeats a
                    // frame; a copy of a first arrival outside the
                    // contract (which may have come after the next
                    // command went out) is outside it too.
                    Some(a) => {
                        let dup = u64::from(c.duplicate_window_ms);
                        m.first_ok && dup > 0 && clock <= a + dup
                    }
                };
                ok && !m.lie
            }
            Kind::Noise => true,
            Kind::Forged => false,
        };
        d.ok = Some(ok);
        ok
    }

    /// A whole frame made of delivery `d` alone was heard.
    pub fn heard_whole(&mut self, d: &Delivery) {
        if let Kind::Reply { made, .. } = d.kind {
            if d.first {
                self.made[made].first_heard = true;
            }
        }
    }

    /// The command whose reply delivery `d` is, if the line must be able
    /// to place it when it comes whole: a reply within the contract (not a
    /// lie), the original or a copy of a first arrival the line heard
    /// whole. An original in time is owed (or awaited), a copy in the
    /// window is expected.
    pub fn placeable(&self, d: &Delivery) -> Option<usize> {
        let Kind::Reply { made, .. } = d.kind else {
            return None;
        };
        let m = &self.made[made];
        (d.ok() && (d.first || m.first_heard)).then_some(m.cmd)
    }

    /// The command a delivery answers, if it is the controller's.
    pub fn origin(&self, d: &Delivery) -> Option<usize> {
        match d.kind {
            Kind::Reply { made, .. } | Kind::Broken { made, .. } => Some(self.made[made].cmd),
            _ => None,
        }
    }

    /// Noise: a byte `k`, then `k % 64` bytes of the script, LF replaced
    /// unless raw noise is on; with `k & 0x40` the next delivery follows
    /// right behind it (no poll between: the noise may hold a frame's
    /// start that takes the next frame in).
    pub fn noise(&self, input: &mut Input<'_>, clock: u64) -> (Delivery, bool) {
        let k = input.u8();
        let n = usize::from(k % 64);
        let raw = self.setup.raw_noise;
        let bytes = input
            .take(n)
            .iter()
            .map(|&b| if b == b'\n' && !raw { b'?' } else { b })
            .collect();
        let kind = if raw { Kind::Forged } else { Kind::Noise };
        (Delivery::new(clock, bytes, kind), k & 0x40 != 0)
    }
}

impl Link {
    /// A copy of a reply made before, now: a byte `i` picks it (`(i &
    /// 0x7F) % made`), and with `i & 0x80` a byte of it is changed.
    pub fn copy(&self, input: &mut Input<'_>, clock: u64) -> Option<Delivery> {
        if self.made.is_empty() {
            return None;
        }
        let i = input.u8();
        let made = usize::from(i & 0x7F) % self.made.len();
        let mut bytes = self.made[made].bytes.clone();
        let kind = if i & 0x80 != 0 && corrupt_body(&mut bytes, u32::from(i) * 131 + 17) {
            Kind::Broken { made, copy: true }
        } else {
            Kind::Reply { made, copy: true }
        };
        Some(Delivery::new(clock, bytes, kind))
    }
}

/// A frame with a computed checksum.
pub fn frame(header: Header, station: Station, code: u16, body: &[u8]) -> Vec<u8> {
    let mut buf = vec![0u8; body.len() + 16];
    let n = emit_frame(
        &mut buf,
        header,
        station,
        code,
        ChecksumMode::Compute,
        |w| w.put(body),
    )
    .expect("a frame fits");
    buf.truncate(n);
    buf
}

/// Replaces one byte after the envelope (a body digit or the SC) with
/// another that is no header byte, CR or LF, so that the frame fails its
/// check with its envelope intact. Returns whether it changed a byte.
pub fn corrupt_body(frame: &mut [u8], pick: u32) -> bool {
    if frame.len() < 10 {
        return false;
    }
    for k in 0..64u32 {
        let at = 6 + (pick as usize + k as usize) % (frame.len() - 8);
        let old = frame[at];
        let mut new = (pick >> 8).wrapping_add(k) as u8;
        for _ in 0..256 {
            if new != old && !matches!(new, b'!' | b'#' | b'&' | b'%' | b'\r' | b'\n') {
                break;
            }
            new = new.wrapping_add(1);
        }
        frame[at] = new;
        if Frame::new_checked(frame, BypassPolicy::Accept).is_err() {
            return true;
        }
        frame[at] = old;
    }
    false
}

/// The engine's decoders mirrored: fed the same bytes as the engine's
/// `received`, they tell which delivery made each frame it heard.
///
/// An engine decodes with its receiver's `FrameDecoder<N>` (policy
/// `Reject`) until it takes a reply it keeps (a client's answer, a
/// read-back window to deliver); from then until its next fresh send
/// (`Receiver::clear`) the bytes go to the line's own decoder of frames
/// heard in passing (`line/overheard.rs`: a `FrameSkipper` per frame, no
/// buffer, its state kept across those phases), which [`Overheard`]
/// mirrors. The harness says when a reply is kept ([`Shadow::hold`]) and
/// when the engine sends afresh ([`Shadow::release`]); every call is then
/// checked to consume the same bytes and end the same way.
pub struct Shadow<const N: usize> {
    dec: FrameDecoder<N>,
    /// Bytes fed to `dec` since its last reset, where each delivery's
    /// begin (index into `deliveries`), and where the last frame ended.
    stream: Vec<u8>,
    fed: Vec<(usize, usize)>,
    cursor: usize,
    over: Overheard,
    /// Bytes fed to the line's decoder, ever, and where each delivery's
    /// begin.
    held_stream: Vec<u8>,
    held_fed: Vec<(usize, usize)>,
    deliveries: Vec<Delivery>,
    held: bool,
    /// While a reply is kept, replies of this kind stream by the engine's
    /// own decoder ([`Passing`]) rather than the line's.
    streams: Option<PositionStream>,
    passing: Passing,
}

/// Who made a frame the engine heard.
#[derive(Debug, Clone)]
pub enum Source {
    /// A delivery of the controller's (or noise).
    Delivery(Delivery),
    /// Bytes of raw noise are in it, or of several deliveries: anything.
    Forged,
}

/// A whole frame the engine heard.
#[derive(Debug, Clone)]
pub struct Seen {
    pub bytes: Vec<u8>,
    pub envelope: (Header, Station, u16),
    pub source: Source,
    /// Heard by the line's own decoder while the engine kept a reply (its
    /// bytes passed the frame's SC check, not necessarily
    /// `Frame::new_checked`).
    pub held: bool,
}

impl Seen {
    /// The frame, checked (an engine's decoder gives only such frames).
    pub fn frame(&self) -> Frame<'_> {
        Frame::new_checked(&self.bytes, BypassPolicy::Reject).expect("a checked frame")
    }
}

impl<const N: usize> Default for Shadow<N> {
    fn default() -> Self {
        Shadow {
            dec: FrameDecoder::with_policy(BypassPolicy::Reject),
            stream: Vec::new(),
            fed: Vec::new(),
            cursor: 0,
            over: Overheard::default(),
            held_stream: Vec::new(),
            held_fed: Vec::new(),
            deliveries: Vec::new(),
            held: false,
            streams: None,
            passing: Passing::default(),
        }
    }
}

impl<const N: usize> Shadow<N> {
    /// A shadow of an engine that reads replies of `kind` as they pass
    /// while it keeps one (a read-back).
    pub fn streaming(kind: PositionStream) -> Self {
        Shadow {
            streams: Some(kind),
            ..Shadow::default()
        }
    }

    /// The engine sent afresh: its receiver drops what it half decoded
    /// and the reply it kept. Returns the deliveries whose bytes its
    /// decoder still held (unless it kept a reply): dropped unread.
    pub fn release(&mut self) -> Vec<Delivery> {
        let mut dropped = Vec::new();
        if !self.held && self.dec.pending() > 0 {
            let first = self
                .fed
                .iter()
                .rposition(|(s, _)| *s <= self.cursor)
                .unwrap_or(0);
            for &(_, d) in &self.fed[first..] {
                dropped.push(self.deliveries[d].clone());
            }
        }
        self.dec.reset();
        self.stream.clear();
        self.fed.clear();
        self.cursor = 0;
        self.held = false;
        self.passing.stop();
        dropped
    }

    /// The engine keeps the reply it just took: the next bytes go to the
    /// line's own decoder.
    pub fn hold(&mut self) {
        self.held = true;
    }

    pub fn holding(&self) -> bool {
        self.held
    }

    /// A delivery begins.
    pub fn begin(&mut self, d: &Delivery) {
        self.deliveries.push(d.clone());
    }

    fn current(&self) -> usize {
        self.deliveries
            .len()
            .checked_sub(1)
            .expect("a delivery begun")
    }

    /// The engine's `received` was given `rest` and answered `r`: the
    /// shadow decodes the same bytes and checks that it ends alike.
    /// Returns the whole frame heard, if any.
    pub fn decoded(&mut self, rest: &[u8], r: &Received<Heard>) -> Option<Seen> {
        if self.held {
            self.decoded_held(rest, r)
        } else {
            self.decoded_engine(rest, r)
        }
    }

    fn decoded_engine(&mut self, rest: &[u8], r: &Received<Heard>) -> Option<Seen> {
        let cur = self.current();
        let s = self.dec.decode(rest);
        assert_eq!(s.consumed, r.consumed, "the engine decodes otherwise");
        if s.consumed > 0 && self.fed.last().is_none_or(|&(_, d)| d != cur) {
            self.fed.push((self.stream.len(), cur));
        }
        self.stream.extend_from_slice(&rest[..s.consumed]);
        let bytes = match (r.status, s.status) {
            (Status::Partial, Status::Partial) => return None,
            (Status::Complete(Heard::Broken(a)), Status::Complete(Event::Error(b))) => {
                assert_eq!(a, b, "the engine decodes otherwise");
                return None;
            }
            (Status::Complete(h), Status::Complete(Event::Frame(f)))
                if !matches!(h, Heard::Broken(_)) =>
            {
                f.as_bytes().to_vec()
            }
            (heard, e) => panic!("the engine heard {heard:?}, the decoder {e:?}"),
        };
        // Frames come out in stream order (bytes of a failed text frame
        // are decoded again, so a frame may come from an earlier delivery).
        let at = self.stream[self.cursor..]
            .windows(bytes.len())
            .position(|w| w == bytes.as_slice())
            .expect("a frame that is not in the bytes fed")
            + self.cursor;
        let end = at + bytes.len();
        self.cursor = end;
        let source = self.source(&self.fed, at, end);
        let envelope = read_envelope(&bytes).expect("a frame's envelope");
        Some(Seen {
            bytes,
            envelope,
            source,
            held: false,
        })
    }

    fn decoded_held(&mut self, rest: &[u8], r: &Received<Heard>) -> Option<Seen> {
        let cur = self.current();
        let base = self.held_stream.len();
        let (used, passed) = match self.streams {
            None => self.over.decode(rest, base),
            Some(kind) => self.decode_streaming(kind, rest, base),
        };
        assert_eq!(used, r.consumed, "the line's decoder decodes otherwise");
        if used > 0 && self.held_fed.last().is_none_or(|&(_, d)| d != cur) {
            self.held_fed.push((base, cur));
        }
        self.held_stream.extend_from_slice(&rest[..used]);
        match (r.status, passed) {
            (Status::Partial, None) => None,
            (Status::Complete(Heard::Broken(a)), Some(Passed::Broken(b, _))) => {
                assert_eq!(a, b, "the line's decoder decodes otherwise");
                None
            }
            (Status::Complete(h), Some(Passed::Whole { start, envelope }))
                if !matches!(h, Heard::Broken(_)) =>
            {
                let end = base + used;
                let bytes = self.held_stream[start..end].to_vec();
                let source = self.source(&self.held_fed, start, end);
                Some(Seen {
                    bytes,
                    envelope,
                    source,
                    held: true,
                })
            }
            (heard, p) => panic!("the line heard {heard:?}, its decoder {p:?}"),
        }
    }

    /// The held decoding of a read-back: every byte goes to the line's
    /// decoder and to the engine's passing one; a reply of `kind` is the
    /// passing decoder's (the line's skips it), anything else the line's.
    fn decode_streaming(
        &mut self,
        kind: PositionStream,
        rest: &[u8],
        base: usize,
    ) -> (usize, Option<Passed>) {
        let streamed = |env: &(Header, Station, u16)| env.0 == kind.header && env.2 == kind.id;
        for (i, &b) in rest.iter().enumerate() {
            let at = base + i;
            let passing = self.passing.push(kind, b, at);
            let (_, other) = self.over.decode(&[b], at);
            let other = match other {
                Some(Passed::Whole { envelope, .. }) if streamed(&envelope) => None,
                Some(Passed::Broken(_, Some(envelope))) if streamed(&envelope) => None,
                other => other,
            };
            if let Some(p) = passing.or(other) {
                return (i + 1, Some(p));
            }
        }
        (rest.len(), None)
    }

    /// Who made the bytes `at..end` of a stream fed as `fed` says.
    fn source(&self, fed: &[(usize, usize)], at: usize, end: usize) -> Source {
        let first = fed.iter().rposition(|(s, _)| *s <= at).expect("fed");
        let last = fed.iter().rposition(|(s, _)| *s < end).expect("fed");
        let d = &self.deliveries[fed[first].1];
        if first != last || d.kind == Kind::Forged {
            Source::Forged
        } else {
            Source::Delivery(d.clone())
        }
    }
}

/// What the line's decoder of frames heard in passing made of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Passed {
    /// Its SC checked; it began at this index of the stream.
    Whole {
        start: usize,
        envelope: (Header, Station, u16),
    },
    /// Broken, with its envelope if it was read.
    Broken(Error, Option<(Header, Station, u16)>),
}

/// A read-back's decoder of its query's replies heard while it keeps one
/// (`readback.rs`, `Passing`), rebuilt from its rules: a header byte
/// starts a `PositionStreamDecoder`; a frame of another kind is left to
/// the line's; a reply of the kind ends whole or, once its envelope was
/// read, broken.
#[derive(Debug, Clone)]
struct Passing {
    dec: PositionStreamDecoder,
    hunting: bool,
    started: bool,
    station: Station,
    start: usize,
}

impl Default for Passing {
    fn default() -> Self {
        Passing {
            dec: PositionStreamDecoder::new(BypassPolicy::Reject),
            hunting: true,
            started: false,
            station: Station(0),
            start: 0,
        }
    }
}

impl Passing {
    fn stop(&mut self) {
        self.hunting = true;
        self.started = false;
    }

    fn push(&mut self, kind: PositionStream, b: u8, at: usize) -> Option<Passed> {
        if self.hunting {
            Header::from_byte(b)?;
            self.dec.reset();
            self.hunting = false;
            self.started = false;
            self.start = at;
        }
        match self.dec.push(b) {
            Status::Partial => None,
            Status::Complete(StreamEvent::Start {
                kind: k, station, ..
            }) => {
                self.started = k == kind;
                self.hunting = !self.started;
                self.station = station;
                None
            }
            Status::Complete(StreamEvent::Record(_)) => None,
            Status::Complete(StreamEvent::End { .. }) => {
                self.hunting = true;
                self.started = false;
                Some(Passed::Whole {
                    start: self.start,
                    envelope: (kind.header, self.station, kind.id),
                })
            }
            Status::Complete(StreamEvent::Error { error, .. }) => {
                self.hunting = true;
                let started = std::mem::take(&mut self.started);
                if Header::from_byte(b).is_some() {
                    self.dec.reset();
                    self.hunting = false;
                    self.start = at;
                    let _ = self.dec.push(b);
                }
                started.then(|| Passed::Broken(error, Some((kind.header, self.station, kind.id))))
            }
        }
    }
}

/// The line's decoder of frames heard in passing (`line/overheard.rs`),
/// rebuilt from its rules: a header byte starts a frame; in its envelope
/// a header byte, CR or LF cuts it; once the envelope reads, a
/// `FrameSkipper` takes the rest, and a header byte it breaks at starts
/// the next frame.
#[derive(Debug, Clone, Default)]
struct Overheard {
    /// Bytes of the frame so far, and where it began.
    frame: Vec<u8>,
    start: usize,
    envelope: Option<(Header, Station, u16)>,
    skipper: Option<FrameSkipper>,
}

impl Overheard {
    fn restart(&mut self) {
        self.frame.clear();
        self.envelope = None;
        self.skipper = None;
    }

    /// Decodes `input` (from index `base` of the stream) up to the first
    /// frame that ends; returns the bytes used.
    fn decode(&mut self, input: &[u8], base: usize) -> (usize, Option<Passed>) {
        for (i, &b) in input.iter().enumerate() {
            let at = base + i;
            let header = Header::from_byte(b);
            if self.frame.is_empty() {
                if header.is_some() {
                    self.frame.push(b);
                    self.start = at;
                }
                continue;
            }
            let broken = |o: &mut Overheard, e: Error, again: bool| {
                let envelope = o.envelope;
                o.restart();
                if again {
                    o.frame.push(b);
                    o.start = at;
                }
                (i + 1, Some(Passed::Broken(e, envelope)))
            };
            if let Some(mut skipper) = self.skipper {
                let status = skipper.push(b);
                self.skipper = Some(skipper);
                let cut = Error::Truncated {
                    len: self.frame.len(),
                };
                match status {
                    Status::Partial => self.frame.push(b),
                    Status::Complete(Skipped::End { checksum_ok: true }) => {
                        let envelope = self.envelope.expect("an envelope read");
                        let start = self.start;
                        self.restart();
                        return (i + 1, Some(Passed::Whole { start, envelope }));
                    }
                    Status::Complete(Skipped::End { checksum_ok: false }) => {
                        return broken(self, skipper.checksum_error(), false);
                    }
                    Status::Complete(Skipped::Broken) => {
                        return broken(self, cut, header.is_some());
                    }
                }
                continue;
            }
            if header.is_some() || b == b'\r' || b == b'\n' {
                let cut = Error::Truncated {
                    len: self.frame.len(),
                };
                return broken(self, cut, header.is_some());
            }
            self.frame.push(b);
            if self.frame.len() == ENVELOPE_LEN {
                self.envelope = read_envelope(&self.frame);
                match self.envelope {
                    Some((h, _, _)) => {
                        let env: [u8; ENVELOPE_LEN] =
                            self.frame[..].try_into().expect("an envelope");
                        self.skipper = Some(FrameSkipper::new(h, &env, BypassPolicy::Reject));
                    }
                    None => {
                        let e = Error::InvalidHeader {
                            byte: self.frame[0],
                        };
                        return broken(self, e, false);
                    }
                }
            }
        }
        (input.len(), None)
    }
}

/// The text of fence `seq` of a line whose nonce is the seed's: six hex
/// digits of it, then the sequence number (four). The engines of these
/// targets never stir the nonce (`Line::stir`: the bridge does), so the
/// seed's digits hold for every fence they send.
pub fn fence_text(setup: &Setup, seq: u32) -> String {
    format!("{:06X}{:04X}", setup.seed & 0xFF_FFFF, seq & 0xFFFF)
}

/// Checks that `seen` (from the station if `ours`) was heard as the echo
/// of fence `seq` exactly when it is one: a 200H reply carrying that
/// fence's text while it is awaited.
pub fn check_fence_echo(
    setup: &Setup,
    seen: &Seen,
    ours: bool,
    heard: Heard,
    seq: u32,
    awaited: bool,
) {
    let (header, _, code) = seen.envelope;
    let body = &seen.bytes[6..seen.bytes.len() - 4];
    let echo = awaited
        && (header, code) == (Header::Response, 0x200)
        && body == fence_text(setup, seq).as_bytes();
    assert_eq!(
        heard == Heard::Fence,
        ours && echo,
        "{heard:?} for {:?} (fence {seq} awaited: {awaited})",
        String::from_utf8_lossy(&seen.bytes),
    );
}

/// Checks fence number `seq` (the line's `stats().fences` once it is
/// due) that an engine transmitted: a 200H command for the station whose
/// ten characters are the seed's nonce and `seq` ([`fence_text`]).
pub fn check_fence(setup: &Setup, bytes: &[u8], seq: u32) {
    let f = Frame::new_checked(bytes, BypassPolicy::Accept).expect("an invalid fence");
    assert_eq!(
        (f.header(), f.station(), f.code()),
        (Header::Command, setup.line.station, 0x200)
    );
    assert_eq!(
        f.body(),
        fence_text(setup, seq).as_bytes(),
        "fence {seq} has another text: {:?}",
        String::from_utf8_lossy(bytes)
    );
}
