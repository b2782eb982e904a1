//! `iai table write`: a CSV table to the controller, verified; with
//! `--replace` the table becomes the file's (246H clears first, 208H
//! checks after).

use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::Ordering;

use iai_cli::codes::answered_with;
use iai_cli::csvtable;
use iai_cli::link::{Flow, Link};
use iai_cli::resume::{self, refuse_stale, write_progress, ResumeState};
use iai_cli::table::{self, Hooks, Plan, TableError};
use iai_protocol_b::error::Failure as CoreFailure;
use iai_protocol_b::position::{PositionRecord, PositionStream};
use iai_protocol_b::transfer::{Guarantee, Verify as CoreVerify};

use super::{progress_bar, stop_flag, table_failure, Failure, Run};
use crate::{Verify, WriteArgs};

/// Exit status of a write that completed but leaves records confirmed by
/// an earlier run (`--resume`) unread on this controller.
const EXIT_RESUMED_UNVERIFIED: u8 = 3;

/// The records of the CSV file, every cell checked; the error lists the
/// first errors, their total and a hint for a spreadsheet's export.
pub(crate) fn load(file: &Path, plan: &Plan) -> Result<(Vec<u8>, Vec<PositionRecord>), String> {
    let bytes =
        std::fs::read(file).map_err(|e| format!("{}: cannot read it: {e}", file.display()))?;
    let records = csvtable::read(bytes.as_slice(), plan.write_stream().layout).map_err(|errs| {
        let mut m = format!(
            "{}: {}; nothing was sent:",
            file.display(),
            errs.count_text()
        );
        for e in &errs.errors {
            m.push_str(&format!("\n  {e}"));
        }
        if let Some(h) = &errs.hint {
            m.push_str(&format!("\n  hint: {h}"));
        }
        m
    })?;
    Ok((bytes, records))
}

/// The last position `--replace` clears on this profile.
fn replace_reach(plan: &Plan) -> u16 {
    table::clear_last().min(plan.last_position())
}

