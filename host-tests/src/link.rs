//! Runs the core's engines against the simulator on a virtual clock: a
//! 1.6 MB table with 3-second timeouts takes seconds of real time.
//!
//! [`drive`] moves bytes and time between any engine, its [`Line`] and a
//! [`Simulator`]: replies are fed when the simulator makes them due, and
//! time jumps to the next deadline or reply. At `baud` 0 bytes take no
//! time on the line; otherwise each byte takes 10 bit times (8N1) in
//! either direction, so that the virtual time is the wire time.

use iai_protocol_b::engine::{feed, Engine, Step};
use iai_protocol_b::message::Request;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::readback::ReadBackStats;
use iai_protocol_b::transfer::{Guarantee, RecordSource};
use iai_protocol_b::{
    client::Client, client::Pending, error::Failure, line::Line, line::LineConfig,
    readback::ReadBack, transfer::Transfer,
};

use iai_simulator::Simulator;

/// How a simulated run ended.
#[derive(Debug)]
pub struct LinkRun<T = Guarantee> {
    /// The engine's result.
    pub result: Result<T, Failure>,
    /// Virtual milliseconds elapsed.
    pub virtual_ms: u32,
    /// Bytes host → controller.
    pub bytes_to_controller: u64,
    /// Bytes controller → host.
    pub bytes_to_host: u64,
}

/// Milliseconds `bytes` take on a line of `baud` (8N1), rounded up; 0 at
/// `baud` 0.
pub fn wire_ms(bytes: usize, baud: u32) -> u32 {
    if baud == 0 {
        return 0;
    }
    (bytes as u64 * 10 * 1000).div_ceil(u64::from(baud)) as u32
}

/// The next tick: whichever comes first of a reply and `deadline`, and
/// always later than `now`.
fn next_tick(sim: &Simulator, now: u32, deadline: u32) -> u32 {
    sim.next_output_at()
        .map_or(deadline, |r| r.min(deadline))
        .max(now + 1)
}

/// Steps at one virtual instant after which a runner declares the engine
/// stuck.
const STUCK_STEPS: u64 = 1_000_000;

/// Virtual time after which a runner declares the engine stuck: two days,
/// far beyond the slowest fault class of the suite.
const MAX_VIRTUAL_MS: u32 = 48 * 3_600_000;

/// The line of a simulated controller: its station, the spec's settings.
pub fn line_to(sim: &Simulator) -> Line {
    Line::new(LineConfig::new(sim.station), 0x5EED)
}

/// Drives `engine` on `line` against `sim` from tick `now` until it is
/// done; `between` runs before every step (to feed a source), and after a
/// failure `resume` may continue the engine (`true`) or end the run.
pub fn drive<G: Engine>(
    engine: &mut G,
    line: &mut Line,
    sim: &mut Simulator,
    baud: u32,
    mut now: u32,
    mut between: impl FnMut(&mut G),
    mut resume: impl FnMut(&mut G, &mut Line, u32) -> bool,
) -> LinkRun<G::Output> {
    let (mut up, mut down) = (0u64, 0u64);
    let mut steps_at_now = (now, 0u64);
    let mut pending: Vec<u8> = Vec::new();
    loop {
        // An engine that keeps asking for work without time passing is
        // stuck: fail loudly instead of spinning.
        if steps_at_now.0 == now {
            steps_at_now.1 += 1;
            assert!(
                steps_at_now.1 < STUCK_STEPS,
                "the engine made {STUCK_STEPS} steps at {now} ms without time passing"
            );
        } else {
            steps_at_now = (now, 0);
        }
        assert!(
            now < MAX_VIRTUAL_MS,
            "the engine is still running after {MAX_VIRTUAL_MS} virtual ms"
        );
        between(engine);
        let reply = sim.take_output(now);
        if !reply.is_empty() {
            down += reply.len() as u64;
            now += wire_ms(reply.len(), baud);
            pending.extend_from_slice(&reply);
        }
        if !pending.is_empty() {
            feed(engine, line, &pending, now);
            pending.clear();
        }
        let result = match engine.poll(line, now) {
            Step::Transmit(bytes) => {
                up += bytes.len() as u64;
                let bytes = bytes.to_vec();
                now += wire_ms(bytes.len(), baud);
                sim.receive(&bytes, now);
                engine.sent(line, now);
                continue;
            }
            Step::WaitUntil(deadline) => {
                now = next_tick(sim, now, deadline);
                continue;
            }
            Step::Idle => {
                now += 1;
                continue;
            }
            Step::Done(Ok(out)) => Ok(out),
            Step::Done(Err(e)) => {
                if resume(engine, line, now) {
                    continue;
                }
                Err(e)
            }
        };
        return LinkRun {
            result,
            virtual_ms: now,
            bytes_to_controller: up,
            bytes_to_host: down,
        };
    }
}

