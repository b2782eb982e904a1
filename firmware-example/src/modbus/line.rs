//! The gateway's side of the controller line: its exchanges, one at a
//! time, run by the core's engines on the bridge's one [`Line`] while the
//! bridge grants it ([`crate::bridge::Guest`]): the client for polls and
//! commands, the read-back for the table window, the verified transfer for
//! window writes. A queued command goes before the next poll.

use iai_protocol_b::axis::AxisPattern;
use iai_protocol_b::axis::MAX_AXES;
use iai_protocol_b::clock::reached;
use iai_protocol_b::engine::{Driver, Engine, Turn};
use iai_protocol_b::line::Line;
use iai_protocol_b::message::{
    AbsoluteMove, AlarmReset, AxisStatusQuery, ErrorDetailQuery, FlagChange, FlagQuery, HomeReturn,
    InputPortQuery, IntegerVariableChange, IntegerVariableQuery, OperationStop, OutputPortChange,
    OutputPortQuery, PositionNumberMove2, ProgramStatusQuery, Repeated, ServoOnOff,
    SystemStatusQuery, VersionQuery,
};
use iai_protocol_b::transfer::{packed_len, Guarantee, RecordBuffer};
use iai_protocol_b::{
    client::Client, client::Pending, error::Error, error::Failure, profile::Profile,
    readback::ReadBack, readback::ReadBackConfig, transfer::Transfer, transfer::TransferConfig,
};

use super::cache::Cache;
use super::command::{record_words, words_record, Job};
use super::map::{
    BITS, FIRST_FLAG, FIRST_INPUT, FIRST_INTEGER, FIRST_OUTPUT, INTEGERS, RECORD_WORDS,
    WINDOW_RECORDS,
};
use super::poll::Query;
use super::registers::Registers;
use crate::codes;
use crate::serial::{Counted, Port};

/// Largest frame of the window's engines: a 21FH reply with three 8-axis
/// records (264 bytes; a 26DH of three takes 260). The five records of
/// the window go in two frames (3 + 2) and come back in two replies: 336
/// bytes of RAM less than frames of five, for about one exchange more.
pub const WINDOW_FRAME: usize = 264;

/// Records in one frame of the window's engines (see [`WINDOW_FRAME`]).
pub const FRAME_RECORDS: usize = 3;

/// The client for polls and commands: the longest command is a 24CH of
/// eight variables (81 bytes), the longest reply a 212H of eight axes
/// (140 bytes; a 216H with a message string longer than about 60
/// characters does not fit, and that poll fails).
pub type Poller = Client<96, 160>;

/// The window write's records, packed (five 8-axis records, 215 bytes).
pub const WINDOW_BYTES: usize = WINDOW_RECORDS * packed_len(MAX_AXES);

/// What the gateway has on the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Exchange {
    Idle,
    Poll(Polled),
    Command(Job),
}

/// The engines and the exchange in progress.
pub struct Engines {
    client: Poller,
    /// The table window's reads: one window at a time, so two queued.
    readback: ReadBack<WINDOW_FRAME, 2>,
    transfer: Transfer<RecordBuffer<WINDOW_BYTES>, WINDOW_FRAME>,
    exchange: Exchange,
    /// Where the transmission of the exchange stands.
    driver: Driver,
    /// The engine waits until this tick.
    deadline: Option<u32>,
    /// A transmission waits for room downstream.
    blocked: bool,
    /// Bytes written downstream.
    pub bytes_out: u64,
    /// Bytes read downstream.
    pub bytes_in: u64,
}

/// How an engine's run ended for now.
enum Drive<T> {
    Pending,
    Done(Result<T, Failure>),
}

impl Engines {
    /// Idle engines.
    #[inline(always)]
    pub fn new() -> Self {
        Engines {
            client: Client::new(),
            readback: ReadBack::new(window_config(0)),
            transfer: Transfer::new(transfer_config(), RecordBuffer::new()),
            exchange: Exchange::Idle,
            driver: Driver::new(),
            deadline: None,
            blocked: false,
            bytes_out: 0,
            bytes_in: 0,
        }
    }

