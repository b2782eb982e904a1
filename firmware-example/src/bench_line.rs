//! Instructions per received byte of the firmware on its controller line:
//! the bridge's pass-through and the Modbus gateway's polling, whole
//! ([`Bridge::poll`], [`Bridge::poll_with`] and everything under them: the
//! ports, the driver, the line's receiver and frame decoder, the engines),
//! counted as [`crate::bench`] counts (see its docs).
//!
//! A controller of the bench's own answers each command the bridge writes
//! as soon as its LF is written, with a reply of the right layout (the
//! test call's echo, 212H of the axes asked, a 21FH window of 8-axis
//! records, the gateway's status and I/O queries). Time is virtual: when
//! the bridge waits, it jumps to the deadline. Only the bridge's polls are
//! timed, not the controller.
//!
//! # What is counted
//! Workload `bridge`, instructions in [`Bridge::poll`] per byte it read
//! (the host's command and the controller's reply):
//! - `212h-8axis`: a host's 212H for 8 axes (13 bytes) and its 140-byte
//!   reply, relayed, eight times;
//! - `21fh-window`: a host's 21FH and its reply of 24 8-axis records
//!   (2,038 bytes), relayed, eight times;
//! - `listen`: the same replies arriving while no command runs (a late
//!   reply, a copy): heard by the line in passing, dropped.
//!
//! Workload `gateway`, instructions in [`Bridge::poll_with`] per byte read
//! from the controller: `poll-round`, four rounds of the gateway's polls
//! (212H of 8 axes, 215H, 213H, 216H, 20BH, 20CH, 20DH, 20EH).
//!
//! Lines: `bench <workload> <what> <ticks> <bytes>`, as [`crate::bench`].

use core::hint::black_box;

use crate::bridge::{Bridge, Guest, NoGuest, Poll};
use crate::config::{Config, ModbusConfig, Source};
use crate::modbus::Gateway;
use crate::serial::Port;
use embedded_io::{ErrorType, Read, ReadReady, Write, WriteReady};
use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::frame::{Frame, Station};
use iai_protocol_b::message::{
    AxisStatus, AxisStatusQuery, AxisStatusResponse, Command, EffectivePositionQuery2,
    ErrorDetailResponse, ErrorResponse, FlagResponse, InputPortResponse, IntegerVariableResponse,
    Message, OutputPortResponse, PortData, ProgramStatusResponse, Repeated, SystemStatusResponse,
    TestCallResponse, VersionResponse,
};
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::PositionStreamEncoder;

use crate::bench::{record, timed};

/// The controller's station (the bridge's default configuration).
const STATION: Station = Station(0x99);
/// Exchanges of each kind timed.
const EXCHANGES: u32 = 8;
/// Gateway rounds timed.
const ROUNDS: u32 = 4;
/// Records of a 21FH window reply: as many 8-axis records as a TTA's
/// 2,048-byte reply holds.
const WINDOW: u16 = 24;
/// Largest reply: the TTA's (2,048 bytes), and room to spare.
const REPLY_CAP: usize = 2051;
/// Polls after which an exchange that has not ended is a failure.
const MAX_POLLS: u32 = 10_000;

/// A serial port over fixed buffers: reads drain `input`, writes append to
/// `output` (up to its size; beyond, only counted).
struct Wire<const IN: usize, const OUT: usize> {
    input: [u8; IN],
    in_len: usize,
    in_pos: usize,
    output: [u8; OUT],
    out_len: usize,
    /// Bytes read so far.
    read: usize,
    /// Bytes written so far.
    written: usize,
}

impl<const IN: usize, const OUT: usize> Wire<IN, OUT> {
    fn new() -> Self {
        Wire {
            input: [0; IN],
            in_len: 0,
            in_pos: 0,
            output: [0; OUT],
            out_len: 0,
            read: 0,
            written: 0,
        }
    }

