//! `iai`: inspect captures, encode and send messages, write and read
//! position tables as CSV, run the controller simulator. See `iai --help`.

use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use clap::{Args, Parser, Subcommand, ValueEnum};

use iai_cli::csvtable;
use iai_cli::encode::{encode, field_help, find_message, EncodeOptions};
use iai_cli::inspect::{self, Format, InspectError};
use iai_cli::link::{Link, Target};
use iai_cli::resume::ResumeState;
use iai_cli::send::{describe, request, Outcome};
use iai_cli::sim::Controller;
use iai_cli::simulate::{self, ServeOptions, Shared};
use iai_cli::table::{self, Plan, TableError};
use iai_cli::text::escape;
use iai_protocol_b::catalogue;
use iai_protocol_b::frame::{Header, Station};
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::profile::Profile;
use iai_protocol_b::transfer::{Guarantee, Verify as CoreVerify};

/// IAI protocol B tools: captures, messages, position tables, a simulator.
#[derive(Parser)]
#[command(name = "iai", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// List every frame of a capture with offsets, fields and checksum
    /// status, and every error at its byte offset. Exit status 1 if the
    /// capture had errors (broken frames, noise, bodies that do not decode).
    Inspect {
        /// Raw bytes, or a text log with one frame per line (optionally
        /// prefixed '> '/'< ' or 'TX '/'RX ', with \r \n \\ \xNN escapes);
        /// '-' reads stdin.
        file: String,
        /// One JSON object per line.
        #[arg(long)]
        json: bool,
        /// Input format (guessed when not given).
        #[arg(long, value_enum)]
        format: Option<FormatArg>,
    },
    /// Build one frame from field=value arguments or JSON.
    Encode {
        #[command(flatten)]
        msg: MessageArgs,
        /// Station (two hex digits).
        #[arg(long, default_value = "99", value_parser = parse_station)]
        station: u8,
        /// Build the normal response instead of the command.
        #[arg(long)]
        response: bool,
        /// Send '@@' instead of the checksum.
        #[arg(long)]
        bypass: bool,
        /// List the message's fields instead.
        #[arg(long)]
        fields: bool,
    },
    /// List the frames arriving on a line, live.
    Monitor {
        #[command(flatten)]
        line: LineArgs,
        /// One JSON object per line.
        #[arg(long)]
        json: bool,
    },
    /// Send one command, wait for its reply (3 s, resent up to 3 times
    /// when resending cannot repeat an operation) and print it.
    Send {
        #[command(flatten)]
        msg: MessageArgs,
        #[command(flatten)]
        line: LineArgs,
        /// Print the reply as JSON (as `inspect --json` does).
        #[arg(long, value_enum, default_value = "text")]
        output: OutputArg,
        /// On an error response, also query its details (216H, latest
        /// system error).
        #[arg(long)]
        detail: bool,
    },
    /// Position tables as CSV (see the README for the format).
    Table {
        #[command(subcommand)]
        op: TableCmd,
    },
    /// Run the controller simulator.
    Simulate(SimArgs),
}

#[derive(Subcommand)]
enum TableCmd {
    /// Write a CSV table to the controller, with a progress bar. Exit
    /// status 0 only when the controller holds the table (or, with
    /// --verify off, when every frame was confirmed; the output then says
    /// the table is unverified).
    Write {
        /// The CSV file.
        file: PathBuf,
        #[command(flatten)]
        line: LineArgs,
        /// Read the table back and compare: always (full), only after a
        /// timeout, error reply or line error (after-fault), or never (off).
        #[arg(long, value_enum, default_value = "full")]
        verify: Verify,
        /// Continue after the last confirmed record of an interrupted
        /// write (state kept in FILE.csv.iai-state).
        #[arg(long)]
        resume: bool,
    },
    /// Read positions FIRST .. FIRST+COUNT-1 back as CSV.
    Read {
        /// First position number.
        #[arg(long, value_parser = clap::value_parser!(u16))]
        first: u16,
        /// Number of positions.
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
        count: u32,
        /// Write to this file instead of stdout.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Axis columns (default: up to the highest axis read).
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=8))]
        axes: Option<u8>,
        #[command(flatten)]
        line: LineArgs,
    },
}

