//! `iai`: inspect captures, encode and send messages, write and read
//! position tables as CSV, run the controller simulator. See `iai --help`.

mod cmd;

use cmd::help;

use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand, ValueEnum};

use cmd::line::{station_text, DEFAULT_BAUD, DEFAULT_STATION};
use cmd::Failure;
use firmware_example::config::{Config as BridgeConfig, BAUD_RATES};
use iai_cli::link::{Parity, SerialSettings};
use iai_protocol_b::line::{MAX_SENDS, TIMEOUT_MS};
use iai_protocol_b::profile::Profile;
use iai_simulator::server::CONNECT_PATIENCE;

/// IAI protocol B tools: captures, messages, position tables, a simulator.
///
/// Flags mean the same in every command: --json prints JSON (one object
/// per line) on stdout; -o/--output names an output file; --fields-json
/// and --fields-file give a message's fields as JSON.
#[derive(Parser)]
#[command(name = "iai", version, about, after_help = help::IAI)]
pub(crate) struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
pub(crate) enum Cmd {
    /// List every frame of a capture with offsets (hex), fields, what
    /// their values mean and checksum status, and every error at its byte
    /// offset. Exit status 1 if the capture had errors (broken frames,
    /// noise, bodies that do not decode).
    #[command(after_help = help::INSPECT)]
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
    /// Build one frame from field=value arguments or JSON. Only the frame
    /// goes to stdout (escaped, one line; --raw: the bytes); its checksum
    /// and length go to stderr.
    #[command(after_help = help::ENCODE)]
    Encode {
        #[command(flatten)]
        msg: MessageArgs,
        /// Station (two hex digits).
        #[arg(long, default_value = station_text(DEFAULT_STATION), value_parser = parse_station)]
        station: u8,
        /// Build the normal response instead of the command.
        #[arg(long)]
        response: bool,
        /// Send '@@' instead of the checksum.
        #[arg(long)]
        bypass: bool,
        /// List the message's fields instead (which may be left out, and
        /// the names a field takes).
        #[arg(long)]
        fields: bool,
        /// Write the frame's bytes as they go on the wire (CR LF
        /// included), not escaped.
        #[arg(long)]
        raw: bool,
    },
    /// List the frames arriving on a line, live, until Ctrl-C (exit 130).
    #[command(after_help = help::MONITOR)]
    Monitor {
        #[command(flatten)]
        line: LinkArgs,
        /// One JSON object per line.
        #[arg(long)]
        json: bool,
        /// Prefix each entry with the time since the start ("t_ms" in
        /// JSON).
        #[arg(long)]
        timestamps: bool,
        /// Also save the bytes as received to FILE (raw; `iai inspect`
        /// reads it).
        #[arg(long, value_name = "FILE")]
        save: Option<PathBuf>,
    },
    /// Send one command, wait for its reply (--timeout; sent again up to
    /// --retries times when resending cannot repeat an operation) and print
    /// it with what its values mean. A field without a documented default
    /// must be given.
    #[command(after_help = help::SEND)]
    Send {
        #[command(flatten)]
        msg: MessageArgs,
        #[command(flatten)]
        line: LineArgs,
        /// Print the reply, or the failure, as one JSON object (the reply
        /// as `inspect --json` prints it).
        #[arg(long)]
        json: bool,
        /// Former spelling of --json (--output json).
        #[arg(long, value_enum, hide = true)]
        output: Option<OutputArg>,
        /// On an error response, also query its details (216H, latest
        /// system error).
        #[arg(long)]
        detail: bool,
    },
    /// Position tables as CSV.
    Table {
        #[command(subcommand)]
        op: TableCmd,
    },
    /// The bridge firmware on the line.
    Bridge {
        #[command(subcommand)]
        op: BridgeCmd,
    },
    /// The Modbus gateway of the bridge firmware.
    Modbus {
        #[command(subcommand)]
        op: ModbusCmd,
    },
    /// List the serial ports of this machine (name, kind, USB IDs).
    #[command(after_help = help::PORTS)]
    Ports {
        /// One JSON object per port.
        #[arg(long)]
        json: bool,
    },
    /// Find what answers on a line: at each baud rate, a 200H test call
    /// with a nonce to each station (--station, then any station that
    /// replies show); says what came back. Exit status 0 when a controller
    /// answered.
    #[command(after_help = help::PROBE)]
    Probe(ProbeArgs),
    /// Run the controller simulator.
    #[command(after_help = help::SIMULATE)]
    Simulate(SimArgs),
}