    /// `bytes` become the next to read; `false` if they do not fit or
    /// some are still unread.
    fn give(&mut self, bytes: &[u8]) -> bool {
        self.fill(|input| {
            let dst = input.get_mut(..bytes.len())?;
            dst.copy_from_slice(bytes);
            Some(bytes.len())
        })
    }

    /// What `f` writes at the start of `input` (its length) becomes the
    /// next to read; `false` if `f` fails or bytes are still unread.
    fn fill(&mut self, f: impl FnOnce(&mut [u8; IN]) -> Option<usize>) -> bool {
        if self.in_pos < self.in_len {
            return false;
        }
        let Some(n) = f(&mut self.input) else {
            return false;
        };
        self.in_len = n.min(IN);
        self.in_pos = 0;
        true
    }

    fn unread(&self) -> usize {
        self.in_len - self.in_pos
    }

    /// The frame written so far if it ends with LF, then forgotten.
    fn take_frame(&mut self, into: &mut [u8; 128]) -> Option<usize> {
        let n = self.out_len;
        let bytes = self.output.get(..n)?;
        if bytes.last() != Some(&b'\n') {
            return None;
        }
        into.get_mut(..n)?.copy_from_slice(bytes);
        self.out_len = 0;
        Some(n)
    }
}

impl<const IN: usize, const OUT: usize> ErrorType for Wire<IN, OUT> {
    type Error = core::convert::Infallible;
}

impl<const IN: usize, const OUT: usize> ReadReady for Wire<IN, OUT> {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(self.in_pos < self.in_len)
    }
}

impl<const IN: usize, const OUT: usize> Read for Wire<IN, OUT> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let rest = self.input.get(self.in_pos..self.in_len).unwrap_or(&[]);
        let n = buf.len().min(rest.len());
        if let (Some(dst), Some(src)) = (buf.get_mut(..n), rest.get(..n)) {
            dst.copy_from_slice(src);
        }
        self.in_pos += n;
        self.read += n;
        Ok(n)
    }
}

impl<const IN: usize, const OUT: usize> WriteReady for Wire<IN, OUT> {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(true)
    }
}

