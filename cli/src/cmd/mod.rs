//! The commands' handlers: each takes its parsed arguments and returns
//! the exit status, or a [`Failure`] for `main` to report.

pub(crate) mod bridge;
pub(crate) mod diag;
pub(crate) mod encode;
pub(crate) mod help;
pub(crate) mod inspect;
pub(crate) mod line;
pub(crate) mod modbus;
pub(crate) mod monitor;
pub(crate) mod send;
pub(crate) mod simulate;
pub(crate) mod table_clear;
pub(crate) mod table_read;
pub(crate) mod table_write;

use std::io;
use std::process::ExitCode;

use iai_cli::link::Link;
use iai_cli::table::TableError;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Exit status of a run stopped by Ctrl-C (128 + SIGINT, as a shell
/// reports a process the signal killed).
pub(crate) const EXIT_INTERRUPTED: u8 = 130;

/// What went wrong, and the exit status for it.
pub(crate) enum Failure {
    /// Exit 1 with this message.
    Failed(String),
    /// Exit with this status and message (none if empty: the command
    /// said it already, as a JSON object on stdout).
    Exit(u8, String),
    /// The reader of stdout went away: stop quietly.
    ClosedPipe,
}

impl Failure {
    /// The failure of a table operation: exit 130 when the user stopped
    /// it, 1 otherwise.
    pub(crate) fn of_table(e: &iai_cli::table::TableError, msg: String) -> Failure {
        match e {
            iai_cli::table::TableError::Interrupted => Failure::Exit(EXIT_INTERRUPTED, msg),
            _ => Failure::Failed(msg),
        }
    }
}

/// Whether `e` means no valid reply came (where the line's hint helps).
pub(crate) fn unanswered(e: &iai_protocol_b::error::Failure) -> bool {
    matches!(
        e,
        iai_protocol_b::error::Failure::Timeout { .. }
            | iai_protocol_b::error::Failure::OutcomeUnknown { .. }
    )
}

/// A table operation's failure on `link`: "TARGET: what went wrong WHAT",
/// with the line's hint when no reply came; exit 130 when interrupted.
pub(crate) fn table_failure(link: &Link, e: TableError, what: &str) -> Failure {
    let mut msg = match &e {
        TableError::Engine(iai_protocol_b::error::Failure::Timeout { sends }) => format!(
            "{}: the controller did not answer ({sends} send(s), {} each){what}",
            link.target(),
            iai_cli::send::wait_text(link.line().config().timeout_ms)
        ),
        _ => format!("{}: {e}{what}", link.target()),
    };
    if let TableError::Engine(f) = &e {
        if let (true, Some(h)) = (unanswered(f), link.hint()) {
            msg.push_str(&format!("\n  hint: {h}"));
        }
    }
    Failure::of_table(&e, msg)
}

impl From<String> for Failure {
    fn from(s: String) -> Self {
        Failure::Failed(s)
    }
}

/// A write to stdout: a closed pipe ends the program quietly.
pub(crate) fn out_err(e: io::Error) -> Failure {
    if e.kind() == io::ErrorKind::BrokenPipe {
        Failure::ClosedPipe
    } else {
        Failure::Failed(format!("cannot write the output: {e}"))
    }
}

pub(crate) type Run = Result<ExitCode, Failure>;

pub(crate) fn stop_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    // A second handler cannot be installed; the first one is enough.
    let _ = ctrlc::set_handler(move || f.store(true, Ordering::SeqCst));
    flag
}

/// A progress bar on stderr (drawn only when stderr is a terminal) of
/// `total` `unit` (records, positions, bytes).
pub(crate) fn progress_bar(total: u64, what: &str, unit: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(total),
        indicatif::ProgressDrawTarget::stderr(),
    );
    if let Ok(style) = indicatif::ProgressStyle::with_template(&format!(
        "{{msg}} [{{bar:30}}] {{pos}}/{{len}} {unit} ({{per_sec}}, {{eta}} left)"
    )) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}
