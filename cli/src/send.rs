//! `iai send`: one command, its reply under the timeout-and-retry rules of
//! the 2003 spec's chapter 5 (2003 p. 62).
//!
//! A reply counts only if it is a normal response from the same station
//! with the same message ID, or an error response from the same station.
//! Without one within [`TIMEOUT_MS`] after the command was sent, the
//! command is sent again, [`MAX_SENDS`] sends in all, but only when sending
//! it twice cannot repeat an operation: queries and position-table writes
//! (which write the same records again). Any other command is sent once.
//! 25BH (software reset) has no normal response: it is sent once and only
//! an error response is waited for.
//!
//! The core on this branch has no general request engine yet (its
//! transfer and read-back engines apply the same rules to position
//! tables); this module is the interim one.

use std::time::Duration;

use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::message::{message_name, Response};
use iai_protocol_b::stream::PositionStream;

use crate::link::Link;

/// Reply timeout after the end of transmission, ms (2003 p. 62).
pub const TIMEOUT_MS: u32 = 3000;
/// Sends of one command at most (2003 p. 62: 2 or 3 re-sends; 3 sends).
pub const MAX_SENDS: u32 = 3;

/// How a request ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The normal response (the whole frame).
    Reply(Vec<u8>),
    /// An error response with this code.
    Refused(u16),
    /// No response is defined for this command, and no error came.
    NoReplyExpected,
    /// No valid reply after this many sends.
    Timeout {
        /// Sends made.
        sends: u32,
        /// Whether the command could be sent again.
        resend_safe: bool,
    },
}

/// Whether sending `id` twice cannot repeat an operation.
pub fn resend_safe(id: u16) -> bool {
    let query = message_name(id).is_some_and(|n| n.contains("Query"));
    query || PositionStream::find(Header::Command, id).is_some()
}

/// Sends `frame` (a checked command) and waits for its reply.
pub fn request(link: &mut Link, frame: &[u8]) -> std::io::Result<Outcome> {
    let (station, id) = match Frame::new_checked(frame, BypassPolicy::Accept) {
        Ok(f) => (f.station(), f.code()),
        Err(e) => return Err(std::io::Error::other(format!("not a frame: {e}"))),
    };
    let replies = Response::default_for(id).is_some();
    let safe = resend_safe(id);
    let sends = if replies && safe { MAX_SENDS } else { 1 };
    let mut dec: Box<FrameDecoder<4096>> =
        Box::new(FrameDecoder::with_policy(BypassPolicy::Reject));
    let mut buf = [0u8; 4096];
    for _ in 0..sends {
        dec.reset();
        link.write_all(frame)?;
        let deadline = link.now().saturating_add(TIMEOUT_MS);
        loop {
            let now = link.now();
            if now >= deadline {
                break;
            }
            let wait = Duration::from_millis(u64::from(deadline - now));
            let n = link.read_for(&mut buf, wait.min(Duration::from_millis(200)))?;
            let mut rest = buf.get(..n).unwrap_or(&[]);
            while !rest.is_empty() {
                let d = dec.decode(rest);
                rest = rest.get(d.consumed..).unwrap_or(&[]);
                if let Event::Frame(f) = d.event {
                    if let Some(o) = matches(&f, station, id) {
                        return Ok(o);
                    }
                }
                if d.consumed == 0 {
                    break;
                }
            }
        }
    }
    if !replies {
        return Ok(Outcome::NoReplyExpected);
    }
    Ok(Outcome::Timeout {
        sends,
        resend_safe: safe,
    })
}

fn matches(f: &Frame<'_>, station: Station, id: u16) -> Option<Outcome> {
    if f.station() != station {
        return None;
    }
    match f.header() {
        Header::Error => Some(Outcome::Refused(f.code())),
        Header::Response if f.code() == id => Some(Outcome::Reply(f.as_bytes().to_vec())),
        _ => None,
    }
}