pub(crate) fn table_write(a: &WriteArgs) -> Run {
    let (file, line) = (a.file.as_path(), &a.line);
    let verify = a.verify.unwrap_or_default();
    let plan = line.plan();
    if a.bridge && plan.write_stream().id != PositionStream::CHANGE_2.id {
        return Err(format!(
            "--bridge sends the table as one 26DH, a message of the TTA profile, not of {}",
            plan.profile.name()
        )
        .into());
    }
    if a.bridge && a.verify.is_some() {
        eprintln!("iai: warning: --verify does not apply with --bridge: the bridge reads every chunk back itself");
    }
    let (bytes, records) = load(file, &plan)?;
    if records.is_empty() && !a.replace {
        return Err(format!(
            "{}: no records (only the header); nothing was sent. To empty the controller's table: iai table clear --all, or iai table write {} --replace",
            file.display(),
            file.display()
        )
        .into());
    }
    let total = u32::try_from(records.len()).map_err(|_| "too many records".to_string())?;
    let identity = line.identity();
    let state_path = resume::path(file);
    let mut state = if a.resume {
        let st = ResumeState::resume(file, &bytes, total, &identity)?;
        if st.replace != a.replace {
            return Err(if st.replace {
                "--resume: the interrupted write was a --replace (the table was cleared first): add --replace to resume it".to_string()
            } else {
                "--resume: the interrupted write was not a --replace (nothing was cleared): resume it without --replace, or --restart".to_string()
            }
            .into());
        }
        st
    } else {
        if !a.restart {
            refuse_stale(&state_path, "table write", &write_progress(&state_path))?;
        }
        ResumeState::new(&bytes, total, &identity)
    };
    let skip = state.confirmed;
    if a.resume {
        eprintln!("resuming after record {skip} of {total}");
    }
    let mut link = if a.bridge {
        line.open_with(Flow::XonXoff)?
    } else {
        line.open()?
    };
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let note = |m: &str| eprintln!("{m}");
    let hooks = Hooks {
        note: &note,
        stop: &stopped,
    };
    if a.replace && !state.replace {
        let reach = replace_reach(&plan);
        eprintln!("--replace: clearing positions 0..={reach} first (246H)");
        table::clear(&mut link, 0, reach, |_| {}, &hooks).map_err(|e| {
            table_failure(
                &link,
                e,
                "; the table may be cleared in part, nothing was written",
            )
        })?;
        state.replace = true;
        state.save(file);
    }
    if records.is_empty() {
        ResumeState::remove(file);
        return replaced(&mut link, &plan, 0, &hooks).map_err(|e| table_failure(&link, e, ""))?;
    }
    if a.bridge {
        // One message, answered once: no state to resume from.
        ResumeState::remove(file);
        super::bridge::write_table(a, &records, &mut link, &hooks)?;
        if a.replace {
            return replaced(&mut link, &plan, total, &hooks)
                .map_err(|e| table_failure(&link, e, ""))?;
        }
        return Ok(ExitCode::SUCCESS);
    }
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
            .map_err(|e| table_failure(&link, e, "; nothing was written"))?;
        if let Some(first) = redo.first() {
            eprintln!(
                "{} of them are not held as the file says (first: position {}); writing them again",
                redo.len(),
                first.number
            );
        }
        redo
    } else {
        Vec::new()
    };
    let redo_len = u32::try_from(redo.len()).unwrap_or(u32::MAX);
    let bar = progress_bar(u64::from(total), "writing", "records");
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
        &Hooks {
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
            let what = format!(
                "; {confirmed} of {total} records confirmed{}; run again with --resume to continue (state in {})",
                if verify == Verify::Off { "" } else { " and verified" },
                state_path.display()
            );
            return Err(table_failure(&link, e, &what));
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
    if let Some(note) = link.repeats_note() {
        eprintln!("{note}");
    }
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
    if a.replace {
        let code = replaced(&mut link, &plan, total, &hooks)
            .map_err(|e| table_failure(&link, e, ""))??;
        if code != ExitCode::SUCCESS {
            return Ok(code);
        }
    }
    if unread_prefix {
        return Ok(ExitCode::from(EXIT_RESUMED_UNVERIFIED));
    }
    Ok(ExitCode::SUCCESS)
}

/// After a `--replace`: 208H must count exactly the file's `total`
/// records. Positions past 246H's reach are the only ones a replace
/// cannot clear; a count above the file's means some are defined.
fn replaced(
    link: &mut Link,
    plan: &Plan,
    total: u32,
    hooks: &Hooks<'_>,
) -> Result<Run, TableError> {
    let reach = replace_reach(plan);
    let n = match table::count(link, hooks) {
        Ok(n) if n < table::count_max() => u32::from(n),
        Ok(n) => {
            println!(
                "replace: positions 0..={reach} were cleared first; 208H counts {n}, its largest value, so whether positions past {reach} are defined was not checked"
            );
            return Ok(Ok(ExitCode::SUCCESS));
        }
        Err(TableError::Engine(CoreFailure::Controller { code, .. })) => {
            println!(
                "replace: positions 0..={reach} were cleared first; 208H could not count the table ({}), so whether positions past {reach} are defined was not checked",
                answered_with(code)
            );
            return Ok(Ok(ExitCode::SUCCESS));
        }
        Err(e) => return Err(e),
    };
    if n == total {
        if total == 0 {
            println!("replaced: the controller's table defines no position now (208H: 0)");
        } else {
            println!("replaced: the controller's table defines exactly these {total} positions (208H: {n})");
        }
        return Ok(Ok(ExitCode::SUCCESS));
    }
    Ok(Err(Failure::Failed(format!(
        "replace: the table defines {n} positions (208H), the file {total}: {} defined position(s) past {reach} remain, out of 246H's reach (iai table read --all lists them)",
        n.saturating_sub(total)
    ))))
}
