//! The read-back of a confirmed frame: windows of the frame's positions
//! queried (21FH, 22DH or 209H), the reply compared record by record with
//! the frame as it streams in, and the verdict (see the module docs of
//! [`crate::transfer`]).

use super::source::RecordSource;
use super::{grow, Resume, State, Transfer, TransferError, TransferEvent};
use crate::catalogue;
use crate::checksum::BypassPolicy;
use crate::clock::{later, passed};
use crate::error::Error;
use crate::exchange::Offer;
use crate::field::{FieldSpec, Reader, Writer};
use crate::frame::{emit_envelope, emit_trailer, Header, Station, ENVELOPE_LEN};
use crate::position::{PositionRecord, PositionStream};
use crate::stream::{PositionStreamDecoder, StreamEvent};

/// The read-back of the frame in flight.
#[derive(Debug, Clone)]
pub(super) struct Verifier {
    pub(super) stream: PositionStream,
    pub(super) decoder: PositionStreamDecoder,
    /// After a frame ended or broke: waiting for the next header byte.
    pub(super) hunting: bool,
    pub(super) query: [u8; 24],
    pub(super) query_len: usize,
    pub(super) head: u16,
    pub(super) asked: u16,
    /// Records of the frame compared (or superseded by a later copy).
    pub(super) checked: u128,
    /// Records of the frame found different or missing.
    pub(super) differ: u128,
    /// For the reply being decoded: records found equal so far.
    pub(super) seen: u128,
    /// Whether the reply being decoded can still be the awaited one.
    pub(super) candidate: bool,
    /// Whether the frame being decoded is a read-back reply from the
    /// station (so that breaking means the reply was lost).
    pub(super) started: bool,
    pub(super) station: Station,
    pub(super) rewrites: u8,
    /// The chunk was written again after some of it was read back: its
    /// read-back queries wait until this tick, when no reply to the
    /// earlier ones can arrive any more (a read-back reply carries nothing
    /// that ties it to one query, so an old reply would pass for the new
    /// state).
    pub(super) hold: Option<u32>,
    /// A read-back query of the chunk in flight was sent.
    pub(super) queried: bool,
}

