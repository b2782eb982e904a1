//! A controller simulator: the controller's side of protocol B, built on
//! the core, with a position table and faults injected on demand.
//!
//! Sans-IO: bytes from the host go in with [`Simulator::receive`], reply
//! bytes come out of [`Simulator::take_output`] once their time has come.
//! Time is a millisecond tick supplied by the caller, so tests can run a
//! 1.6 MB transfer with 3-second timeouts in a fraction of a second of real
//! time. [`serve_tcp`] puts it on a real socket.
//!
//! Like the controller (manual p. 9), it does not answer a command it could
//! not receive: bad checksum, broken frame, or one longer than the
//! profile's receive buffer.

use std::collections::BTreeMap;

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::field::{FieldSpec, Reader, Writer};
use iai_protocol_b::frame::{emit_envelope, emit_trailer, Frame, Header, Station};
use iai_protocol_b::message::{
    AxisStatus, AxisStatusQuery, AxisStatusResponse, Command, ErrorDetailQuery,
    ErrorDetailResponse, Message, Response, SystemStatusQuery, SystemStatusResponse,
};
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::stream::PositionStream;

/// Error code the simulator sends when it injects an error response.
pub const INJECTED_ERROR_CODE: u16 = 0x0E1;
/// Error code for a command whose body does not fit its layout (or whose ID
/// is not in the catalogue).
pub const UNSUPPORTED_ERROR_CODE: u16 = 0x0E2;

/// Faults to inject. Probabilities are per byte or per reply.
#[derive(Debug, Clone, Default)]
pub struct Faults {
    /// Chance that a received byte has one bit flipped.
    pub flip_bit_in: f64,
    /// Chance that a received byte is lost.
    pub drop_byte_in: f64,
    /// Chance that a sent byte has one bit flipped.
    pub flip_bit_out: f64,
    /// Every n-th reply is not sent at all.
    pub drop_every_nth_reply: Option<u32>,
    /// Every n-th reply is sent late, after this many ms.
    pub late_every_nth_reply: Option<(u32, u32)>,
    /// Chance that a command gets an `&` error response instead of its reply.
    pub error_reply: f64,
    /// Chance that noise bytes precede a reply.
    pub garbage_before_reply: f64,
    /// Chance that a reply is not sent at all.
    pub drop_reply: f64,
    /// Chance that a reply is sent this many ms late (past the host's
    /// timeout, so that it meets the resend).
    pub late_reply: Option<(f64, u32)>,
    /// Chance that a reply is sent a second time, up to this many ms after
    /// the first (an echoing converter, a late copy).
    pub dup_reply: Option<(f64, u32)>,
    /// The controller stops answering anything once this many position
    /// records were written (it hangs in the middle of a table).
    pub stop_after_records: Option<u64>,
    /// The controller stops answering anything after this many commands.
    pub stop_after_commands: Option<u32>,
    /// Chance, per position write, that one record is stored altered in a
    /// way that keeps the frame's SC valid (two hex digits of a coordinate
    /// swapped): what only reading back can catch.
    pub swap_record: f64,
}

/// What the simulator counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Valid commands received.
    pub commands: u32,
    /// Replies sent (normal and error).
    pub replies: u32,
    /// Replies withheld by fault injection.
    pub dropped_replies: u32,
    /// Replies delayed by fault injection.
    pub late_replies: u32,
    /// Error responses injected.
    pub injected_errors: u32,
    /// Broken frames received (not answered).
    pub broken_frames: u32,
    /// Frames over the receive limit (not answered).
    pub oversize_frames: u32,
    /// Bytes received / sent.
    pub bytes_in: u64,
    /// Bytes sent.
    pub bytes_out: u64,
    /// Position records written.
    pub records_written: u64,
    /// Replies sent twice.
    pub duplicated_replies: u32,
    /// Records stored altered (SC-preserving swap).
    pub swapped_records: u32,
}

/// Deterministic xorshift generator (tests must be reproducible).
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }
    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }
    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

/// The simulated controller.
pub struct Simulator {
    /// Station code.
    pub station: Station,
    /// Largest command frame accepted (TTA 2,051; X-SEL J/K 1,023).
    pub max_receive: usize,
    /// Largest response frame sent (TTA 2,048; X-SEL J/K 1,024).
    pub max_transmit: usize,
    /// Delay before replying (the controller's α), ms.
    pub response_delay_ms: u32,
    /// Faults to inject.
    pub faults: Faults,
    /// The position table.
    pub table: BTreeMap<u16, PositionRecord>,
    decoder: Box<FrameDecoder<4096>>,
    outbox: Vec<(u32, Vec<u8>)>,
    rng: Rng,
    reply_no: u32,
    stats: SimStats,
}