    /// Whether an exchange of the gateway's is under way.
    pub fn holds_line(&self) -> bool {
        self.exchange != Exchange::Idle
    }

    /// Whether it is a poll not in the middle of its transmission: it may
    /// be abandoned for the protocol-B host (the next round asks again).
    pub fn may_yield(&self) -> bool {
        matches!(self.exchange, Exchange::Poll(_)) && !self.driver.writing()
    }

    /// Abandons a poll: the line owes its reply and fences before the next
    /// command.
    pub fn yield_line(&mut self, line: &mut Line, now: u32) {
        if self.may_yield() {
            line.abandon(now);
            self.exchange = Exchange::Idle;
        }
    }

    /// What it waits for: `(deadline, room downstream)`.
    pub fn wait(&self) -> (Option<u32>, bool) {
        (self.deadline, self.blocked)
    }

    /// Whether it has something for the line at `now`.
    pub fn wants_line(regs: &Registers, now: u32) -> bool {
        regs.hs.queued() || (regs.active && regs.schedule.due_at().is_none_or(|t| reached(now, t)))
    }

    /// Starts the next exchange (a queued command first) and drives the
    /// current one; `Ok(moved)`.
    pub fn run<D: Port>(
        &mut self,
        regs: &mut Registers,
        line: &mut Line,
        down: &mut D,
        now: u32,
    ) -> Result<bool, D::Error> {
        let mut moved = false;
        if self.exchange == Exchange::Idle {
            if !self.start(regs, line, now) {
                return Ok(false);
            }
            moved = true;
        }
        let mut port = Counted::new(down, &mut self.bytes_in, &mut self.bytes_out);
        let mut tx = Tx {
            driver: &mut self.driver,
            deadline: None,
            blocked: false,
        };
        let result = match self.exchange {
            Exchange::Idle => return Ok(moved),
            Exchange::Command(Job::ReadWindow { head }) => {
                let window = &mut regs.window;
                let mut rb = self.readback.delivering(|records| {
                    for rec in records {
                        let k = usize::from(rec.number.wrapping_sub(head));
                        if let Some(dst) = window.get_mut(k * RECORD_WORDS..(k + 1) * RECORD_WORDS)
                        {
                            dst.copy_from_slice(&record_words(&rec));
                        }
                    }
                });
                match drive(&mut rb, line, &mut port, now, &mut tx)? {
                    (m, Drive::Pending) => (m, None),
                    (m, Drive::Done(r)) => (m, Some(r.map(|_| ()))),
                }
            }
            Exchange::Command(Job::WriteWindow { .. }) => {
                match drive(&mut self.transfer, line, &mut port, now, &mut tx)? {
                    (m, Drive::Pending) => (m, None),
                    (m, Drive::Done(r)) => (m, Some(r.map(|_: Guarantee| ()))),
                }
            }
            Exchange::Command(_) | Exchange::Poll(_) => {
                match drive(&mut self.client, line, &mut port, now, &mut tx)? {
                    (m, Drive::Pending) => (m, None),
                    (m, Drive::Done(r)) => (m, Some(r)),
                }
            }
        };
        self.deadline = tx.deadline;
        self.blocked = tx.blocked;
        moved |= result.0;
        if let Some(r) = result.1 {
            self.finished(regs, r, now);
            moved = true;
        }
        Ok(moved)
    }

