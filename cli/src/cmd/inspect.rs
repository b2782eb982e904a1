//! `iai inspect`: a capture as a listing.

use std::io;
use std::process::ExitCode;

use iai_cli::inspect::{self, Format, InspectError};

use super::{out_err, Failure, Run};
use crate::FormatArg;

pub(crate) fn inspect_cmd(file: &str, json: bool, format: Option<FormatArg>) -> Run {
    let format = format.map(|f| match f {
        FormatArg::Raw => Format::Raw,
        FormatArg::Text => Format::Text,
    });
    let mut out = io::BufWriter::new(io::stdout().lock());
    match inspect::command(file, format, json, &mut out) {
        Ok(code) => Ok(ExitCode::from(u8::try_from(code).unwrap_or(1))),
        Err(InspectError::Write(e)) => Err(out_err(e)),
        Err(InspectError::Read(e)) => Err(Failure::Failed(format!("{file}: cannot read it: {e}"))),
    }
}