impl Simulator {
    /// A TTA at `station`, no faults.
    pub fn tta(station: Station) -> Self {
        Simulator {
            station,
            max_receive: 2051,
            max_transmit: 2048,
            response_delay_ms: 2,
            faults: Faults::default(),
            table: BTreeMap::new(),
            decoder: Box::new(FrameDecoder::with_policy(BypassPolicy::CommandsOnly)),
            outbox: Vec::new(),
            rng: Rng::new(1),
            reply_no: 0,
            stats: SimStats::default(),
        }
    }

    /// A 2003-generation X-SEL (1,023 / 1,024-byte buffers).
    pub fn xsel_2003(station: Station) -> Self {
        Simulator {
            max_receive: 1023,
            max_transmit: 1024,
            ..Self::tta(station)
        }
    }

    /// With these faults and this random seed.
    pub fn with_faults(mut self, faults: Faults, seed: u64) -> Self {
        self.faults = faults;
        self.rng = Rng::new(seed);
        self
    }

    /// Counters so far.
    pub fn stats(&self) -> SimStats {
        self.stats
    }

    /// Tick at which the next reply byte is due, if any.
    pub fn next_output_at(&self) -> Option<u32> {
        self.outbox.iter().map(|(t, _)| *t).min()
    }

    /// Reply bytes due by `now`, in order.
    pub fn take_output(&mut self, now: u32) -> Vec<u8> {
        self.outbox.sort_by_key(|(t, _)| *t);
        let due = self.outbox.iter().take_while(|(t, _)| *t <= now).count();
        let out: Vec<u8> = self.outbox.drain(..due).flat_map(|(_, b)| b).collect();
        self.stats.bytes_out += out.len() as u64;
        out
    }

    /// Bytes from the host at `now`.
    pub fn receive(&mut self, bytes: &[u8], now: u32) {
        for &b in bytes {
            self.stats.bytes_in += 1;
            if self.rng.chance(self.faults.drop_byte_in) {
                continue;
            }
            let b = if self.rng.chance(self.faults.flip_bit_in) {
                b ^ (1 << self.rng.below(8))
            } else {
                b
            };
            let reply = match self.decoder.push(b) {
                Event::NeedMore => None,
                Event::Error(e) => {
                    if matches!(e, iai_protocol_b::Error::FrameTooLong { .. }) {
                        self.stats.oversize_frames += 1;
                    } else {
                        self.stats.broken_frames += 1;
                    }
                    None
                }
                Event::Frame(f) => {
                    let f: Frame<'_> = f;
                    if f.len() > self.max_receive {
                        self.stats.oversize_frames += 1;
                        None
                    } else if f.header() != Header::Command || f.station() != self.station {
                        None
                    } else {
                        // Copy out: the frame borrows the decoder.
                        Some(f.as_bytes().to_vec())
                    }
                }
            };
            if let Some(cmd) = reply {
                if self.stopped() {
                    continue;
                }
                self.stats.commands += 1;
                let frame = Frame::new_checked(&cmd, BypassPolicy::CommandsOnly)
                    .expect("decoder checked it");
                let out = self.execute(&frame);
                self.schedule(out, now);
            }
        }
    }

    fn schedule(&mut self, reply: Option<Vec<u8>>, now: u32) {
        let Some(mut reply) = reply else { return };
        self.reply_no += 1;
        let n = self.reply_no;
        if self
            .faults
            .drop_every_nth_reply
            .is_some_and(|k| n.is_multiple_of(k))
            || self.rng.chance(self.faults.drop_reply)
        {
            self.stats.dropped_replies += 1;
            return;
        }
        if self.rng.chance(self.faults.error_reply) {
            self.stats.injected_errors += 1;
            reply = self.error_frame(INJECTED_ERROR_CODE);
        }
        for b in reply.iter_mut() {
            if self.rng.chance(self.faults.flip_bit_out) {
                *b ^= 1 << self.rng.below(8);
            }
        }
        if self.rng.chance(self.faults.garbage_before_reply) {
            let noise: Vec<u8> = (0..1 + self.rng.below(12))
                .map(|_| b"xyz\r\n0123?"[self.rng.below(10) as usize])
                .collect();
            reply.splice(0..0, noise);
        }
        let mut at = now + self.response_delay_ms;
        if let Some((k, late)) = self.faults.late_every_nth_reply {
            if n.is_multiple_of(k) {
                self.stats.late_replies += 1;
                at = now + late;
            }
        }
        if let Some((p, late)) = self.faults.late_reply {
            if self.rng.chance(p) {
                self.stats.late_replies += 1;
                at = now + late;
            }
        }
        if let Some((p, max)) = self.faults.dup_reply {
            if self.rng.chance(p) {
                self.stats.duplicated_replies += 1;
                let again = at + 1 + self.rng.below(u64::from(max.max(1))) as u32;
                self.outbox.push((again, reply.clone()));
            }
        }
        self.stats.replies += 1;
        self.outbox.push((at, reply));
    }

