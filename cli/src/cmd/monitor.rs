//! `iai monitor`: the frames arriving on a line, live.

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::atomic::Ordering;

use iai_cli::inspect;
use iai_cli::link::Link;

use super::{out_err, stop_flag, Run};
use crate::LineArgs;

pub(crate) fn print_item(out: &mut impl Write, item: &inspect::Item, json: bool) -> io::Result<()> {
    if json {
        writeln!(out, "{}", inspect::json_line(item))?;
    } else {
        for l in inspect::text_entry(item) {
            writeln!(out, "{l}")?;
        }
    }
    out.flush()
}

pub(crate) fn monitor_cmd(line: &LineArgs, json: bool) -> Run {
    let mut link = Link::open(&line.target(), line.plan().line)?;
    let stop = stop_flag();
    let mut ins = inspect::Inspector::new();
    let mut out = io::stdout().lock();
    let mut buf = [0u8; 4096];
    while !stop.load(Ordering::SeqCst) {
        let n = link
            .read_for(&mut buf, std::time::Duration::from_millis(100))
            .map_err(|e| format!("{}: {e}", line.target()))?;
        ins.feed(buf.get(..n).unwrap_or(&[]));
        for item in ins.take_items() {
            print_item(&mut out, &item, json).map_err(out_err)?;
        }
    }
    ins.finish();
    for item in ins.take_items() {
        print_item(&mut out, &item, json).map_err(out_err)?;
    }
    Ok(ExitCode::SUCCESS)
}