#[derive(Subcommand)]
pub(crate) enum BridgeCmd {
    /// Ask the bridge for its status (B00H to its own station) and show
    /// it decoded: configuration, counters, last error.
    #[command(after_help = help::BRIDGE_STATUS)]
    Status(BridgeStatusArgs),
    /// The gateway's configuration page: show it, change settings, apply
    /// a file, or make an image to flash.
    #[command(subcommand)]
    Config(ConfigCmd),
    /// Restart the gateway (B23H to its own station, with the password):
    /// what was applied takes effect. Waits until it answers again.
    #[command(after_help = help::BRIDGE_RESTART)]
    Restart(BridgeRestartArgs),
}

#[derive(Subcommand)]
pub(crate) enum ConfigCmd {
    /// Show every setting of the configuration page in force (B20H), as
    /// TOML (the form `config apply` takes) or JSON.
    #[command(after_help = help::CONFIG_GET)]
    Get(ConfigGetArgs),
    /// Change settings (key=value, as `config get` names them) and apply
    /// the page (B21H, B22H; B24H for access.password). Most take effect
    /// at the next start (`iai bridge restart`).
    #[command(after_help = help::CONFIG_SET)]
    Set(ConfigSetArgs),
    /// Apply the settings a TOML file gives (the others keep their
    /// values).
    #[command(after_help = help::CONFIG_APPLY)]
    Apply(ConfigApplyArgs),
    /// Write a TOML file's settings as an image of the configuration page
    /// to flash with a programmer (no gateway needed); says where.
    #[command(after_help = help::CONFIG_BLOCK)]
    Block(ConfigBlockArgs),
}

/// The bridge on a line, for its configuration messages.
#[derive(Args)]
pub(crate) struct BridgeAt {
    #[command(flatten)]
    pub(crate) link: LinkArgs,
    /// The bridge's own station (two hex digits).
    #[arg(long, default_value = "BB", value_parser = parse_station)]
    pub(crate) bridge_station: u8,
    /// How long each reply may take, ms.
    #[arg(long, value_name = "MS", default_value_t = 3_000,
          value_parser = clap::value_parser!(u32).range(1..=600_000))]
    pub(crate) timeout: u32,
    /// Reads sent again after the first when no reply came (changes are
    /// sent once).
    #[arg(long, value_name = "N", default_value_t = 2,
          value_parser = clap::value_parser!(u8).range(0..=9))]
    pub(crate) retries: u8,
}