    /// Starts a queued command, or the next poll due; `false` if none.
    fn start(&mut self, regs: &mut Registers, line: &mut Line, now: u32) -> bool {
        if let Some(job) = regs.hs.take() {
            match self.start_job(regs, job, line, now) {
                Ok(()) => self.exchange = Exchange::Command(job),
                Err(_) => regs.hs.finish(Err(codes::INTERNAL)),
            }
            return true;
        }
        let policy = regs.policy;
        if !regs.active {
            return false;
        }
        let Some(q) = regs.schedule.next(now, |q| policy.allows(q.message().id)) else {
            return false;
        };
        let c = &mut self.client;
        let axes = AxisPattern::first(regs.cfg.axes);
        let started = match q {
            Query::Axes => poll(
                c,
                line,
                &AxisStatusQuery {
                    query_axis_pattern: axes,
                },
                now,
            )
            .map(Polled::Axes),
            Query::System => poll(c, line, &SystemStatusQuery {}, now).map(Polled::System),
            Query::Program => poll(
                c,
                line,
                &ProgramStatusQuery {
                    program_number: regs.program,
                },
                now,
            )
            .map(Polled::Program),
            Query::ErrorDetail => poll(c, line, &ErrorDetailQuery::latest_system_error(), now)
                .map(Polled::ErrorDetail),
            Query::Inputs => poll(
                c,
                line,
                &InputPortQuery {
                    query_start_port_number: FIRST_INPUT,
                    number_of_query_ports: BITS,
                },
                now,
            )
            .map(Polled::Inputs),
            Query::Outputs => poll(
                c,
                line,
                &OutputPortQuery {
                    query_start_port_number: FIRST_OUTPUT,
                    number_of_query_ports: BITS,
                },
                now,
            )
            .map(Polled::Outputs),
            Query::Flags => poll(
                c,
                line,
                &FlagQuery {
                    program_number: 0,
                    query_start_flag_number: FIRST_FLAG,
                    number_of_query_flags: BITS,
                },
                now,
            )
            .map(Polled::Flags),
            Query::Integers => poll(
                c,
                line,
                &IntegerVariableQuery {
                    program_number: 0,
                    query_start_variable_number: FIRST_INTEGER,
                    number_of_query_variables: INTEGERS as u8,
                },
                now,
            )
            .map(Polled::Integers),
            Query::Version => poll(
                c,
                line,
                &VersionQuery {
                    unit_type: 0,
                    device_number: 0,
                },
                now,
            )
            .map(Polled::Version),
        };
        match started {
            Ok(polled) => {
                self.exchange = Exchange::Poll(polled);
                true
            }
            Err(_) => false,
        }
    }

