//! `iai send`: one command and its reply, through the core's request
//! engine ([`Client`]) on the link's line: chapter 5's timeout and resends
//! (2003 p. 62), a resend only where the catalogue says repeating the
//! command is safe, 25BH's missing reply, and `&` codes with their
//! optional 216H detail.

use std::time::Duration;

use iai_protocol_b::{client::Client, error::Failure};

use crate::link::Link;

/// How a request ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The normal response (the whole frame).
    Reply(Vec<u8>),
    /// The command has no normal response, and no error response came.
    NoReplyExpected,
    /// The engine's verdict when no normal response came.
    Failed(Failure),
}

/// Sends `frame` (a complete command frame) and waits for its reply;
/// with `detail`, an error response is followed by the 216H query.
pub fn request(link: &mut Link, frame: &[u8], detail: bool) -> std::io::Result<Outcome> {
    let mut client: Box<Client> = Box::new(Client::new().with_proof());
    if detail {
        *client = Client::new()
            .with_proof()
            .with_error_detail_except(firmware_example::codes::is_bridge_code);
    }
    let now = link.now();
    client
        .start_frame(link.line_mut(), frame, now)
        .map_err(|e| std::io::Error::other(format!("not a command frame: {e}")))?;
    loop {
        match link.turn(client.as_mut(), Duration::from_millis(200))? {
            None => {}
            Some(Ok(())) => {
                return Ok(match client.reply_frame() {
                    Some(f) => Outcome::Reply(f.as_bytes().to_vec()),
                    None => Outcome::NoReplyExpected,
                })
            }
            Some(Err(e)) => return Ok(Outcome::Failed(e)),
        }
    }
}

/// What a failed request means, for the user: `target` is the line,
/// `asked_detail` whether 216H was asked for, `timeout_ms` the wait for
/// each reply.
pub fn describe(
    e: &Failure,
    target: &impl std::fmt::Display,
    asked_detail: bool,
    timeout_ms: u32,
) -> String {
    match *e {
        Failure::Controller {
            code,
            detail: fetched,
        } => {
            let mut m = crate::codes::answered_with(code);
            if let Some(d) = fetched {
                m.push_str(&format!(
                    "; 216H latest system error {:03X}{}: details {} {} {} {} {:?}",
                    d.error_number,
                    if d.matches_code {
                        ""
                    } else {
                        " (not the same number: it may be another error)"
                    },
                    d.detail_1,
                    d.detail_2,
                    d.detail_3,
                    d.detail_4,
                    d.detail_5_to_8
                ));
            } else if asked_detail {
                m.push_str("; the 216H detail did not come");
            }
            m
        }
        Failure::Timeout { sends } => {
            format!(
                "no valid reply from {target} after {sends} send(s), {} each",
                wait_text(timeout_ms)
            )
        }
        Failure::OutcomeUnknown { sends } => format!(
            "no valid reply from {target} after {sends} send(s); not sent again, since a second send could repeat the operation: check the controller's state (212H)"
        ),
        Failure::Protocol(e) => format!("the reply does not decode: {e}"),
        e => format!("{e}"),
    }
}

/// "3 s" or "200 ms".
pub fn wait_text(ms: u32) -> String {
    if ms.is_multiple_of(1000) {
        format!("{} s", ms / 1000)
    } else {
        format!("{ms} ms")
    }
}

/// A failed request as one JSON object (for `iai send --json`, on
/// stdout): `{"type":"failure","failure":KIND,…,"message":TEXT}`. KIND is
/// `error_response` (with the `code`, its `meaning` where the tool knows
/// it, and the 216H `detail` if it came), `timeout`, `outcome_unknown`
/// (with `sends`), or another failure's kind.
pub fn failure_json(e: &Failure, message: &str) -> String {
    use serde_json::json;
    let mut v = match *e {
        Failure::Controller { code, detail } => {
            let mut v = json!({
                "type": "failure",
                "failure": "error_response",
                "code": format!("{code:03X}"),
            });
            if let Some(m) = crate::codes::meaning(code) {
                v["meaning"] = json!(m);
            }
            if let Some(d) = detail {
                v["detail"] = json!({
                    "error_number": format!("{:03X}", d.error_number),
                    "matches_code": d.matches_code,
                    "detail_1": d.detail_1,
                    "detail_2": d.detail_2,
                    "detail_3": d.detail_3,
                    "detail_4": d.detail_4,
                    "detail_5_to_8": d.detail_5_to_8,
                });
            }
            v
        }
        Failure::Timeout { sends } => {
            json!({"type": "failure", "failure": "timeout", "sends": sends})
        }
        Failure::OutcomeUnknown { sends } => {
            json!({"type": "failure", "failure": "outcome_unknown", "sends": sends})
        }
        Failure::Unconfirmed { unplaced } => {
            json!({"type": "failure", "failure": "unconfirmed", "unplaced": unplaced})
        }
        Failure::Protocol(_) => json!({"type": "failure", "failure": "protocol"}),
        _ => json!({"type": "failure", "failure": "other"}),
    };
    v["message"] = json!(message);
    v.to_string()
}

/// A failure before or beside the exchange (bad arguments, a line that
/// cannot be opened) as one JSON object.
pub fn plain_failure_json(kind: &str, message: &str) -> String {
    serde_json::json!({"type": "failure", "failure": kind, "message": message}).to_string()
}