impl<const IN: usize, const OUT: usize> Write for Wire<IN, OUT> {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let end = self.out_len.saturating_add(buf.len());
        if let Some(dst) = self.output.get_mut(self.out_len..end) {
            dst.copy_from_slice(buf);
            self.out_len = end;
        }
        self.written += buf.len();
        Ok(buf.len())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl<const IN: usize, const OUT: usize> Port for Wire<IN, OUT> {}

/// The bench's controller: its reply to each command, and a counter that
/// makes every reply's values differ.
struct Controller {
    serial: u32,
}

impl Controller {
    /// Answers the command `cmd` (a whole frame) into `out`; its length.
    fn answer(&mut self, cmd: &[u8], out: &mut [u8]) -> Option<usize> {
        let f = Frame::new_checked(cmd, BypassPolicy::Accept).ok()?;
        self.serial = self.serial.wrapping_add(1);
        let k = self.serial;
        let n = match Command::parse(&f).ok()? {
            Command::TestCall(c) => TestCallResponse {
                test_string: c.test_string,
            }
            .emit(STATION, out),
            Command::VersionQuery(q) => VersionResponse {
                unit_type: q.unit_type,
                device_number: q.device_number,
                model_code: 0x5A,
                unit_code: 1,
                version_number: 0x0100,
                year: 2026,
                month: 12,
                day: 1,
                hour: 0,
                minute: 0,
                second: 0,
            }
            .emit(STATION, out),
            Command::AxisStatusQuery(q) => {
                let mut axes = PerAxis::new();
                for n in q.query_axis_pattern.iter() {
                    let _ = axes.push(AxisStatus {
                        axis_status: 0b1_1101,
                        sensor_input_status: 0,
                        error_code: 0,
                        encoder_status: 0,
                        current_position: record(k, 8).positions.first().copied().unwrap_or(0)
                            + i32::from(n),
                    });
                }
                AxisStatusResponse {
                    axis_pattern: q.query_axis_pattern,
                    axes,
                }
                .emit(STATION, out)
            }
            Command::SystemStatusQuery(_) => SystemStatusResponse {
                system_mode: 1,
                status_byte_3: 0b110,
                status_byte_4: k as u8,
                ..SystemStatusResponse::default()
            }
            .emit(STATION, out),
            Command::ProgramStatusQuery(q) => ProgramStatusResponse {
                program_number: q.program_number,
                executing_step_number: k as u16,
                ..ProgramStatusResponse::default()
            }
            .emit(STATION, out),
            Command::ErrorDetailQuery(q) => ErrorDetailResponse {
                error_number: 0xC74,
                detail_1: u32::from(q.type_2),
                detail_2: k,
                ..ErrorDetailResponse::default()
            }
            .emit(STATION, out),
            Command::InputPortQuery(q) => InputPortResponse {
                response_start_port_number: q.query_start_port_number,
                input_port_data: ports(q.number_of_query_ports, k, &mut [0; 16]),
            }
            .emit(STATION, out),
            Command::OutputPortQuery(q) => OutputPortResponse {
                response_start_port_number: q.query_start_port_number,
                output_port_data: ports(q.number_of_query_ports, k, &mut [0; 16]),
            }
            .emit(STATION, out),
            Command::FlagQuery(q) => FlagResponse {
                program_number: q.program_number,
                response_start_flag_number: q.query_start_flag_number,
                flag_data: ports(q.number_of_query_flags, k, &mut [0; 16]),
            }
            .emit(STATION, out),
            Command::IntegerVariableQuery(q) => {
                let values: [i32; 16] = core::array::from_fn(|i| (k as i32) * 7 + i as i32);
                let n = usize::from(q.number_of_query_variables).min(values.len());
                IntegerVariableResponse {
                    program_number: q.program_number,
                    response_start_variable_number: q.query_start_variable_number,
                    integer_variable_data: Repeated::from_slice(values.get(..n)?),
                }
                .emit(STATION, out)
            }
            Command::EffectivePositionQuery2(q) => {
                return window(q.query_head_position_number, q.number_of_query_records, out)
            }
            _ => ErrorResponse { code: 0x0E3 }.emit(STATION, out),
        };
        n.ok()
    }
}

/// `units` ports (at most 128) as bytes of bits that change with `k`.
fn ports(units: u16, k: u32, bytes: &mut [u8; 16]) -> PortData<'_> {
    let units = usize::from(units).min(8 * bytes.len());
    for (i, b) in bytes.iter_mut().enumerate() {
        *b = (k as u8).wrapping_add(i as u8);
    }
    let n = units.div_ceil(8);
    PortData {
        units,
        items: Repeated::from_slice(bytes.get(..n).unwrap_or(&[])),
    }
}

/// A 21FH reply: `count` 8-axis records from `head`, into `out`.
fn window(head: u16, count: u16, out: &mut [u8]) -> Option<usize> {
    let recs = (0..u32::from(count)).map(|i| record(u32::from(head) + i, 8));
    let kind = PositionStream::QUERY_2_RESPONSE;
    let mut enc = PositionStreamEncoder::new(kind, STATION, head, count, recs).ok()?;
    let mut len = 0;
    loop {
        match enc.read(out.get_mut(len..)?) {
            Ok(0) => return Some(len),
            Ok(n) => len += n,
            Err(_) => return None,
        }
    }
}

/// Ticks and bytes read of one figure.
#[derive(Default)]
struct Count {
    ticks: u32,
    bytes: usize,
}

/// The bridge's ports (the upstream one keeps `UP` bytes of what the
/// bridge writes) and the controller behind the downstream one.
struct Bench<const UP: usize> {
    up: Wire<64, UP>,
    down: Wire<REPLY_CAP, 128>,
    ctl: Controller,
    now: u32,
    /// Ticks of an empty timed piece.
    empty: u32,
}

