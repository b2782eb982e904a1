//! `iai table read`: positions back as CSV, a range or the whole table
//! (`--all`: 208H says how many positions are defined; the read looks for
//! them from position 0 up and stops once it has them all). A read that
//! fails or is interrupted keeps what it read: in the output file, with a
//! state file for `--resume`, or on stdout; stderr says which positions
//! that covers.

use std::collections::BTreeMap;
use std::io::{self, Write};
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::Ordering;

use iai_cli::codes::answered_with;
use iai_cli::csvtable;
use iai_cli::link::Link;
use iai_cli::resume::{read_path, read_progress, refuse_stale, ReadState};
use iai_cli::table::{self, Hooks, TableError};
use iai_protocol_b::error::Failure as CoreFailure;
use iai_protocol_b::position::{PositionRecord, RecordLayout};

use super::{out_err, progress_bar, stop_flag, table_failure, Failure, Run};
use crate::ReadArgs;

/// The CSV of `recs` with `axes` axis columns (default: the highest used).
fn csv_bytes(recs: &BTreeMap<u16, PositionRecord>, axes: Option<u8>) -> Vec<u8> {
    let axes = axes.map_or_else(|| csvtable::axes_used(recs.values()), usize::from);
    let mut out = Vec::new();
    // Writing to a Vec cannot fail.
    let _ = csvtable::write_header(&mut out, axes);
    for r in recs.values() {
        let _ = csvtable::write_row(&mut out, r, axes);
    }
    out
}

/// Writes the CSV to the file or stdout.
fn put(out: Option<&Path>, bytes: &[u8]) -> Result<(), Failure> {
    match out {
        Some(p) => std::fs::write(p, bytes)
            .map_err(|e| Failure::Failed(format!("-o {}: cannot write it: {e}", p.display()))),
        None => {
            let mut o = io::stdout().lock();
            o.write_all(bytes).and_then(|_| o.flush()).map_err(out_err)
        }
    }
}

/// The positions asked: `--first/--count` checked against what the
/// profile's read-back query numbers, or the whole range for `--all`.
fn range(a: &ReadArgs, top: u16) -> Result<(u16, u16), String> {
    if a.all {
        return Ok((0, top));
    }
    let (first, count) = (a.first.unwrap_or(0), a.count.unwrap_or(1));
    let last = u32::from(first) + count - 1;
    match u16::try_from(last) {
        Ok(l) if l <= top => Ok((first, l)),
        _ => Err(format!(
            "--first {first} --count {count}: the last position would be {last}, past {top} (the last position this profile's read-back query numbers)"
        )),
    }
}