    /// Starts the engine of `job`.
    fn start_job(
        &mut self,
        regs: &mut Registers,
        job: Job,
        line: &mut Line,
        now: u32,
    ) -> Result<(), Error> {
        let c = &mut self.client;
        let one = |axis: u8| AxisPattern::of(&[axis]);
        match job {
            Job::Servo { axis, on } => c.start(line, &ServoOnOff::new(&[axis], on)?, now).map(drop),
            Job::Home { axis } => c.start(line, &HomeReturn::of(&[axis])?, now).map(drop),
            Job::MoveToPosition { axis, number } => {
                let m = PositionNumberMove2 {
                    axis_pattern: one(axis)?,
                    position_number: number,
                    ..PositionNumberMove2::default()
                };
                c.start(line, &m, now).map(drop)
            }
            Job::Move {
                axis,
                position,
                speed,
                acceleration,
            } => {
                let m = AbsoluteMove::to(&[(axis, position)])?
                    .with_speed(speed)
                    .with_acceleration(acceleration)
                    .with_deceleration(acceleration);
                c.start(line, &m, now).map(drop)
            }
            Job::Stop { axis } => {
                let m = OperationStop {
                    stop_axis_pattern: one(axis)?,
                    appended_command_byte: 0,
                };
                c.start(line, &m, now).map(drop)
            }
            Job::AlarmReset => c.start(line, &AlarmReset {}, now).map(drop),
            Job::Output { port, on } => {
                let m = OutputPortChange {
                    output_port_number: port,
                    change_type: u8::from(on),
                };
                c.start(line, &m, now).map(drop)
            }
            Job::Flag { flag, on } => {
                let m = FlagChange {
                    program_number: 0,
                    flag_number: flag,
                    change_type: u8::from(on),
                };
                c.start(line, &m, now).map(drop)
            }
            Job::Integers {
                first,
                count,
                values,
            } => {
                let m = IntegerVariableChange {
                    program_number: 0,
                    change_start_variable_number: first,
                    integer_variable_data: Repeated::from_slice(
                        values.get(..usize::from(count)).unwrap_or(&[]),
                    ),
                };
                c.start(line, &m, now).map(drop)
            }
            Job::ReadWindow { head } => {
                // Positions the controller does not hold read as their
                // number and nothing else.
                for (k, rec) in regs.window.chunks_exact_mut(RECORD_WORDS).enumerate() {
                    rec.fill(0);
                    if let Some(n) = rec.first_mut() {
                        *n = head.wrapping_add(k as u16);
                    }
                }
                self.readback = ReadBack::new(window_config(head));
                Ok(())
            }
            Job::WriteWindow { first, count } => {
                let q = self.transfer.source_mut();
                q.clear();
                let from = usize::from(first) * RECORD_WORDS;
                let to = from + usize::from(count) * RECORD_WORDS;
                let staged = regs.window.get(from..to).unwrap_or(&[]);
                for rec in staged.chunks_exact(RECORD_WORDS).filter_map(words_record) {
                    q.push(rec).map_err(|_| Error::BufferTooSmall)?;
                }
                q.finish();
                self.transfer.restart(transfer_config());
                Ok(())
            }
        }
    }

    /// The exchange ended with `r`.
    fn finished(&mut self, regs: &mut Registers, r: Result<(), Failure>, now: u32) {
        let exchange = core::mem::replace(&mut self.exchange, Exchange::Idle);
        let c = &mut regs.cache;
        if let Err(Failure::Controller { code, .. }) = r {
            c.last_error = code;
        }
        match exchange {
            Exchange::Idle => {}
            Exchange::Poll(polled) => {
                // An `&` is an answer too: the controller is there.
                if c.set_link(matches!(r, Ok(()) | Err(Failure::Controller { .. }))) {
                    regs.schedule.version_soon();
                }
                if r.is_ok() {
                    c.polls_ok = c.polls_ok.wrapping_add(1);
                    take_reply(&self.client, polled, c, now);
                } else {
                    c.polls_failed = c.polls_failed.wrapping_add(1);
                }
            }
            Exchange::Command(job) => {
                let result = match r {
                    Ok(()) => {
                        if job.moves() != 0 {
                            c.stale |= job.moves();
                            regs.schedule.axes_soon();
                        }
                        if c.set_link(true) {
                            regs.schedule.version_soon();
                        }
                        Ok(())
                    }
                    Err(Failure::Controller { code, .. }) => Err(code),
                    Err(Failure::Timeout { .. } | Failure::OutcomeUnknown { .. }) => {
                        c.set_link(false);
                        Err(codes::CONTROLLER_TIMEOUT)
                    }
                    Err(Failure::Mismatch { .. } | Failure::Misplaced { .. }) => {
                        Err(codes::VERIFY_MISMATCH)
                    }
                    Err(_) => Err(codes::INTERNAL),
                };
                regs.hs.finish(result);
            }
        }
    }
}

impl Default for Engines {
    fn default() -> Self {
        Self::new()
    }
}

/// A poll on the line: its query, with the ticket to its typed reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Polled {
    Axes(Pending<AxisStatusQuery>),
    System(Pending<SystemStatusQuery>),
    Program(Pending<ProgramStatusQuery>),
    ErrorDetail(Pending<ErrorDetailQuery>),
    Inputs(Pending<InputPortQuery>),
    Outputs(Pending<OutputPortQuery>),
    Flags(Pending<FlagQuery>),
    Integers(Pending<IntegerVariableQuery>),
    Version(Pending<VersionQuery>),
}