impl<const UP: usize> Bench<UP> {
    /// Lets the controller answer what the bridge wrote; `true` if it did.
    fn controller(&mut self) -> Result<bool, &'static str> {
        let mut cmd = [0u8; 128];
        let Some(n) = self.down.take_frame(&mut cmd) else {
            return Ok(false);
        };
        self.reply(cmd.get(..n).unwrap_or(&[]))?;
        Ok(true)
    }

    /// The controller's reply to `cmd` becomes the next bytes to read.
    fn reply(&mut self, cmd: &[u8]) -> Result<(), &'static str> {
        let ctl = &mut self.ctl;
        if self.down.fill(|input| ctl.answer(cmd, input)) {
            Ok(())
        } else {
            Err("the controller could not answer")
        }
    }

    /// Polls the bridge (timed) until `done`, the controller answering
    /// and virtual time jumping to each deadline; adds the ticks and the
    /// bytes the bridge read to `count`.
    fn run<G: Guest>(
        &mut self,
        bridge: &mut Bridge,
        guest: &mut G,
        count: &mut Count,
        mut done: impl FnMut(&Self, &Bridge, &G) -> bool,
    ) -> Result<(), &'static str> {
        let before = self.up.read + self.down.read;
        for _ in 0..MAX_POLLS {
            let (up, down, now) = (&mut self.up, &mut self.down, self.now);
            let (t, r) = timed(|| bridge.poll_with(up, down, guest, now));
            count.ticks += t.saturating_sub(self.empty);
            let w = match r.map_err(|_| "a port failed")? {
                Poll::Busy => continue,
                Poll::Quit => return Err("the bridge quit"),
                Poll::Wait(w) => w,
            };
            if self.controller()? {
                continue;
            }
            let unread = (w.interest.down_read && self.down.unread() > 0)
                || (w.interest.up_read && self.up.unread() > 0);
            if unread {
                continue;
            }
            if done(self, bridge, guest) {
                count.bytes += self.up.read + self.down.read - before;
                return Ok(());
            }
            match w.deadline {
                Some(d) if d != self.now => self.now = d,
                Some(_) => {}
                None => return Err("the bridge waits for nothing"),
            }
        }
        Err("the work did not end")
    }

    /// The host sends `cmd` through the bridge; the reply relayed whole.
    fn exchange(
        &mut self,
        bridge: &mut Bridge,
        cmd: &[u8],
        count: &mut Count,
    ) -> Result<(), &'static str> {
        if !self.up.give(cmd) {
            return Err("the host's command does not fit");
        }
        self.up.out_len = 0;
        let (written, answered) = (self.up.written, self.ctl.serial);
        self.run(bridge, &mut NoGuest, count, |b, bridge, _| {
            let reply = b.down.in_len;
            b.ctl.serial != answered
                && b.up.written - written == reply
                && b.down.unread() == 0
                && bridge.is_idle()
        })?;
        // The reply the host got is the controller's, byte for byte.
        let relayed = self.up.output.get(..self.up.out_len);
        if relayed != self.down.input.get(..self.down.in_len) {
            return Err("the host did not get the controller's reply");
        }
        Ok(())
    }
}