#[derive(Args)]
struct MessageArgs {
    /// Message: hex ID (212, 212H) or name ("Axis Status Query").
    message: String,
    /// field=value: decimal or 0x hex, one optional '-' for signed fields;
    /// repeat-group fields take comma lists, '/' between outer items.
    assignments: Vec<String>,
    /// The fields as JSON, in the form `inspect --json` prints under "fields".
    #[arg(long, conflicts_with = "json_file")]
    json: Option<String>,
    /// The fields as JSON, from a file.
    #[arg(long)]
    json_file: Option<PathBuf>,
}

#[derive(Args)]
#[group(required = true, multiple = false, id = "where")]
struct Where {
    /// Serial device (/dev/ttyUSB0, COM3).
    #[arg(long)]
    port: Option<String>,
    /// HOST:PORT of a TCP link (a serial server, or `iai simulate --tcp`).
    #[arg(long)]
    tcp: Option<String>,
}

#[derive(Args)]
struct LineArgs {
    #[command(flatten)]
    target: Where,
    /// Baud rate of the serial port.
    #[arg(long, default_value_t = 38_400)]
    baud: u32,
    /// Station code (two hex digits, I/O parameter No. 91).
    #[arg(long, default_value = "99", value_parser = parse_station)]
    station: u8,
    /// Controller kind: buffer sizes and messages.
    #[arg(long, value_enum, default_value = "tta")]
    profile: ProfileArg,
    /// How long after a reply a copy of it may still come, ms, on a line
    /// that repeats frames (an echoing converter). A command goes out only
    /// when no copy could pass for its reply. Default 0: a direct line.
    #[arg(long, default_value_t = 0)]
    duplicate_window_ms: u32,
}

impl LineArgs {
    fn target(&self) -> Target {
        match (&self.target.port, &self.target.tcp) {
            (Some(path), _) => Target::Serial {
                path: path.clone(),
                baud: self.baud,
            },
            (None, Some(addr)) => Target::Tcp(addr.clone()),
            // clap requires one of the two.
            (None, None) => Target::Tcp(String::new()),
        }
    }
    fn plan(&self) -> Plan {
        let mut plan = Plan::new(self.profile.profile(), Station(self.station));
        plan.line = plan.line.with_duplicate_window(self.duplicate_window_ms);
        plan
    }
    /// What a state file records of the line: a resume elsewhere is
    /// refused.
    fn identity(&self) -> String {
        format!(
            "{} station {:02X} profile {}",
            self.target(),
            self.station,
            self.profile.profile().name()
        )
    }
}

#[derive(Args)]
#[command(group(clap::ArgGroup::new("place").required(true).args(["tcp", "pty", "connect"])))]
struct SimArgs {
    /// Listen on 127.0.0.1:PORT (port 0 picks a free one).
    #[arg(long)]
    tcp: Option<String>,
    /// Serve on a new pseudo-terminal (/dev/pts/N).
    #[arg(long)]
    pty: bool,
    /// Connect to a listening HOST:PORT (such as the bridge's controller
    /// port under QEMU), serve that one connection and exit when it closes.
    #[arg(long)]
    connect: Option<String>,
    /// How long --connect keeps trying while nothing listens yet, ms
    /// (default 10000).
    #[arg(long, conflicts_with_all = ["tcp", "pty"])]
    connect_wait_ms: Option<u64>,
    /// Controller kind.
    #[arg(long, value_enum, default_value = "tta")]
    profile: ProfileArg,
    /// Station code (two hex digits).
    #[arg(long, default_value = "99", value_parser = parse_station)]
    station: u8,
    /// Delay before each reply, ms (the controller's α).
    #[arg(long, default_value_t = 2)]
    reply_delay_ms: u32,
    /// Faults: corrupt=P,swap=P,drop=P,late=P:MS,dup=P:MS,error=P.
    #[arg(long, value_parser = simulate::parse_faults)]
    faults: Option<iai_cli::sim::Faults>,
    /// Seed of the fault draws.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// On SIGTERM or SIGINT (or the end of the --connect connection),
    /// write the position table to this CSV file.
    #[arg(long)]
    dump: Option<PathBuf>,
    /// Print only connection summaries, not every frame.
    #[arg(long)]
    quiet: bool,
    /// Do not refuse moves with the servo off, before homing, on a busy
    /// axis or to an undefined position (messages the simulator does not
    /// model are still refused).
    #[arg(long)]
    accept_all: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum FormatArg {
    Raw,
    Text,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
enum OutputArg {
    Text,
    Json,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug)]
enum Verify {
    Off,
    AfterFault,
    Full,
}

#[derive(Clone, Copy, ValueEnum)]
enum ProfileArg {
    Tta,
    Xsel2003,
}

impl ProfileArg {
    fn profile(self) -> Profile {
        match self {
            ProfileArg::Tta => Profile::TTA,
            ProfileArg::Xsel2003 => Profile::XSEL_2003,
        }
    }
}

fn parse_station(v: &str) -> Result<u8, String> {
    if v.len() != 2 || !v.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(format!("{v:?}: expected two hex digits (00..FF)"));
    }
    u8::from_str_radix(v, 16).map_err(|e| e.to_string())
}

