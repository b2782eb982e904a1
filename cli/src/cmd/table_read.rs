//! `iai table read`: positions back as CSV.

use std::io::{self, Write};
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::Ordering;

use iai_cli::csvtable;
use iai_cli::link::Link;
use iai_cli::table::{self, TableError};
use iai_protocol_b::position::PositionRecord;

use super::{out_err, stop_flag, Run};
use crate::LineArgs;

pub(crate) fn table_read(
    first: u16,
    count: u32,
    output: Option<&Path>,
    axes: Option<u8>,
    line: &LineArgs,
) -> Run {
    let last = u32::from(first) + count - 1;
    let last = u16::try_from(last).map_err(|_| {
        format!("--first {first} --count {count}: the last position would be {last}, past 65535")
    })?;
    let plan = line.plan();
    let target = line.target();
    let mut link = Link::open(&target, plan.line)?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let mut by_number = std::collections::BTreeMap::new();
    table::read(
        &mut link,
        &plan,
        first,
        last,
        |r| {
            by_number.insert(r.number, r);
        },
        &table::Hooks {
            note: &|m: &str| eprintln!("{m}"),
            stop: &stopped,
        },
    )
    .map_err(|e: TableError| format!("{target}: {e}"))?;
    let recs: Vec<PositionRecord> = by_number.into_values().collect();
    let axes = axes.map_or_else(|| csvtable::axes_used(&recs), usize::from);
    let write_all = |out: &mut dyn Write| -> io::Result<()> {
        let mut out = io::BufWriter::new(out);
        csvtable::write_header(&mut out, axes)?;
        for r in &recs {
            csvtable::write_row(&mut out, r, axes)?;
        }
        out.flush()
    };
    match output {
        Some(p) => {
            let mut f = std::fs::File::create(p)
                .map_err(|e| format!("-o {}: cannot create it: {e}", p.display()))?;
            write_all(&mut f).map_err(|e| format!("-o {}: {e}", p.display()))?;
        }
        None => write_all(&mut io::stdout().lock()).map_err(out_err)?,
    }
    eprintln!("{} defined position(s) in {first}..={last}", recs.len());
    Ok(ExitCode::SUCCESS)
}