pub(crate) fn table_read(a: &ReadArgs) -> Run {
    let line = &a.line;
    let plan = line.plan();
    let (lo, hi) = range(a, plan.last_position())?;
    let out = a.output.as_deref();
    let identity = line.identity();
    let mut state = match out {
        Some(p) if a.resume => Some(ReadState::resume(p, lo, hi, a.all, &identity)?),
        Some(p) => {
            if !a.restart {
                let st = read_path(p);
                refuse_stale(&st, "table read", &read_progress(&st))?;
            }
            None
        }
        None => None,
    };
    let mut recs: BTreeMap<u16, PositionRecord> = BTreeMap::new();
    let mut start = u32::from(lo);
    if let (Some(st), Some(p)) = (&state, out) {
        let bytes =
            std::fs::read(p).map_err(|e| format!("--resume: cannot read {}: {e}", p.display()))?;
        let prior = csvtable::read(bytes.as_slice(), RecordLayout::NUMBER_4).map_err(|e| {
            format!(
                "--resume: {} does not read as the table it was ({}); run with --restart",
                p.display(),
                e.count_text()
            )
        })?;
        recs.extend(prior.into_iter().map(|r| (r.number, r)));
        start = st.next;
        eprintln!(
            "resuming at position {start}: {} record(s) of positions {lo}..{start} are in {}",
            recs.len(),
            p.display()
        );
    }
    let mut link = line.open()?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let note = |m: &str| eprintln!("{m}");
    let hooks = Hooks {
        note: &note,
        stop: &stopped,
    };
    if state.is_some() && start > u32::from(lo) {
        // What was kept must still hold on this controller: read once more,
        // it and the confirmed read that kept it agree, or it all goes.
        let kept_last = (start - 1) as u16;
        eprintln!("checking that positions {lo}..={kept_last} still hold what was kept");
        let now = table::read_once(&mut link, &plan, lo, kept_last, &hooks)
            .map_err(|e| table_failure(&link, e, " (checking the kept positions)"))?;
        if now == recs {
            eprintln!("they do: resuming at position {start}");
        } else {
            let changed = now
                .keys()
                .chain(recs.keys())
                .filter(|n| now.get(n) != recs.get(n))
                .collect::<std::collections::BTreeSet<_>>();
            eprintln!(
                "{} position(s) of {lo}..={kept_last} changed since the interrupted read (first: {}): reading from {lo} again",
                changed.len(),
                changed.first().map_or(0, |n| **n)
            );
            recs.clear();
            start = u32::from(lo);
        }
    }
    let expected = if a.all {
        expect(&mut link, &hooks, hi).map_err(|e| table_failure(&link, e, " (208H)"))?
    } else {
        None
    };
    let reached = |recs: &BTreeMap<u16, PositionRecord>| expected.is_some_and(|n| recs.len() >= n);
    let mut covered: Option<u16> = start.checked_sub(1).and_then(|c| u16::try_from(c).ok());
    let result = if start > u32::from(hi) || reached(&recs) {
        Ok(())
    } else {
        let bar = match expected {
            Some(n) => progress_bar(n as u64, "reading", "records"),
            None => progress_bar(u64::from(hi) + 1 - start as u64, "reading", "positions"),
        };
        bar.set_position(match expected {
            Some(_) => recs.len() as u64,
            None => 0,
        });
        let first = start as u16;
        let note = |m: &str| bar.suspend(|| eprintln!("{m}"));
        let r = table::read(
            &mut link,
            &plan,
            first,
            hi,
            |w| {
                covered = Some(*w.span.end());
                recs.extend(w.records.into_iter().map(|r| (r.number, r)));
                match expected {
                    Some(_) => bar.set_position(recs.len() as u64),
                    None => bar.set_position(u64::from(*w.span.end()) + 1 - u64::from(first)),
                }
                !reached(&recs)
            },
            &Hooks {
                note: &note,
                stop: &stopped,
            },
        );
        match r {
            Ok(_) => bar.finish_and_clear(),
            Err(_) => bar.abandon(),
        }
        r.map(|_| ())
    };
    let bytes = csv_bytes(&recs, a.axes);
    if let Some(note) = link.repeats_note() {
        eprintln!("{note}");
    }
    if let Err(e) = result {
        return Err(keep_partial(
            a,
            &mut state,
            (lo, hi),
            covered,
            &recs,
            &bytes,
            e,
            &link,
            &identity,
        ));
    }
    put(out, &bytes)?;
    if let Some(p) = out {
        ReadState::remove(p);
    }
    let n = recs.len();
    match (a.all, expected) {
        (_, _) if n == 0 && a.all => eprintln!("no records: the controller's table defines no position"),
        (_, _) if n == 0 => eprintln!("no records: no position in {lo}..={hi} is defined"),
        (true, Some(e)) if n != e => {
            return Err(Failure::Failed(format!(
                "{n} defined position(s) found in 0..={hi}, but 208H counted {e}: the table changed during the read; the output is not the table the controller holds"
            )))
        }
        (true, Some(_)) => eprintln!(
            "all {n} defined position(s) of the table (208H), found in 0..={}",
            covered.unwrap_or(hi)
        ),
        _ => eprintln!("{n} defined position(s) in {lo}..={hi}"),
    }
    Ok(ExitCode::SUCCESS)
}

/// `--all`: how many records to look for (208H), or `None` when 208H
/// cannot say (refused, or at its maximum): then every position is read.
fn expect(link: &mut Link, hooks: &Hooks<'_>, hi: u16) -> Result<Option<usize>, TableError> {
    match table::count(link, hooks) {
        Ok(n) if n < table::count_max() => {
            eprintln!("the table defines {n} position(s) (208H)");
            Ok(Some(usize::from(n)))
        }
        Ok(n) => {
            eprintln!(
                "208H counts {n}, its largest value: the table may define more; reading every position 0..={hi}"
            );
            Ok(None)
        }
        Err(TableError::Engine(CoreFailure::Controller { code, .. })) => {
            eprintln!(
                "208H could not count the table ({}); reading every position 0..={hi}",
                answered_with(code)
            );
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// A read that stopped: what it read goes out (file or stdout) and, into
/// a file, with a state for `--resume`; the failure says which positions
/// it covers.
#[allow(clippy::too_many_arguments)]
fn keep_partial(
    a: &ReadArgs,
    state: &mut Option<ReadState>,
    (lo, hi): (u16, u16),
    covered: Option<u16>,
    recs: &BTreeMap<u16, PositionRecord>,
    bytes: &[u8],
    e: TableError,
    link: &Link,
    identity: &str,
) -> Failure {
    let read = match covered {
        Some(c) => format!(
            "positions {lo}..={c} of {lo}..={hi} were read ({} defined record(s))",
            recs.len()
        ),
        None => "nothing was read".to_string(),
    };
    let out = a.output.as_deref();
    if let Err(f) = put(out, bytes) {
        return f;
    }
    let tail = match out {
        Some(p) => {
            let next = covered.map_or(u32::from(lo), |c| u32::from(c) + 1);
            let st = state.get_or_insert_with(|| ReadState {
                first: lo,
                last: hi,
                all: a.all,
                next,
                records: 0,
                line: identity.to_string(),
                output_hash: String::new(),
            });
            st.next = next;
            st.records = recs.len() as u32;
            st.save(p, bytes);
            format!(
                " and are in {}; run again with --resume to continue (state in {})",
                p.display(),
                read_path(p).display()
            )
        }
        None => " and are printed above (give -o FILE to keep them for a --resume)".to_string(),
    };
    table_failure(link, e, &format!("; {read}{tail}"))
}