    /// Whether the controller has stopped (see [`Faults::stop_after_records`]).
    pub fn stopped(&self) -> bool {
        self.faults
            .stop_after_records
            .is_some_and(|n| self.stats.records_written >= n)
            || self
                .faults
                .stop_after_commands
                .is_some_and(|n| self.stats.commands >= n)
    }

    /// Alters one coordinate of one of `recs` so that the frame's SC would
    /// not change: two different hex digits of its wire form swapped.
    fn swap_one(&mut self, recs: &mut [PositionRecord]) {
        let with_axes: Vec<usize> = (0..recs.len())
            .filter(|&i| !recs[i].positions.is_empty())
            .collect();
        if with_axes.is_empty() {
            return;
        }
        let i = with_axes[self.rng.below(with_axes.len() as u64) as usize];
        let rec = &mut recs[i];
        let a = self.rng.below(rec.positions.len() as u64) as usize;
        let digits = format!("{:08X}", rec.positions[a] as u32).into_bytes();
        for j in 0..7 {
            if digits[j] != digits[j + 1] {
                let mut d = digits.clone();
                d.swap(j, j + 1);
                let v = u32::from_str_radix(std::str::from_utf8(&d).unwrap(), 16).unwrap();
                rec.positions[a] = v as i32;
                self.stats.swapped_records += 1;
                return;
            }
        }
    }

    fn error_frame(&self, code: u16) -> Vec<u8> {
        let mut buf = [0u8; 16];
        let mut w = Writer::new(&mut buf);
        emit_envelope(&mut w, Header::Error, self.station, code).unwrap();
        emit_trailer(&mut w, Default::default()).unwrap();
        w.written().to_vec()
    }

    fn emit<'a, M: Message<'a>>(&self, msg: &M) -> Vec<u8> {
        let mut buf = vec![0u8; self.max_transmit];
        let n = msg
            .emit(self.station, &mut buf)
            .expect("reply fits the transmit buffer");
        buf.truncate(n);
        buf
    }

    /// Executes one command; the reply frame, or `None` for no reply.
    fn execute(&mut self, f: &Frame<'_>) -> Option<Vec<u8>> {
        if let Some(kind) = PositionStream::find(Header::Command, f.code()) {
            return Some(self.write_positions(kind, f));
        }
        if let Some(kind) = PositionStream::find(Header::Response, f.code()) {
            return Some(self.query_positions(kind, f));
        }
        match f.code() {
            0x212 => {
                let q = AxisStatusQuery::parse(f).ok()?;
                let mut axes = iai_protocol_b::axis::PerAxis::new();
                for axis in q.query_axis_pattern.iter() {
                    let pos = self
                        .table
                        .values()
                        .next()
                        .and_then(|r| r.position(axis))
                        .unwrap_or(0);
                    let _ = axes.push(AxisStatus {
                        axis_status: 0x1C,
                        sensor_input_status: 0,
                        error_code: 0,
                        encoder_status: 0,
                        current_position: pos,
                    });
                }
                Some(self.emit(&AxisStatusResponse {
                    axis_pattern: q.query_axis_pattern,
                    axes,
                }))
            }
            0x215 => {
                SystemStatusQuery::parse(f).ok()?;
                Some(self.emit(&SystemStatusResponse::default()))
            }
            0x216 => {
                let q = ErrorDetailQuery::parse(f).ok()?;
                // Illustrative details (error C74H, program 1, step 5, axis 2, point -3).
                Some(self.emit(&ErrorDetailResponse {
                    error_number: 0xC74,
                    detail_1: u32::from(q.type_2),
                    detail_2: 5,
                    detail_3: 2,
                    detail_4: -3,
                    ..ErrorDetailResponse::default()
                }))
            }
            // Every other message of the catalogue: a well-formed command gets
            // its response with default (zero) fields; 25BH gets none.
            id => match Command::parse(f) {
                Err(_) => Some(self.error_frame(UNSUPPORTED_ERROR_CODE)),
                Ok(_) => {
                    let r = Response::default_for(id)?;
                    let mut buf = vec![0u8; self.max_transmit];
                    let n = r
                        .emit(self.station, &mut buf)
                        .expect("default responses fit");
                    buf.truncate(n);
                    Some(buf)
                }
            },
        }
    }