/// The gateway's password (every change needs it): --password,
/// --password-file, or the environment variable IAI_BRIDGE_PASSWORD.
#[derive(Args)]
pub(crate) struct PasswordArgs {
    /// The gateway's password (seen by other users of this machine in the
    /// process list: prefer --password-file or IAI_BRIDGE_PASSWORD).
    #[arg(long, value_name = "PASSWORD", conflicts_with = "password_file")]
    pub(crate) password: Option<String>,
    /// A file whose first line is the gateway's password.
    #[arg(long, value_name = "FILE")]
    pub(crate) password_file: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct ConfigGetArgs {
    #[command(flatten)]
    pub(crate) at: BridgeAt,
    /// One JSON object instead of TOML.
    #[arg(long)]
    pub(crate) json: bool,
    /// Also write the page as an image for `--board`'s slots (with the
    /// password, its verifier too, so that the image keeps the password).
    #[arg(long, value_name = "FILE")]
    pub(crate) image: Option<PathBuf>,
    /// The board whose slots the image is for.
    #[arg(long, value_enum, default_value = "lm3s6965")]
    pub(crate) board: BoardArg,
    #[command(flatten)]
    pub(crate) password: PasswordArgs,
}

#[derive(Args)]
pub(crate) struct ConfigSetArgs {
    /// Settings as key=value (`modbus.unit=5`, `access.password=NEW`).
    #[arg(required = true, value_name = "KEY=VALUE")]
    pub(crate) settings: Vec<String>,
    #[command(flatten)]
    pub(crate) at: BridgeAt,
    #[command(flatten)]
    pub(crate) password: PasswordArgs,
    /// One JSON object for the result.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args)]
pub(crate) struct ConfigApplyArgs {
    /// A TOML file (as `config get` prints).
    pub(crate) file: PathBuf,
    #[command(flatten)]
    pub(crate) at: BridgeAt,
    #[command(flatten)]
    pub(crate) password: PasswordArgs,
    /// One JSON object for the result.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args)]
pub(crate) struct ConfigBlockArgs {
    /// A TOML file (as `config get` prints); what it leaves out is blank
    /// (the defaults).
    pub(crate) file: PathBuf,
    /// The image to write.
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub(crate) output: PathBuf,
    /// The board whose slots the image is for.
    #[arg(long, value_enum, default_value = "lm3s6965")]
    pub(crate) board: BoardArg,
}

#[derive(Args)]
pub(crate) struct BridgeRestartArgs {
    #[command(flatten)]
    pub(crate) at: BridgeAt,
    #[command(flatten)]
    pub(crate) password: PasswordArgs,
    /// How long to wait for the gateway to answer again, s (0: do not
    /// wait).
    #[arg(long, value_name = "S", default_value_t = 30)]
    pub(crate) wait: u32,
}

/// Boards with configuration slots.
#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum BoardArg {
    /// QEMU lm3s6965evb, or an LM3S6965 (two 1 KiB slots at 0x3F800).
    Lm3s6965,
    /// QEMU mps2-an386 (two 1 KiB slots at 0x3F800).
    #[value(name = "mps2-an386")]
    Mps2An386,
    /// STM32G030x8 (two 2 KiB slots at 0x0800F000).
    Stm32g030,
    /// STM32G070xB (two 2 KiB slots at 0x0801F000).
    Stm32g070,
}

#[derive(Subcommand)]
pub(crate) enum ModbusCmd {
    /// Print the gateway's register map from the firmware's own table:
    /// a Markdown table field by field (default), or every register and
    /// bit of every axis as CSV, JSON or a KEPServerEX tag import.
    #[command(after_help = cmd::modbus::MAP_HELP)]
    Map(ModbusMapArgs),
}

#[derive(Args)]
#[group(multiple = false)]
pub(crate) struct ModbusMapArgs {
    /// CSV: address, functions, name, type, unit, access, meaning.
    #[arg(long)]
    csv: bool,
    /// One JSON object per register, bit or pair.
    #[arg(long)]
    json: bool,
    /// A KEPServerEX CSV tag import (Modbus TCP/IP Ethernet or Modbus
    /// RTU Serial driver).
    #[arg(long)]
    kepware: bool,
}

#[derive(Args)]
pub(crate) struct BridgeStatusArgs {
    #[command(flatten)]
    pub(crate) link: LinkArgs,
    /// The bridge's own station (two hex digits).
    #[arg(long, default_value = bridge_station_text(), value_parser = parse_station)]
    pub(crate) bridge_station: u8,
    /// How long the reply may take, ms.
    #[arg(long, value_name = "MS", default_value_t = TIMEOUT_MS,
          value_parser = clap::value_parser!(u32).range(1..=600_000))]
    pub(crate) timeout: u32,
    /// Queries after the first when no reply came.
    #[arg(long, value_name = "N", default_value_t = MAX_SENDS - 1,
          value_parser = clap::value_parser!(u8).range(0..=9))]
    pub(crate) retries: u8,
    /// One JSON object: the fields and what they mean.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Args)]
