//! `iai table clear`: positions cleared with 246H, an explicit range or
//! every position 246H reaches (`--all`), with 208H's count before and
//! after.

use std::process::ExitCode;
use std::sync::atomic::Ordering;

use iai_cli::link::Link;
use iai_cli::table::{self, Hooks, TableError};
use iai_protocol_b::error::Failure as CoreFailure;

use super::{progress_bar, stop_flag, table_failure, Failure, Run};
use crate::ClearArgs;

/// 208H's count, when it can give one (below its largest value, not
/// refused).
fn count(link: &mut Link, hooks: &Hooks<'_>) -> Result<Option<u16>, TableError> {
    match table::count(link, hooks) {
        Ok(n) if n < table::count_max() => Ok(Some(n)),
        Ok(_) | Err(TableError::Engine(CoreFailure::Controller { .. })) => Ok(None),
        Err(e) => Err(e),
    }
}

pub(crate) fn table_clear(a: &ClearArgs) -> Run {
    let line = &a.line;
    let plan = line.plan();
    let top = plan.last_position();
    let (lo, hi) = if a.all {
        (0, table::clear_last().min(top))
    } else {
        let (first, n) = (a.first.unwrap_or(0), a.count.unwrap_or(1));
        let last = u32::from(first) + n - 1;
        let last = u16::try_from(last)
            .ok()
            .filter(|l| *l <= top)
            .ok_or_else(|| {
                format!(
                    "--first {first} --count {n}: the last position would be {last}, past {top}"
                )
            })?;
        (first, last)
    };
    // Checked before connecting: a range 246H cannot express sends nothing.
    let cmds = table::clear_commands(lo, hi).map_err(|e| format!("{e}; nothing was sent"))?;
    let mut link = line.open()?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let note = |m: &str| eprintln!("{m}");
    let hooks = Hooks {
        note: &note,
        stop: &stopped,
    };
    let before =
        count(&mut link, &hooks).map_err(|e| table_failure(&link, e, "; nothing was cleared"))?;
    let bar = progress_bar(u64::from(hi - lo) + 1, "clearing", "positions");
    let mut cleared_to = None;
    let r = table::clear(
        &mut link,
        lo,
        hi,
        |last| {
            cleared_to = Some(last);
            bar.set_position(u64::from(last - lo) + 1);
        },
        &Hooks {
            note: &|m: &str| bar.suspend(|| eprintln!("{m}")),
            stop: &stopped,
        },
    );
    if let Err(e) = r {
        bar.abandon();
        let done = match cleared_to {
            Some(c) => format!(
                "; positions {lo}..={c} were cleared, {}..={hi} may not be",
                c + 1
            ),
            None => format!("; positions {lo}..={hi} may not be cleared"),
        };
        return Err(table_failure(&link, e, &done));
    }
    bar.finish_and_clear();
    println!("cleared positions {lo}..={hi} ({} x 246H)", cmds.len());
    let after = count(&mut link, &hooks)
        .map_err(|e| table_failure(&link, e, " (208H, after the clear)"))?;
    if let Some(note) = link.repeats_note() {
        eprintln!("{note}");
    }
    match (before, after) {
        (Some(b), Some(n)) => println!(
            "{} defined position(s) removed; the table defines {n} now (208H)",
            b.saturating_sub(n)
        ),
        (None, Some(n)) => println!("the table defines {n} position(s) now (208H)"),
        _ => println!(
            "208H could not count the table (a table this large exceeds its 3-digit count)"
        ),
    }
    if a.all && after.is_some_and(|n| n > 0) {
        return Err(Failure::Failed(format!(
            "{} position(s) remain defined past {hi}, out of 246H's reach (iai table read --all lists them)",
            after.unwrap_or(0)
        )));
    }
    Ok(ExitCode::SUCCESS)
}