impl Verifier {
    pub(super) const fn new(stream: PositionStream) -> Self {
        Verifier {
            stream,
            decoder: PositionStreamDecoder::new(BypassPolicy::Reject),
            hunting: true,
            query: [0; 24],
            query_len: 0,
            head: 0,
            asked: 0,
            checked: 0,
            differ: 0,
            seen: 0,
            candidate: false,
            started: false,
            station: Station(0),
            rewrites: 0,
            hold: None,
            queried: false,
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

pub(super) fn bit(i: usize) -> u128 {
    1u128.checked_shl(i as u32).unwrap_or(0)
}

impl<I: RecordSource, const N: usize> Transfer<I, N> {
    /// Records of the chunk that a later copy in the same chunk replaces.
    pub(super) fn superseded(&self) -> u128 {
        let mut mask = 0u128;
        for (i, n) in self.chunk_numbers().enumerate() {
            if self.chunk_numbers().skip(i + 1).any(|m| m == n) {
                mask |= bit(i);
            }
        }
        mask
    }

    pub(super) fn walk(&self) -> Walk<'_> {
        let records_start = ENVELOPE_LEN + self.cfg.stream.prefix_len();
        let cut = self.chunk.map_or(records_start, |c| c.cut);
        Walk {
            bytes: self.frame.get(..cut).unwrap_or(&[]),
            at: records_start,
            stream: self.cfg.stream,
        }
    }

    /// The position numbers of the chunk's records, in order.
    pub(super) fn chunk_numbers(&self) -> impl Iterator<Item = u16> + '_ {
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

    /// Starts the query for the next window of unchecked records, or gives
    /// the chunk's verdict.
    pub(super) fn start_verify(&mut self, now: u32) {
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
            self.verdict(now, all_mask);
            return;
        };
        let v = &mut self.verifier;
        let field_max = v.stream.count_field().max_unsigned();
        let room = field_max.saturating_add(1).saturating_sub(u64::from(head));
        let full = v
            .stream
            .window(self.cfg.max_response)
            .min(self.window_limit);
        // No further than the chunk's highest unchecked position: what lies
        // beyond it was not written by this frame.
        let span = u64::from(highest - head) + 1;
        let window = u64::from(full).min(room).min(span).max(1);
        v.head = head;
        v.asked = window as u16;
        let built = self.write_query();
        let h = self.exchange.horizon();
        let at = match self.verifier.hold {
            Some(t) if !passed(now, t, h) => {
                self.stats.held_queries += 1;
                t
            }
            _ => now,
        };
        // As in `start_write`: the rules, not the entry.
        let id = self.verifier.stream.id;
        match (built, catalogue::request_rules(id)) {
            (Ok(()), Some((resend, reply))) => {
                self.exchange.start_raw(id, resend, reply, at);
                self.verifier.queried = true;
                self.state = State::Verify;
            }
            (Err(e), _) => self.state = State::Failed(TransferError::Config(e), Resume::Nothing),
            (_, None) => {
                self.state = State::Failed(
                    TransferError::Config(Error::UnknownMessageId { id }),
                    Resume::Nothing,
                )
            }
        }
    }

    /// Writes the read-back query for the verifier's window.
    pub(super) fn write_query(&mut self) -> Result<(), Error> {
        let v = &mut self.verifier;
        let mut w = Writer::new(&mut v.query);
        emit_envelope(
            &mut w,
            Header::Command,
            self.cfg.exchange.station,
            v.stream.id,
        )?;
        v.stream.write_query(&mut w, v.head, v.asked)?;
        emit_trailer(&mut w, self.cfg.checksum)?;
        v.query_len = w.len();
        Ok(())
    }

    pub(super) fn verdict(&mut self, now: u32, all: u128) {
        let differ = self.verifier.differ & all;
        if differ == 0 {
            self.stats.frames_verified += 1;
            self.stats.records_verified += u32::from(self.chunk.map_or(0, |c| c.records));
            self.verifier.rewrites = 0;
            self.finish_chunk(now);
            return;
        }
        if self.verifier.rewrites < self.cfg.rewrites {
            self.verifier.rewrites += 1;
            self.stats.rewrites += 1;
            self.start_write(now);
            return;
        }
        let first_position = self.mismatched_positions().next().unwrap_or(0);
        self.state = State::Failed(
            TransferError::Mismatch {
                first_position,
                records: differ.count_ones() as u16,
            },
            Resume::Write,
        );
    }

    /// A read-back window was answered (and compared): let the window
    /// grow back, ask the next.
    pub(super) fn window_answered(&mut self, now: u32) {
        let full = self.verifier.stream.window(self.cfg.max_response);
        self.window_limit = grow(self.window_limit, full);
        self.start_verify(now);
    }

    /// One byte in the read-back: the stream decoder compares the reply's
    /// records as they arrive; the comparison counts when its SC checks.
    pub(super) fn verify_byte(&mut self, b: u8, now: u32) -> TransferEvent {
        let v = &mut self.verifier;
        if v.hunting {
            if Header::from_byte(b).is_none() {
                return TransferEvent::NeedMore;
            }
            v.decoder.reset();
            v.hunting = false;
            v.candidate = false;
        }
        match v.decoder.push(b) {
            StreamEvent::NeedMore => TransferEvent::NeedMore,
            StreamEvent::Start {
                kind,
                station,
                count,
                ..
            } => {
                v.station = station;
                v.seen = 0;
                v.candidate = kind == v.stream && count <= v.asked;
                v.started = kind == v.stream && station == self.cfg.exchange.station;
                TransferEvent::NeedMore
            }
            StreamEvent::Record(rec) => {
                let (head, asked) = (self.verifier.head, self.verifier.asked);
                let inside = u32::from(rec.number) >= u32::from(head)
                    && u32::from(rec.number) < u32::from(head) + u32::from(asked);
                if !inside {
                    self.verifier.candidate = false;
                } else if self.verifier.candidate {
                    if let Some(i) = self.matching_record(&rec) {
                        self.verifier.seen |= bit(i);
                    }
                }
                TransferEvent::NeedMore
            }
            StreamEvent::End { .. } => {
                let v = &mut self.verifier;
                v.hunting = true;
                v.started = false;
                let (station, id, ok) = (v.station, v.stream.id, v.candidate);
                match self
                    .exchange
                    .offer_head(Header::Response, station, id, ok, now)
                {
                    Offer::Accepted => self.commit_window(),
                    // A reply to another window, or one that came early.
                    // A copy of it may follow: the chunk's next read-back
                    // waits until none can come.
                    Offer::Mismatch | Offer::Stale => {
                        self.stats.stale_replies += 1;
                        self.stale_read_back(now);
                        TransferEvent::Stale
                    }
                    other => self.judged(other, 0),
                }
            }
            StreamEvent::Error { .. } => {
                v.hunting = true;
                if core::mem::take(&mut v.started) {
                    if !self.exchange.awaiting() {
                        // A read-back reply, broken, while none is awaited:
                        // a copy of it may follow intact.
                        self.stale_read_back(now);
                    }
                    // The awaited read-back reply arrived broken.
                    self.exchange.reply_lost(now);
                    let v = &mut self.verifier;
                    if Header::from_byte(b).is_some() {
                        v.decoder.reset();
                        v.hunting = false;
                        let _ = v.decoder.push(b);
                    }
                    return TransferEvent::NeedMore;
                }
                if Header::from_byte(b).is_some() {
                    v.decoder.reset();
                    v.hunting = false;
                    let _ = v.decoder.push(b);
                }
                TransferEvent::NeedMore
            }
        }
    }

    /// A read-back reply (whole or broken) came that answers no query in
    /// flight: a copy of it may follow within the duplicate window, and a
    /// read-back reply names nothing that ties it to one query. The chunk's
    /// next read-back waits until no copy can come, also one already
    /// started but not yet sent.
    pub(super) fn stale_read_back(&mut self, now: u32) {
        let dup = now.wrapping_add(self.cfg.exchange.duplicate_window_ms);
        let h = self.exchange.horizon();
        let hold = match self.verifier.hold {
            Some(t) if !passed(now, t, h) => later(t, dup),
            _ => dup,
        };
        self.verifier.hold = Some(hold);
        if self.state == State::Verify {
            self.exchange.defer(hold);
        }
    }

    /// The index of the chunk record `rec` should equal, if it does.
    pub(super) fn matching_record(&self, rec: &PositionRecord) -> Option<usize> {
        let last = self
            .chunk_numbers()
            .enumerate()
            .filter(|&(_, n)| n == rec.number)
            .map(|(i, _)| i)
            .last()?;
        let bytes = self.walk().nth(last)?;
        let mut r = Reader::new(bytes, 0);
        let mut mine = self.cfg.stream.layout.read_record(&mut r).ok()?;
        mine.number = rec.number;
        let extended_ok = !self.cfg.stream.layout.extended || mine.extended == rec.extended;
        let same = mine.axes == rec.axes
            && mine.acceleration == rec.acceleration
            && mine.deceleration == rec.deceleration
            && mine.speed == rec.speed
            && mine.positions == rec.positions
            && extended_ok;
        same.then_some(last)
    }

    pub(super) fn commit_window(&mut self) -> TransferEvent {
        let (head, asked) = (self.verifier.head, self.verifier.asked);
        let end = u32::from(head) + u32::from(asked);
        let seen = self.verifier.seen;
        let mut checked = self.verifier.checked;
        let mut differ = self.verifier.differ;
        let (mut equal, mut missing) = (0u16, 0u16);
        for (i, n) in self.chunk_numbers().enumerate() {
            let m = bit(i);
            if checked & m != 0 || u32::from(n) < u32::from(head) || u32::from(n) >= end {
                continue;
            }
            checked |= m;
            if seen & m != 0 {
                equal += 1;
            } else {
                differ |= m;
                missing += 1;
            }
        }
        self.verifier.checked = checked;
        self.verifier.differ = differ;
        TransferEvent::Compared {
            head,
            equal,
            differ: missing,
        }
    }

    /// A read-back query timed out: ask the same head for half the window.
    /// A late reply to the larger window still answers the smaller one
    /// exactly: it lists every record in it.
    pub(super) fn shrink_window(&mut self) {
        let v = &mut self.verifier;
        if v.asked > 1 {
            v.asked /= 2;
            self.window_limit = v.asked;
            if self.write_query().is_err() {
                self.state = State::Failed(
                    TransferError::Config(Error::BufferTooSmall),
                    Resume::Nothing,
                );
            }
        }
    }
}
