//! The PLC gateway: a Modbus RTU server in front of protocol B, on the
//! bridge MCU; on the Ethernet build also a Modbus TCP server
//! ([`Gateway::serve_tcp`], framing in [`tcp`]) with the same map, cache
//! and handshake: one request handler, two transports.
//!
//! Two sides, never blocking:
//! - the **Modbus port** ([`Gateway::serve`]): frames found by silence
//!   ([`rtu`]), checked (CRC, length) and answered at once from the
//!   gateway's registers ([`registers`]): reads from the cache
//!   ([`cache`]), writes stored or queued as a command behind the
//!   handshake ([`command`]). No reply waits for the controller, so none
//!   is late, and none says done before the controller confirmed.
//! - the **controller line** ([`mod@line`]): polls on a schedule ([`poll`])
//!   and the queued command, one exchange at a time, on the bridge's one
//!   line while the bridge grants it ([`Guest`]); the protocol-B host goes
//!   first (a poll in its way is abandoned, a command finishes).
//!
//! The gateway polls once a master has addressed it (a bridge without a
//! PLC leaves the line to its host). The register map is one table
//! ([`map::MAP`]). The unit is the configured one (on TCP also
//! [`tcp::GATEWAY_UNIT`]); broadcasts (unit 0) are executed if they are
//! writes and never answered; frames for other units, with a wrong CRC
//! or a length that does not fit their function, are not answered.
//!
//! One handler answers both transports alike, function by function:
//! reads (01 to 04) through rmodbus's external read calls with
//! [`Registers`] as their context; writes (05, 06, 15, 16: quantity and
//! byte count checked against each other first) and Read Device
//! Identification ([`ident`]) by the gateway itself, since rmodbus
//! answers every failed write with 02 (the gateway needs 01, 03 and 06
//! too) and parses no Modbus TCP ADU shorter than 6 bytes; every other
//! function is exception 01.

pub mod cache;
pub mod command;
pub mod ident;
pub mod line;
pub mod map;
pub mod poll;
pub mod registers;
pub mod rtu;
pub mod tcp;

use core::convert::Infallible;

use iai_protocol_b::line::Line;
use rmodbus::consts::ModbusFunction;
use rmodbus::server::{ModbusFrame, Read};
use rmodbus::{ErrorKind, ModbusProto};

use crate::bridge::{write_some, Bridge, Error, Guest, GuestWait, NoPort, Poll};
use crate::config::{ModbusConfig, Policy, UpstreamProtocol};
use crate::serial::Port;
use crate::status::Stats;
use line::Engines;
pub use registers::Registers;
use rtu::Framer;

/// A Modbus response (at most 256 bytes).
type Response = heapless::Vec<u8, { rtu::MAX_FRAME }>;

/// What the Modbus side counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ModbusStats {
    /// Requests answered (exceptions included).
    pub answered: u32,
    /// Exception responses among them.
    pub exceptions: u32,
    /// Frames dropped: wrong CRC or length, too long.
    pub dropped: u32,
    /// Frames for another unit, and broadcasts (not answered).
    pub unanswered: u32,
    /// Bytes written to the Modbus port.
    pub bytes_out: u64,
}

/// The gateway's state. Keep it in a static (about 3 KiB).
pub struct Gateway {
    /// The registers (settings, cache, handshake, window).
    pub regs: Registers,
    engines: Engines,
    framer: Framer,
    resp: Response,
    resp_off: usize,
    stats: ModbusStats,
}

