//! Position tables of any size, streamed through fixed, small buffers.
//!
//! A 26DH command may carry 20,000 records of 8 axes, 1,640,014 bytes. The
//! [`PositionStreamEncoder`] produces such a frame chunk by chunk from any
//! record source, computing SC on the fly; the [`PositionStreamDecoder`]
//! takes the bytes of one as they arrive and hands out records one by one,
//! checking SC at the end. Neither depends on the record count for its RAM:
//! each holds one staging buffer of [`STAGE_LEN`] bytes (the longest record,
//! 84 bytes, rounded up) plus a few counters.
//!
//! Every message with a run of position records has a [`PositionStream`]
//! descriptor (in [`crate::position`], the one place their layouts are
//! written): the writes 244H, 245H, 26DH, 290H, 291H and the queries'
//! responses 209H, 21FH, 22DH.
//!
//! ```
//! use iai_protocol_b::position::PositionStream;
//! use iai_protocol_b::table::PositionStreamEncoder;
//! use iai_protocol_b::position::PositionRecord;
//! use iai_protocol_b::frame::Station;
//! let recs = [PositionRecord::new(1, 30, 30, 100, &[(1, 100_000), (2, -25_500)]).unwrap()];
//! let mut enc = PositionStreamEncoder::new(
//!     PositionStream::CHANGE_2, Station(0x99), 0, 1, recs.iter().cloned()).unwrap();
//! let mut out = [0u8; 64];
//! let mut n = 0;
//! // Pull the frame 7 bytes at a time, as a UART TX FIFO would.
//! loop {
//!     let end = (n + 7).min(out.len());
//!     let got = enc.read(&mut out[n..end]).unwrap();
//!     if got == 0 { break }
//!     n += got;
//! }
//! assert_eq!(&out[..n], &b"!9926D0001000103001E001E0064000186A0FFFF9C6438\r\n"[..]);
//! ```

use crate::position::PositionStream;

use core::borrow::Borrow;

use crate::checksum::{BypassPolicy, Checksum};
use crate::decoder::{Received, Status};
use crate::error::{Error, Failure, Result};
use crate::field::{hex_digit, hex_value, FieldSpec, Reader, Writer};
use crate::frame::{emit_envelope, Header, Station, ENVELOPE_LEN};
use crate::hex;
use crate::position::{len_as, put_exact, PositionRecord, PER_FIELD, RESERVED};

/// Staging buffer size of the streaming encoder and decoder: the longest
/// record (4 + 2 + 12 + 8 × 8 + 2 = 84 bytes) or the longest envelope and
/// prefix (16 bytes), rounded up.
pub const STAGE_LEN: usize = 88;

/// A staging buffer and its read position.
#[derive(Debug, Clone)]
struct Stage {
    buf: [u8; STAGE_LEN],
    len: usize,
    pos: usize,
}

