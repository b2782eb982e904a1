//! How much of a 26DH the bridge holds between the host and the
//! controller: chunk and queue sizes for the downstream rate, so that what
//! is left when the host's last byte arrives can be written and read back
//! before the host's reply timeout (3 s after its last byte, 2003 p. 62).
//!
//! Two phases. In the middle of a message the buffer holds a whole chunk
//! of the host's records while the controller writes and reads back the
//! chunk before: the host's bytes hide under the downstream time. Once the
//! host has at most [`END_PHASE_RECORDS`] records left to send, the queue
//! is held to [`Pipeline::queued_records`], so that what is left when the
//! last byte arrives fits the budget; that many records cannot all sit in
//! the receive ring, so the host's last byte cannot arrive before the
//! buffer has drained to that size.

use iai_protocol_b::transfer::MAX_FRAME_RECORDS;

use super::{FRAME_CAP, STREAM};
use crate::serial::{self, UPSTREAM_MARKS};

/// Of the host's 3 s for a 26DH reply (counted from the end of its
/// transmission), what the bridge may spend writing and reading back what
/// is left when the host's last byte arrives; the rest is the margin for
/// the controller's processing and the reply's way up.
pub const FINAL_BUDGET_MS: u32 = 2_000;

/// Controller time allowed per command when the 26DH pipeline is sized:
/// its response delay (α, I/O parameter 97, 2003 p. 8) plus the time it
/// takes to store a chunk. Neither manual gives a figure, so this is an
/// **assumption** (the processing time of the host model's tests); a
/// slower controller makes the final reply later by the difference per
/// command.
pub const PROCESSING_ALLOWANCE_MS: u32 = 50;

/// A 26DH command's envelope, count and trailer.
const CHUNK_ENVELOPE_BYTES: u64 = 14;

/// Bytes on the downstream line per chunk besides its records: the 26DH
/// command's envelope, count and trailer, its reply (14), the 21FH query
/// (18) and its reply's envelope, count, start and trailer (18).
const CHUNK_OVERHEAD_BYTES: u64 = CHUNK_ENVELOPE_BYTES + 14 + 18 + 18;

/// Bytes of an 8-axis 26DH record, the longest (TTA p. 60).
const LONGEST_RECORD_BYTES: u64 = 82;

/// Most records queued in the end phase (see [`pipeline`]).
pub const END_QUEUE_RECORDS: usize = 8;

/// Bytes the receive ring may hold when the host stops: its pause mark
/// plus what the host sends after being told.
const RING_BYTES: usize = UPSTREAM_MARKS.pause_at + serial::HOST_LATENCY;

/// Records the host may still have to send when the end phase begins:
/// one more than the shortest records (no axes) that fit `RING_BYTES`
/// (the host ring up to its pause mark, plus what the host sends after
/// the pause).
pub const END_PHASE_RECORDS: u16 = (RING_BYTES / STREAM.layout.record_len(0) + 1) as u16;

/// Fewest records per chunk, whatever the rate: below it the two commands
/// and two replies of each chunk and the controller's time per command
/// outweigh the records (on a line that repeats frames, three also leave
/// the transfer two other counts to choose from).
const MIN_CHUNK_RECORDS: u16 = 3;

/// How much of a 26DH the bridge holds between the host and the
/// controller (see [`pipeline`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pipeline {
    /// Most records per 26DH chunk.
    pub chunk_records: u16,
    /// Most records decoded from the host and waiting for a chunk, in the
    /// end phase (before it, as many as the buffer holds).
    pub queued_records: usize,
}

/// Microseconds `bytes` take at `baud` (8N1).
const fn line_us(bytes: u64, baud: u64) -> u64 {
    bytes * 10_000_000 / baud
}

