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
//! use iai_protocol_b::stream::{PositionStream, PositionStreamEncoder};
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

pub use crate::position::PositionStream;

use crate::checksum::{BypassPolicy, Checksum};
use crate::error::{Error, Result};
use crate::field::{hex_digit, hex_value, FieldSpec, Reader, Writer};
use crate::frame::{emit_envelope, Header, Station, ENVELOPE_LEN};
use crate::io::IoError;
use crate::position::{axis_count, PositionRecord};

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
        self.buf.get(self.pos..self.len).unwrap_or(&[])
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EncPhase {
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
    count: u16,
    emitted: u16,
    sum: Checksum,
    stage: Stage,
    phase: EncPhase,
}

impl<I: Iterator<Item = PositionRecord>> PositionStreamEncoder<I> {
    /// Starts a frame of `kind` from `station` with `count` records taken
    /// from `source` (`start` is the start number where the message has one).
    pub fn new(
        kind: PositionStream,
        station: Station,
        start: u16,
        count: u16,
        source: I,
    ) -> Result<Self> {
        let mut stage = Stage::new();
        let mut w = Writer::new(&mut stage.buf);
        emit_envelope(&mut w, kind.header, station, kind.id)?;
        kind.write_prefix(&mut w, start, count)?;
        stage.len = w.len();
        let mut sum = Checksum::new();
        sum.update(stage.pending());
        Ok(PositionStreamEncoder {
            kind,
            source,
            count,
            emitted: 0,
            sum,
            stage,
            phase: EncPhase::Records,
        })
    }

    /// Records emitted so far.
    pub fn records_emitted(&self) -> u16 {
        self.emitted
    }

    /// Fills `out` with the next bytes of the frame; `Ok(0)` once the whole
    /// frame (through LF) was produced.
    pub fn read(&mut self, out: &mut [u8]) -> Result<usize> {
        let mut n = 0;
        while n < out.len() {
            let room = out.get_mut(n..).unwrap_or(&mut []);
            if self.stage.pos < self.stage.len {
                let k = copy_words(room, self.stage.pending());
                self.stage.pos += k;
                n += k;
                continue;
            }
            if self.phase == EncPhase::Records && self.emitted < self.count {
                let Some(rec) = self.source.next() else {
                    self.phase = EncPhase::Failed;
                    return Err(Error::CountMismatch {
                        expected: usize::from(self.count),
                        found: usize::from(self.emitted),
                    });
                };
                // Straight into `out` when the record fits, else staged.
                let fits = room.len() >= self.kind.layout.record_len(axis_count(rec.axes));
                let dst: &mut [u8] = if fits { room } else { &mut self.stage.buf };
                match self.kind.layout.put_record(&rec, dst) {
                    Ok((len, sum)) => {
                        self.sum.add_sum(sum);
                        self.emitted += 1;
                        if fits {
                            n += len;
                        } else {
                            self.stage.len = len;
                            self.stage.pos = 0;
                        }
                    }
                    Err(e) => {
                        self.phase = EncPhase::Failed;
                        return Err(e);
                    }
                }
                continue;
            }
            if !self.refill()? {
                break;
            }
        }
        Ok(n)
    }

    /// After the last record: loads the trailer into the stage; `false`
    /// when done. (`read` encodes the records.)
    fn refill(&mut self) -> Result<bool> {
        match self.phase {
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
    ) -> core::result::Result<usize, IoError<W::Error>> {
        let mut chunk = [0u8; STAGE_LEN];
        let mut total = 0;
        loop {
            let n = self.read(&mut chunk)?;
            if n == 0 {
                return Ok(total);
            }
            w.write_all(chunk.get(..n).unwrap_or(&[]))
                .map_err(IoError::Io)?;
            total += n;
        }
    }
}

/// What the [`PositionStreamDecoder`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StreamEvent {
    /// More bytes are needed.
    NeedMore,
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