pub(crate) struct ProbeArgs {
    #[command(flatten)]
    pub(crate) target: Where,
    /// Baud rates to try, comma-separated [default: every rate the
    /// controllers offer].
    #[arg(long, value_delimiter = ',', help = format!(
        "Baud rates to try, comma-separated [default: {}]",
        BAUD_RATES.map(|b| b.to_string()).join(",")
    ))]
    pub(crate) baud: Vec<u32>,
    #[command(flatten)]
    pub(crate) serial: SerialArgs,
    /// Stations to try (two hex digits each, comma-separated).
    #[arg(long, value_parser = parse_station, value_delimiter = ',',
          default_values = cmd::diag::PROBE_STATIONS.map(station_text))]
    pub(crate) station: Vec<u8>,
    /// How long to wait after each test call, ms.
    #[arg(long, value_name = "MS", default_value_t = 500,
          value_parser = clap::value_parser!(u32).range(10..=60_000))]
    pub(crate) timeout: u32,
    /// The station a bridge would answer its status query at (two hex
    /// digits); asked at each baud rate first.
    #[arg(long, default_value = bridge_station_text(), value_parser = parse_station)]
    pub(crate) bridge_station: u8,
    /// One JSON object per try, then the result.
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Subcommand)]
pub(crate) enum TableCmd {
    /// Write a CSV table to the controller, with a progress bar. Exit
    /// status 0 only when the controller holds the table (or, with
    /// --verify off, when every frame was confirmed; the output then says
    /// the table is unverified).
    #[command(after_help = help::TABLE_WRITE)]
    Write(WriteArgs),
    /// Read positions back as CSV: FIRST .. FIRST+COUNT-1, or --all.
    #[command(after_help = help::TABLE_READ)]
    Read(ReadArgs),
    /// Clear positions (246H): FIRST .. FIRST+COUNT-1, or --all. No
    /// confirmation is asked: the range must be given.
    #[command(after_help = help::TABLE_CLEAR)]
    Clear(ClearArgs),
}

#[derive(Args)]
pub(crate) struct WriteArgs {
    /// The CSV file.
    pub file: PathBuf,
    #[command(flatten)]
    pub line: LineArgs,
    /// Read the table back and compare: always (full), only after a
    /// timeout, error reply or line error (after-fault), or never (off)
    /// [default: full; with --bridge the bridge reads every chunk back].
    #[arg(long, value_enum)]
    pub verify: Option<Verify>,
    /// Continue after the last confirmed record of an interrupted
    /// write (state kept in FILE.csv.iai-state).
    #[arg(long, conflicts_with = "restart")]
    pub resume: bool,
    /// Start over although an interrupted write left its state file.
    #[arg(long)]
    pub restart: bool,
    /// Make the controller's table the file's: clear every position 246H
    /// reaches (0..=8189) first, then write; afterwards 208H must count
    /// exactly the file's records.
    #[arg(long)]
    pub replace: bool,
    /// Send the whole table to the bridge firmware as one 26DH (it writes
    /// it in controller-sized commands and reads every one back); its `#`
    /// means the controller holds every record. Flow control defaults to
    /// XON/XOFF, the bridge's.
    #[arg(long, conflicts_with = "resume")]
    pub bridge: bool,
    /// The bridge's own station (two hex digits), for --bridge.
    #[arg(long, default_value = bridge_station_text(), value_parser = parse_station, requires = "bridge")]
    pub bridge_station: u8,
}

#[derive(Args)]
pub(crate) struct ReadArgs {
    /// First position number.
    #[arg(long, required_unless_present = "all", requires = "count")]
    pub first: Option<u16>,
    /// Number of positions.
    #[arg(long, requires = "first", value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub count: Option<u32>,
    /// The whole table: as many defined positions as 208H counts, looked
    /// for from position 0 up.
    #[arg(long, conflicts_with_all = ["first", "count"])]
    pub all: bool,
    /// Write to this file instead of stdout (needed for --resume).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Axis columns (default: up to the highest axis read).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub axes: Option<u8>,
    /// Continue an interrupted read into the same -o FILE (state kept in
    /// FILE.iai-read-state).
    #[arg(long, conflicts_with = "restart", requires = "output")]
    pub resume: bool,
    /// Start over although an interrupted read left its state file.
    #[arg(long)]
    pub restart: bool,
    #[command(flatten)]
    pub line: LineArgs,
}

#[derive(Args)]
pub(crate) struct ClearArgs {
    /// First position to clear.
    #[arg(long, required_unless_present = "all", requires = "count")]
    pub first: Option<u16>,
    /// Number of positions to clear.
    #[arg(long, requires = "first", value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub count: Option<u32>,
    /// Every position 246H reaches (0..=8189; 0..=4095 on a 2003 X-SEL).
    #[arg(long, conflicts_with_all = ["first", "count"])]
    pub all: bool,
    #[command(flatten)]
    pub line: LineArgs,
}

