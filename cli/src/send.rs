//! `iai send`: one command and its reply, through the core's request
//! engine ([`Client`]): chapter 5's timeout and resends (2003 p. 62), a
//! resend only where the catalogue says repeating the command is safe,
//! 25BH's missing reply, and `&` codes with their optional 216H detail.

use std::time::Duration;

use iai_protocol_b::client::{CallError, Client, ClientConfig, ClientStep, Outcome as Done};
use iai_protocol_b::frame::Station;

use crate::link::Link;

/// How a request ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The normal response (the whole frame).
    Reply(Vec<u8>),
    /// The command has no normal response, and no error response came.
    NoReplyExpected,
    /// The engine's verdict when no normal response came.
    Failed(CallError),
}

/// Sends `frame` (a complete command frame) and waits for its reply;
/// with `detail`, an error response is followed by the 216H query.
pub fn request(
    link: &mut Link,
    station: Station,
    frame: &[u8],
    detail: bool,
) -> std::io::Result<Outcome> {
    let mut cfg = ClientConfig::new(station);
    if detail {
        cfg = cfg.with_error_detail();
    }
    let mut client: Box<Client> = Box::new(Client::new(cfg));
    client
        .start_frame(frame, link.now())
        .map_err(|e| std::io::Error::other(format!("not a command frame: {e}")))?;
    let mut buf = [0u8; 4096];
    loop {
        let now = link.now();
        match client.poll(now) {
            ClientStep::Idle => return Ok(Outcome::NoReplyExpected),
            ClientStep::Transmit(bytes) => {
                link.write_all(bytes)?;
                client.sent(link.now());
            }
            ClientStep::WaitUntil(until) => {
                let left = Duration::from_millis(u64::from(until.saturating_sub(now)));
                let n = link.read_for(&mut buf, left.min(Duration::from_millis(200)))?;
                if n > 0 {
                    client.received_all(buf.get(..n).unwrap_or(&[]), link.now());
                }
            }
            ClientStep::Done(Ok(Done::Replied)) => {
                let reply = client
                    .reply_frame()
                    .map(|f| f.as_bytes().to_vec())
                    .unwrap_or_default();
                return Ok(Outcome::Reply(reply));
            }
            ClientStep::Done(Ok(Done::NoReplyExpected)) => return Ok(Outcome::NoReplyExpected),
            ClientStep::Done(Err(e)) => return Ok(Outcome::Failed(e)),
        }
    }
}