    /// Consumes bytes until an event; returns `(consumed, event)`.
    ///
    /// Bytes are copied a whole field group at a time. After
    /// [`StreamEvent::End`] or [`StreamEvent::Error`] nothing more is
    /// consumed (`(0, NeedMore)`) until [`PositionStreamDecoder::reset`]:
    /// the rest of the input belongs to whatever follows the frame.
    pub fn decode(&mut self, input: &[u8]) -> (usize, StreamEvent) {
        let mut used = 0;
        while self.phase != DecPhase::Finished {
            let rest = input.get(used..).unwrap_or(&[]);
            if rest.is_empty() {
                break;
            }
            // A whole well-formed record in the input: read it in place.
            if self.phase == DecPhase::RecordHead && self.stage.len == 0 {
                if let Some(kind) = self.kind {
                    if let Some((rec, len, sum)) = kind.layout.read_fast(rest) {
                        self.sum.add_sum(sum);
                        self.offset += len;
                        self.done += 1;
                        self.enter_record_or_trailer(kind);
                        return (used + len, StreamEvent::Record(rec));
                    }
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
            if !keep && !matches!(ev, StreamEvent::Error { .. }) {
                self.offset += self.stage.len;
                self.stage.len = 0;
            }
            if ev != StreamEvent::NeedMore {
                return (used, ev);
            }
        }
        (used, StreamEvent::NeedMore)
    }

    /// Pushes one byte (ignored after the end of the frame, see [`Self::decode`]).
    pub fn push(&mut self, byte: u8) -> StreamEvent {
        self.decode(&[byte]).1
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

    fn fail(&mut self, error: Error) -> StreamEvent {
        self.phase = DecPhase::Finished;
        StreamEvent::Error {
            error,
            records_ok: self.done,
        }
    }

    /// Handles a complete unit of `need` bytes. Returns the event and
    /// whether the stage keeps its bytes (the unit grows instead).
    fn unit_complete(&mut self) -> (StreamEvent, bool) {
        let ev = self.unit_event();
        let keep = matches!(ev, StreamEvent::NeedMore);
        (ev, keep)
    }

    fn unit_event(&mut self) -> StreamEvent {
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
                StreamEvent::NeedMore
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
                        StreamEvent::Start {
                            kind,
                            station,
                            start,
                            count,
                        }
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
                        StreamEvent::NeedMore
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
                        StreamEvent::Record(rec)
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
                StreamEvent::End { records: self.done }
            }
            DecPhase::Finished => StreamEvent::NeedMore,
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

/// Copies as much of `src` as fits into `dst`, a 4-byte word at a time
/// (the library `memcpy` is slow for the short, unaligned pieces a record
/// leaves); returns the bytes copied.
#[inline(always)]
fn copy_words(dst: &mut [u8], src: &[u8]) -> usize {
    let n = dst.len().min(src.len());
    if let (Some(d), Some(s)) = (dst.get_mut(..n), src.get(..n)) {
        let mut dw = d.chunks_exact_mut(4);
        let mut sw = s.chunks_exact(4);
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

    /// Pushes `bytes` one at a time; the events other than `NeedMore`,
    /// with the index of the byte that gave each.
    fn push_all(bytes: &[u8]) -> std::vec::Vec<(usize, StreamEvent)> {
        let mut d = PositionStreamDecoder::new(BypassPolicy::CommandsOnly);
        bytes
            .iter()
            .enumerate()
            .map(|(i, &b)| (i, d.push(b)))
            .filter(|(_, e)| *e != StreamEvent::NeedMore)
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
        let (used, start) = d.decode(&broken);
        assert!(matches!(start, StreamEvent::Start { count: 2, .. }));
        assert_eq!(
            d.decode(&broken[used..]),
            (
                31 - used,
                StreamEvent::Error {
                    error: Error::BodyTooShort { offset: 30 },
                    records_ok: 0,
                }
            )
        );
    }
}
