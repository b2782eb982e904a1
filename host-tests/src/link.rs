//! Runs the core's transfer engine against the simulator on a virtual
//! clock: a 1.6 MB table with 3-second timeouts takes seconds of real time.

use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::transfer::{RecordSource, Step, Transfer, TransferError, TransferStats};

use crate::sim::Simulator;

/// Outcome of a simulated transfer.
#[derive(Debug)]
pub struct LinkRun {
    /// How the transfer ended.
    pub result: Result<TransferStats, TransferError>,
    /// Virtual milliseconds elapsed.
    pub virtual_ms: u32,
    /// Bytes host → controller.
    pub bytes_to_controller: u64,
    /// Bytes controller → host.
    pub bytes_to_host: u64,
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

/// Like [`run`], calling `feed` with the transfer's source at every step
/// (e.g. to push records into a `RecordQueue` as they "arrive").
pub fn run_fed<I, const N: usize>(
    t: &mut Transfer<I, N>,
    sim: &mut Simulator,
    max_resumes: u32,
    mut feed: impl FnMut(&mut I),
) -> LinkRun
where
    I: RecordSource,
{
    let mut now: u32 = 0;
    let mut resumes = 0;
    let (mut up, mut down) = (0u64, 0u64);
    loop {
        feed(t.source_mut());
        let reply = sim.take_output(now);
        if !reply.is_empty() {
            down += reply.len() as u64;
            t.received(&reply, now);
        }
        match t.poll(now) {
            Step::Transmit(bytes) => {
                up += bytes.len() as u64;
                let bytes = bytes.to_vec();
                sim.receive(&bytes, now);
                t.sent(now);
            }
            Step::WaitUntil(deadline) => {
                // Jump to whichever comes first: a reply or the deadline.
                let next = sim.next_output_at().map_or(deadline, |r| r.min(deadline));
                now = next.max(now + 1);
            }
            Step::NeedRecords => now += 1,
            Step::Complete(stats) => {
                return LinkRun {
                    result: Ok(stats),
                    virtual_ms: now,
                    bytes_to_controller: up,
                    bytes_to_host: down,
                }
            }
            Step::Failed(e) => {
                if resumes >= max_resumes {
                    return LinkRun {
                        result: Err(e),
                        virtual_ms: now,
                        bytes_to_controller: up,
                        bytes_to_host: down,
                    };
                }
                resumes += 1;
                t.resume(now);
            }
        }
    }
}