impl Stage {
    const fn new() -> Self {
        Stage {
            buf: [0; STAGE_LEN],
            len: 0,
            pos: 0,
        }
    }
    fn pending(&self) -> &[u8] {
        self.pending_from(self.pos)
    }
    fn pending_from(&self, pos: usize) -> &[u8] {
        self.buf.get(pos..self.len).unwrap_or(&[])
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EncPhase {
    /// The envelope and prefix are still to be staged (by the first `read`).
    Start,
    Records,
    Trailer,
    Done,
    Failed,
}

/// Produces one position-stream frame, chunk by chunk, from a record source.
///
/// RAM: one [`STAGE_LEN`]-byte stage, a running checksum and counters,
/// plus the source itself — independent of the record count. The count is
/// needed up front (it precedes the records on the wire); a source that ends
/// early or runs long is an error.
///
/// If a record is invalid (coordinates not matching its axis pattern, a
/// value that does not fit), `read` fails and the frame stays unterminated:
/// no SC, CR or LF is produced, so no receiver can accept it.
#[derive(Debug, Clone)]
pub struct PositionStreamEncoder<I> {
    kind: PositionStream,
    source: I,
    station: Station,
    start: u16,
    count: u16,
    emitted: u16,
    sum: Checksum,
    stage: Stage,
    phase: EncPhase,
}

impl<I> PositionStreamEncoder<I>
where
    I: Iterator,
    I::Item: Borrow<PositionRecord>,
{
    /// Starts a frame of `kind` from `station` with `count` records taken
    /// from `source` (`start` is the start number where the message has one).
    ///
    /// The source may yield records or references to them: `records.iter()`
    /// over a slice hands each record over without copying it.
    #[inline]
    pub fn new(
        kind: PositionStream,
        station: Station,
        start: u16,
        count: u16,
        source: I,
    ) -> Result<Self> {
        // Checked here, written by the first `read`: a stage filled here
        // and returned by value would be copied on the way out.
        let mut head = [0u8; STAGE_LEN];
        let mut w = Writer::new(&mut head);
        emit_envelope(&mut w, kind.header, station, kind.id)?;
        kind.write_prefix(&mut w, start, count)?;
        Ok(PositionStreamEncoder {
            kind,
            source,
            station,
            start,
            count,
            emitted: 0,
            sum: Checksum::new(),
            stage: Stage::new(),
            phase: EncPhase::Start,
        })
    }

    /// Records emitted so far.
    pub fn records_emitted(&self) -> u16 {
        self.emitted
    }

    /// Fills `out` with the next bytes of the frame; `Ok(0)` once the whole
    /// frame (through LF) was produced.
    ///
    /// Records go straight into `out`; only a record that `out` cannot
    /// take whole is encoded into the stage, and as much of it as fits is
    /// copied out at once.
    pub fn read(&mut self, out: &mut [u8]) -> Result<usize> {
        let mut n = 0;
        while n < out.len() {
            let room = out.get_mut(n..).unwrap_or(&mut []);
            if self.stage.pos < self.stage.len {
                let k = copy_words(room, self.stage.pending());
                self.stage.pos += k;
                n += k;
            } else if self.phase == EncPhase::Records && self.emitted < self.count {
                n = self.records(out, n)?;
            } else if !self.refill()? {
                break;
            }
        }
        Ok(n)
    }

    /// Encodes records into `out` from `n` on, until it is full or the
    /// records are done; a record that does not fit whole goes to the
    /// stage, and its first bytes to `out`. Returns the new `n`. The
    /// layout's shape is picked once, here.
    #[inline(always)]
    fn records(&mut self, out: &mut [u8], n: usize) -> Result<usize> {
        let layout = self.kind.layout;
        match (layout.number_width, layout.extended) {
            (4, false) => self.records_as::<4, 18, false>(out, n),
            (4, true) => self.records_as::<4, 18, true>(out, n),
            (3, false) => self.records_as::<3, 17, false>(out, n),
            (0, false) => self.records_as::<0, 14, false>(out, n),
            (0, true) => self.records_as::<0, 14, true>(out, n),
            _ => self.records_as::<PER_FIELD, 0, false>(out, n),
        }
    }

    /// [`Self::records`] for one shape (see `position::whole_field::put_as`).
    #[inline(always)]
    fn records_as<const NW: usize, const HEAD: usize, const EXT: bool>(
        &mut self,
        out: &mut [u8],
        n: usize,
    ) -> Result<usize> {
        let layout = self.kind.layout;
        let count = self.count;
        let mut emitted = self.emitted;
        let mut sum = 0u32;
        let mut result = Ok(());
        let total = out.len();
        // What is left of `out`, as one moving slice.
        let mut rest = out.get_mut(n..).unwrap_or(&mut []);
        while emitted < count && !rest.is_empty() {
            let Some(rec) = self.source.next() else {
                result = Err(Error::CountMismatch {
                    expected: usize::from(count),
                    found: usize::from(emitted),
                });
                break;
            };
            let rec = rec.borrow();
            let len = match len_as::<NW, HEAD, EXT>(layout, rec) {
                Ok(len) => len,
                Err(e) => {
                    result = Err(e);
                    break;
                }
            };
            if len <= rest.len() {
                let (dst, tail) = core::mem::take(&mut rest).split_at_mut(len);
                match put_exact::<NW, HEAD, EXT>(layout, rec, dst) {
                    Ok(s) => sum = sum.wrapping_add(s),
                    Err(e) => {
                        result = Err(e);
                        break;
                    }
                }
                rest = tail;
                emitted += 1;
                continue;
            }
            // Not whole into `out`: into the stage, and what fits out now.
            let staged = stage_record::<NW, HEAD, EXT>(layout, rec, &mut self.stage.buf, len);
            match staged {
                Ok(s) => {
                    sum = sum.wrapping_add(s);
                    emitted += 1;
                    self.stage.len = len;
                    let k = copy_words(rest, self.stage.pending_from(0));
                    self.stage.pos = k;
                    rest = rest.get_mut(k..).unwrap_or(&mut []);
                }
                Err(e) => result = Err(e),
            }
            break;
        }
        let n = total - rest.len();
        self.emitted = emitted;
        self.sum.add_sum(sum);
        if result.is_err() {
            self.phase = EncPhase::Failed;
        }
        result.map(|()| n)
    }

    /// After the last record: loads the trailer into the stage; `false`
    /// when done. (`read` encodes the records.)
    fn refill(&mut self) -> Result<bool> {
        match self.phase {
            EncPhase::Start => {
                let mut w = Writer::new(&mut self.stage.buf);
                emit_envelope(&mut w, self.kind.header, self.station, self.kind.id)?;
                self.kind.write_prefix(&mut w, self.start, self.count)?;
                self.stage.len = w.len();
                self.stage.pos = 0;
                self.sum.update(self.stage.pending());
                self.phase = EncPhase::Records;
                Ok(true)
            }
            EncPhase::Records => {
                if self.source.next().is_some() {
                    self.phase = EncPhase::Failed;
                    return Err(Error::CountMismatch {
                        expected: usize::from(self.count),
                        found: usize::from(self.count) + 1,
                    });
                }
                let s = self.sum.value();
                let trailer = [hex_digit(s >> 4), hex_digit(s), b'\r', b'\n'];
                let mut w = Writer::new(&mut self.stage.buf);
                w.put(&trailer)?;
                self.stage.len = w.len();
                self.stage.pos = 0;
                self.phase = EncPhase::Trailer;
                Ok(true)
            }
            EncPhase::Trailer => {
                self.phase = EncPhase::Done;
                Ok(false)
            }
            EncPhase::Done | EncPhase::Failed => Ok(false),
        }
    }

    /// Writes the whole frame to `w` in stage-sized chunks; returns its length.
    pub fn write_to<W: embedded_io::Write>(
        &mut self,
        w: &mut W,
    ) -> core::result::Result<usize, Failure<W::Error>> {
        let mut chunk = [0u8; STAGE_LEN];
        let mut total = 0;
        loop {
            let n = self.read(&mut chunk)?;
            if n == 0 {
                return Ok(total);
            }
            w.write_all(chunk.get(..n).unwrap_or(&[]))
                .map_err(Failure::Io)?;
            total += n;
        }
    }
}

/// What the [`PositionStreamDecoder`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StreamEvent {
    /// The envelope and prefix were read.
    Start {
        /// The message's stream descriptor.
        kind: PositionStream,
        /// Station.
        station: Station,
        /// Start number (0 where the message has none).
        start: u16,
        /// Number of records announced.
        count: u16,
    },
    /// One well-formed record (its checksum is only known at the end).
    Record(PositionRecord),
    /// The frame ended with a valid SC (or an accepted `@@`) and CR LF.
    End {
        /// Records delivered.
        records: u16,
    },
    /// The frame is broken; `records_ok` records were well-formed before.
    /// Feed no more bytes without [`PositionStreamDecoder::reset`].
    Error {
        /// What was wrong.
        error: Error,
        /// Well-formed records delivered before the error.
        records_ok: u16,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum DecPhase {
    Envelope,
    RecordHead,
    RecordRest,
    Trailer,
    Finished,
}

/// What [`PositionStreamDecoder::decode_records`] made of its input.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordsReceived {
    /// Bytes of the input consumed.
    pub consumed: usize,
    /// Records written to the start of the output.
    pub records: usize,
    /// The event it stopped at, never a record.
    pub status: Status<StreamEvent>,
}

/// Reads one position-stream frame record by record as bytes arrive.
///
/// Accepts any message of [`PositionStream::ALL`] (the envelope says
/// which). RAM: one [`STAGE_LEN`]-byte stage and counters, whatever the
/// record count. Records are handed out as soon as they are complete; SC
/// covers the whole frame and is checked at the end, so a consumer that
/// must not act on unverified data holds its effect until [`StreamEvent::End`]
/// (a controller applies the write only after the checksum; the bridge
/// forwards records but confirms upstream only after `End`).
#[derive(Debug, Clone)]
pub struct PositionStreamDecoder {
    policy: BypassPolicy,
    kind: Option<PositionStream>,
    header: Header,
    station: Station,
    stage: Stage,
    need: usize,
    offset: usize,
    sum: Checksum,
    count: u16,
    done: u16,
    phase: DecPhase,
}

impl Default for PositionStreamDecoder {
    fn default() -> Self {
        Self::new(BypassPolicy::default())
    }
}

impl PositionStreamDecoder {
    /// A decoder expecting a new frame.
    pub const fn new(policy: BypassPolicy) -> Self {
        PositionStreamDecoder {
            policy,
            kind: None,
            header: Header::Command,
            station: Station(0),
            stage: Stage::new(),
            need: ENVELOPE_LEN,
            offset: 0,
            sum: Checksum::new(),
            count: 0,
            done: 0,
            phase: DecPhase::Envelope,
        }
    }

    /// Forgets the current frame; the next byte must be a header byte.
    pub fn reset(&mut self) {
        *self = Self::new(self.policy);
    }

    /// Records delivered so far in this frame.
    pub fn records_done(&self) -> u16 {
        self.done
    }

    /// Records announced by the frame's count field (0 before `Start`).
    pub fn records_announced(&self) -> u16 {
        self.count
    }

    /// Bytes of the frame consumed so far.
    pub fn offset(&self) -> usize {
        self.offset
    }

    /// Consumes bytes until an event.
    ///
    /// Bytes are copied a whole field group at a time. After
    /// [`StreamEvent::End`] or [`StreamEvent::Error`] nothing more is
    /// consumed (0 bytes, [`Status::Partial`]) until [`PositionStreamDecoder::reset`]:
    /// the rest of the input belongs to whatever follows the frame.
    #[inline]
    pub fn decode(&mut self, input: &[u8]) -> Received<StreamEvent> {
        let (consumed, status) = self.decode_inner(input);
        Received { consumed, status }
    }

    #[inline]
    fn decode_inner(&mut self, input: &[u8]) -> (usize, Status<StreamEvent>) {
        let mut used = 0;
        while self.phase != DecPhase::Finished {
            let rest = input.get(used..).unwrap_or(&[]);
            if rest.is_empty() {
                break;
            }
            // A whole well-formed record in the input: read it in place.
            if self.phase == DecPhase::RecordHead && self.stage.len == 0 {
                if let Some(kind) = self.kind {
                    let mut rec = PositionRecord::default();
                    if let Some((len, sum)) = kind.layout.read_in_place(rest, &mut rec) {
                        self.sum.add_sum(sum);
                        self.offset += len;
                        self.done += 1;
                        self.enter_record_or_trailer(kind);
                        return (used + len, Status::Complete(StreamEvent::Record(rec)));
                    }
                }
            }
            // A whole, well-formed envelope and prefix, or trailer, in the
            // input: read in place (anything else goes through the stage,
            // which says what is wrong).
            if self.stage.len == 0 {
                let whole = match self.phase {
                    DecPhase::Envelope => self.start_in_place(rest),
                    DecPhase::Trailer => self.end_in_place(rest),
                    _ => None,
                };
                if let Some((len, ev)) = whole {
                    return (used + len, Status::Complete(ev));
                }
            }
            let want = self.need.saturating_sub(self.stage.len);
            let take = want.min(rest.len());
            let end = self.stage.len + take;
            match (
                self.stage.buf.get_mut(self.stage.len..end),
                rest.get(..take),
            ) {
                (Some(dst), Some(src)) if take > 0 => dst.copy_from_slice(src),
                _ => return (used, self.fail(Error::FrameTooLong { limit: STAGE_LEN })),
            }
            // A CR or LF where the unit has none: the frame ended early (a
            // byte was lost or changed). Say so now, not after waiting for
            // bytes that will not come.
            if let Some(at) = self.early_end(self.stage.len, rest.get(..take).unwrap_or(&[])) {
                return (
                    used + at + 1,
                    self.fail(Error::BodyTooShort {
                        offset: self.offset + self.stage.len + at,
                    }),
                );
            }
            self.stage.len = end;
            used += take;
            if self.stage.len < self.need {
                break;
            }
            let (ev, keep) = self.unit_complete();
            if !keep && !matches!(ev, Status::Complete(StreamEvent::Error { .. })) {
                self.offset += self.stage.len;
                self.stage.len = 0;
            }
            if !ev.is_partial() {
                return (used, ev);
            }
        }
        (used, Status::Partial)
    }

    /// Consumes bytes as [`Self::decode`] does, but writes the records
    /// into `out` (overwriting them in place) instead of handing them out
    /// one event at a time: the bulk path, for a caller that takes many
    /// records at once: the records are `out[..records]`, and the status is
    /// never a [`StreamEvent::Record`].
    ///
    /// It stops at `Start`, `End` or `Error` (the status says which, as
    /// `decode` would), and otherwise when the input is used up or `out` is
    /// full ([`Status::Partial`] either way; call again with more input, or
    /// with `out` emptied). Whole records in the input are read in place;
    /// a record cut by the end of the input is staged and completed on the
    /// next call, as by `decode`. Elements of `out` past `records` may have
    /// been overwritten.
    ///
    /// ```
    /// use iai_protocol_b::checksum::BypassPolicy;
    /// use iai_protocol_b::position::PositionRecord;
    /// use iai_protocol_b::decoder::Status;
    /// use iai_protocol_b::table::{PositionStreamDecoder, StreamEvent};
    /// let wire = b"!9926D0002000103001E001E0064000186A0FFFF9C64000201000000000000000030392B\r\n";
    /// let mut dec = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
    /// let mut recs: [PositionRecord; 8] = Default::default();
    /// let r = dec.decode_records(wire, &mut recs);
    /// assert_eq!(r.records, 0);
    /// assert!(matches!(r.status, Status::Complete(StreamEvent::Start { count: 2, .. })));
    /// let rest = dec.decode_records(&wire[r.consumed..], &mut recs);
    /// assert_eq!(r.consumed + rest.consumed, wire.len());
    /// assert_eq!((rest.records, rest.status), (2, Status::Complete(StreamEvent::End { records: 2 })));
    /// assert_eq!(recs[1].position(1), Some(12_345));
    /// ```
    pub fn decode_records(&mut self, input: &[u8], out: &mut [PositionRecord]) -> RecordsReceived {
        let (consumed, records, status) = self.decode_records_inner(input, out);
        RecordsReceived {
            consumed,
            records,
            status,
        }
    }

    fn decode_records_inner(
        &mut self,
        input: &[u8],
        out: &mut [PositionRecord],
    ) -> (usize, usize, Status<StreamEvent>) {
        let mut used = 0;
        let mut n = 0;
        loop {
            if let (DecPhase::RecordHead, 0, Some(kind)) = (self.phase, self.stage.len, self.kind) {
                let left = usize::from(self.count.saturating_sub(self.done));
                let room = out.get_mut(n..).unwrap_or(&mut []);
                let fit = room.len().min(left);
                let room = room.get_mut(..fit).unwrap_or(&mut []);
                let rest = input.get(used..).unwrap_or(&[]);
                let (len, k, sum) = kind.layout.read_records(rest, room);
                if k > 0 {
                    self.sum.add_sum(sum);
                    self.offset += len;
                    // At most `left` records: `done` stays within its u16 count.
                    self.done += k as u16;
                    used += len;
                    n += k;
                    self.enter_record_or_trailer(kind);
                }
            }
            let in_records = matches!(self.phase, DecPhase::RecordHead | DecPhase::RecordRest);
            if in_records && n >= out.len() {
                return (used, n, Status::Partial);
            }
            let (len, ev) = self.decode_inner(input.get(used..).unwrap_or(&[]));
            used += len;
            match (ev, out.get_mut(n)) {
                (Status::Complete(StreamEvent::Record(rec)), Some(slot)) => {
                    *slot = rec;
                    n += 1;
                }
                // `out` had room: a record always finds its slot.
                (Status::Complete(StreamEvent::Record(_)), None) => {
                    return (used, n, Status::Partial)
                }
                (ev, _) => return (used, n, ev),
            }
        }
    }

    /// The envelope and prefix at the start of `bytes`, if they are whole
    /// and well-formed: what the stage would make of them (the bytes used
    /// and `Start`), without it.
    fn start_in_place(&mut self, bytes: &[u8]) -> Option<(usize, StreamEvent)> {
        if self.kind.is_some() {
            return None;
        }
        let (envelope, rest) = bytes.split_first_chunk::<ENVELOPE_LEN>()?;
        let [first, s1, s2, i1, i2, i3] = *envelope;
        let header = Header::from_byte(first)?;
        let station = hex_field(&[s1, s2])?;
        let kind = PositionStream::find(header, hex_field(&[i1, i2, i3])?)?;
        let prefix = rest.get(..kind.prefix_len())?;
        let mut fields = prefix;
        if kind.reserved {
            fields = fields.strip_prefix(RESERVED.0)?;
        }
        let (start, count) = fields.split_at_checked(usize::from(kind.start_width))?;
        let start = if start.is_empty() {
            0
        } else {
            hex_field(start)?
        };
        let count = hex_field(count)?;
        if count > kind.max_records {
            return None;
        }
        self.sum.update(envelope);
        self.sum.update(prefix);
        self.kind = Some(kind);
        self.header = header;
        self.station = Station(station as u8);
        self.count = count;
        let len = ENVELOPE_LEN + prefix.len();
        self.offset += len;
        self.enter_record_or_trailer(kind);
        let station = self.station;
        Some((
            len,
            StreamEvent::Start {
                kind,
                station,
                start,
                count,
            },
        ))
    }

    /// The trailer at the start of `bytes`, if it is whole and right (its
    /// SC, or an `@@` the policy allows, then CR LF): the bytes used and
    /// `End`, as the stage would give them.
    fn end_in_place(&mut self, bytes: &[u8]) -> Option<(usize, StreamEvent)> {
        let [h, l, b'\r', b'\n'] = *bytes.first_chunk::<4>()? else {
            return None;
        };
        let ok = if [h, l] == *b"@@" {
            self.policy.allows(self.header)
        } else {
            hex::decode2(&[h, l]) == Some(self.sum.value())
        };
        if !ok {
            return None;
        }
        self.offset += 4;
        self.phase = DecPhase::Finished;
        Some((4, StreamEvent::End { records: self.done }))
    }

    /// Pushes one byte (ignored after the end of the frame, see [`Self::decode`]).
    pub fn push(&mut self, byte: u8) -> Status<StreamEvent> {
        self.decode_inner(&[byte]).1
    }

    /// The index in `bytes` (which go to the stage at `from`) of the first
    /// CR or LF out of place: anywhere but the trailer's last two bytes.
    fn early_end(&self, from: usize, bytes: &[u8]) -> Option<usize> {
        let trailer = self.phase == DecPhase::Trailer;
        bytes.iter().enumerate().position(|(i, &b)| {
            let at = from + i;
            match b {
                b'\r' => !(trailer && at == 2),
                b'\n' => !(trailer && at == 3),
                _ => false,
            }
        })
    }

    fn fail(&mut self, error: Error) -> Status<StreamEvent> {
        self.phase = DecPhase::Finished;
        Status::Complete(StreamEvent::Error {
            error,
            records_ok: self.done,
        })
    }

    /// Handles a complete unit of `need` bytes. Returns the event and
    /// whether the stage keeps its bytes (the unit grows instead).
    fn unit_complete(&mut self) -> (Status<StreamEvent>, bool) {
        let ev = self.unit_event();
        let keep = ev.is_partial();
        (ev, keep)
    }

    fn unit_event(&mut self) -> Status<StreamEvent> {
        let unit = self.stage.buf.get(..self.stage.len).unwrap_or(&[]);
        let base = self.offset;
        match self.phase {
            DecPhase::Envelope if self.kind.is_none() => {
                let first = unit.first().copied().unwrap_or(0);
                let Some(header) = Header::from_byte(first) else {
                    return self.fail(Error::InvalidHeader { byte: first });
                };
                let mut r = Reader::new(unit, 0);
                let _ = r.take(1);
                match r.unsigned(FieldSpec::hex(2)) {
                    Ok(s) => self.station = Station(s as u8),
                    Err(e) => return self.fail(e),
                }
                let id = match r.unsigned(FieldSpec::hex(3)) {
                    Ok(s) => s as u16,
                    Err(e) => return self.fail(e),
                };
                let Some(kind) = PositionStream::find(header, id) else {
                    return self.fail(Error::UnknownMessageId { id });
                };
                self.kind = Some(kind);
                self.header = header;
                self.sum.update(unit);
                // Keep the envelope in the stage; the prefix follows it.
                self.need = ENVELOPE_LEN + kind.prefix_len();
                if self.need == ENVELOPE_LEN {
                    return self.fail(Error::BodyTooShort {
                        offset: ENVELOPE_LEN,
                    });
                }
                Status::Partial
            }
            DecPhase::Envelope => {
                let Some(kind) = self.kind else {
                    return self.fail(Error::BodyTooShort { offset: base });
                };
                let station = self.station;
                let prefix = unit.get(ENVELOPE_LEN..).unwrap_or(&[]);
                self.sum.update(prefix);
                let mut r = Reader::new(prefix, ENVELOPE_LEN);
                match kind.read_prefix(&mut r) {
                    Ok((start, count)) => {
                        self.count = count;
                        self.enter_record_or_trailer(kind);
                        Status::Complete(StreamEvent::Start {
                            kind,
                            station,
                            start,
                            count,
                        })
                    }
                    Err(e) => self.fail(e),
                }
            }
            DecPhase::RecordHead => {
                let Some(kind) = self.kind else {
                    return self.fail(Error::BodyTooShort { offset: base });
                };
                let at = base + kind.layout.pattern_end() - 2;
                let pat = unit.get(kind.layout.pattern_end() - 2..).unwrap_or(&[]);
                match crate::field::decode_unsigned(FieldSpec::hex(2), pat, at) {
                    Ok(bits) => {
                        // Keep the head in the stage; the record is read whole.
                        self.need = kind.layout.record_len((bits as u8).count_ones() as usize);
                        self.phase = DecPhase::RecordRest;
                        Status::Partial
                    }
                    Err(e) => self.fail(e),
                }
            }
            DecPhase::RecordRest => {
                let Some(kind) = self.kind else {
                    return self.fail(Error::BodyTooShort { offset: base });
                };
                let mut r = Reader::new(unit, base);
                match kind.layout.read_record(&mut r) {
                    Ok(rec) => {
                        self.sum.update(unit);
                        self.done += 1;
                        self.enter_record_or_trailer(kind);
                        Status::Complete(StreamEvent::Record(rec))
                    }
                    Err(e) => self.fail(e),
                }
            }
            DecPhase::Trailer => {
                let sc = unit.get(..2).unwrap_or(&[]);
                let crlf = unit.get(2..4).unwrap_or(&[]);
                if sc == b"@@" {
                    if !self.policy.allows(self.header) {
                        return self.fail(Error::ChecksumBypassRejected);
                    }
                } else {
                    let mut received = 0u8;
                    for (i, &b) in sc.iter().enumerate() {
                        match hex_value(b) {
                            Some(d) => received = (received << 4) | d,
                            None => {
                                return self.fail(Error::InvalidHexDigit {
                                    offset: base + i,
                                    byte: b,
                                })
                            }
                        }
                    }
                    if received != self.sum.value() {
                        return self.fail(Error::ChecksumMismatch {
                            computed: self.sum.value(),
                            received,
                        });
                    }
                }
                match crlf {
                    [b'\r', b'\n'] => {}
                    [b'\r', b] => return self.fail(Error::MissingLineFeed { byte: *b }),
                    _ => return self.fail(Error::MissingCarriageReturn),
                }
                self.phase = DecPhase::Finished;
                Status::Complete(StreamEvent::End { records: self.done })
            }
            DecPhase::Finished => Status::Partial,
        }
    }

    fn enter_record_or_trailer(&mut self, kind: PositionStream) {
        if self.done < self.count {
            self.phase = DecPhase::RecordHead;
            self.need = kind.layout.pattern_end();
        } else {
            self.phase = DecPhase::Trailer;
            self.need = 4;
        }
    }
}

/// The value of a field of 1 to 4 hex digits of either case.
fn hex_field(digits: &[u8]) -> Option<u16> {
    let v = hex::decode_bytewise(digits).ok()?;
    u16::try_from(v).ok().filter(|_| !digits.is_empty())
}

/// [`put_exact`] of a record of `len` bytes into the stage: the path of
/// the one record per `read` that does not fit `out` whole, kept out of
/// line so that the loop over the others stays small.
#[inline(never)]
fn stage_record<const NW: usize, const HEAD: usize, const EXT: bool>(
    layout: crate::position::RecordLayout,
    rec: &PositionRecord,
    stage: &mut [u8; STAGE_LEN],
    len: usize,
) -> Result<u32> {
    match stage.get_mut(..len) {
        Some(dst) => put_exact::<NW, HEAD, EXT>(layout, rec, dst),
        None => Err(Error::BufferTooSmall),
    }
}

/// Copies as much of `src` as fits into `dst`, 16 bytes (four words) at
/// a time, then a word at a time (the library `memcpy` is slow for the
/// short, unaligned pieces a record leaves); returns the bytes copied.
#[inline(always)]
fn copy_words(dst: &mut [u8], src: &[u8]) -> usize {
    let n = dst.len().min(src.len());
    if let (Some(d), Some(s)) = (dst.get_mut(..n), src.get(..n)) {
        let mut d16 = d.chunks_exact_mut(16);
        let mut s16 = s.chunks_exact(16);
        for (a, b) in (&mut d16).zip(&mut s16) {
            a.copy_from_slice(b);
        }
        let mut dw = d16.into_remainder().chunks_exact_mut(4);
        let mut sw = s16.remainder().chunks_exact(4);
        for (a, b) in (&mut dw).zip(&mut sw) {
            a.copy_from_slice(b);
        }
        for (a, b) in dw.into_remainder().iter_mut().zip(sw.remainder()) {
            *a = *b;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// Two 26DH records of different length (EXAMPLES 6.2).
    const WIRE: &[u8] =
        b"!9926D0002000103001E001E0064000186A0FFFF9C64000201000000000000000030392B\r\n";

    /// Pushes `bytes` one at a time; the events other than `Partial`,
    /// with the index of the byte that gave each.
    fn push_all(bytes: &[u8]) -> std::vec::Vec<(usize, StreamEvent)> {
        let mut d = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
        bytes
            .iter()
            .enumerate()
            .filter_map(|(i, &b)| d.push(b).complete().map(|e| (i, e)))
            .collect()
    }

    #[test]
    fn the_example_ends_at_its_line_feed() {
        let events = push_all(WIRE);
        assert_eq!(events.len(), 4, "{events:?}");
        assert_eq!(events[3], (WIRE.len() - 1, StreamEvent::End { records: 2 }));
    }

    #[test]
    fn a_frame_one_byte_short_fails_at_its_carriage_return() {
        // A digit of the last coordinate lost (a 0x11 taken for XON by the
        // UART): the record still decodes, shifted, and the SC's second
        // digit and the CR stand where the SC should. The CR ends the
        // frame at once; the decoder does not wait for a fourth byte.
        let mut short = WIRE.to_vec();
        short.remove(WIRE.len() - 6);
        let events = push_all(&short);
        let cr = short.len() - 2;
        assert_eq!(
            events.last(),
            Some(&(
                cr,
                StreamEvent::Error {
                    error: Error::BodyTooShort { offset: cr },
                    records_ok: 2,
                }
            )),
            "{events:?}"
        );
    }

    #[test]
    fn a_line_feed_inside_a_record_fails_there() {
        let mut broken = WIRE.to_vec();
        broken[30] = b'\n';
        let events = push_all(&broken);
        assert_eq!(
            events.last(),
            Some(&(
                30,
                StreamEvent::Error {
                    error: Error::BodyTooShort { offset: 30 },
                    records_ok: 0,
                }
            ))
        );
        // Fed whole, the same.
        let mut d = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
        let start = d.decode(&broken);
        assert!(matches!(
            start.status,
            Status::Complete(StreamEvent::Start { count: 2, .. })
        ));
        let used = start.consumed;
        assert_eq!(
            d.decode(&broken[used..]),
            Received {
                consumed: 31 - used,
                status: Status::Complete(StreamEvent::Error {
                    error: Error::BodyTooShort { offset: 30 },
                    records_ok: 0,
                })
            }
        );
    }

    /// Bulk decoding against event-by-event decoding.
    pub(super) mod bulk {
        use super::*;
        use crate::axis::{AxisPattern, PerAxis};
        use std::vec::Vec;

        pub(in super::super) fn xorshift(seed: u32) -> impl FnMut() -> u32 {
            let mut x = seed | 1;
            move || {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                x
            }
        }

        /// `count` records that fit `kind`'s layout, of 0 to 8 axes.
        pub(in super::super) fn records(
            kind: PositionStream,
            count: usize,
            next: &mut impl FnMut() -> u32,
        ) -> Vec<PositionRecord> {
            (0..count)
                .map(|_| {
                    let axes = AxisPattern::from_bits(next() as u8);
                    let mut positions = PerAxis::new();
                    for _ in 0..axes.count() {
                        positions.push(next() as i32).unwrap();
                    }
                    PositionRecord {
                        number: match kind.layout.number_width {
                            0 => 0,
                            3 => (next() & 0xFFF) as u16,
                            _ => next() as u16,
                        },
                        axes,
                        acceleration: next() as u16,
                        deceleration: next() as u16,
                        speed: next() as u16,
                        positions,
                        extended: if kind.layout.extended {
                            next() as u8
                        } else {
                            0
                        },
                    }
                })
                .collect()
        }

        /// A whole frame of `recs`, pulled in `chunk`-byte pieces, the
        /// records handed over by reference.
        fn frame(kind: PositionStream, recs: &[PositionRecord], chunk: usize) -> Vec<u8> {
            let mut enc =
                PositionStreamEncoder::new(kind, Station(0x99), 1, recs.len() as u16, recs.iter())
                    .unwrap();
            let mut out = Vec::new();
            let mut buf = [0u8; 200];
            loop {
                let n = enc.read(&mut buf[..chunk]).unwrap();
                if n == 0 {
                    return out;
                }
                out.extend_from_slice(&buf[..n]);
            }
        }

        /// Every event other than `Partial` of `decode`, the input given
        /// in pieces of `chunk` bytes; and the bytes consumed.
        fn by_events(bytes: &[u8], chunk: usize) -> (Vec<StreamEvent>, usize) {
            let mut d = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
            let mut events = Vec::new();
            let mut used = 0;
            for piece in bytes.chunks(chunk) {
                let mut rest = piece;
                loop {
                    let Received {
                        consumed: n,
                        status,
                    } = d.decode(rest);
                    used += n;
                    rest = &rest[n..];
                    match status {
                        Status::Partial => break,
                        Status::Complete(ev) => events.push(ev),
                    }
                }
            }
            (events, used)
        }

        /// The same through `decode_records` into `room` records (their
        /// contents stale), the records as `Record` events.
        fn by_bulk(
            bytes: &[u8],
            chunk: usize,
            room: usize,
            stale: &PositionRecord,
        ) -> (Vec<StreamEvent>, usize) {
            let mut d = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
            let mut out = std::vec![stale.clone(); room];
            let mut events = Vec::new();
            let mut used = 0;
            for piece in bytes.chunks(chunk) {
                let mut rest = piece;
                loop {
                    let RecordsReceived {
                        consumed: n,
                        records: k,
                        status: ev,
                    } = d.decode_records(rest, &mut out);
                    assert!(k <= room);
                    assert_ne!(ev, Status::Complete(StreamEvent::Record(stale.clone())));
                    assert!(!matches!(ev, Status::Complete(StreamEvent::Record(_))));
                    used += n;
                    rest = &rest[n..];
                    events.extend(out[..k].iter().cloned().map(StreamEvent::Record));
                    match ev {
                        // Stopped for input, or for room: call again.
                        Status::Partial if k < room || n == 0 && k == 0 => break,
                        Status::Partial => {}
                        Status::Complete(ev) => events.push(ev),
                    }
                }
            }
            (events, used)
        }

        #[test]
        fn the_same_events_however_the_input_and_the_room_come() {
            let mut next = xorshift(29);
            for kind in PositionStream::ALL {
                for count in [0usize, 1, 2, 5, 9] {
                    let recs = records(kind, count, &mut next);
                    let mut wire = frame(kind, &recs, 1 + next() as usize % 90);
                    // Bytes after the frame belong to whatever follows it.
                    wire.extend_from_slice(b"#99");
                    let stale = records(kind, 1, &mut next).remove(0);
                    let staged = by_events(&wire, 1);
                    for chunk in [1, 2, 7, 30, 64, 1000] {
                        let (expect, used) = by_events(&wire, chunk);
                        assert_eq!((&expect, used), (&staged.0, staged.1), "{kind:?}");
                        assert_eq!(expect.len(), count + 2, "{kind:?}");
                        assert_eq!(
                            expect.last(),
                            Some(&StreamEvent::End {
                                records: count as u16
                            })
                        );
                        assert_eq!(used, wire.len() - 3);
                        for room in [1, 2, 3, 8] {
                            let got = by_bulk(&wire, chunk, room, &stale);
                            assert_eq!(
                                got,
                                (expect.clone(), used),
                                "{kind:?} chunk {chunk} room {room}"
                            );
                        }
                    }
                }
            }
        }

        #[test]
        fn the_same_errors() {
            let mut next = xorshift(31);
            for kind in [
                PositionStream::CHANGE_2,
                PositionStream::RANGE,
                PositionStream::QUERY_3_RESPONSE,
            ] {
                let recs = records(kind, 4, &mut next);
                let wire = frame(kind, &recs, 64);
                let stale = recs[0].clone();
                for at in 0..wire.len() {
                    for bad in [b'G', b'0', b'f', b'\r', b'\n', b'@', b'#'] {
                        let mut w = wire.clone();
                        if w[at] == bad {
                            continue;
                        }
                        w[at] = bad;
                        // Byte by byte every unit goes through the stage;
                        // whole, the envelope, the records and the trailer
                        // are read in place where they are well-formed:
                        // the same events and errors either way.
                        let staged = by_events(&w, 1);
                        for chunk in [5, 1000] {
                            let expect = by_events(&w, chunk);
                            assert_eq!(expect, staged, "{kind:?} {bad:#04X} at {at}");
                            for room in [1, 3] {
                                let got = by_bulk(&w, chunk, room, &stale);
                                assert_eq!(got, expect, "{kind:?} {bad:#04X} at {at}");
                            }
                        }
                    }
                }
                // Cut short: the same records, no end.
                for cut in 0..wire.len() {
                    assert_eq!(
                        by_bulk(&wire[..cut], 1000, 2, &stale),
                        by_events(&wire[..cut], 1000)
                    );
                }
            }
        }

        /// `decode_records` as a tuple: (consumed, records, event).
        fn bulk(
            d: &mut PositionStreamDecoder,
            input: &[u8],
            out: &mut [PositionRecord],
        ) -> (usize, usize, Status<StreamEvent>) {
            let r = d.decode_records(input, out);
            (r.consumed, r.records, r.status)
        }

        #[test]
        fn room_is_respected_and_nothing_follows_the_end() {
            let mut next = xorshift(37);
            let kind = PositionStream::CHANGE_2;
            let recs = records(kind, 5, &mut next);
            let wire = frame(kind, &recs, 64);
            let mut d = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
            let mut out: [PositionRecord; 2] = Default::default();
            let (used, n, ev) = bulk(&mut d, &wire, &mut out);
            assert!(matches!(
                ev,
                Status::Complete(StreamEvent::Start { count: 5, .. })
            ));
            assert_eq!((used, n), (10, 0));
            assert_eq!(
                bulk(&mut d, &wire[used..], &mut []),
                (0, 0, Status::Partial),
                "no room"
            );
            let mut at = used;
            let mut got = Vec::new();
            loop {
                let (u, n, ev) = bulk(&mut d, &wire[at..], &mut out);
                at += u;
                got.extend_from_slice(&out[..n]);
                assert_eq!(d.records_done() as usize, got.len());
                assert_eq!(d.offset(), at);
                if !ev.is_partial() {
                    assert_eq!(ev, Status::Complete(StreamEvent::End { records: 5 }));
                    break;
                }
                assert_eq!(n, 2, "stopped for room");
            }
            assert_eq!((at, &got), (wire.len(), &recs));
            assert_eq!(bulk(&mut d, b"!99", &mut out), (0, 0, Status::Partial));
            // A record cut by the end of the input completes on the next call.
            let mut d = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
            let (u, _, _) = bulk(&mut d, &wire, &mut out);
            let (u2, n, ev) = bulk(&mut d, &wire[u..u + 5], &mut out);
            assert_eq!((u2, n, ev), (5, 0, Status::Partial));
            let (_, n, _) = bulk(&mut d, &wire[u + 5..], &mut out);
            assert_eq!(&out[..n], &recs[..2]);
        }
    }

    /// The encoder against a frame written field by field.
    mod encoder {
        use super::bulk::{records, xorshift};
        use super::*;
        use crate::checksum::ChecksumMode;
        use crate::frame::emit_trailer;
        use crate::position::RecordLayout;
        use std::vec::Vec;

        fn reference(kind: PositionStream, start: u16, recs: &[PositionRecord]) -> Vec<u8> {
            let mut buf = std::vec![0u8; 4096];
            let mut w = Writer::new(&mut buf);
            emit_envelope(&mut w, kind.header, Station(0x42), kind.id).unwrap();
            kind.write_prefix(&mut w, start, recs.len() as u16).unwrap();
            for r in recs {
                kind.layout.write_record_per_field(r, &mut w).unwrap();
            }
            emit_trailer(&mut w, ChecksumMode::Compute).unwrap();
            let n = w.len();
            buf.truncate(n);
            buf
        }

        /// The whole frame pulled in pieces of `chunk` bytes (a repeating
        /// pattern of sizes when `chunk` is 0); the error, if any, and
        /// what came before it.
        fn pull<I>(enc: &mut PositionStreamEncoder<I>, chunk: usize) -> (Vec<u8>, Option<Error>)
        where
            I: Iterator,
            I::Item: Borrow<PositionRecord>,
        {
            let mut out = Vec::new();
            let mut buf = [0u8; 300];
            for k in 0.. {
                let size = if chunk == 0 {
                    [1, 7, 64, 3, 90, 26][k % 6]
                } else {
                    chunk
                };
                match enc.read(&mut buf[..size]) {
                    Ok(0) => return (out, None),
                    Ok(n) => {
                        assert!(n == size || enc.phase == EncPhase::Done, "{n} of {size}");
                        out.extend_from_slice(&buf[..n]);
                    }
                    Err(e) => return (out, Some(e)),
                }
            }
            unreachable!()
        }

        #[test]
        fn every_kind_and_piece_size_gives_the_reference_frame() {
            let mut next = xorshift(41);
            for kind in PositionStream::ALL {
                for count in [0usize, 1, 3, 11] {
                    let recs = records(kind, count, &mut next);
                    let expect = reference(kind, 7, &recs);
                    for chunk in [0, 1, 2, 5, 13, 26, 64, 81, 82, 83, 88, 89, 300] {
                        let by_ref = PositionStreamEncoder::new(
                            kind,
                            Station(0x42),
                            7,
                            count as u16,
                            recs.iter(),
                        );
                        let mut by_ref = by_ref.unwrap();
                        assert_eq!(
                            pull(&mut by_ref, chunk),
                            (expect.clone(), None),
                            "{kind:?} {chunk}"
                        );
                        assert_eq!(by_ref.records_emitted() as usize, count);
                        assert_eq!(by_ref.read(&mut [0u8; 8]), Ok(0), "done stays done");
                        let mut by_value = PositionStreamEncoder::new(
                            kind,
                            Station(0x42),
                            7,
                            count as u16,
                            recs.iter().cloned(),
                        )
                        .unwrap();
                        assert_eq!(pull(&mut by_value, chunk).0, expect);
                    }
                }
            }
        }

        /// A layout no message has goes field by field, through the same
        /// paths.
        #[test]
        fn other_layouts_too() {
            let mut next = xorshift(43);
            let mut kind = PositionStream::CHANGE_3;
            kind.layout = RecordLayout {
                number_width: 2,
                extended: true,
            };
            let mut recs = records(PositionStream::CHANGE_3, 6, &mut next);
            for r in &mut recs {
                r.number &= 0xFF;
            }
            let expect = reference(kind, 0, &recs);
            for chunk in [0, 1, 30, 300] {
                let mut enc =
                    PositionStreamEncoder::new(kind, Station(0x42), 0, 6, recs.iter()).unwrap();
                assert_eq!(pull(&mut enc, chunk), (expect.clone(), None));
            }
            // Longer than the stage: refused when it does not fit `out`.
            kind.layout = RecordLayout {
                number_width: 16,
                extended: true,
            };
            let rec = PositionRecord::new(
                1,
                0,
                0,
                0,
                &[
                    (1, 1),
                    (2, 2),
                    (3, 3),
                    (4, 4),
                    (5, 5),
                    (6, 6),
                    (7, 7),
                    (8, 8),
                ],
            )
            .unwrap();
            let mut enc =
                PositionStreamEncoder::new(kind, Station(0x42), 0, 1, core::iter::once(&rec))
                    .unwrap();
            assert_eq!(pull(&mut enc, 300).1, None, "fits a large enough out");
            let mut enc =
                PositionStreamEncoder::new(kind, Station(0x42), 0, 1, core::iter::once(&rec))
                    .unwrap();
            assert_eq!(pull(&mut enc, 50).1, Some(Error::BufferTooSmall));
        }

        #[test]
        fn refusals_leave_the_frame_unterminated() {
            let mut next = xorshift(47);
            let kind = PositionStream::CHANGE_2;
            let recs = records(kind, 5, &mut next);
            let full = reference(kind, 0, &recs);
            for chunk in [0, 1, 64, 300] {
                // The source ends early.
                let mut enc =
                    PositionStreamEncoder::new(kind, Station(0x42), 0, 6, recs.iter()).unwrap();
                let (got, err) = pull(&mut enc, chunk);
                assert_eq!(
                    err,
                    Some(Error::CountMismatch {
                        expected: 6,
                        found: 5
                    })
                );
                assert!(full.starts_with(&got[..got.len().min(6)]), "the envelope");
                assert!(!got.ends_with(b"\r\n"));
                assert_eq!(enc.read(&mut [0u8; 8]), Ok(0), "nothing after a refusal");
                // Or runs long.
                let mut enc =
                    PositionStreamEncoder::new(kind, Station(0x42), 0, 4, recs.iter()).unwrap();
                assert_eq!(
                    pull(&mut enc, chunk).1,
                    Some(Error::CountMismatch {
                        expected: 4,
                        found: 5
                    })
                );
                // A record whose coordinates do not match its pattern, third.
                let mut bad = recs.clone();
                bad[2].positions.clear();
                if bad[2].axes.is_empty() {
                    bad[2].positions.push(1).unwrap();
                }
                let mut enc =
                    PositionStreamEncoder::new(kind, Station(0x42), 0, 5, bad.iter()).unwrap();
                let (got, err) = pull(&mut enc, chunk);
                assert!(matches!(err, Some(Error::CountMismatch { .. })), "{err:?}");
                assert_eq!(enc.records_emitted(), 2);
                assert!(got.len() < full.len() - 4);
                assert_eq!(enc.read(&mut [0u8; 8]), Ok(0));
            }
            // A number too wide for 3 digits.
            let mut recs = records(PositionStream::CHANGE, 2, &mut next);
            recs[1].number = 0x1000;
            let mut enc = PositionStreamEncoder::new(
                PositionStream::CHANGE,
                Station(0x42),
                0,
                2,
                recs.iter(),
            )
            .unwrap();
            assert_eq!(
                pull(&mut enc, 64).1,
                Some(Error::ValueOutOfRange { offset: 0 })
            );
            // What the prefix cannot carry is refused up front.
            assert_eq!(
                PositionStreamEncoder::new(kind, Station(0x42), 0, 20_001, recs.iter()).err(),
                Some(Error::CountTooLarge {
                    count: 20_001,
                    max: 20_000
                })
            );
            assert!(PositionStreamEncoder::new(
                PositionStream::RANGE,
                Station(0x42),
                0x1000,
                1,
                recs.iter()
            )
            .is_err());
        }
    }
}
