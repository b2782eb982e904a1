//! `iai monitor`: the frames arriving on a line, live.

use std::io::{self, Write};
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Instant;

use iai_cli::inspect;
use iai_cli::link::{Flow, Link};
use iai_protocol_b::frame::Station;
use iai_protocol_b::line::LineConfig;

use super::line::DEFAULT_STATION;
use super::{out_err, stop_flag, Run, EXIT_INTERRUPTED};
use crate::LinkArgs;

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

/// An entry, prefixed with its time (ms since the monitor started) when
/// `t_ms` is given: `[+12.345 s]` before the text, `"t_ms"` in the JSON.
fn print_timed(
    out: &mut impl Write,
    item: &inspect::Item,
    json: bool,
    t_ms: Option<u128>,
) -> io::Result<()> {
    let Some(t) = t_ms else {
        return print_item(out, item, json);
    };
    if json {
        let line = inspect::json_line(item);
        writeln!(out, "{{\"t_ms\":{t},{}", line.get(1..).unwrap_or("}"))?;
    } else {
        let stamp = format!("[+{}.{:03} s] ", t / 1000, t % 1000);
        for (i, l) in inspect::text_entry(item).iter().enumerate() {
            if i == 0 {
                writeln!(out, "{stamp}{l}")?;
            } else {
                writeln!(out, "{}{l}", " ".repeat(stamp.len()))?;
            }
        }
    }
    out.flush()
}

pub(crate) fn monitor_cmd(
    line: &LinkArgs,
    json: bool,
    timestamps: bool,
    save: Option<&Path>,
) -> Run {
    let target = line.resolve(Flow::None);
    let mut link = Link::open(&target, LineConfig::new(Station(DEFAULT_STATION)))?;
    let mut saved = match save {
        Some(p) => Some((
            io::BufWriter::new(
                std::fs::File::create(p)
                    .map_err(|e| format!("--save {}: cannot create it: {e}", p.display()))?,
            ),
            0u64,
        )),
        None => None,
    };
    let stop = stop_flag();
    let t0 = Instant::now();
    let mut ins = inspect::Inspector::new();
    let mut out = io::stdout().lock();
    let mut buf = [0u8; 4096];
    let save_err = |e: io::Error| {
        format!(
            "--save {}: {e}",
            save.map(|p| p.display().to_string()).unwrap_or_default()
        )
    };
    while !stop.load(Ordering::SeqCst) {
        let n = link
            .read_for(&mut buf, std::time::Duration::from_millis(100))
            .map_err(|e| format!("{target}: {e}"))?;
        let got = buf.get(..n).unwrap_or(&[]);
        if let Some((f, count)) = saved.as_mut() {
            f.write_all(got).and_then(|_| f.flush()).map_err(save_err)?;
            *count += got.len() as u64;
        }
        ins.feed(got);
        let t = timestamps.then(|| t0.elapsed().as_millis());
        for item in ins.take_items() {
            print_timed(&mut out, &item, json, t).map_err(out_err)?;
        }
    }
    ins.finish();
    let t = timestamps.then(|| t0.elapsed().as_millis());
    for item in ins.take_items() {
        print_timed(&mut out, &item, json, t).map_err(out_err)?;
    }
    if let (Some((mut f, count)), Some(p)) = (saved, save) {
        f.flush().map_err(save_err)?;
        eprintln!(
            "saved {count} byte(s) as received to {} (iai inspect reads it)",
            p.display()
        );
    }
    // Stopped by Ctrl-C, the only way it ends without an error.
    Ok(ExitCode::from(EXIT_INTERRUPTED))
}