/// Runs transfer `t` on `line` against `sim` on a line of `baud` from tick
/// `from` until it completes or fails (at most `max_resumes` resumptions
/// after a failure, to show that resuming loses nothing).
pub fn run_transfer<I: RecordSource, const N: usize>(
    t: &mut Transfer<I, N>,
    line: &mut Line,
    sim: &mut Simulator,
    max_resumes: u32,
    baud: u32,
    from: u32,
) -> LinkRun {
    run_fed(t, line, sim, max_resumes, baud, from, |_| {})
}

/// Like [`run_transfer`], calling `feed` with the transfer's source at
/// every step (e.g. to push records into a `RecordBuffer` as they
/// "arrive").
pub fn run_fed<I: RecordSource, const N: usize>(
    t: &mut Transfer<I, N>,
    line: &mut Line,
    sim: &mut Simulator,
    max_resumes: u32,
    baud: u32,
    from: u32,
    mut feed: impl FnMut(&mut I),
) -> LinkRun {
    let mut resumes = 0;
    drive(
        t,
        line,
        sim,
        baud,
        from,
        |t| feed(t.source_mut()),
        |t, line, now| {
            if resumes >= max_resumes {
                return false;
            }
            resumes += 1;
            t.resume(line, now);
            true
        },
    )
}

/// Outcome of a simulated read-back.
#[derive(Debug)]
pub struct ReadRun {
    /// The records delivered, in delivery order.
    pub records: Vec<PositionRecord>,
    /// How it ended.
    pub result: Result<ReadBackStats, Failure>,
    /// Virtual milliseconds elapsed.
    pub virtual_ms: u32,
}

/// Reads back with `rb` on `line` against `sim` on a line of `baud`,
/// resuming at most `max_resumes` times after a failure.
pub fn read_back<const N: usize, const Q: usize>(
    rb: &mut ReadBack<N, Q>,
    line: &mut Line,
    sim: &mut Simulator,
    max_resumes: u32,
    baud: u32,
) -> ReadRun {
    let mut records = Vec::new();
    let mut now = 0;
    let mut resumes = 0;
    loop {
        let run = {
            let mut engine = rb.delivering(|recs| records.extend(recs));
            drive(&mut engine, line, sim, baud, now, |_| {}, |_, _, _| false)
        };
        now = run.virtual_ms;
        match run.result {
            Err(_) if resumes < max_resumes => {
                resumes += 1;
                rb.resume();
            }
            result => {
                return ReadRun {
                    records,
                    result,
                    virtual_ms: now,
                }
            }
        }
    }
}

/// Runs one request of `client` on `line` against `sim` from tick `now`;
/// returns how it ended, the tick it ended at and the ticket to its reply.
pub fn call<'a, R: Request<'a>, const C: usize, const P: usize>(
    client: &mut Client<C, P>,
    line: &mut Line,
    sim: &mut Simulator,
    req: &R,
    now: u32,
) -> (Result<(), Failure>, u32, Pending<R>) {
    let pending = client
        .start(line, req, now)
        .expect("the request fits the command buffer");
    let run = drive(client, line, sim, 0, now, |_| {}, |_, _, _| false);
    (run.result, run.virtual_ms, pending)
}
