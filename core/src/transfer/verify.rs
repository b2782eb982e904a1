//! The read-back of a confirmed frame: windows of its positions queried
//! (21FH, 22DH or 209H, planned as the read-back engine's are), each reply compared
//! record by record with the frame as it streams in, and the verdict.
//!
//! A comparison counts only when the reply's SC, station and ID check out
//! and the line takes it as the answer: a read-back reply carries nothing
//! that ties it to its query, so the line sends the query only when no
//! copy of an earlier reply that could pass for it may still arrive (the
//! same window read again after a rewrite, or positions written twice).
//! What is compared: every field the write sends. A record sent twice in
//! one frame is compared against its last copy.

use super::source::RecordSource;
use super::{Resume, State, Transfer, TransferConfig};
use crate::checksum::BypassPolicy;
use crate::decoder::Status;
use crate::error::Failure;
use crate::field::{FieldSpec, Reader};
use crate::frame::{Header, Station, ENVELOPE_LEN};
use crate::line::{fingerprint_more, Claim, Command, Heard, Line, Span, Verdict};
use crate::position::{PositionRecord, PositionStream};
use crate::table::{PositionStreamDecoder, StreamEvent};
use crate::window::{write_query, Windows, QUERY_LEN};

/// The read-back of the frame in flight.
#[derive(Debug, Clone)]
pub(super) struct Verifier {
    pub(super) stream: PositionStream,
    decoder: PositionStreamDecoder,
    /// After a frame ended or broke: waiting for the next header byte.
    pub(super) hunting: bool,
    query: [u8; QUERY_LEN],
    query_len: usize,
    head: u16,
    asked: u16,
    windows: Windows,
    /// Records of the frame compared (or superseded by a later copy).
    checked: u128,
    /// Records of the frame found different or missing.
    pub(super) differ: u128,
    /// Records of the frame a reply of their window lacked altogether.
    missing: u128,
    /// Missing records were read a second time for this write.
    rechecked: bool,
    /// The first position whose record a read-back did not find: it went
    /// elsewhere ([`Failure::Misplaced`]).
    pub(super) misplaced: Option<u16>,
    /// For the reply being decoded: records of the frame it carried, equal
    /// or not.
    present: u128,
    /// For the reply being decoded: records found equal so far, and the
    /// lowest and highest position it carried.
    seen: u128,
    carried: Span,
    /// Whether the reply being decoded can still be the awaited one.
    candidate: bool,
    /// Whether the frame being decoded is a read-back reply from the
    /// station (so that breaking means the reply was lost).
    started: bool,
    /// The fingerprint of the frame's bytes so far.
    print: u32,
    station: Station,
    pub(super) rewrites: u8,
}

impl Verifier {
    pub(super) const fn new(cfg: &TransferConfig) -> Self {
        let stream = cfg.stream.read_back();
        Verifier {
            stream,
            decoder: PositionStreamDecoder::new(BypassPolicy::Reject),
            hunting: true,
            query: [0; QUERY_LEN],
            query_len: 0,
            head: 0,
            asked: 0,
            windows: Windows::new(stream.window(cfg.max_response)),
            checked: 0,
            differ: 0,
            missing: 0,
            rechecked: false,
            misplaced: None,
            present: 0,
            seen: 0,
            carried: Span::UNKNOWN,
            candidate: false,
            started: false,
            print: crate::line::FINGERPRINT_START,
            station: Station(0),
            rewrites: 0,
        }
    }

    /// The query in flight.
    pub(super) fn query(&self) -> &[u8] {
        self.query.get(..self.query_len).unwrap_or(&[])
    }

    /// The positions the query in flight asks for.
    fn window(&self) -> Span {
        Span {
            lo: self.head,
            hi: self.head.saturating_add(self.asked.saturating_sub(1)),
        }
    }
}

/// The records of a frame, walked from their wire bytes.
pub(super) struct Walk<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) at: usize,
    pub(super) stream: PositionStream,
}