/// What went wrong, and the exit status for it.
enum Failure {
    /// Exit 1 with this message.
    Failed(String),
    /// The reader of stdout went away: stop quietly.
    ClosedPipe,
}

impl From<String> for Failure {
    fn from(s: String) -> Self {
        Failure::Failed(s)
    }
}

/// A write to stdout: a closed pipe ends the program quietly.
fn out_err(e: io::Error) -> Failure {
    if e.kind() == io::ErrorKind::BrokenPipe {
        Failure::ClosedPipe
    } else {
        Failure::Failed(format!("cannot write the output: {e}"))
    }
}

type Run = Result<ExitCode, Failure>;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.command {
        Cmd::Inspect { file, json, format } => inspect_cmd(&file, json, format),
        Cmd::Encode {
            msg,
            station,
            response,
            bypass,
            fields,
        } => encode_cmd(&msg, station, response, bypass, fields),
        Cmd::Monitor { line, json } => monitor_cmd(&line, json),
        Cmd::Send {
            msg,
            line,
            output,
            detail,
        } => send_cmd(&msg, &line, output, detail),
        Cmd::Table { op } => match op {
            TableCmd::Write {
                file,
                line,
                verify,
                resume,
            } => table_write(&file, &line, verify, resume),
            TableCmd::Read {
                first,
                count,
                output,
                axes,
                line,
            } => table_read(first, count, output.as_deref(), axes, &line),
        },
        Cmd::Simulate(args) => simulate_cmd(&args),
    };
    match r {
        Ok(code) => code,
        Err(Failure::ClosedPipe) => ExitCode::SUCCESS,
        Err(Failure::Failed(msg)) => {
            let _ = writeln!(io::stderr(), "iai: {msg}");
            ExitCode::from(1)
        }
    }
}

fn inspect_cmd(file: &str, json: bool, format: Option<FormatArg>) -> Run {
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

fn message_json(msg: &MessageArgs) -> Result<Option<serde_json::Value>, String> {
    let (text, from) = match (&msg.json, &msg.json_file) {
        (Some(t), _) => (t.clone(), "--json".to_string()),
        (None, Some(p)) => (
            std::fs::read_to_string(p)
                .map_err(|e| format!("--json-file {}: cannot read it: {e}", p.display()))?,
            format!("--json-file {}", p.display()),
        ),
        (None, None) => return Ok(None),
    };
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| format!("{from}: not valid JSON: {e}"))
}

fn build(msg: &MessageArgs, station: u8, response: bool, bypass: bool) -> Result<Vec<u8>, String> {
    let opts = EncodeOptions {
        message: msg.message.clone(),
        assignments: msg.assignments.clone(),
        station,
        response,
        bypass,
        json: message_json(msg)?,
    };
    encode(&opts)
}