    fn write_positions(&mut self, kind: PositionStream, f: &Frame<'_>) -> Vec<u8> {
        let mut r = f.reader();
        let parsed = (|| {
            let (start, count) = kind.read_prefix(&mut r)?;
            let mut recs = Vec::with_capacity(usize::from(count));
            for i in 0..count {
                let mut rec = kind.layout.read_record(&mut r)?;
                if kind.layout.number_width == 0 {
                    rec.number = start + i;
                }
                recs.push(rec);
            }
            r.finish()?;
            Ok::<_, iai_protocol_b::Error>((start, recs))
        })();
        let Ok((start, mut recs)) = parsed else {
            return self.error_frame(UNSUPPORTED_ERROR_CODE);
        };
        if self.rng.chance(self.faults.swap_record) {
            self.swap_one(&mut recs);
        }
        let n = recs.len() as u16;
        for rec in recs {
            self.table.insert(rec.number, rec);
        }
        self.stats.records_written += u64::from(n);
        let mut buf = [0u8; 32];
        let mut w = Writer::new(&mut buf);
        emit_envelope(&mut w, Header::Response, self.station, kind.id).unwrap();
        kind.write_prefix(&mut w, start, n).unwrap();
        emit_trailer(&mut w, Default::default()).unwrap();
        w.written().to_vec()
    }

    /// 209H / 21FH / 22DH: the defined records in the window of position
    /// numbers `head..head + asked`, as many as fit the transmit buffer.
    fn query_positions(&mut self, kind: PositionStream, f: &Frame<'_>) -> Vec<u8> {
        let body = f.body();
        let w_num = kind.count_width;
        let mut r = Reader::new(body, 6);
        let q = (|| {
            if kind.reserved {
                r.take(2)?;
            }
            let head = r.unsigned(FieldSpec::hex(w_num))? as u16;
            let n = r.unsigned(FieldSpec::hex(w_num))? as u16;
            r.finish()?;
            Ok::<_, iai_protocol_b::Error>((head, n))
        })();
        let Ok((head, asked)) = q else {
            return self.error_frame(UNSUPPORTED_ERROR_CODE);
        };
        let mut buf = vec![0u8; self.max_transmit];
        let mut w = Writer::new(&mut buf);
        emit_envelope(&mut w, Header::Response, self.station, kind.id).unwrap();
        kind.write_prefix(&mut w, 0, 0).unwrap();
        let count_at = w.len() - usize::from(kind.count_width);
        let mut n = 0u16;
        // The window head..head+asked; only defined records are returned.
        let end = u32::from(head) + u32::from(asked);
        for rec in self
            .table
            .values()
            .filter(|r| r.number >= head && u32::from(r.number) < end)
        {
            if w.len() + kind.layout.record_len(rec.axes.count()) + 4 > self.max_transmit {
                break;
            }
            kind.layout.write_record(rec, &mut w).unwrap();
            n += 1;
        }
        w.patch_unsigned(count_at, FieldSpec::hex(kind.count_width), u64::from(n))
            .unwrap();
        emit_trailer(&mut w, Default::default()).unwrap();
        w.written().to_vec()
    }
}

/// What passed over a served connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Traffic<'a> {
    /// Bytes from the host.
    Received(&'a [u8]),
    /// Bytes the simulator sent.
    Sent(&'a [u8]),
    /// The host closed the connection.
    Closed,
}

/// Serves the simulator on a TCP stream with real time until the peer
/// closes the connection.
pub fn serve_tcp(sim: &mut Simulator, stream: std::net::TcpStream) -> std::io::Result<()> {
    serve_tcp_observed(sim, stream, |_| Ok(()))
}

/// Like [`serve_tcp`], showing every read and write to `observe`.
pub fn serve_tcp_observed(
    sim: &mut Simulator,
    mut stream: std::net::TcpStream,
    mut observe: impl FnMut(Traffic<'_>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    use std::io::{Read, Write};
    let t0 = std::time::Instant::now();
    let now = || u32::try_from(t0.elapsed().as_millis()).unwrap_or(u32::MAX);
    stream.set_read_timeout(Some(std::time::Duration::from_millis(1)))?;
    stream.set_nodelay(true)?;
    let mut buf = [0u8; 4096];
    loop {
        match stream.read(&mut buf) {
            Ok(0) => return observe(Traffic::Closed),
            Ok(n) => {
                sim.receive(&buf[..n], now());
                observe(Traffic::Received(&buf[..n]))?;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => return Err(e),
        }
        let out = sim.take_output(now());
        if !out.is_empty() {
            stream.write_all(&out)?;
            observe(Traffic::Sent(&out))?;
        }
    }
}