#[derive(Args)]
pub(crate) struct MessageArgs {
    /// Message: hex ID (212, 212H) or name ("Axis Status Query").
    message: String,
    /// field=value: decimal or 0x hex, one optional '-' for signed fields;
    /// repeat-group fields take comma lists, '/' between outer items.
    assignments: Vec<String>,
    /// The fields as JSON, in the form `inspect --json` prints under
    /// "fields".
    #[arg(long, value_name = "JSON", conflicts_with = "fields_file")]
    fields_json: Option<String>,
    /// The fields as JSON, from a file (former spelling: --json-file).
    #[arg(long, value_name = "FILE", alias = "json-file")]
    fields_file: Option<PathBuf>,
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

/// Where the line is, and a serial port's settings.
#[derive(Args)]
pub(crate) struct LinkArgs {
    #[command(flatten)]
    pub(crate) target: Where,
    /// Baud rate of the serial port.
    #[arg(long, help = format!("Baud rate of the serial port [default: {DEFAULT_BAUD}]"))]
    pub(crate) baud: Option<u32>,
    #[command(flatten)]
    pub(crate) serial: SerialArgs,
}

/// A serial port's framing and flow control (the controller's I/O
/// parameters Nos. 93-95 must match).
#[derive(Args)]
pub(crate) struct SerialArgs {
    /// Data bits of the serial port, 7 or 8 (I/O parameter No. 93).
    #[arg(long, value_parser = clap::value_parser!(u8).range(7..=8), help = format!(
        "Data bits of the serial port, 7 or 8 (I/O parameter No. 93) [default: {}]",
        SerialSettings::DEFAULT.data_bits
    ))]
    pub(crate) data_bits: Option<u8>,
    /// Parity of the serial port (No. 95).
    #[arg(long, value_enum, help = format!(
        "Parity of the serial port (No. 95) [default: {}]",
        ParityArg::name(SerialSettings::DEFAULT.parity)
    ))]
    pub(crate) parity: Option<ParityArg>,
    /// Stop bits of the serial port, 1 or 2 (No. 94).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=2), help = format!(
        "Stop bits of the serial port, 1 or 2 (No. 94) [default: {}]",
        SerialSettings::DEFAULT.stop_bits
    ))]
    pub(crate) stop_bits: Option<u8>,
    /// Flow control: xonxoff (over TCP, done by iai), rtscts (a serial
    /// port's modem lines) or none [default: none; xonxoff with --bridge].
    #[arg(long, value_enum)]
    pub(crate) flow: Option<FlowArg>,
}

/// A line to a controller: where, which station and kind, and chapter 5's
/// timeout and resends.
#[derive(Args)]
pub(crate) struct LineArgs {
    #[command(flatten)]
    pub(crate) link: LinkArgs,
    /// Station code (two hex digits, I/O parameter No. 91).
    #[arg(long, default_value = station_text(DEFAULT_STATION), value_parser = parse_station)]
    pub(crate) station: u8,
    /// Controller kind: buffer sizes and messages.
    #[arg(long, value_enum, default_value = "tta")]
    pub(crate) profile: ProfileArg,
    /// How long after a reply a copy of it may still come, ms, on a line
    /// that repeats frames (an echoing converter). A command goes out only
    /// when no copy could pass for its reply. Not given: the line's
    /// default, a direct line that repeats nothing.
    #[arg(long, value_name = "MS")]
    pub(crate) duplicate_window_ms: Option<u32>,
    /// How long a reply may take after the command was sent, ms (2003
    /// p. 62).
    #[arg(long, value_name = "MS", default_value_t = TIMEOUT_MS,
          value_parser = clap::value_parser!(u32).range(1..=600_000))]
    pub(crate) timeout: u32,
    /// Sends of a command after the first when no reply came (2003 p. 62:
    /// 2 or 3); a command that is unsafe to repeat is sent once.
    #[arg(long, value_name = "N", default_value_t = MAX_SENDS - 1,
          value_parser = clap::value_parser!(u8).range(0..=9))]
    pub(crate) retries: u8,
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
    /// How long --connect keeps trying while nothing listens yet, ms.
    #[arg(long, conflicts_with_all = ["tcp", "pty"], help = format!(
        "How long --connect keeps trying while nothing listens yet, ms [default: {}]",
        CONNECT_PATIENCE.as_millis()
    ))]
    connect_wait_ms: Option<u64>,
    /// Controller kind.
    #[arg(long, value_enum, default_value = "tta")]
    profile: ProfileArg,
    /// Station code (two hex digits).
    #[arg(long, default_value = station_text(DEFAULT_STATION), value_parser = parse_station)]
    station: u8,
    /// Delay before each reply, ms (the controller's α).
    #[arg(long, default_value_t = iai_simulator::REPLY_DELAY_MS)]
    reply_delay_ms: u32,
    /// Faults: corrupt=P,swap=P,drop=P,late=P:MS,dup=P:MS,error=P.
    #[arg(long, value_parser = iai_simulator::server::parse_faults)]
    faults: Option<iai_simulator::Faults>,
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
pub(crate) enum ParityArg {
    None,
    Odd,
    Even,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub(crate) enum FlowArg {
    None,
    Xonxoff,
    Rtscts,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub(crate) enum OutputArg {
    Text,
    Json,
}

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug, Default)]
pub(crate) enum Verify {
    Off,
    AfterFault,
    #[default]
    Full,
}