impl Gateway {
    /// A gateway with these settings and the bridge's command policy.
    #[inline(always)]
    pub fn new(cfg: ModbusConfig, policy: Policy) -> Self {
        Gateway {
            regs: Registers::new(cfg, policy),
            engines: Engines::new(),
            framer: Framer::new(cfg.baud),
            resp: Response::new(),
            resp_off: 0,
            stats: ModbusStats::default(),
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> ModbusStats {
        self.stats
    }

    /// The Modbus side at `now` (ms) and `now_us` (the board's microsecond
    /// clock, for the silence between frames): sends the pending response,
    /// reads what arrived, answers a frame whose silence has passed.
    /// `Ok(moved)`.
    pub fn serve<P: Port>(
        &mut self,
        port: &mut P,
        now: u32,
        now_us: u32,
    ) -> Result<bool, P::Error> {
        let mut moved = false;
        if self.resp_off < self.resp.len() {
            let out = &mut self.stats.bytes_out;
            moved |= write_some(port, &self.resp, &mut self.resp_off, out)? > 0;
        }
        let mut buf = [0u8; 16];
        while port.read_ready()? {
            let n = port.read(&mut buf)?;
            if n == 0 {
                break;
            }
            let at = port.last_rx_us().unwrap_or(now_us);
            for &b in buf.get(..n).unwrap_or(&[]) {
                self.framer.push(b, at);
            }
            moved = true;
        }
        if port.take_overruns() > 0 {
            // A byte was lost: whatever frame it was in fails its CRC.
            self.stats.dropped = self.stats.dropped.wrapping_add(1);
        }
        if self.resp_off < self.resp.len() {
            return Ok(moved);
        }
        let Gateway {
            framer,
            regs,
            resp,
            stats,
            ..
        } = self;
        match framer.take(now_us) {
            None => {}
            Some(Err(_)) => {
                stats.dropped = stats.dropped.wrapping_add(1);
                moved = true;
            }
            Some(Ok(frame)) => {
                answer(frame, ModbusProto::Rtu, regs, resp, stats, now);
                self.resp_off = 0;
                let out = &mut self.stats.bytes_out;
                write_some(port, &self.resp, &mut self.resp_off, out)?;
                moved = true;
            }
        }
        Ok(moved)
    }

    /// When the Modbus side must look again (µs): the end of the frame
    /// being received.
    pub fn serve_deadline_us(&self) -> Option<u32> {
        self.framer.ends_at()
    }

    /// Whether a response is still going out.
    pub fn sending(&self) -> bool {
        self.resp_off < self.resp.len()
    }

    /// One Modbus TCP request `adu` (MBAP header and PDU, as
    /// [`tcp::adu_len`] cut it from a connection) at `now` (ms): answered
    /// into `resp` by the same handler, map, cache and handshake as an RTU
    /// frame. `resp` is left empty when nothing is to be sent: an ADU that
    /// fails [`tcp::check`] (a protocol ID other than 0, a length that does
    /// not fit its function), another unit, or a broadcast.
    pub fn serve_tcp(&mut self, adu: &[u8], resp: &mut tcp::Response, now: u32) {
        resp.clear();
        let Gateway { regs, stats, .. } = self;
        match tcp::check(adu) {
            Ok(()) => answer(adu, ModbusProto::TcpUdp, regs, resp, stats, now),
            Err(_) => stats.dropped = stats.dropped.wrapping_add(1),
        }
        if let Ok(n) = u64::try_from(resp.len()) {
            stats.bytes_out = stats.bytes_out.wrapping_add(n);
        }
    }
}

/// Answers one checked frame into `resp` (left empty: no answer): an RTU
/// frame (checked by [`rtu::check`], its CRC at the end) or a Modbus TCP
/// ADU (checked by [`tcp::check`], its MBAP header in front). The one
/// request handler of both transports: the same map, cache, handshake and
/// exceptions.
fn answer<const N: usize>(
    frame: &[u8],
    proto: ModbusProto,
    regs: &mut Registers,
    resp: &mut heapless::Vec<u8, N>,
    stats: &mut ModbusStats,
    now: u32,
) {
    resp.clear();
    let tcp = proto == ModbusProto::TcpUdp;
    // Where the unit ID is (after the MBAP header's first six bytes), and
    // what follows the PDU (the RTU CRC).
    let (start, tail) = if tcp { (tcp::UNIT_AT, 0) } else { (0, 2) };
    let end = frame.len().saturating_sub(tail);
    let (Some(&unit), Some(pdu)) = (frame.get(start), frame.get(start + 1..end)) else {
        stats.dropped = stats.dropped.wrapping_add(1);
        return;
    };
    let Some(&function) = pdu.first() else {
        stats.dropped = stats.dropped.wrapping_add(1);
        return;
    };
    let to_me = unit == regs.cfg.unit || (tcp && unit == tcp::GATEWAY_UNIT);
    let write = matches!(function, 5 | 6 | 15 | 16);
    let broadcast_write = unit == 0 && write;
    if !(to_me || broadcast_write) {
        // Another unit, or a broadcast that is not a write.
        stats.unanswered = stats.unanswered.wrapping_add(1);
        return;
    }
    // Addressed: polling starts.
    regs.active = true;
    let reply = Reply { frame, proto, unit };
    let result = match function {
        1..=4 => read(frame, proto, unit, regs, resp, now),
        5 | 6 | 15 | 16 => {
            let res = write_pdu(regs, pdu);
            if !to_me {
                stats.unanswered = stats.unanswered.wrapping_add(1);
                return;
            }
            res.and_then(|()| {
                // The echo: function, address, value or quantity.
                let echo = pdu.get(..5).unwrap_or(&[]);
                reply.send(resp, |r| r.extend_from_slice(echo).map_err(|_| 4))
            })
        }
        ident::FUNCTION => {
            let version = regs.cache.version.as_ref();
            reply.send(resp, |r| ident::answer(pdu, version, r))
        }
        _ => Err(1),
    };
    match result {
        Ok(()) => {}
        Err(code) => {
            stats.exceptions = stats.exceptions.wrapping_add(1);
            let sent = reply.send(resp, |r| {
                r.extend_from_slice(&[function | 0x80, code]).map_err(|_| 4)
            });
            if sent.is_err() {
                resp.clear();
                stats.dropped = stats.dropped.wrapping_add(1);
                return;
            }
        }
    }
    if resp.is_empty() {
        stats.dropped = stats.dropped.wrapping_add(1);
        return;
    }
    stats.answered = stats.answered.wrapping_add(1);
}

/// How a response is framed: after the request's MBAP header (its
/// transaction and protocol IDs, the new length, the unit) or the unit,
/// and on RTU with the CRC after it.
struct Reply<'a> {
    frame: &'a [u8],
    proto: ModbusProto,
    unit: u8,
}

impl Reply<'_> {
    /// Frames the PDU `pdu` appends into `resp` (emptied first); `Err`
    /// (`resp` left empty) with the exception code `pdu` gave.
    fn send<const N: usize>(
        &self,
        resp: &mut heapless::Vec<u8, N>,
        pdu: impl FnOnce(&mut heapless::Vec<u8, N>) -> Result<(), u8>,
    ) -> Result<(), u8> {
        resp.clear();
        let tcp = self.proto == ModbusProto::TcpUdp;
        let head = if tcp {
            resp.extend_from_slice(self.frame.get(..4).unwrap_or(&[0; 4]))
                .and_then(|()| resp.extend_from_slice(&[0, 0, self.unit]))
                .map_err(|_| ())
        } else {
            resp.push(self.unit).map_err(|_| ())
        };
        let body = head.map_err(|_| 4).and_then(|()| pdu(resp));
        let framed = body.and_then(|()| {
            if tcp {
                let n = u16::try_from(resp.len() - tcp::UNIT_AT).map_err(|_| 4)?;
                if let Some(len) = resp.get_mut(4..6) {
                    len.copy_from_slice(&n.to_be_bytes());
                }
                Ok(())
            } else {
                let crc = rtu::crc16(resp);
                resp.extend_from_slice(&crc.to_le_bytes()).map_err(|_| 4)
            }
        });
        if framed.is_err() {
            resp.clear();
        }
        framed
    }
}

