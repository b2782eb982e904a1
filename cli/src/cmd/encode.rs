//! `iai encode`: one frame from field=value arguments or JSON.

use std::io::{self, Write};
use std::process::ExitCode;

use iai_cli::encode::{encode, field_help, find_message, EncodeOptions};
use iai_cli::text::escape;
use iai_protocol_b::catalogue;
use iai_protocol_b::frame::Header;

use super::{out_err, Run};
use crate::MessageArgs;

pub(crate) fn message_json(msg: &MessageArgs) -> Result<Option<serde_json::Value>, String> {
    let (text, from) = match (&msg.fields_json, &msg.fields_file) {
        (Some(t), _) => (t.clone(), "--fields-json".to_string()),
        (None, Some(p)) => (
            std::fs::read_to_string(p)
                .map_err(|e| format!("--fields-file {}: cannot read it: {e}", p.display()))?,
            format!("--fields-file {}", p.display()),
        ),
        (None, None) => return Ok(None),
    };
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| format!("{from}: not valid JSON: {e}"))
}

pub(crate) fn build(
    msg: &MessageArgs,
    station: u8,
    response: bool,
    bypass: bool,
) -> Result<Vec<u8>, String> {
    let opts = EncodeOptions {
        message: msg.message.clone(),
        assignments: msg.assignments.clone(),
        station,
        response,
        bypass,
        json: message_json(msg)?,
    };
    encode(&opts)
}

pub(crate) fn encode_cmd(
    msg: &MessageArgs,
    station: u8,
    response: bool,
    bypass: bool,
    fields: bool,
    raw: bool,
) -> Run {
    let mut out = io::stdout().lock();
    let header = if response {
        Header::Response
    } else {
        Header::Command
    };
    if fields {
        let id = find_message(&msg.message, header)?;
        writeln!(
            out,
            "{id:03X}H {} ({}):",
            catalogue::lookup(id).map(|m| m.name).unwrap_or(""),
            if response { "response" } else { "command" }
        )
        .map_err(out_err)?;
        for l in field_help(header, id) {
            writeln!(out, "{l}").map_err(out_err)?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    let frame = build(msg, station, response, bypass)?;
    let sc = frame
        .len()
        .checked_sub(4)
        .and_then(|at| frame.get(at..at + 2))
        .map(|s| String::from_utf8_lossy(s).into_owned())
        .unwrap_or_default();
    // Only the frame goes to stdout, so that `iai encode … | iai inspect -`
    // and redirections get the frame alone.
    if raw {
        out.write_all(&frame)
            .and_then(|_| out.flush())
            .map_err(out_err)?;
    } else {
        writeln!(out, "{}", escape(&frame)).map_err(out_err)?;
    }
    eprintln!("checksum {sc}, {} bytes", frame.len());
    Ok(ExitCode::SUCCESS)
}
