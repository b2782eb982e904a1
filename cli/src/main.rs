//! `iai`: inspect captures, encode and send messages, write and read
//! position tables as CSV, run the controller simulator. See `iai --help`.

mod cmd;

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};

use cmd::Failure;
use iai_cli::link::Target;
use iai_cli::table::Plan;
use iai_protocol_b::frame::Station;
use iai_protocol_b::profile::Profile;

/// IAI protocol B tools: captures, messages, position tables, a simulator.
#[derive(Parser)]
#[command(name = "iai", version, about, long_about = None)]
pub(crate) struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
pub(crate) enum Cmd {
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
pub(crate) enum TableCmd {
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
pub(crate) struct MessageArgs {
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
pub(crate) struct Where {
    /// Serial device (/dev/ttyUSB0, COM3).
    #[arg(long)]
    port: Option<String>,
    /// HOST:PORT of a TCP link (a serial server, or `iai simulate --tcp`).
    #[arg(long)]
    tcp: Option<String>,
}

#[derive(Args)]
pub(crate) struct LineArgs {
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
pub(crate) struct SimArgs {
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
    #[arg(long, value_parser = iai_cli::simulate::parse_faults)]
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
pub(crate) enum FormatArg {
    Raw,
    Text,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub(crate) enum OutputArg {
    Text,
    Json,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug)]
pub(crate) enum Verify {
    Off,
    AfterFault,
    Full,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum ProfileArg {
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.command {
        Cmd::Inspect { file, json, format } => cmd::inspect::inspect_cmd(&file, json, format),
        Cmd::Encode {
            msg,
            station,
            response,
            bypass,
            fields,
        } => cmd::encode::encode_cmd(&msg, station, response, bypass, fields),
        Cmd::Monitor { line, json } => cmd::monitor::monitor_cmd(&line, json),
        Cmd::Send {
            msg,
            line,
            output,
            detail,
        } => cmd::send::send_cmd(&msg, &line, output, detail),
        Cmd::Table { op } => match op {
            TableCmd::Write {
                file,
                line,
                verify,
                resume,
            } => cmd::table_write::table_write(&file, &line, verify, resume),
            TableCmd::Read {
                first,
                count,
                output,
                axes,
                line,
            } => cmd::table_read::table_read(first, count, output.as_deref(), axes, &line),
        },
        Cmd::Simulate(args) => cmd::simulate::simulate_cmd(&args),
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