/// Worst-case time (µs) from the host's last byte to the end of the last
/// chunk's read-back with chunks of `chunk` records and a queue of `queued`
/// at `baud`. Still to be written and read back (each byte crossing the
/// line twice): what the receive ring may hold (up to its pause mark plus
/// the host's latency), the queued records, the held-back last record and
/// a chunk just sent, all of 8-axis records (the longest; a chunk is at
/// most a 2,051-byte frame whatever its records), each chunk with its
/// commands' overhead and [`PROCESSING_ALLOWANCE_MS`] per command.
const fn finish_us(chunk: u64, queued: u64, baud: u64) -> u64 {
    let ring = RING_BYTES as u64;
    let frame_records = (FRAME_CAP as u64 - CHUNK_ENVELOPE_BYTES) / LONGEST_RECORD_BYTES;
    let chunk_bytes = if chunk < frame_records {
        chunk
    } else {
        frame_records
    } * LONGEST_RECORD_BYTES;
    let bytes = ring + (queued + 1) * LONGEST_RECORD_BYTES + chunk_bytes;
    let chunks = bytes.div_ceil(chunk_bytes);
    let per_chunk =
        line_us(CHUNK_OVERHEAD_BYTES, baud) + 2 * 1_000 * PROCESSING_ALLOWANCE_MS as u64;
    2 * line_us(bytes, baud) + chunks * per_chunk
}

/// The largest chunks (then the longest queue) such that, when the host's
/// last byte arrives, what is left can be written and read back within
/// [`FINAL_BUDGET_MS`] at `baud`, in a worst-case model: the receive ring
/// full to its pause mark plus the host's latency, the queue, the held-back
/// record and a chunk just sent, all of 8-axis records, written and read
/// back, with [`PROCESSING_ALLOWANCE_MS`] per command. Chunks of at least
/// three records and a queue of at least one whatever the rate. At 9,600
/// baud: chunks of 5 records and a queue of 1 (1.93 s left at
/// the end, worst case); 19,200: 15 and 1 (1.92 s); from 38,400: chunks
/// as long as a 2,051-byte frame allows (24 8-axis records, more of fewer
/// axes) and the full end-phase queue of [`END_QUEUE_RECORDS`] (1.74 s at 38,400, 0.71 s at
/// 115,200).
pub const fn pipeline(baud: u32) -> Pipeline {
    let baud = if baud == 0 { 1 } else { baud as u64 };
    let budget = FINAL_BUDGET_MS as u64 * 1_000;
    let mut chunk = MAX_FRAME_RECORDS as u64;
    while chunk > MIN_CHUNK_RECORDS as u64 {
        if finish_us(chunk, 1, baud) <= budget {
            break;
        }
        chunk -= 1;
    }
    let mut queued = END_QUEUE_RECORDS as u64;
    while queued > 1 && finish_us(chunk, queued, baud) > budget {
        queued -= 1;
    }
    Pipeline {
        chunk_records: chunk as u16,
        queued_records: queued as usize,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pipeline_fits_the_final_reply_budget() {
        let p = |chunk_records, queued_records| Pipeline {
            chunk_records,
            queued_records,
        };
        assert_eq!(pipeline(9_600), p(5, 1));
        assert_eq!(pipeline(19_200), p(15, 1));
        assert_eq!(pipeline(38_400), p(MAX_FRAME_RECORDS, END_QUEUE_RECORDS));
        assert_eq!(pipeline(u32::MAX), p(MAX_FRAME_RECORDS, END_QUEUE_RECORDS));
        // Too slow for the budget: the smallest pipeline that still runs.
        assert_eq!(pipeline(0), p(MIN_CHUNK_RECORDS, 1));
        assert_eq!(pipeline(1_200), p(MIN_CHUNK_RECORDS, 1));
        for baud in [9_600u32, 19_200, 38_400, 57_600, 115_200, 230_400] {
            let q = pipeline(baud);
            let t = finish_us(
                u64::from(q.chunk_records),
                q.queued_records as u64,
                baud.into(),
            );
            assert!(t <= u64::from(FINAL_BUDGET_MS) * 1_000, "{baud}: {t} us");
        }
    }
}