/// The exception code of a refusal.
fn code(e: ErrorKind) -> u8 {
    e.to_modbus_error().map_or(4, |c| c.byte())
}

/// A read (functions 01 to 04) answered by rmodbus into `resp` from the
/// registers; `Err` with the exception code.
fn read<const N: usize>(
    frame: &[u8],
    proto: ModbusProto,
    unit: u8,
    regs: &Registers,
    resp: &mut heapless::Vec<u8, N>,
    now: u32,
) -> Result<(), u8> {
    // The unit the request named (the configured one, or 255 on TCP) is
    // the one answered.
    let mut f = ModbusFrame::new(unit, frame, proto, resp);
    if f.parse().is_err() || !f.response_required {
        f.response.clear();
        return Ok(());
    }
    if f.processing_required {
        let inputs = f.func == ModbusFunction::GetInputs;
        let discretes = f.func == ModbusFunction::GetDiscretes;
        let done = match f.get_external_read() {
            Ok(Read::Words(r)) => {
                let res = regs.read_words(r.address, r.count, inputs, r.buf, now);
                f.process_external_read(res)
            }
            Ok(Read::Bits(r)) => {
                let space = if discretes {
                    map::Space::Discretes
                } else {
                    map::Space::Coils
                };
                r.buf.fill(0);
                let res = regs.read_bits(space, r.address, r.count, r.buf);
                f.process_external_read(res)
            }
            Err(e) => Err(e),
        };
        if done.is_err() {
            f.response.clear();
            return Ok(());
        }
    }
    if let Some(e) = f.error {
        f.response.clear();
        return Err(e.byte());
    }
    if f.finalize_response().is_err() {
        f.response.clear();
    }
    Ok(())
}

