//! `iai probe`: what a line answers. Each try sends a 200H test call whose
//! ten characters are a nonce (2003 p. 15: the controller sends them
//! back) to one station, and [`observe`] sorts what came back within the
//! timeout: the echo of the nonce from that station (a controller
//! answers), an `&` from it, our own frame echoed back, replies from other
//! stations (tried next), or bytes that are not protocol B (a wrong baud
//! rate or framing).

use std::collections::BTreeSet;

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::{Header, Station};
use iai_protocol_b::message::{Message, TestCall, TestCallResponse};

use crate::codes;

/// A 200H test call to `station` carrying `nonce`.
pub fn test_call(station: u8, nonce: &[u8; 10]) -> Vec<u8> {
    let call = TestCall {
        test_string: *nonce,
    };
    let mut buf = vec![0u8; call.emit_len()];
    let n = call.emit(Station(station), &mut buf).unwrap_or(0);
    buf.truncate(n);
    buf
}

/// Ten characters for a test call: `P` and nine upper-case hex digits of
/// `seed` (never a frame's header, CR, LF or XON/XOFF).
pub fn nonce(seed: u64) -> [u8; 10] {
    let mut out = *b"P000000000";
    let digits = format!("{:09X}", seed & 0xF_FFFF_FFFF);
    for (slot, d) in out.iter_mut().skip(1).zip(digits.bytes()) {
        *slot = d;
    }
    out
}

/// What the station tried answered, if anything.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// The test call came back with the nonce: a controller (or a bridge
    /// passing it on) answers at this station.
    Echoed,
    /// An `&` reply with this code.
    Refused(u16),
    /// A `#` reply to another ID, or with another text.
    Other(u16),
}

/// What came back after one test call.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Observation {
    /// Bytes received.
    pub bytes: usize,
    /// The test call itself came back (a loopback or an echoing converter).
    pub echo: bool,
    /// The reply of the station tried.
    pub reply: Option<Reply>,
    /// Other stations that sent replies.
    pub foreign: BTreeSet<u8>,
    /// Bytes that were not part of a valid frame.
    pub garbage: u64,
    /// Valid frames that are none of the above.
    pub other_frames: u32,
}

/// Sorts `received`, the bytes that came after `sent` (a test call to
/// `station` with `nonce`).
pub fn observe(sent: &[u8], station: u8, nonce: &[u8; 10], received: &[u8]) -> Observation {
    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Accept);
    let mut o = Observation {
        bytes: received.len(),
        ..Observation::default()
    };
    let mut rest = received;
    while !rest.is_empty() {
        let r = dec.decode(rest);
        rest = rest.get(r.consumed..).unwrap_or(&[]);
        if let Status::Complete(Event::Frame(f)) = r.status {
            let st = f.station().0;
            match f.header() {
                Header::Command if f.as_bytes() == sent => o.echo = true,
                Header::Command => o.other_frames += 1,
                _ if st != station => {
                    o.foreign.insert(st);
                }
                Header::Error => o.reply = Some(Reply::Refused(f.code())),
                _ if TestCallResponse::parse(&f).is_ok_and(|r| r.test_string == *nonce) => {
                    o.reply = Some(Reply::Echoed)
                }
                _ => o.reply = Some(Reply::Other(f.code())),
            }
        }
        if r.consumed == 0 {
            break;
        }
    }
    // What a cut frame left at the end counts as garbage too.
    o.garbage = u64::from(dec.stats().discarded_bytes) + dec.pending() as u64;
    o
}

impl Observation {
    /// A short name of the result (`answered`, `error_reply`, `echo`,
    /// `other_station`, `garbage`, `other`, `silent`).
    pub fn kind(&self) -> &'static str {
        match (&self.reply, self.echo) {
            (Some(Reply::Echoed), _) => "answered",
            (Some(Reply::Refused(_)), _) => "error_reply",
            (Some(Reply::Other(_)), _) => "other",
            (None, true) => "echo",
            (None, false) if !self.foreign.is_empty() => "other_station",
            (None, false) if self.garbage > 0 => "garbage",
            (None, false) if self.bytes > 0 => "other",
            _ => "silent",
        }
    }

    /// What the result means, in words.
    pub fn describe(&self, station: u8) -> String {
        let mut parts = Vec::new();
        match &self.reply {
            Some(Reply::Echoed) => parts.push(format!(
                "ANSWERED: station {station:02X} sent the test call's text back"
            )),
            Some(Reply::Refused(code)) => parts.push(format!(
                "station {station:02X} answered & {code:03X}{} (something listens there)",
                codes::meaning(*code).map_or(String::new(), |m| format!(" ({m})"))
            )),
            Some(Reply::Other(id)) => parts.push(format!(
                "station {station:02X} answered, but not the test call ({id:03X}H)"
            )),
            None => {}
        }
        if self.echo {
            parts.push("our own frame came back (a loopback or an echoing converter)".into());
        }
        if !self.foreign.is_empty() {
            let list: Vec<String> = self.foreign.iter().map(|s| format!("{s:02X}")).collect();
            parts.push(format!("replies from station {}", list.join(", ")));
        }
        if self.garbage > 0 {
            parts.push(format!(
                "{} byte(s) that are not protocol B (wrong baud rate or framing?)",
                self.garbage
            ));
        }
        if self.other_frames > 0 {
            parts.push(format!("{} other frame(s)", self.other_frames));
        }
        if parts.is_empty() {
            parts.push("nothing came back".into());
        }
        parts.join("; ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use iai_protocol_b::checksum::ChecksumMode;
    use iai_protocol_b::frame::emit_frame;

    fn reply(station: u8, id: u16, body: &[u8], header: Header) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let n = emit_frame(
            &mut buf,
            header,
            Station(station),
            id,
            ChecksumMode::Compute,
            |w| w.put(body),
        )
        .unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn each_kind_of_answer_is_told_apart() {
        let n = nonce(0x1234);
        assert_eq!(&n, b"P000001234");
        let sent = test_call(0x99, &n);
        assert_eq!(&sent[..7], b"!99200P");
        let ours = reply(0x99, TestCallResponse::ID, &n, Header::Response);
        assert_eq!(observe(&sent, 0x99, &n, &ours).kind(), "answered");
        assert_eq!(observe(&sent, 0x99, &n, &sent).kind(), "echo");
        let other = reply(0x12, TestCallResponse::ID, &n, Header::Response);
        let o = observe(&sent, 0x99, &n, &other);
        assert_eq!(o.kind(), "other_station");
        assert_eq!(o.foreign.iter().copied().collect::<Vec<_>>(), vec![0x12]);
        let noise: Vec<u8> = (0..40u8).map(|i| i.wrapping_mul(97) | 0x80).collect();
        let o = observe(&sent, 0x99, &n, &noise);
        assert_eq!((o.kind(), o.garbage), ("garbage", 40));
        assert_eq!(observe(&sent, 0x99, &n, &[]).kind(), "silent");
        let refused = reply(0x99, 0xB06, b"", Header::Error);
        let o = observe(&sent, 0x99, &n, &refused);
        assert_eq!(o.kind(), "error_reply");
        assert!(
            o.describe(0x99)
                .contains("bridge: the command policy refuses"),
            "{}",
            o.describe(0x99)
        );
        // A stale text is not our answer.
        let stale = reply(0x99, TestCallResponse::ID, b"P999999999", Header::Response);
        assert_eq!(observe(&sent, 0x99, &n, &stale).kind(), "other");
    }
}
