//! `iai table write`: a CSV table to the controller, verified.

use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::Ordering;

use iai_cli::csvtable;
use iai_cli::link::Link;
use iai_cli::resume::ResumeState;
use iai_cli::table;
use iai_protocol_b::transfer::{Guarantee, Verify as CoreVerify};

use super::{progress_bar, stop_flag, Run};
use crate::{LineArgs, Verify};

/// Exit status of a write that completed but leaves records confirmed by
/// an earlier run (`--resume`) unread on this controller.
const EXIT_RESUMED_UNVERIFIED: u8 = 3;

pub(crate) fn table_write(file: &Path, line: &LineArgs, verify: Verify, resume: bool) -> Run {
    let plan = line.plan();
    let bytes =
        std::fs::read(file).map_err(|e| format!("{}: cannot read it: {e}", file.display()))?;
    let records = csvtable::read(bytes.as_slice(), plan.write_stream().layout).map_err(|errs| {
        let mut m = format!(
            "{}: {} error(s); nothing was sent:",
            file.display(),
            errs.len()
        );
        for e in &errs {
            m.push_str(&format!("\n  {e}"));
        }
        m
    })?;
    let total = u32::try_from(records.len()).map_err(|_| "too many records".to_string())?;
    let identity = line.identity();
    let state = if resume {
        ResumeState::resume(file, &bytes, total, &identity)?
    } else {
        ResumeState::new(&bytes, total, &identity)
    };
    let skip = state.confirmed;
    if resume {
        eprintln!("resuming after record {skip} of {total}");
    }
    let target = line.target();
    let mut link = Link::open(&target, plan.line)?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let hooks = table::Hooks {
        note: &|m: &str| eprintln!("{m}"),
        stop: &stopped,
    };
    let policy = match verify {
        Verify::Off => CoreVerify::Off,
        Verify::AfterFault => CoreVerify::AfterFault,
        Verify::Full => CoreVerify::Full,
    };
    let prefix = records.get(..skip as usize).unwrap_or(&[]);
    // Full verification covers the records confirmed before the resume too:
    // read them back here, and write again those this controller lacks.
    let redo = if skip > 0 && policy == CoreVerify::Full {
        eprintln!("reading back the {skip} records confirmed before the resume");
        let redo = table::not_held(&mut link, &plan, prefix, &hooks)
            .map_err(|e| format!("{target}: {e}; nothing was written"))?;
        if !redo.is_empty() {
            eprintln!(
                "{} of them are not held as the file says (first: position {}); writing them again",
                redo.len(),
                redo[0].number
            );
        }
        redo
    } else {
        Vec::new()
    };
    let redo_len = u32::try_from(redo.len()).unwrap_or(u32::MAX);
    let bar = progress_bar(u64::from(total), "writing");
    bar.set_position(u64::from(skip));
    let t0 = std::time::Instant::now();
    let mut last_save = std::time::Instant::now();
    let save = |n: u32| {
        ResumeState {
            confirmed: skip + n.saturating_sub(redo_len),
            ..state.clone()
        }
        .save(file)
    };
    let (result, s) = table::write(
        &mut link,
        &plan,
        policy,
        redo.iter()
            .cloned()
            .chain(records.iter().skip(skip as usize).cloned()),
        redo_len + (total - skip),
        |n| {
            bar.set_position(u64::from(skip + n.saturating_sub(redo_len)));
            if last_save.elapsed() > std::time::Duration::from_millis(500) {
                last_save = std::time::Instant::now();
                save(n);
            }
        },
        &table::Hooks {
            note: &|m: &str| bar.suspend(|| eprintln!("{m}")),
            stop: &stopped,
        },
    );
    let guarantee = match result {
        Ok(g) => g,
        Err(e) => {
            bar.abandon();
            save(s.records_confirmed);
            let confirmed = skip + s.records_confirmed.saturating_sub(redo_len);
            return Err(format!(
                "{target}: {e}; {confirmed} of {total} records confirmed{}; run again with --resume to continue (state in {})",
                if verify == Verify::Off { "" } else { " and verified" },
                iai_cli::resume::path(file).display()
            )
            .into());
        }
    };
    bar.finish_and_clear();
    ResumeState::remove(file);
    let l = link.line().stats();
    eprintln!(
        "{total} records in {} frames, {:.1} s: {} bytes written, {} read-back queries ({} bytes), {} resends, {} timeouts, {} error replies, {} line errors, {} stale replies, {} fences, {} rewrites",
        s.frames_confirmed,
        t0.elapsed().as_secs_f64(),
        s.bytes_sent,
        s.verify_queries,
        s.verify_bytes_sent,
        s.retries,
        s.timeouts,
        s.error_replies,
        s.line_errors,
        s.stale_replies,
        l.fences,
        s.rewrites
    );
    let unread_prefix = skip > 0 && policy != CoreVerify::Full;
    let resumed = match (skip, unread_prefix) {
        (0, _) => String::new(),
        (_, false) => format!(
            " (the {skip} records confirmed before the resume were read back on this controller{})",
            if redo_len > 0 {
                format!("; {redo_len} of them were written again")
            } else {
                String::new()
            }
        ),
        (_, true) => format!(
            "; records 1 to {skip} of the file were confirmed by an earlier run and NOT read back on this controller (run with --verify full to check them)"
        ),
    };
    let written = if unread_prefix { total - skip } else { total };
    match guarantee {
        Guarantee::Verified => println!(
            "verified: the controller holds all {written} records written now (read back and compared){resumed}"
        ),
        Guarantee::FaultsVerified => println!(
            "UNVERIFIED in part: every frame was confirmed; the {} frame(s) confirmed after a fault were read back and compared, the others were not (--verify after-fault){resumed}",
            s.frames_verified
        ),
        Guarantee::Unverified => println!(
            "UNVERIFIED: every frame was confirmed, but the table was not read back (--verify off){resumed}"
        ),
    }
    if unread_prefix {
        return Ok(ExitCode::from(EXIT_RESUMED_UNVERIFIED));
    }
    Ok(ExitCode::SUCCESS)
}
