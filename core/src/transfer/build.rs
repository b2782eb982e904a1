//! Packing records into the frame buffer, and choosing how many of them
//! the next frame carries: as many as fit, but never a count that a reply
//! which may still arrive could confirm (the line's ledger says which).

use super::source::{Pull, RecordSource};
use super::verify::Walk;
use super::{Chunk, Resume, State, Transfer};
use crate::error::{Error, Failure};
use crate::field::{move_within, Writer};
use crate::frame::{emit_envelope, emit_trailer, Header, ENVELOPE_LEN, TRAILER_LEN};
use crate::line::{Line, Span};

/// What [`Transfer::build`] achieved.
pub(super) enum Built {
    Ready,
    Pending,
    Exhausted,
    /// Every count that fits could still be confirmed by a copy until this
    /// tick.
    Wait(u32),
}

impl<I: RecordSource, const N: usize> Transfer<I, N> {
    /// Takes the next record: the held-back one first, then the source.
    fn pull(&mut self) -> Pull {
        if let Some(r) = self.held.take() {
            return Pull::Record(r);
        }
        if self.source_done {
            return Pull::End;
        }
        let p = self.source.pull();
        if p == Pull::End {
            self.source_done = true;
        }
        p
    }

    /// Packs records until the frame is full or the source ends, then
    /// chooses how many go in this frame and closes it.
    pub(super) fn build(&mut self, line: &mut Line, now: u32) -> Result<Built, Failure> {
        let cfg = self.cfg;
        let stream = cfg.stream;
        let limit = cfg.max_frame.min(N);
        let records_start = ENVELOPE_LEN + stream.prefix_len();
        let first_index = self.stats.records_confirmed;
        let start = u32::from(cfg.start) + first_index;
        let max_records = stream.max_records.min(self.frame_limit);
        if self.fill < records_start {
            // Begin a frame only when a record is there for it: a table that
            // ends at the top of a range write's start field must complete.
            match self.pull() {
                Pull::Record(r) => self.held = Some(r),
                Pull::Pending => return Ok(Built::Pending),
                Pull::End => return Ok(Built::Exhausted),
            }
            self.fill = records_start;
            self.packed = 0;
        }
        while self.packed < max_records {
            let rec = match self.pull() {
                Pull::Record(r) => r,
                Pull::Pending => return Ok(Built::Pending),
                Pull::End => break,
            };
            let index = first_index + u32::from(self.packed);
            // In a range write record i is position start + i: a number the
            // start field must be able to express.
            if stream.start_width > 0
                && u64::from(cfg.start) + u64::from(index) > stream.start_field().max_unsigned()
            {
                self.held = Some(rec);
                if self.packed == 0 {
                    self.fill = 0;
                    return Err(Failure::Protocol(Error::ValueOutOfRange {
                        offset: ENVELOPE_LEN,
                    }));
                }
                break;
            }
            let len = stream.layout.record_len(rec.axes.count());
            if self.fill + len + TRAILER_LEN > limit {
                self.held = Some(rec);
                if self.packed == 0 {
                    self.fill = 0;
                    return Err(Failure::Protocol(Error::BufferTooSmall));
                }
                break;
            }
            let mut w = Writer::resume(self.frame.buffer(), self.fill);
            if let Err(error) = stream.layout.write_record(&rec, &mut w) {
                return Err(Failure::InvalidRecord { index, error });
            }
            self.fill = w.len();
            self.packed += 1;
        }
        if self.packed == 0 {
            self.fill = 0;
            return Ok(Built::Exhausted);
        }
        let n = match self.count_at_most(line, self.packed, now) {
            Ok(n) => n,
            Err(wake) => return Ok(Built::Wait(wake)),
        };
        if n < self.packed {
            self.stats.guarded_frames += 1;
        }
        let start = u16::try_from(start).map_err(|_| {
            Failure::Protocol(Error::ValueOutOfRange {
                offset: ENVELOPE_LEN,
            })
        })?;
        let (cut, saved) = self.close_frame(line, n, start)?;
        self.chunk = Some(Chunk {
            records: n,
            cut,
            saved,
            start,
            faulted: core::mem::take(&mut self.pending_fault),
            provable: false,
        });
        Ok(Built::Ready)
    }

