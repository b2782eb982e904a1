//! The 26DH path: the host's stream decoded record by record into a
//! bounded queue, written by the core's transfer engine in controller-sized
//! chunks, each confirmed and **read back (21FH) and compared record by
//! record before more is taken from the host** ([`Verify::Full`]); a chunk
//! that reads back different is rewritten, twice at most. While the queue
//! is full the bridge stops reading the host; its receive ring then fills
//! and flow control stops the host ([`crate::serial`]). The host's last
//! record waits for the upstream checksum, so a 26DH whose checksum fails
//! never completes a write. At the end, one `#` with the count.
//!
//! [`Verify::Full`]: iai_protocol_b::transfer::Verify::Full

use iai_protocol_b::axis::MAX_AXES;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::clock::reached;
use iai_protocol_b::decoder::Status;
use iai_protocol_b::engine::Turn;
use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::table::{PositionStreamDecoder, StreamEvent};
use iai_protocol_b::{error::Failure, profile::Profile, transfer::TransferConfig};

use super::pipeline::{pipeline, Pipeline, END_PHASE_RECORDS};
use super::upstream::Up;
use super::{Bridge, Error, Job, Mode, Port, UPSTREAM_STALL_MS};
use crate::codes;
use crate::log;
use crate::serial::Counted;

/// The 26DH state beside the transfer: the upstream decoder.
pub(super) struct StreamWork {
    decoder: PositionStreamDecoder,
    /// The transfer was restarted for this 26DH (its count is known).
    pub(super) started: bool,
    /// The host's last record, held back until its checksum is known: a
    /// 26DH whose checksum fails never completes a write.
    last: Option<PositionRecord>,
    /// Chunk and queue sizes for the downstream rate.
    pipeline: Pipeline,
}

impl StreamWork {
    #[inline(always)]
    pub(super) const fn new(downstream_baud: u32) -> Self {
        StreamWork {
            decoder: PositionStreamDecoder::new(BypassPolicy::CommandsOnly),
            started: false,
            last: None,
            pipeline: pipeline(downstream_baud),
        }
    }
}

impl Bridge {
    /// A 26DH begins: the envelope goes to the stream decoder.
    pub(super) fn start_stream(&mut self, station: Station, now: u32) {
        let work = &mut self.stream;
        work.decoder = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
        for &b in &self.up.head {
            // The envelope alone never completes an event.
            let _ = work.decoder.push(b);
        }
        work.started = false;
        work.last = None;
        work.pipeline = pipeline(self.cfg.downstream_baud);
        self.stream_deadline = None;
        self.tx_blocked = false;
        self.mode = Mode::Stream {
            station,
            upstream_done: false,
            abort: None,
            waiting_since: now,
        };
        log::info!("26DH stream for station {=u8:02X}", station.0);
    }

    /// Whether the 26DH buffer holds all the records the pipeline allows
    /// (see [`pipeline`]): the bridge then stops reading the host. Before
    /// the end phase, as many as fit (room for an 8-axis record is kept);
    /// in it, [`Pipeline::queued_records`].
    pub(super) fn queue_full(&mut self) -> bool {
        if !self.stream.started {
            return false;
        }
        let decoder = &self.stream.decoder;
        let to_come = decoder
            .records_announced()
            .saturating_sub(decoder.records_done());
        let limit = if to_come > END_PHASE_RECORDS {
            usize::MAX
        } else {
            self.stream.pipeline.queued_records
        };
        let q = self.job.source_mut();
        !q.fits(MAX_AXES) || q.len() >= limit
    }