/// A write (functions 05, 06, 15, 16; the PDU `pdu`, function code first,
/// its length checked by [`rtu::check`] or [`tcp::check`]) carried out on
/// the registers; `Err` with the exception code. Functions 15 and 16
/// check the quantity and the byte count against each other first
/// (Modbus application protocol 6.11, 6.12: 03 when they disagree).
fn write_pdu(regs: &mut Registers, pdu: &[u8]) -> Result<(), u8> {
    let word = |at: usize| {
        let hi = pdu.get(at).copied().unwrap_or(0);
        u16::from_be_bytes([hi, pdu.get(at + 1).copied().unwrap_or(0)])
    };
    let (function, addr, value) = (pdu.first().copied().unwrap_or(0), word(1), word(3));
    let data = pdu.get(6..).unwrap_or(&[]);
    let bytes = usize::from(pdu.get(5).copied().unwrap_or(0));
    let res = match function {
        5 => match value {
            0xFF00 => regs.write_bits(addr, 1, &[1]),
            0x0000 => regs.write_bits(addr, 1, &[0]),
            _ => Err(ErrorKind::IllegalDataValue),
        },
        6 => regs.write_words(addr, 1, pdu.get(3..5).unwrap_or(&[])),
        15 => {
            if !(1..=MAX_WRITE_COILS).contains(&value) || bytes != usize::from(value).div_ceil(8) {
                return Err(3);
            }
            regs.write_bits(addr, value, data)
        }
        16 => {
            if !(1..=MAX_WRITE_REGISTERS).contains(&value) || bytes != 2 * usize::from(value) {
                return Err(3);
            }
            regs.write_words(addr, value, data)
        }
        _ => Err(ErrorKind::IllegalFunction),
    };
    res.map_err(code)
}

/// Most coils function 15 writes (Modbus application protocol 6.11).
const MAX_WRITE_COILS: u16 = 0x07B0;
/// Most registers function 16 writes (6.12).
const MAX_WRITE_REGISTERS: u16 = 0x007B;

impl Guest for Gateway {
    fn holds_line(&self) -> bool {
        self.engines.holds_line()
    }

    fn wants_line(&self, now: u32) -> bool {
        Engines::wants_line(&self.regs, now)
    }

    fn may_yield(&self) -> bool {
        self.engines.may_yield()
    }

    fn yield_line(&mut self, line: &mut Line, now: u32) {
        self.engines.yield_line(line, now);
    }

