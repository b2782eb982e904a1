//! The bridge with its Modbus gateway in virtual time: a Modbus master on
//! the gateway's port, a protocol-B host on the bridge's upstream, the
//! simulator on the controller line. Every line carries one byte per 10
//! bit times (11 on the Modbus line: 8 data, parity, stop) in each
//! direction; the bridge's loop takes no time. Nothing reads a wall clock.
//!
//! The master sends a request and waits for the response (the frame ends
//! at 3.5 characters of silence) for at most [`MASTER_TIMEOUT_MS`], as a
//! PLC does; the host sends protocol-B commands and takes every frame the
//! bridge sends it.

use std::collections::VecDeque;
use std::convert::Infallible;

use firmware_example::bridge::{Bridge, Poll};
use firmware_example::config::{Config, Source};
use firmware_example::modbus::{rtu, Gateway};
use firmware_example::serial::Port;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};

use iai_simulator::Simulator;

/// How long the master waits for a response.
pub const MASTER_TIMEOUT_MS: u64 = 1_000;

/// A serial port in virtual time: bytes to read, bytes written (taken by
/// the line at its rate), and when the last byte arrived.
#[derive(Default)]
struct VPort {
    rx: VecDeque<u8>,
    tx: VecDeque<u8>,
    last_rx_us: Option<u32>,
}

/// Bytes a port's transmit ring takes (the boards' 64-byte rings).
const TX_ROOM: usize = 63;