/// The bridge's pass-through and what it hears in passing (see the module
/// docs); `Err` if an exchange did not end as it should.
#[inline(never)]
fn bridge(print: fn(core::fmt::Arguments<'_>), empty: u32) -> Result<(), &'static str> {
    let mut bridge = Bridge::new(Config::DEFAULT, Source::Default, 0x2604_0032);
    let mut b = Bench::<REPLY_CAP> {
        up: Wire::new(),
        down: Wire::new(),
        ctl: Controller { serial: 0 },
        now: 0,
        empty,
    };
    let mut cmd = [0u8; 64];
    let status = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(8),
    };
    let n = status.emit(STATION, &mut cmd).map_err(|_| "212H")?;
    let status = cmd.get(..n).ok_or("212H")?;
    // The line's first command is fenced: not counted.
    b.exchange(&mut bridge, status, &mut Count::default())?;
    let mut c = Count::default();
    for _ in 0..EXCHANGES {
        b.exchange(&mut bridge, status, &mut c)?;
    }
    print(format_args!(
        "bench bridge 212h-8axis {} {}\n",
        c.ticks, c.bytes
    ));

    let mut c = Count::default();
    for k in 0..EXCHANGES {
        let q = EffectivePositionQuery2 {
            query_head_position_number: 1 + k as u16 * WINDOW,
            number_of_query_records: WINDOW,
        };
        let mut cmd = [0u8; 64];
        let n = q.emit(STATION, &mut cmd).map_err(|_| "21FH")?;
        b.exchange(&mut bridge, cmd.get(..n).ok_or("21FH")?, &mut c)?;
    }
    print(format_args!(
        "bench bridge 21fh-window {} {}\n",
        c.ticks, c.bytes
    ));

    // The same replies with no command: heard in passing.
    b.up.out_len = 0;
    let mut c = Count::default();
    for k in 0..EXCHANGES {
        let q = EffectivePositionQuery2 {
            query_head_position_number: 1 + k as u16 * WINDOW,
            number_of_query_records: WINDOW,
        };
        for window in [true, false] {
            let n = if window {
                q.emit(STATION, &mut cmd)
            } else {
                status_frame(&mut cmd)
            };
            let n = n.map_err(|_| "a command")?;
            b.reply(cmd.get(..n).ok_or("a command")?)?;
            b.run(&mut bridge, &mut NoGuest, &mut c, |b, bridge, _| {
                b.down.unread() == 0 && bridge.is_idle()
            })?;
        }
    }
    if b.up.out_len != 0 {
        return Err("the bridge relayed a reply nobody asked for");
    }
    print(format_args!(
        "bench bridge listen {} {}\n",
        c.ticks, c.bytes
    ));
    black_box(&bridge);
    Ok(())
}

/// A 212H for 8 axes into `buf`.
fn status_frame(buf: &mut [u8]) -> iai_protocol_b::error::Result<usize> {
    AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(8),
    }
    .emit(STATION, buf)
}

/// The Modbus gateway's poll rounds through the bridge (see the module
/// docs).
#[inline(never)]
fn gateway(print: fn(core::fmt::Arguments<'_>), empty: u32) -> Result<(), &'static str> {
    let mut bridge = Bridge::new(Config::DEFAULT, Source::Default, 0x2604_0033);
    let mut gw = Gateway::new(ModbusConfig::DEFAULT, Config::DEFAULT.policy);
    // As if a PLC had asked: the gateway polls from then on.
    gw.regs.active = true;
    let mut b = Bench::<0> {
        up: Wire::new(),
        down: Wire::new(),
        ctl: Controller { serial: 0 },
        now: 0,
        empty,
    };
    let mut round = |b: &mut Bench<0>, count: &mut Count| {
        let answered = b.ctl.serial;
        b.run(&mut bridge, &mut gw, count, |b, _, gw| {
            b.ctl.serial.wrapping_sub(answered) >= 8 && !gw.holds_line() && !gw.wants_line(b.now)
        })
    };
    // The first round (a fence, the controller's version): not counted.
    round(&mut b, &mut Count::default())?;
    let mut c = Count::default();
    for _ in 0..ROUNDS {
        round(&mut b, &mut c)?;
    }
    print(format_args!(
        "bench gateway poll-round {} {}\n",
        c.ticks, c.bytes
    ));
    Ok(())
}

/// Runs the line workloads and prints their figures; `false` (with a
/// `bench failed` line) if one did not end as it should.
#[inline(never)]
pub fn run(print: fn(core::fmt::Arguments<'_>), empty: u32) -> bool {
    for (name, work) in [
        ("bridge", bridge as fn(_, _) -> _),
        ("gateway", gateway as fn(_, _) -> _),
    ] {
        if let Err(why) = work(print, empty) {
            print(format_args!("bench failed {name}: {why}\n"));
            return false;
        }
    }
    true
}
