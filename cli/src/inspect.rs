//! `iai inspect`: a capture (raw bytes or a text log) as a listing of
//! frames and errors, each at its byte offset.
//!
//! [`run`] reads the capture in chunks and feeds an [`Inspector`] (a text
//! log unescaped line by line first), handing each entry on as soon as it
//! is found; [`command`] prints the entries as JSON lines or text.
//! Submodules: `item` (the entries), `inspector` (bytes in, entries out:
//! frames, errors and position streams), `listing` (the two output forms)
//! and `text_log` (reading text logs).

mod held;
mod inspector;
mod item;
mod listing;
mod text_log;

pub use inspector::Inspector;
pub use item::{frame_item, FrameItem, Item, Origin, StreamItem, What};
pub use listing::{json_line, text_entry};
pub use text_log::split_prefix;

use std::io::{BufRead, Read, Write};

use text_log::TextLog;

/// Input format of a capture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Bytes as on the wire.
    Raw,
    /// One frame per line, escaped, optional direction prefix.
    Text,
}

/// Why inspecting stopped: the input could not be read, or the output
/// could not be written (a closed pipe, for one).
#[derive(Debug)]
pub enum InspectError {
    /// Reading the capture failed.
    Read(std::io::Error),
    /// Writing the listing failed.
    Write(std::io::Error),
}

/// Inspects a whole capture, calling `emit` for each entry as it is found.
/// Returns (frames, errors). Memory stays the same whatever the size of
/// the capture or of its lines.
pub fn run(
    mut input: impl BufRead,
    format: Format,
    mut emit: impl FnMut(&Item) -> std::io::Result<()>,
) -> Result<(u64, u64), InspectError> {
    let mut ins = Inspector::new();
    let mut counts = (0u64, 0u64);
    let mut drain = |ins: &mut Inspector, counts: &mut (u64, u64)| -> Result<(), InspectError> {
        for item in ins.take_items() {
            if item.is_error() {
                counts.1 += 1;
            } else {
                counts.0 += 1;
            }
            emit(&item).map_err(InspectError::Write)?;
        }
        Ok(())
    };
    let mut text = TextLog::default();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = match input.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(InspectError::Read(e)),
        };
        if n == 0 {
            break;
        }
        let chunk = buf.get(..n).unwrap_or(&[]);
        match format {
            Format::Raw => ins.feed(chunk),
            Format::Text => text.feed(chunk, &mut ins),
        }
        drain(&mut ins, &mut counts)?;
    }
    text.finish(&mut ins);
    ins.finish();
    drain(&mut ins, &mut counts)?;
    Ok(counts)
}

/// Guesses the format from the first bytes: escaped `\r` or a direction
/// prefix means a text log; otherwise a CR byte means raw bytes; a file
/// without either is read as a text log (one frame per line).
pub fn guess_format(head: &[u8]) -> Format {
    let escaped = head.windows(2).any(|w| w == b"\\r");
    let prefixed = head
        .split(|b| *b == b'\n')
        .any(|l| split_prefix(l.trim_ascii_start()).0.is_some());
    if escaped || prefixed || !head.contains(&b'\r') {
        Format::Text
    } else {
        Format::Raw
    }
}

/// `iai inspect` with parsed options; returns the process exit code
/// (0, or 1 when the capture had errors).
pub fn command(
    path: &str,
    format: Option<Format>,
    json: bool,
    out: &mut impl Write,
) -> Result<i32, InspectError> {
    let reader: Box<dyn Read> = if path == "-" {
        Box::new(std::io::stdin().lock())
    } else {
        Box::new(std::fs::File::open(path).map_err(InspectError::Read)?)
    };
    let mut reader = std::io::BufReader::with_capacity(1 << 16, reader);
    let format = match format {
        Some(f) => f,
        None => guess_format(reader.fill_buf().map_err(InspectError::Read)?),
    };
    let (frames, errors) = run(reader, format, |item| {
        if json {
            writeln!(out, "{}", json_line(item))
        } else {
            for l in text_entry(item) {
                writeln!(out, "{l}")?;
            }
            Ok(())
        }
    })?;
    if !json {
        writeln!(out, "-- {frames} frame(s), {errors} error(s)").map_err(InspectError::Write)?;
    }
    out.flush().map_err(InspectError::Write)?;
    Ok(if errors > 0 { 1 } else { 0 })
}
