//! Runs the core's engines against the simulator on a virtual clock: a
//! 1.6 MB table with 3-second timeouts takes seconds of real time.
//!
//! Each runner moves bytes and time between an engine and a
//! [`Simulator`]: replies are fed when the simulator makes them due, and
//! time jumps to the next deadline or reply. At `baud` 0 bytes take no
//! time on the line; otherwise each byte takes 10 bit times (8N1) in
//! either direction, so that the virtual time is the wire time.

use iai_protocol_b::client::{Client, ClientStep, Outcome};
use iai_protocol_b::message::Request;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::readback::{ReadBack, ReadBackStats, ReadStep};
use iai_protocol_b::transfer::{RecordSource, Step, Transfer, TransferError, TransferReport};

use crate::sim::Simulator;

/// Outcome of a simulated transfer.
#[derive(Debug)]
pub struct LinkRun {
    /// How the transfer ended.
    pub result: Result<TransferReport, TransferError>,
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

/// Runs `t` against `sim` until it completes or fails (at most `max_resumes`
/// resumptions after a failure, to show that resuming loses nothing).
pub fn run<I, const N: usize>(
    t: &mut Transfer<I, N>,
    sim: &mut Simulator,
    max_resumes: u32,
) -> LinkRun
where
    I: Iterator<Item = PositionRecord>,
{
    run_fed(t, sim, max_resumes, |_| {})
}

/// Like [`run`], on a line of `baud` (see the module docs).
pub fn run_line<I, const N: usize>(
    t: &mut Transfer<I, N>,
    sim: &mut Simulator,
    max_resumes: u32,
    baud: u32,
) -> LinkRun
where
    I: Iterator<Item = PositionRecord>,
{
    run_with(t, sim, max_resumes, baud, |_| {})
}

/// Like [`run`], calling `feed` with the transfer's source at every step
/// (e.g. to push records into a `RecordQueue` as they "arrive").
pub fn run_fed<I, const N: usize>(
    t: &mut Transfer<I, N>,
    sim: &mut Simulator,
    max_resumes: u32,
    feed: impl FnMut(&mut I),
) -> LinkRun
where
    I: RecordSource,
{
    run_with(t, sim, max_resumes, 0, feed)
}

fn run_with<I, const N: usize>(
    t: &mut Transfer<I, N>,
    sim: &mut Simulator,
    max_resumes: u32,
    baud: u32,
    mut feed: impl FnMut(&mut I),
) -> LinkRun
where
    I: RecordSource,
{
    let mut now: u32 = 0;
    let mut resumes = 0;
    let (mut up, mut down) = (0u64, 0u64);
    let mut steps_at_now = (0u32, 0u64);
    loop {
        // An engine that keeps asking for work without time passing is
        // stuck: fail loudly instead of spinning.
        if steps_at_now.0 == now {
            steps_at_now.1 += 1;
            assert!(
                steps_at_now.1 < STUCK_STEPS,
                "transfer made {STUCK_STEPS} steps at {now} ms without time passing: {:?}",
                t.stats()
            );
        } else {
            steps_at_now = (now, 0);
        }
        assert!(
            now < MAX_VIRTUAL_MS,
            "transfer still running after {MAX_VIRTUAL_MS} virtual ms: {:?}",
            t.stats()
        );
        feed(t.source_mut());
        let reply = sim.take_output(now);
        if !reply.is_empty() {
            down += reply.len() as u64;
            now += wire_ms(reply.len(), baud);
            t.received_all(&reply, now);
        }
        let result = match t.poll(now) {
            Step::Transmit(bytes) => {
                up += bytes.len() as u64;
                let bytes = bytes.to_vec();
                now += wire_ms(bytes.len(), baud);
                sim.receive(&bytes, now);
                t.sent(now);
                continue;
            }
            Step::WaitUntil(deadline) => {
                now = next_tick(sim, now, deadline);
                continue;
            }
            Step::NeedRecords => {
                now += 1;
                continue;
            }
            Step::Complete(report) => Ok(report),
            Step::Failed(e) if resumes < max_resumes => {
                resumes += 1;
                t.resume(now);
                let _ = e;
                continue;
            }
            Step::Failed(e) => Err(e),
        };
        return LinkRun {
            result,
            virtual_ms: now,
            bytes_to_controller: up,
            bytes_to_host: down,
        };
    }
}

/// Steps at one virtual instant after which a runner declares the engine
/// stuck.
const STUCK_STEPS: u64 = 1_000_000;

/// Virtual time after which a runner declares the engine stuck: two days,
/// far beyond the slowest fault class of the suite (about 11 hours).
const MAX_VIRTUAL_MS: u32 = 48 * 3_600_000;

/// Outcome of a simulated read-back.
#[derive(Debug)]
pub struct ReadRun {
    /// The records delivered, in delivery order.
    pub records: Vec<PositionRecord>,
    /// How it ended.
    pub result: Result<ReadBackStats, TransferError>,
    /// Virtual milliseconds elapsed.
    pub virtual_ms: u32,
}

/// Drives a read-back against the simulator on a virtual clock.
pub fn read_back<const N: usize>(rb: &mut ReadBack<N>, sim: &mut Simulator) -> ReadRun {
    read_back_line(rb, sim, 0, 0)
}

/// Like [`read_back`], on a line of `baud`, resuming at most
/// `max_resumes` times after a failure.
pub fn read_back_line<const N: usize>(
    rb: &mut ReadBack<N>,
    sim: &mut Simulator,
    max_resumes: u32,
    baud: u32,
) -> ReadRun {
    let mut now = 0u32;
    let mut resumes = 0;
    let mut records = Vec::new();
    let mut pending: Vec<u8> = Vec::new();
    loop {
        let reply = sim.take_output(now);
        now += wire_ms(reply.len(), baud);
        pending.extend(reply);
        if !pending.is_empty() {
            let used = rb.received_all(&pending, now);
            pending.drain(..used);
        }
        let result = match rb.poll(now) {
            ReadStep::Transmit(q) => {
                let q = q.to_vec();
                now += wire_ms(q.len(), baud);
                sim.receive(&q, now);
                rb.sent(now);
                continue;
            }
            ReadStep::WaitUntil(t) => {
                now = next_tick(sim, now, t);
                continue;
            }
            ReadStep::Records(recs) => {
                records.extend(recs);
                continue;
            }
            ReadStep::Complete(s) => Ok(s),
            ReadStep::Failed(_) if resumes < max_resumes => {
                resumes += 1;
                rb.resume(now);
                continue;
            }
            ReadStep::Failed(e) => Err(e),
        };
        return ReadRun {
            records,
            result,
            virtual_ms: now,
        };
    }
}

/// Runs one request of `client` against `sim` from tick `now`; returns how
/// it ended and the tick it ended at.
pub fn call<'a, R: Request<'a>, const C: usize, const P: usize>(
    client: &mut Client<C, P>,
    sim: &mut Simulator,
    req: &R,
    mut now: u32,
) -> (Result<Outcome, iai_protocol_b::client::CallError>, u32) {
    client
        .start(req, now)
        .expect("the request fits the command buffer");
    loop {
        let reply = sim.take_output(now);
        if !reply.is_empty() {
            client.received_all(&reply, now);
        }
        match client.poll(now) {
            ClientStep::Transmit(bytes) => {
                let bytes = bytes.to_vec();
                sim.receive(&bytes, now);
                client.sent(now);
            }
            ClientStep::WaitUntil(t) => now = next_tick(sim, now, t),
            ClientStep::Done(r) => return (r, now),
            ClientStep::Idle => panic!("the client lost its request"),
        }
    }
}