#[derive(Clone, Copy, ValueEnum)]
pub(crate) enum ProfileArg {
    Tta,
    Xsel2003,
}

impl ParityArg {
    /// The name the command line gives `parity`.
    fn name(parity: Parity) -> String {
        let arg = match parity {
            Parity::None => ParityArg::None,
            Parity::Odd => ParityArg::Odd,
            Parity::Even => ParityArg::Even,
        };
        arg.to_possible_value()
            .map_or_else(String::new, |v| v.get_name().to_string())
    }
}

impl ProfileArg {
    fn profile(self) -> Profile {
        match self {
            ProfileArg::Tta => Profile::TTA,
            ProfileArg::Xsel2003 => Profile::XSEL_2003,
        }
    }
}

/// The bridge's own station by default (its configuration's default).
fn bridge_station_text() -> String {
    station_text(BridgeConfig::DEFAULT.bridge_station.0)
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
            raw,
        } => cmd::encode::encode_cmd(&msg, station, response, bypass, fields, raw),
        Cmd::Monitor {
            line,
            json,
            timestamps,
            save,
        } => cmd::monitor::monitor_cmd(&line, json, timestamps, save.as_deref()),
        Cmd::Send {
            msg,
            line,
            json,
            output,
            detail,
        } => {
            let json = json || output == Some(OutputArg::Json);
            cmd::send::send_cmd(&msg, &line, json, detail)
        }
        Cmd::Table { op } => match op {
            TableCmd::Write(a) => cmd::table_write::table_write(&a),
            TableCmd::Read(a) => cmd::table_read::table_read(&a),
            TableCmd::Clear(a) => cmd::table_clear::table_clear(&a),
        },
        Cmd::Bridge {
            op: BridgeCmd::Status(a),
        } => cmd::bridge::status_cmd(&a),
        Cmd::Modbus {
            op: ModbusCmd::Map(a),
        } => {
            use cmd::modbus::Form;
            let form = match (a.csv, a.json, a.kepware) {
                (true, _, _) => Form::Csv,
                (_, true, _) => Form::Json,
                (_, _, true) => Form::Kepware,
                _ => Form::Markdown,
            };
            cmd::modbus::map_cmd(form)
        }
        Cmd::Bridge {
            op: BridgeCmd::Config(c),
        } => match c {
            ConfigCmd::Get(a) => cmd::bridge::config_get(&a),
            ConfigCmd::Set(a) => cmd::bridge::config_set(&a),
            ConfigCmd::Apply(a) => cmd::bridge::config_apply(&a),
            ConfigCmd::Block(a) => cmd::bridge::config_block(&a),
        },
        Cmd::Bridge {
            op: BridgeCmd::Restart(a),
        } => cmd::bridge::restart_cmd(&a),
        Cmd::Ports { json } => cmd::diag::ports_cmd(json),
        Cmd::Probe(a) => cmd::diag::probe_cmd(&a),
        Cmd::Simulate(args) => cmd::simulate::simulate_cmd(&args),
    };
    match r {
        Ok(code) => code,
        Err(Failure::ClosedPipe) => ExitCode::SUCCESS,
        Err(Failure::Failed(msg)) => {
            let _ = writeln!(io::stderr(), "iai: {msg}");
            ExitCode::from(1)
        }
        Err(Failure::Exit(code, msg)) => {
            if !msg.is_empty() {
                let _ = writeln!(io::stderr(), "iai: {msg}");
            }
            ExitCode::from(code)
        }
    }
}