/// Starts a poll: sent once (the next round asks again).
fn poll<'a, R: iai_protocol_b::message::Request<'a>>(
    c: &mut Poller,
    line: &mut Line,
    req: &R,
    now: u32,
) -> Result<Pending<R>, Error> {
    c.start_with_sends(line, req, 1, now)
}

/// Puts the reply to the poll into the cache.
fn take_reply(client: &Poller, polled: Polled, c: &mut Cache, now: u32) {
    match polled {
        Polled::Axes(p) => {
            if let Ok(r) = client.response(&p) {
                c.axes(&r, true, now);
            }
        }
        Polled::System(p) => {
            if let Ok(r) = client.response(&p) {
                c.system(&r, now);
            }
        }
        Polled::Program(p) => {
            if let Ok(r) = client.response(&p) {
                c.program(&r, now);
            }
        }
        Polled::ErrorDetail(p) => {
            if let Ok(r) = client.response(&p) {
                c.error_detail(&r, now);
            }
        }
        Polled::Inputs(p) => {
            if let Ok(r) = client.response(&p) {
                c.inputs = Cache::port_bits(r.input_port_data.items.iter());
                c.io_at.set(now);
            }
        }
        Polled::Outputs(p) => {
            if let Ok(r) = client.response(&p) {
                c.outputs = Cache::port_bits(r.output_port_data.items.iter());
                c.io_at.set(now);
            }
        }
        Polled::Flags(p) => {
            if let Ok(r) = client.response(&p) {
                c.flags = Cache::port_bits(r.flag_data.items.iter());
                c.io_at.set(now);
            }
        }
        Polled::Integers(p) => {
            if let Ok(r) = client.response(&p) {
                for (slot, v) in c.integers.iter_mut().zip(r.integer_variable_data.iter()) {
                    *slot = v;
                }
                c.integers_at.set(now);
            }
        }
        Polled::Version(p) => {
            if let Ok(r) = client.response(&p) {
                c.version = Some(r);
            }
        }
    }
}

/// The window's read-back: positions `head..head+4`, two replies that
/// agree.
fn window_config(head: u16) -> ReadBackConfig {
    ReadBackConfig {
        max_response: WINDOW_FRAME,
        ..ReadBackConfig::new(
            Profile::TTA,
            head,
            head.saturating_add(WINDOW_RECORDS as u16 - 1),
        )
    }
}

/// The window's writes: 26DH of up to three records, each read back
/// (21FH) and compared.
fn transfer_config() -> TransferConfig {
    TransferConfig {
        max_frame: WINDOW_FRAME,
        max_response: WINDOW_FRAME,
        max_records: FRAME_RECORDS as u16,
        ..TransferConfig::new(Profile::TTA)
    }
}

/// The driver and what an engine's turn left to wait for.
struct Tx<'a> {
    driver: &'a mut Driver,
    deadline: Option<u32>,
    blocked: bool,
}

/// One turn of `engine` on the core's driver: feeds what the controller
/// sent, transmits what it asks for as far as the port allows now;
/// `(moved, how it ended)`.
fn drive<G: Engine, D: Port>(
    engine: &mut G,
    line: &mut Line,
    down: &mut D,
    now: u32,
    tx: &mut Tx<'_>,
) -> Result<(bool, Drive<G::Output>), D::Error> {
    let mut clock = || now;
    match tx.driver.turn(engine, line, down, &mut clock) {
        Err(e) => Err(e),
        Ok(Turn::Busy) => {
            tx.deadline = Some(now);
            Ok((true, Drive::Pending))
        }
        Ok(Turn::Wait { until, write }) => {
            tx.deadline = until;
            tx.blocked = write;
            Ok((false, Drive::Pending))
        }
        Ok(Turn::Done(r)) => Ok((true, Drive::Done(r))),
    }
}