    fn run<D: Port>(&mut self, line: &mut Line, down: &mut D, now: u32) -> Result<bool, D::Error> {
        self.engines.run(&mut self.regs, line, down, now)
    }

    fn wait(&self, now: u32) -> GuestWait {
        let (deadline, down_write) = self.engines.wait();
        let deadline = if self.engines.holds_line() {
            deadline
        } else if self.wants_line(now) {
            Some(now)
        } else if self.regs.active {
            // The next poll round.
            self.regs.schedule.due_at()
        } else {
            None
        };
        GuestWait {
            deadline,
            down_write,
        }
    }
}

/// Runs the bridge and the gateway over their three ports until the quit
/// sequence (on the protocol-B upstream) or a port error, as
/// [`crate::bridge::run`] does for the bridge alone; `now_us` is the
/// board's microsecond clock (the silence between Modbus frames). The
/// Modbus port's errors are reported as the upstream's.
#[allow(clippy::too_many_arguments)]
pub fn run<U: Port, D: Port, M: Port<Error = U::Error>>(
    bridge: &mut Bridge,
    gateway: &mut Gateway,
    upstream: &mut U,
    downstream: &mut D,
    modbus: &mut M,
    now_ms: impl Fn() -> u32,
    now_us: impl Fn() -> u32,
    mut sleep: impl FnMut(&mut dyn FnMut() -> bool),
    mut feed: impl FnMut(),
) -> Result<Stats, Error<U::Error, D::Error>> {
    loop {
        feed();
        let served = gateway
            .serve(modbus, now_ms(), now_us())
            .map_err(Error::Upstream)?;
        match bridge.poll_with(upstream, downstream, gateway, now_ms())? {
            Poll::Quit => return Ok(bridge.stats()),
            Poll::Busy => {}
            Poll::Wait(_) if served => {}
            Poll::Wait(w) => {
                let i = w.interest;
                let start = now_ms();
                let sending = gateway.sending();
                sleep(&mut || {
                    now_ms() != start
                        || modbus.read_ready().unwrap_or(true)
                        || (sending && modbus.write_ready().unwrap_or(true))
                        || (i.up_read && upstream.read_ready().unwrap_or(true))
                        || (i.down_read && downstream.read_ready().unwrap_or(true))
                        || (i.up_write && upstream.write_ready().unwrap_or(true))
                        || (i.down_write && downstream.write_ready().unwrap_or(true))
                });
            }
        }
    }
}

/// The loop of a board with one upstream port (two UARTs: the port and
/// the controller's), which speaks what the configuration block chooses
/// (`speaks`, [`crate::config::Config::upstream`]): protocol B through the
/// bridge alone ([`crate::bridge::run`]), or Modbus RTU through the
/// gateway ([`run`]), the bridge then keeping the controller line with no
/// protocol-B host on it ([`NoPort`]). The board
/// sets the port up for what it speaks: the Modbus line without flow
/// control, at [`ModbusConfig::baud`], each byte stamped with `now_us`.
#[allow(clippy::too_many_arguments)]
pub fn run_one_upstream<U: Port<Error = Infallible>, D: Port>(
    speaks: UpstreamProtocol,
    bridge: &mut Bridge,
    gateway: &mut Gateway,
    upstream: &mut U,
    downstream: &mut D,
    now_ms: impl Fn() -> u32,
    now_us: impl Fn() -> u32,
    sleep: impl FnMut(&mut dyn FnMut() -> bool),
    feed: impl FnMut(),
) -> Result<Stats, Error<Infallible, D::Error>> {
    match speaks {
        UpstreamProtocol::ProtocolB => {
            crate::bridge::run(bridge, upstream, downstream, now_ms, sleep, feed)
        }
        UpstreamProtocol::ModbusRtu => run(
            bridge,
            gateway,
            &mut NoPort,
            downstream,
            upstream,
            now_ms,
            now_us,
            sleep,
            feed,
        ),
    }
}

#[cfg(test)]
mod tests;