    /// The most records, at most `most`, that no reply which may still
    /// arrive could confirm; or, if every count could be, the first tick at
    /// which one frees up.
    fn count_at_most(&self, line: &mut Line, most: u16, now: u32) -> Result<u16, u32> {
        let id = self.cfg.stream.id;
        let mut wake: Option<u32> = None;
        for n in (1..=most).rev() {
            let at = line.clear_at(id, Span::one(n), self.cfg.write_claim(), now);
            if at == now {
                return Ok(n);
            }
            wake = Some(match wake {
                Some(w) if w.wrapping_sub(now) <= at.wrapping_sub(now) => w,
                _ => at,
            });
        }
        Err(wake.unwrap_or(now.wrapping_add(1)))
    }

    /// Closes the frame after its first `n` packed records: envelope and
    /// prefix with that count, the trailer after the `n`-th record. Returns
    /// where the trailer starts and the bytes it covers.
    fn close_frame(
        &mut self,
        line: &Line,
        n: u16,
        start: u16,
    ) -> Result<(usize, [u8; TRAILER_LEN]), Failure> {
        let stream = self.cfg.stream;
        let (station, checksum) = (line.config().station, line.config().checksum);
        let cut = {
            let mut walk = Walk {
                bytes: self.frame.buffer().get(..self.fill).unwrap_or(&[]),
                at: ENVELOPE_LEN + stream.prefix_len(),
                stream,
            };
            for _ in 0..n {
                walk.next();
            }
            walk.at
        };
        let mut saved = [0u8; TRAILER_LEN];
        if let Some(src) = self.frame.buffer().get(cut..cut + TRAILER_LEN) {
            saved.copy_from_slice(src);
        }
        let mut w = Writer::new(self.frame.buffer());
        emit_envelope(&mut w, Header::Command, station, stream.id)
            .and_then(|()| stream.write_prefix(&mut w, start, n))
            .map_err(Failure::Protocol)?;
        let mut w = Writer::resume(self.frame.buffer(), cut);
        emit_trailer(&mut w, checksum).map_err(Failure::Protocol)?;
        Ok((cut, saved))
    }

    /// The frame in flight timed out: send its first half instead (a long
    /// frame is more likely hit by noise) and keep frames that small until
    /// they get through again. The rest is carried to the next frame; the
    /// count still avoids those a copy could carry.
    pub(super) fn shrink_chunk(&mut self, line: &mut Line, now: u32) {
        let Some(c) = self.chunk else { return };
        let Ok(n) = self.count_at_most(line, c.records / 2, now) else {
            return;
        };
        if let Some(dst) = self.frame.buffer().get_mut(c.cut..c.cut + TRAILER_LEN) {
            dst.copy_from_slice(&c.saved);
        }
        match self.close_frame(line, n, c.start) {
            Ok((cut, saved)) => {
                self.chunk = Some(Chunk {
                    records: n,
                    cut,
                    saved,
                    ..c
                });
                line.accept(Span::one(n));
                self.frame_limit = n;
                self.stats.shrunk_frames += 1;
            }
            Err(e) => self.state = State::Failed(e, Resume::Nothing),
        }
    }

    /// The frame is done: restore what its trailer covered, carry the
    /// records it did not take to the front.
    pub(super) fn finish_chunk(&mut self) {
        if let Some(c) = self.chunk.take() {
            self.stats.records_confirmed += u32::from(c.records);
            let records_start = ENVELOPE_LEN + self.cfg.stream.prefix_len();
            let buf = self.frame.buffer();
            if let Some(dst) = buf.get_mut(c.cut..c.cut + TRAILER_LEN) {
                dst.copy_from_slice(&c.saved);
            }
            let carried = self.fill.saturating_sub(c.cut);
            // Both ranges lie inside the frame buffer: the chunk was built there.
            let _ = move_within(buf, c.cut, carried, records_start);
            self.packed = self.packed.saturating_sub(c.records);
            self.fill = if self.packed > 0 {
                records_start + carried
            } else {
                0
            };
        }
        self.state = State::Build;
    }
}