impl<'a> Iterator for Walk<'a> {
    type Item = &'a [u8];
    fn next(&mut self) -> Option<&'a [u8]> {
        let rest = self.bytes.get(self.at..)?;
        let len = self.stream.layout.record_len_at(rest)?;
        let rec = rest.get(..len)?;
        self.at += len;
        Some(rec)
    }
}

fn bit(i: usize) -> u128 {
    1u128.checked_shl(i as u32).unwrap_or(0)
}

impl<I: RecordSource, const N: usize> Transfer<I, N> {
    fn walk(&self) -> Walk<'_> {
        let records_start = ENVELOPE_LEN + self.cfg.stream.prefix_len();
        let cut = self.chunk.map_or(records_start, |c| c.cut);
        Walk {
            bytes: self.frame.buffer_ref().get(..cut).unwrap_or(&[]),
            at: records_start,
            stream: self.cfg.stream,
        }
    }

    /// The position numbers of the chunk's records, in order.
    fn chunk_numbers(&self) -> impl Iterator<Item = u16> + '_ {
        let start = self.chunk.map_or(0, |c| c.start);
        let layout = self.cfg.stream.layout;
        self.walk().enumerate().map(move |(i, rec)| {
            if layout.number_width == 0 {
                start.wrapping_add(i as u16)
            } else {
                let digits = rec.get(..usize::from(layout.number_width)).unwrap_or(&[]);
                let spec = FieldSpec::hex(layout.number_width);
                crate::field::decode_unsigned(spec, digits, 0).map_or(0, |n| n as u16)
            }
        })
    }

    /// Positions of the chunk found different or missing.
    pub(super) fn differing(&self) -> impl Iterator<Item = u16> + '_ {
        let differ = self.verifier.differ;
        self.chunk_numbers()
            .enumerate()
            .filter(move |(i, _)| differ & bit(*i) != 0)
            .map(|(_, n)| n)
    }

    /// A read-back of the chunk begins: records a later copy in the same
    /// chunk replaces need no comparison.
    pub(super) fn begin_verify(&mut self) {
        let mut superseded = 0u128;
        for (i, n) in self.chunk_numbers().enumerate() {
            if self.chunk_numbers().skip(i + 1).any(|m| m == n) {
                superseded |= bit(i);
            }
        }
        self.verifier.checked = superseded;
        self.verifier.differ = 0;
        self.verifier.missing = 0;
        self.verifier.rechecked = false;
    }

    /// Starts the query for the next window of unchecked records, or gives
    /// the chunk's verdict.
    pub(super) fn start_verify(&mut self, line: &mut Line, now: u32) {
        let all = self.chunk.map_or(0, |c| c.records);
        let all_mask = if all >= 128 {
            u128::MAX
        } else {
            bit(usize::from(all)) - 1
        };
        let checked = self.verifier.checked;
        let unchecked = || {
            self.chunk_numbers()
                .enumerate()
                .filter(move |(i, _)| checked & bit(*i) == 0)
                .map(|(_, n)| n)
        };
        let (Some(head), Some(highest)) = (unchecked().min(), unchecked().max()) else {
            self.verdict(line, now, all_mask);
            return;
        };
        let v = &mut self.verifier;
        let field_max = v.stream.count_field().max_unsigned();
        let room = field_max.saturating_add(1).saturating_sub(u64::from(head));
        // No further than the chunk's highest unchecked position: what lies
        // beyond it was not written by this frame.
        let left = (u64::from(highest - head) + 1).min(room);
        v.head = head;
        v.asked = v.windows.span(left as u32);
        if self.write_query(line).is_err() {
            return;
        }
        let cmd = Command::of(
            self.verifier.stream.id,
            self.verifier.window(),
            Claim::Proof,
            line.config().max_sends,
        );
        line.begin(cmd, now);
        self.state = State::Verify;
    }

    /// Writes the read-back query for the verifier's window.
    fn write_query(&mut self, line: &Line) -> Result<(), ()> {
        let (station, checksum) = (line.config().station, line.config().checksum);
        let v = &mut self.verifier;
        match write_query(v.stream, station, checksum, v.head, v.asked, &mut v.query) {
            Ok(n) => {
                v.query_len = n;
                Ok(())
            }
            Err(e) => {
                self.state = State::Failed(Failure::Protocol(e), Resume::Nothing);
                Err(())
            }
        }
    }

    fn verdict(&mut self, line: &mut Line, now: u32, all: u128) {
        let differ = self.verifier.differ & all;
        let missing = self.verifier.missing & all;
        let provable = self.chunk.is_some_and(|c| c.provable);
        if missing != 0 && provable && !self.verifier.rechecked {
            // Before concluding, those records' windows are read once more:
            // a query hit on the way (a shorter count) reads fewer.
            self.verifier.rechecked = true;
            self.verifier.checked &= !missing;
            self.verifier.differ &= !missing;
            self.verifier.missing = 0;
            self.start_verify(line, now);
            return;
        }
        if missing != 0 && provable {
            // The controller took the whole frame (its own reply said so)
            // yet a record is twice not at its number: it was stored at
            // another. The frame is rewritten, but what the stray record
            // overwrote is not known.
            self.stats.misplaced += missing.count_ones();
            if self.verifier.misplaced.is_none() {
                let first = self.chunk_numbers().nth(missing.trailing_zeros() as usize);
                self.verifier.misplaced = first;
            }
        }
        if differ == 0 {
            self.stats.frames_verified += 1;
            self.stats.records_verified += u32::from(self.chunk.map_or(0, |c| c.records));
            self.verifier.rewrites = 0;
            self.finish_chunk();
            return;
        }
        if self.verifier.rewrites < self.cfg.rewrites {
            self.verifier.rewrites += 1;
            self.stats.rewrites += 1;
            self.start_write(line, now);
            return;
        }
        let first_position = self.differing().next().unwrap_or(0);
        self.state = State::Failed(
            Failure::Mismatch {
                first_position,
                records: differ.count_ones() as u16,
            },
            Resume::Write,
        );
    }

    /// A read-back window was answered (and compared): let the windows
    /// grow back, ask the next.
    pub(super) fn window_answered(&mut self, line: &mut Line, now: u32) {
        self.verifier.windows.grow();
        self.start_verify(line, now);
    }

    /// A read-back query timed out: ask the same head for half the window.
    /// A late reply to the larger window still answers the smaller one
    /// exactly: it lists every record in it.
    pub(super) fn shrink_window(&mut self, line: &mut Line) {
        let v = &mut self.verifier;
        if v.asked > 1 {
            v.asked = v.windows.shrink(v.asked);
            if self.write_query(line).is_ok() {
                line.accept(self.verifier.window());
            }
        }
    }

    /// One byte in the read-back: the stream decoder compares the reply's
    /// records as they arrive; the comparison counts when the line takes
    /// the reply.
    pub(super) fn verify_byte(&mut self, line: &mut Line, b: u8, now: u32) -> Status<Heard> {
        let verifying = self.state == State::Verify;
        let v = &mut self.verifier;
        if v.hunting {
            if Header::from_byte(b).is_none() {
                return Status::Partial;
            }
            v.decoder.reset();
            v.hunting = false;
            v.candidate = false;
            v.print = crate::line::FINGERPRINT_START;
        }
        v.print = fingerprint_more(v.print, core::slice::from_ref(&b));
        let Status::Complete(event) = v.decoder.push(b) else {
            return Status::Partial;
        };
        match event {
            StreamEvent::Start {
                kind,
                station,
                count,
                ..
            } => {
                v.station = station;
                v.seen = 0;
                v.present = 0;
                v.carried = Span::UNKNOWN;
                // Outside a read-back it answers nothing: it is only heard.
                v.candidate = kind == v.stream && count <= v.asked && verifying;
                v.started = kind == v.stream && station == line.config().station;
                Status::Partial
            }
            StreamEvent::Record(rec) => {
                let v = &mut self.verifier;
                let n = rec.number;
                v.carried = v.carried.holding(n);
                let window = v.window();
                if n < window.lo || n > window.hi {
                    v.candidate = false;
                } else if v.candidate {
                    if let Some((i, same)) = self.matching_record(&rec) {
                        self.verifier.present |= bit(i);
                        if same {
                            self.verifier.seen |= bit(i);
                        }
                    }
                }
                Status::Partial
            }
            StreamEvent::End { .. } => {
                v.hunting = true;
                v.started = false;
                let (station, id, print) = (v.station, v.stream.id, v.print);
                let verdict = Verdict {
                    fits: v.candidate,
                    values: v.carried,
                    keep: false,
                };
                let heard = line.hear(Header::Response, station, id, None, verdict, print, now);
                match heard {
                    Heard::Answer => self.commit_window(),
                    // A reply to another window, or one that came early.
                    Heard::Mismatch | Heard::Stale | Heard::Unplaced => {
                        self.stats.stale_replies += 1
                    }
                    _ => self.judged(heard),
                }
                Status::Complete(heard)
            }
            StreamEvent::Error { .. } => {
                v.hunting = true;
                if core::mem::take(&mut v.started) {
                    // A read-back reply from the station, broken.
                    let station = v.station;
                    line.broken(Some((Header::Response, station, v.stream.id)), now);
                }
                let v = &mut self.verifier;
                if Header::from_byte(b).is_some() {
                    v.decoder.reset();
                    v.hunting = false;
                    v.print = fingerprint_more(crate::line::FINGERPRINT_START, &[b]);
                    let _ = v.decoder.push(b);
                }
                Status::Partial
            }
        }
    }

    /// Before a send at `now`: a read-back reply half streamed by is
    /// dropped; a copy of it may still come whole.
    pub(super) fn drop_read_back(&mut self, line: &mut Line, now: u32) {
        let v = &mut self.verifier;
        v.hunting = true;
        if core::mem::take(&mut v.started) {
            line.broken(Some((Header::Response, v.station, v.stream.id)), now);
        }
    }

    /// The index of the chunk record `rec` should equal, if the chunk has
    /// its number, and whether it does.
    fn matching_record(&self, rec: &PositionRecord) -> Option<(usize, bool)> {
        let last = self
            .chunk_numbers()
            .enumerate()
            .filter(|&(_, n)| n == rec.number)
            .map(|(i, _)| i)
            .last()?;
        let Some(bytes) = self.walk().nth(last) else {
            return Some((last, false));
        };
        let mut r = Reader::new(bytes, 0);
        let Ok(mut mine) = self.cfg.stream.layout.read_record(&mut r) else {
            return Some((last, false));
        };
        mine.number = rec.number;
        let extended_ok = !self.cfg.stream.layout.extended || mine.extended == rec.extended;
        let same = mine.axes == rec.axes
            && mine.acceleration == rec.acceleration
            && mine.deceleration == rec.deceleration
            && mine.speed == rec.speed
            && mine.positions == rec.positions
            && extended_ok;
        Some((last, same))
    }

    /// The window's reply was taken: its records are checked, those of the
    /// window it did not hold (or held different) differ.
    fn commit_window(&mut self) {
        let window = self.verifier.window();
        let (seen, present) = (self.verifier.seen, self.verifier.present);
        let mut checked = self.verifier.checked;
        let mut differ = self.verifier.differ;
        let mut missing = self.verifier.missing;
        for (i, n) in self.chunk_numbers().enumerate() {
            let m = bit(i);
            if checked & m != 0 || n < window.lo || n > window.hi {
                continue;
            }
            checked |= m;
            if seen & m == 0 {
                differ |= m;
            }
            if present & m == 0 {
                missing |= m;
            }
        }
        self.verifier.checked = checked;
        self.verifier.differ = differ;
        self.verifier.missing = missing;
    }
}