fn encode_cmd(msg: &MessageArgs, station: u8, response: bool, bypass: bool, fields: bool) -> Run {
    let mut out = io::stdout().lock();
    let header = if response {
        Header::Response
    } else {
        Header::Command
    };
    if fields {
        let id = find_message(&msg.message, header)?;
        writeln!(
            out,
            "{id:03X}H {} ({}):",
            catalogue::lookup(id).map(|m| m.name).unwrap_or(""),
            if response { "response" } else { "command" }
        )
        .map_err(out_err)?;
        for l in field_help(header, id) {
            writeln!(out, "{l}").map_err(out_err)?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    let frame = build(msg, station, response, bypass)?;
    let sc = frame
        .len()
        .checked_sub(4)
        .and_then(|at| frame.get(at..at + 2))
        .map(|s| String::from_utf8_lossy(s).into_owned())
        .unwrap_or_default();
    writeln!(out, "{}", escape(&frame)).map_err(out_err)?;
    writeln!(out, "checksum {sc}, {} bytes", frame.len()).map_err(out_err)?;
    Ok(ExitCode::SUCCESS)
}

fn stop_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let f = flag.clone();
    // A second handler cannot be installed; the first one is enough.
    let _ = ctrlc::set_handler(move || f.store(true, Ordering::SeqCst));
    flag
}

fn print_item(out: &mut impl Write, item: &inspect::Item, json: bool) -> io::Result<()> {
    if json {
        writeln!(out, "{}", inspect::json_line(item))?;
    } else {
        for l in inspect::text_entry(item) {
            writeln!(out, "{l}")?;
        }
    }
    out.flush()
}

fn monitor_cmd(line: &LineArgs, json: bool) -> Run {
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

fn show_frame(out: &mut impl Write, frame: &[u8], json: bool) -> io::Result<()> {
    let mut ins = inspect::Inspector::new();
    ins.feed(frame);
    ins.finish();
    for item in ins.take_items() {
        print_item(out, &item, json)?;
    }
    Ok(())
}

fn send_cmd(msg: &MessageArgs, line: &LineArgs, output: OutputArg, detail: bool) -> Run {
    let frame = build(msg, line.station, false, false)?;
    let profile = line.profile.profile();
    if let Ok(f) = iai_protocol_b::frame::Frame::new_checked(
        &frame,
        iai_protocol_b::checksum::BypassPolicy::Reject,
    ) {
        if !profile.supports(f.code()) {
            return Err(format!(
                "{:03X}H is not a message of the {} profile",
                f.code(),
                profile.name()
            )
            .into());
        }
        profile
            .check_command_len(frame.len())
            .map_err(|e| format!("{:03X}H: {e}", f.code()))?;
    }
    let target = line.target();
    let mut link = Link::open(&target, line.plan().line)?;
    let json = output == OutputArg::Json;
    let mut out = io::stdout().lock();
    let outcome = request(&mut link, &frame, detail).map_err(|e| format!("{target}: {e}"))?;
    let e = match outcome {
        Outcome::Reply(reply) => {
            show_frame(&mut out, &reply, json).map_err(out_err)?;
            return Ok(ExitCode::SUCCESS);
        }
        Outcome::NoReplyExpected => {
            writeln!(
                out,
                "sent; this command has no normal response and no error response came"
            )
            .map_err(out_err)?;
            return Ok(ExitCode::SUCCESS);
        }
        Outcome::Failed(e) => e,
    };
    Err(describe(&e, &target, detail).into())
}

fn progress_bar(total: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::with_draw_target(
        Some(total),
        indicatif::ProgressDrawTarget::stderr(),
    );
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{msg} [{bar:30}] {pos}/{len} records ({per_sec}, {eta} left)",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}

/// Exit status of a write that completed but leaves records confirmed by
/// an earlier run (`--resume`) unread on this controller.
const EXIT_RESUMED_UNVERIFIED: u8 = 3;

fn table_write(file: &Path, line: &LineArgs, verify: Verify, resume: bool) -> Run {
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

fn table_read(
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

fn simulate_cmd(args: &SimArgs) -> Run {
    let station = Station(args.station);
    let mut ctl = match args.profile {
        ProfileArg::Tta => Controller::tta(station),
        ProfileArg::Xsel2003 => Controller::xsel_2003(station),
    };
    ctl.response_delay_ms = args.reply_delay_ms;
    ctl.refuse = !args.accept_all;
    let shared = Shared::new(ctl);
    let opts = ServeOptions {
        faults: args.faults.clone().unwrap_or_default(),
        seed: args.seed,
        log_frames: !args.quiet,
    };
    // Signals: write the table if asked, then exit.
    let (tx, rx) = std::sync::mpsc::channel::<()>();
    let done = tx.clone();
    ctrlc::set_handler(move || {
        let _ = tx.send(());
    })
    .map_err(|e| format!("cannot handle signals: {e}"))?;
    let mut connected = None;
    let listening = if args.pty {
        start_pty(&shared, &opts)?
    } else if let Some(addr) = &args.connect {
        let wait = args
            .connect_wait_ms
            .map_or(simulate::CONNECT_PATIENCE, |ms| {
                std::time::Duration::from_millis(ms)
            });
        let conn = simulate::connect(addr, wait)?;
        let peer = conn
            .peer_addr()
            .map_or_else(|_| addr.clone(), |a| a.to_string());
        connected = Some(conn);
        format!("connected tcp {peer}")
    } else {
        let addr = args.tcp.clone().unwrap_or_default();
        let listener = std::net::TcpListener::bind(addr.as_str()).map_err(|e| {
            format!("--tcp {addr:?}: cannot listen there ({e}); give 127.0.0.1:PORT")
        })?;
        let local = listener
            .local_addr()
            .map_err(|e| format!("--tcp {addr:?}: {e}"))?;
        let (s, o) = (shared.clone(), opts.clone());
        std::thread::spawn(move || simulate::serve_tcp(listener, s, o));
        format!("listening tcp {local}")
    };
    {
        let mut out = io::stdout().lock();
        let ctl = shared.ctl.lock().unwrap_or_else(|p| p.into_inner());
        let _ = writeln!(out, "{listening}");
        let _ = writeln!(
            out,
            "simulating a {} controller, station {:02X} (receive buffer {} bytes, transmit {} bytes); Ctrl-C stops",
            args.profile.profile().name(),
            args.station,
            ctl.max_receive,
            ctl.max_transmit
        );
        let _ = out.flush();
    }
    // The one connection of --connect: its end ends the run, as a signal does.
    if let Some(conn) = connected {
        let (s, o) = (shared.clone(), opts.clone());
        std::thread::spawn(move || {
            simulate::serve_connected(conn, &s, &o);
            let _ = done.send(());
        });
    }
    let _ = rx.recv();
    if let Some(path) = &args.dump {
        let ctl = shared.ctl.lock().unwrap_or_else(|p| p.into_inner());
        let recs: Vec<&PositionRecord> = ctl.table.values().collect();
        let axes = csvtable::axes_used(recs.iter().copied());
        let written = std::fs::File::create(path).and_then(|f| {
            let mut w = io::BufWriter::new(f);
            csvtable::write_header(&mut w, axes)?;
            for r in &recs {
                csvtable::write_row(&mut w, r, axes)?;
            }
            w.flush()
        });
        written.map_err(|e| format!("--dump {}: {e}", path.display()))?;
        let mut out = io::stdout().lock();
        let _ = writeln!(
            out,
            "dumped {} position(s) to {}",
            recs.len(),
            path.display()
        );
        let _ = out.flush();
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(unix)]
fn start_pty(shared: &Shared, opts: &ServeOptions) -> Result<String, Failure> {
    let pty = simulate::pty::Pty::open().map_err(|e| format!("--pty: {e}"))?;
    let line = format!("listening pty {}", pty.path);
    let (s, o) = (shared.clone(), opts.clone());
    std::thread::spawn(move || simulate::pty::serve_pty(pty, s, o));
    Ok(line)
}

#[cfg(not(unix))]
fn start_pty(_: &Shared, _: &ServeOptions) -> Result<String, Failure> {
    Err(Failure::Failed(
        "--pty needs a Unix system; use --tcp 127.0.0.1:PORT".into(),
    ))
}
