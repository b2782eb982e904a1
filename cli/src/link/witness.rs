//! What came back on a line, seen beside the engines: every byte read is
//! decoded again here, and the frames and noise are counted by kind, so
//! that a failure can name its likely cause: our own frames echoed back,
//! bytes that are not protocol B (a wrong baud rate or framing), replies
//! from another station, or nothing at all.

use std::collections::{BTreeMap, VecDeque};

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::Header;

/// Frames sent that an echo is compared with (the latest).
const REMEMBERED: usize = 8;

/// Counts of what a line received.
pub struct Witness {
    station: u8,
    dec: Box<FrameDecoder<4096>>,
    sent: VecDeque<Vec<u8>>,
    /// Bytes received.
    pub bytes_in: u64,
    /// Frames identical to one this side sent.
    pub echoes: u32,
    /// Other command frames (`!`) received.
    pub commands: u32,
    /// Replies (`#`, `&`) from the station addressed.
    pub ours: u32,
    /// Replies from other stations, by station.
    pub foreign: BTreeMap<u8, u32>,
    /// Broken frames (bad checksum, cut short, too long).
    pub broken: u32,
}

impl Witness {
    /// A witness for a line to `station`.
    pub fn new(station: u8) -> Self {
        Witness {
            station,
            dec: Box::new(FrameDecoder::with_policy(BypassPolicy::Accept)),
            sent: VecDeque::new(),
            bytes_in: 0,
            echoes: 0,
            commands: 0,
            ours: 0,
            foreign: BTreeMap::new(),
            broken: 0,
        }
    }

    /// This side sent `bytes` (one frame, or a part of a long one).
    pub fn sent(&mut self, bytes: &[u8]) {
        if bytes.len() > 4096 {
            return;
        }
        if self.sent.len() == REMEMBERED {
            self.sent.pop_front();
        }
        self.sent.push_back(bytes.to_vec());
    }

    /// Bytes arrived.
    pub fn received(&mut self, mut bytes: &[u8]) {
        self.bytes_in += bytes.len() as u64;
        while !bytes.is_empty() {
            let r = self.dec.decode(bytes);
            bytes = bytes.get(r.consumed..).unwrap_or(&[]);
            match r.status {
                Status::Partial => {}
                Status::Complete(Event::Frame(f)) => {
                    let raw = f.as_bytes();
                    if f.header() == Header::Command {
                        if self.sent.iter().any(|s| s.as_slice() == raw) {
                            self.echoes += 1;
                        } else {
                            self.commands += 1;
                        }
                    } else if f.station().0 == self.station {
                        self.ours += 1;
                    } else {
                        *self.foreign.entry(f.station().0).or_insert(0) += 1;
                    }
                }
                Status::Complete(Event::Error(_)) => self.broken += 1,
            }
            if r.consumed == 0 {
                break;
            }
        }
    }

    /// Bytes that belonged to no frame, or to broken ones.
    pub fn garbage(&self) -> u64 {
        u64::from(self.dec.stats().discarded_bytes)
    }

    /// The likely cause of a line that gave no valid reply, from what
    /// came back; `None` when the replies looked right.
    pub fn hint(&self) -> Option<String> {
        let st = self.station;
        if self.bytes_in == 0 {
            return Some(
                "nothing came back at all: check the port and the cable (TX and RX crossed?), that the controller is on, in AUTO mode, with I/O parameter No. 90 = 2 (IAI protocol B) on this port; `iai probe` tries every baud rate and station".to_string(),
            );
        }
        if self.echoes > 0 && self.ours == 0 {
            return Some(format!(
                "our own frames came back ({} of them, each the command as sent): a loopback, an RS-485 converter that echoes, or TX joined to RX; no controller answered",
                self.echoes
            ));
        }
        if !self.foreign.is_empty() && self.ours == 0 {
            let list: Vec<String> = self
                .foreign
                .iter()
                .map(|(s, n)| format!("{s:02X} ({n} frame(s))"))
                .collect();
            let first = self.foreign.keys().next().copied().unwrap_or(0);
            return Some(format!(
                "replies came from station {}, not {st:02X}: wrong --station? Try --station {first:02X}",
                list.join(", ")
            ));
        }
        let garbage = self.garbage();
        if garbage > 0 && self.ours == 0 {
            return Some(format!(
                "{garbage} of the {} byte(s) that came back are not protocol B ({} broken frame(s)): a wrong baud rate, data bits, parity or stop bits? `iai probe` tries the baud rates",
                self.bytes_in, self.broken
            ));
        }
        if self.broken > 0 {
            return Some(format!(
                "{} broken frame(s) came back (bad checksum or cut short) among {} from station {st:02X}: a noisy line, or a framing mismatch",
                self.broken, self.ours
            ));
        }
        None
    }
}
