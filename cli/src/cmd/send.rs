//! `iai send`: one command and its reply.

use std::io::{self, Write};
use std::process::ExitCode;

use iai_cli::inspect;
use iai_cli::send::{describe, failure_json, plain_failure_json, request, Outcome};

use super::encode::build;
use super::monitor::print_item;
use super::{out_err, unanswered, Failure, Run};
use crate::{LineArgs, MessageArgs};

pub(crate) fn show_frame(out: &mut impl Write, frame: &[u8], json: bool) -> io::Result<()> {
    let mut ins = inspect::Inspector::new();
    ins.feed(frame);
    ins.finish();
    for item in ins.take_items() {
        print_item(out, &item, json)?;
    }
    Ok(())
}

pub(crate) fn send_cmd(msg: &MessageArgs, line: &LineArgs, json: bool, detail: bool) -> Run {
    match exchange(msg, line, json, detail) {
        Err(Failure::Failed(m)) if json => {
            // Whatever stopped it before an answer: one object on stdout too.
            let mut out = io::stdout().lock();
            writeln!(out, "{}", plain_failure_json("command", &m)).map_err(out_err)?;
            Err(Failure::Failed(m))
        }
        r => r,
    }
}

fn exchange(msg: &MessageArgs, line: &LineArgs, json: bool, detail: bool) -> Run {
    let frame = build(msg, line.station, false, false)?;
    let profile = line.profile.profile();
    if let Ok(f) = iai_protocol_b::frame::Frame::new_checked(
        &frame,
        iai_protocol_b::checksum::BypassPolicy::Reject,
    ) {
        if !profile.supports(f.code()) {
            return Err(format!(
                "{:03X}H is not a message of the {} profile",
                f.code(),
                profile.name()
            )
            .into());
        }
        profile
            .check_command_len(frame.len())
            .map_err(|e| format!("{:03X}H: {e}", f.code()))?;
    }
    let mut link = line.open()?;
    let target = link.target().clone();
    let mut out = io::stdout().lock();
    let outcome = request(&mut link, &frame, detail).map_err(|e| format!("{target}: {e}"))?;
    if let Some(note) = link.repeats_note() {
        eprintln!("{note}");
    }
    let e = match outcome {
        Outcome::Reply(reply) => {
            show_frame(&mut out, &reply, json).map_err(out_err)?;
            return Ok(ExitCode::SUCCESS);
        }
        Outcome::NoReplyExpected => {
            if json {
                writeln!(
                    out,
                    "{}",
                    serde_json::json!({"type": "sent", "reply": "none"})
                )
            } else {
                writeln!(
                    out,
                    "sent; this command has no normal response and no error response came"
                )
            }
            .map_err(out_err)?;
            return Ok(ExitCode::SUCCESS);
        }
        Outcome::Failed(e) => e,
    };
    let hint = if unanswered(&e) { link.hint() } else { None };
    let mut message = describe(&e, &target, detail, link.line().config().timeout_ms);
    if json {
        let mut v: serde_json::Value =
            serde_json::from_str(&failure_json(&e, &message)).unwrap_or_default();
        if let Some(h) = &hint {
            v["hint"] = serde_json::json!(h);
        }
        writeln!(out, "{v}").map_err(out_err)?;
        out.flush().map_err(out_err)?;
        if let Some(h) = &hint {
            message.push_str(&format!("\n  hint: {h}"));
        }
        return Err(Failure::Exit(1, message));
    }
    if let Some(h) = &hint {
        message.push_str(&format!("\n  hint: {h}"));
    }
    Err(message.into())
}