    /// The 26DH mode: decode upstream bytes into the queue, drive the
    /// transfer, answer once at the end.
    pub(super) fn poll_stream<U: Port, D: Port>(
        &mut self,
        up: &mut U,
        down: &mut D,
        now: u32,
    ) -> Result<bool, Error<U::Error, D::Error>> {
        let Mode::Stream {
            station,
            mut upstream_done,
            mut abort,
            mut waiting_since,
        } = self.mode
        else {
            return Ok(false);
        };
        let mut moved = false;

        // Upstream: decode while the queue has room.
        while !upstream_done && abort.is_none() {
            if self.queue_full() {
                waiting_since = now;
                break;
            }
            let b = match self.next_up(up).map_err(Error::Upstream)? {
                Up::Byte(b) => b,
                Up::Lost => {
                    log::warning!("26DH: upstream bytes lost");
                    abort = Some(codes::UPSTREAM_OVERRUN);
                    moved = true;
                    break;
                }
                Up::Empty => {
                    if reached(now, waiting_since.wrapping_add(UPSTREAM_STALL_MS)) {
                        log::warning!("26DH stalled upstream");
                        abort = Some(codes::UPSTREAM_STALLED);
                    }
                    break;
                }
            };
            moved = true;
            waiting_since = now;
            let work = &mut self.stream;
            let Status::Complete(event) = work.decoder.push(b) else {
                continue;
            };
            match event {
                StreamEvent::Start {
                    station: s, count, ..
                } => {
                    log::info!("26DH: {=u16} records", count);
                    let _ = s;
                    let cfg = TransferConfig {
                        max_records: work.pipeline.chunk_records,
                        ..TransferConfig::new(Profile::TTA)
                    };
                    // In place: a transfer is about 3 KB.
                    self.job.source_mut().clear();
                    self.job.restart(cfg);
                    self.job.set_total(u32::from(count));
                    work.started = true;
                }
                StreamEvent::Record(rec) => {
                    if work.decoder.records_done() == work.decoder.records_announced() {
                        // The last record waits for the checksum.
                        work.last = Some(rec);
                    } else {
                        let pushed = work.started && enqueue(&mut self.job, rec).is_ok();
                        if !pushed {
                            // Cannot happen: the queue had room.
                            abort = Some(codes::INTERNAL);
                        }
                    }
                }
                StreamEvent::End { records: _records } => {
                    log::info!("26DH upstream ended well: {=u16} records", _records);
                    upstream_done = true;
                }
                StreamEvent::Error {
                    error: _error,
                    records_ok: _ok,
                } => {
                    log::warning!("26DH upstream broken after {=u16} records: {}", _ok, _error);
                    abort = Some(codes::UPSTREAM_FRAME);
                }
            }
        }

        // The checksum was right: the held-back record may go, and the
        // transfer learns that no more come.
        if upstream_done && self.stream.started {
            let (job, last) = (&mut self.job, &mut self.stream.last);
            if let Some(rec) = last.take() {
                if let Err(rec) = enqueue(job, rec) {
                    *last = Some(rec);
                }
            }
            if last.is_none() {
                job.source_mut().finish();
            }
        }

        // Downstream: the transfer.
        let mut answer: Option<Result<u16, u16>> = None;
        self.tx_blocked = false;
        self.stream_deadline = None;
        let was_full = self.queue_full();
        if self.guest_holds {
            // The guest finishes its exchange first.
        } else if self.stream.started {
            let (job, line) = (&mut self.job, &mut self.line);
            if abort.is_some() && !self.driver.writing() {
                // Nothing half sent: stop here (what is in flight is the
                // line's to remember).
                answer = abort.map(Err);
            } else {
                let (din, dout) = (
                    &mut self.stats.downstream_in,
                    &mut self.stats.downstream_out,
                );
                let mut port = Counted::new(down, din, dout);
                let mut clock = || now;
                match self.driver.turn(job, line, &mut port, &mut clock) {
                    Err(e) => return Err(Error::Downstream(e)),
                    Ok(Turn::Busy) => moved = true,
                    Ok(Turn::Wait { until, write }) => {
                        self.stream_deadline = until;
                        self.tx_blocked = write;
                    }
                    Ok(Turn::Done(Ok(_verified))) => {
                        // Every chunk was read back and compared equal.
                        answer = Some(Ok(job.stats().records_confirmed as u16));
                    }
                    Ok(Turn::Done(Err(e))) => {
                        log::warning!("26DH transfer failed: {}", e);
                        answer = Some(Err(match e {
                            Failure::Timeout { .. } => codes::CONTROLLER_TIMEOUT,
                            // The controller's own code goes up as it is:
                            // the host can ask it for the 216H detail.
                            Failure::Controller { code, .. } => code,
                            // A record read back different, or not where it
                            // was written: the host must write again.
                            Failure::Mismatch { .. } | Failure::Misplaced { .. } => {
                                codes::VERIFY_MISMATCH
                            }
                            _ => codes::INTERNAL,
                        }));
                    }
                }
            }
            if answer.is_some() {
                let s = job.stats();
                self.stats.records += s.records_confirmed;
                self.stats.chunks_sent += s.frames_sent;
                self.stats.retries += s.retries;
                self.stats.chunk_timeouts += s.timeouts;
                self.stats.chunk_error_replies += s.error_replies;
            }
        } else {
            moved |= self
                .drain_downstream(down, now)
                .map_err(Error::Downstream)?;
            if abort.is_some() {
                answer = abort.map(Err);
            }
        }

        if was_full && !self.queue_full() {
            // The transfer took records: the upstream may be read again.
            moved = true;
        }
        self.mode = Mode::Stream {
            station,
            upstream_done,
            abort,
            waiting_since,
        };
        match answer {
            Some(Ok(count)) => {
                self.stats.streams_ok += 1;
                self.respond_count(station, count);
                moved = true;
            }
            Some(Err(code)) => {
                self.stats.streams_failed += 1;
                self.respond_error(station, code, now);
                moved = true;
            }
            None => {}
        }
        Ok(moved)
    }
}

/// Appends `rec` to the 26DH transfer's queue; gives it back if the queue
/// is full. Not inlined: inlined, the move of the held-back record (which
/// lives beside the queue) becomes a `memmove`, which costs 1.6 KB of
/// flash that nothing else needs.
#[inline(never)]
fn enqueue(job: &mut Job, rec: PositionRecord) -> Result<(), PositionRecord> {
    job.source_mut().push(rec)
}