impl embedded_io::ErrorType for VPort {
    type Error = Infallible;
}
impl embedded_io::ReadReady for VPort {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(!self.rx.is_empty())
    }
}
impl embedded_io::Read for VPort {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let n = buf.len().min(self.rx.len());
        for (slot, b) in buf.iter_mut().zip(self.rx.drain(..n)) {
            *slot = b;
        }
        Ok(n)
    }
}
impl embedded_io::WriteReady for VPort {
    fn write_ready(&mut self) -> Result<bool, Infallible> {
        Ok(self.tx.len() < TX_ROOM)
    }
}
impl embedded_io::Write for VPort {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        let n = buf.len().min(TX_ROOM.saturating_sub(self.tx.len()));
        self.tx.extend(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
impl Port for VPort {
    fn last_rx_us(&mut self) -> Option<u32> {
        self.last_rx_us
    }
}

/// The bridge, its gateway, a master, a host and the simulator, in
/// virtual time.
pub struct Rig {
    /// The simulated controller.
    pub sim: Simulator,
    /// The gateway.
    pub gw: Box<Gateway>,
    /// The bridge.
    pub bridge: Box<Bridge>,
    up: VPort,
    down: VPort,
    mb: VPort,
    /// Virtual time, ns.
    t: u64,
    mb_byte: u64,
    line_byte: u64,
    /// Bytes the master still sends, the host still sends, the
    /// controller still sends.
    master_out: VecDeque<u8>,
    host_out: VecDeque<u8>,
    ctrl_out: VecDeque<u8>,
    /// When each sender may send its next byte.
    master_free: u64,
    host_free: u64,
    ctrl_free: u64,
    gw_free: u64,
    bridge_up_free: u64,
    bridge_down_free: u64,
    /// Bytes the master received and when the last came.
    master_in: Vec<u8>,
    master_in_at: u64,
    host_frames: FrameDecoder<4096>,
    /// Every frame the host received, with its arrival time (ns).
    pub host_replies: Vec<(u64, Vec<u8>)>,
}

impl Rig {
    /// A rig with `cfg` (both lines at the configuration's rates) and a
    /// TTA simulator that refuses moves as a controller would.
    pub fn new(cfg: Config) -> Self {
        let mut sim = Simulator::tta(cfg.controller_station);
        sim.refuse = true;
        Rig {
            sim,
            gw: Box::new(Gateway::new(cfg.modbus, cfg.policy)),
            bridge: Box::new(Bridge::new(cfg, Source::Default, 0x5EED)),
            up: VPort::default(),
            down: VPort::default(),
            mb: VPort::default(),
            t: 0,
            mb_byte: 11_000_000_000 / u64::from(cfg.modbus.baud.max(1)),
            line_byte: 10_000_000_000 / u64::from(cfg.downstream_baud.max(1)),
            master_out: VecDeque::new(),
            host_out: VecDeque::new(),
            ctrl_out: VecDeque::new(),
            master_free: 0,
            host_free: 0,
            ctrl_free: 0,
            gw_free: 0,
            bridge_up_free: 0,
            bridge_down_free: 0,
            master_in: Vec::new(),
            master_in_at: 0,
            host_frames: FrameDecoder::with_policy(BypassPolicy::Reject),
            host_replies: Vec::new(),
        }
    }

    /// Virtual time, ms.
    pub fn now_ms(&self) -> u64 {
        self.t / 1_000_000
    }

    /// Virtual time, ns.
    pub fn now_ns(&self) -> u64 {
        self.t
    }

    /// The host starts sending `frame` (protocol B) now.
    pub fn host_send(&mut self, frame: &[u8]) {
        self.host_out.extend(frame);
    }

    /// The master sends `request` (with its CRC) and waits for a response:
    /// `(response, ns from the request's last byte to the response's last
    /// byte)`, or `None` after [`MASTER_TIMEOUT_MS`].
    pub fn request(&mut self, request: &[u8]) -> Option<(Vec<u8>, u64)> {
        self.master_out.extend(request);
        self.master_in.clear();
        let sent_by = self.t.max(self.master_free) + self.mb_byte * request.len() as u64;
        let silence = u64::from(rtu::silence_us(self.gw.regs.cfg.baud)) * 1_000;
        let limit = sent_by + MASTER_TIMEOUT_MS * 1_000_000;
        loop {
            if !self.master_in.is_empty() && self.t >= self.master_in_at + silence {
                let answer = std::mem::take(&mut self.master_in);
                return Some((answer, self.master_in_at - sent_by));
            }
            if self.t > limit {
                return None;
            }
            let wake = if self.master_in.is_empty() {
                limit + 1
            } else {
                self.master_in_at + silence
            };
            self.step(wake);
        }
    }

    /// Runs for `ms` of virtual time.
    pub fn run_for(&mut self, ms: u64) {
        let end = self.t + ms * 1_000_000;
        while self.t < end {
            self.step(end);
        }
    }

    /// The bridge and the gateway until they wait, then the next event
    /// (no later than `wake`).
    fn step(&mut self, wake: u64) {
        let ms = (self.t / 1_000_000) as u32;
        let us = (self.t / 1_000) as u32;
        let mut deadline = u64::MAX;
        for _ in 0..10_000 {
            let Ok(served) = self.gw.serve(&mut self.mb, ms, us);
            let Ok(p) = self
                .bridge
                .poll_with(&mut self.up, &mut self.down, &mut *self.gw, ms);
            match p {
                Poll::Busy => continue,
                Poll::Quit => break,
                Poll::Wait(w) => {
                    if served {
                        continue;
                    }
                    if let Some(d) = w.deadline {
                        let ahead = d.wrapping_sub(ms);
                        let ahead = if ahead >= 0x8000_0000 { 0 } else { ahead };
                        deadline = (u64::from(ms) + u64::from(ahead).max(1)) * 1_000_000;
                    }
                    break;
                }
            }
        }
        if let Some(end) = self.gw.serve_deadline_us() {
            let ahead = end.wrapping_sub(us);
            let ahead = if ahead >= 0x8000_0000 {
                1
            } else {
                ahead.max(1)
            };
            deadline = deadline.min((u64::from(us) + u64::from(ahead)) * 1_000);
        }
        // The next event.
        let mut next = deadline.min(wake);
        let t = self.t;
        if !self.master_out.is_empty() {
            next = next.min(self.master_free.max(t));
        }
        if !self.host_out.is_empty() {
            next = next.min(self.host_free.max(t));
        }
        if !self.mb.tx.is_empty() {
            next = next.min(self.gw_free.max(t));
        }
        if !self.up.tx.is_empty() {
            next = next.min(self.bridge_up_free.max(t));
        }
        if !self.down.tx.is_empty() {
            next = next.min(self.bridge_down_free.max(t));
        }
        if !self.ctrl_out.is_empty() {
            next = next.min(self.ctrl_free.max(t));
        } else if let Some(at) = self.sim.next_output_at() {
            next = next.min((u64::from(at) * 1_000_000).max(t));
        }
        self.t = next.max(t + 1);
        let t = self.t;
        let ms = (t / 1_000_000) as u32;
        if !self.master_out.is_empty() && self.master_free <= t {
            if let Some(b) = self.master_out.pop_front() {
                self.master_free = t + self.mb_byte;
                self.mb.rx.push_back(b);
                self.mb.last_rx_us = Some((t / 1_000) as u32);
            }
        }
        if !self.mb.tx.is_empty() && self.gw_free <= t {
            if let Some(b) = self.mb.tx.pop_front() {
                self.gw_free = t + self.mb_byte;
                self.master_in.push(b);
                self.master_in_at = t + self.mb_byte;
            }
        }
        if !self.host_out.is_empty() && self.host_free <= t {
            if let Some(b) = self.host_out.pop_front() {
                self.host_free = t + self.line_byte;
                self.up.rx.push_back(b);
            }
        }
        if !self.up.tx.is_empty() && self.bridge_up_free <= t {
            if let Some(b) = self.up.tx.pop_front() {
                self.bridge_up_free = t + self.line_byte;
                if let Status::Complete(Event::Frame(f)) = self.host_frames.push(b) {
                    let frame = f.as_bytes().to_vec();
                    self.host_replies.push((t + self.line_byte, frame));
                }
            }
        }
        if !self.down.tx.is_empty() && self.bridge_down_free <= t {
            if let Some(b) = self.down.tx.pop_front() {
                self.bridge_down_free = t + self.line_byte;
                self.sim.receive(&[b], ms);
            }
        }
        if self.ctrl_out.is_empty() {
            self.ctrl_out.extend(self.sim.take_output(ms));
        }
        if !self.ctrl_out.is_empty() && self.ctrl_free <= t {
            if let Some(b) = self.ctrl_out.pop_front() {
                self.ctrl_free = t + self.line_byte;
                self.down.rx.push_back(b);
            }
        }
    }
}

/// `body` with its Modbus CRC appended.
pub fn rtu_frame(body: &[u8]) -> Vec<u8> {
    let mut v = body.to_vec();
    v.extend_from_slice(&rtu::crc16(body).to_le_bytes());
    v
}

/// A read request (function 03 or 04) of `count` registers from `addr`,
/// unit 1.
pub fn read_request(function: u8, addr: u16, count: u16) -> Vec<u8> {
    let [a, b] = addr.to_be_bytes();
    let [c, d] = count.to_be_bytes();
    rtu_frame(&[1, function, a, b, c, d])
}

/// A write of `values` from `addr` (function 16), unit 1.
pub fn write_request(addr: u16, values: &[u16]) -> Vec<u8> {
    let [a, b] = addr.to_be_bytes();
    let n = values.len() as u16;
    let mut body = vec![1, 16, a, b, (n >> 8) as u8, n as u8, (2 * n) as u8];
    for v in values {
        body.extend(v.to_be_bytes());
    }
    rtu_frame(&body)
}

/// The registers of a function 03/04 response; `Err` with the exception
/// code of an exception response.
pub fn registers(response: &[u8]) -> Result<Vec<u16>, u8> {
    match response {
        [_, f, code, ..] if f & 0x80 != 0 => Err(*code),
        [_, _, n, rest @ ..] => Ok(rest
            .get(..usize::from(*n))
            .unwrap_or(&[])
            .chunks_exact(2)
            .map(|p| u16::from_be_bytes([p[0], p[1]]))
            .collect()),
        _ => Err(0),
    }
}
