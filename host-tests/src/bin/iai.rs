//! `iai`: inspect captures, encode frames and run the controller simulator.
//! See `iai help`.

use std::io::Write;
use std::process::ExitCode;

use host_tests::cli::encode::{encode, field_help, find_message, EncodeOptions};
use host_tests::cli::inspect::{self, Format};
use host_tests::cli::simulate::{self, SimProfile, SimulateOptions};
use host_tests::cli::text::escape;
use iai_protocol_b::catalogue;
use iai_protocol_b::frame::Header;

const USAGE: &str = "\
iai — IAI protocol B tools

USAGE:
  iai inspect [--json] [--format raw|text] FILE|-
      List every frame of a capture (raw bytes, or a text log with one
      frame per line, optionally prefixed '> '/'< ' or 'TX '/'RX ', with
      \\r \\n \\\\ \\xNN escapes) with offsets, fields and checksum status,
      and every error at its byte offset. --json: one object per line.
      Without --format the format is guessed. Exit status 1 if the capture
      had errors.
  iai encode MESSAGE [field=value ...] [--station 99] [--response] [--bypass]
      Build one frame. MESSAGE is a hex ID (212, 212H) or a name
      (\"Axis Status Query\", AxisStatusQuery). Values are decimal or 0x hex,
      negative for signed fields; repeat-group fields take comma lists.
      'iai encode MESSAGE --fields' lists the fields.
  iai simulate [--port P] [--profile tta|xsel2003] [--station 99]
      Run the controller simulator on 127.0.0.1:P (default 5020; 0 picks a
      free port) and print every frame it receives and sends.
  iai help
";

fn fail(msg: &str) -> ExitCode {
    eprintln!("iai: {msg}");
    eprintln!("try 'iai help'");
    ExitCode::from(2)
}

fn station(v: &str) -> Result<u8, String> {
    u8::from_str_radix(v, 16).map_err(|_| format!("station {v:?}: expected two hex digits"))
}

fn value<'a>(it: &mut impl Iterator<Item = &'a String>, opt: &str) -> Result<&'a String, String> {
    it.next().ok_or_else(|| format!("{opt} needs a value"))
}

fn run(args: &[String]) -> Result<ExitCode, String> {
    let Some((cmd, rest)) = args.split_first() else {
        print!("{USAGE}");
        return Ok(ExitCode::from(2));
    };
    let mut stdout = std::io::stdout().lock();
    match cmd.as_str() {
        "inspect" => {
            let (mut json, mut format, mut file) = (false, None, None);
            let mut it = rest.iter();
            while let Some(a) = it.next() {
                match a.as_str() {
                    "--json" => json = true,
                    "--format" => {
                        format = Some(match value(&mut it, a)?.as_str() {
                            "raw" => Format::Raw,
                            "text" => Format::Text,
                            f => return Err(format!("unknown format {f:?} (raw or text)")),
                        })
                    }
                    f if file.is_none() && (f == "-" || !f.starts_with('-')) => file = Some(f),
                    other => return Err(format!("inspect: unexpected {other:?}")),
                }
            }
            let file = file.ok_or("inspect needs a FILE (or - for stdin)")?;
            let code = inspect::command(file, format, json, &mut stdout)
                .map_err(|e| format!("{file}: {e}"))?;
            Ok(ExitCode::from(u8::try_from(code).unwrap_or(1)))
        }
        "encode" => {
            let mut opts = EncodeOptions {
                message: String::new(),
                assignments: Vec::new(),
                station: 0x99,
                response: false,
                bypass: false,
            };
            let mut list_fields = false;
            let mut it = rest.iter();
            while let Some(a) = it.next() {
                match a.as_str() {
                    "--station" => opts.station = station(value(&mut it, a)?)?,
                    "--response" => opts.response = true,
                    "--bypass" => opts.bypass = true,
                    "--fields" => list_fields = true,
                    s if s.contains('=') => opts.assignments.push(s.to_string()),
                    s if opts.message.is_empty() && !s.starts_with("--") => {
                        opts.message = s.to_string()
                    }
                    other => return Err(format!("encode: unexpected {other:?}")),
                }
            }
            if opts.message.is_empty() {
                return Err("encode needs a MESSAGE".into());
            }
            let header = if opts.response {
                Header::Response
            } else {
                Header::Command
            };
            if list_fields {
                let id = find_message(&opts.message, header)?;
                let _ = writeln!(
                    stdout,
                    "{id:03X}H {} ({}):",
                    catalogue::lookup(id).map(|m| m.name).unwrap_or(""),
                    if opts.response { "response" } else { "command" }
                );
                for l in field_help(header, id) {
                    let _ = writeln!(stdout, "{l}");
                }
                return Ok(ExitCode::SUCCESS);
            }
            let frame = encode(&opts)?;
            let sc = frame
                .len()
                .checked_sub(4)
                .and_then(|at| frame.get(at..at + 2))
                .map(|s| String::from_utf8_lossy(s).into_owned())
                .unwrap_or_default();
            let _ = writeln!(stdout, "{}", escape(&frame));
            let _ = writeln!(stdout, "checksum {sc}, {} bytes", frame.len());
            Ok(ExitCode::SUCCESS)
        }
        "simulate" => {
            let mut opts = SimulateOptions {
                port: 5020,
                profile: SimProfile::Tta,
                station: 0x99,
                connections: None,
            };
            let mut it = rest.iter();
            while let Some(a) = it.next() {
                match a.as_str() {
                    "--port" => {
                        let v = value(&mut it, a)?;
                        opts.port = v.parse().map_err(|_| format!("port {v:?}"))?;
                    }
                    "--pty" => return Err("--pty is not supported yet; use --port".into()),
                    "--profile" => {
                        opts.profile = match value(&mut it, a)?.as_str() {
                            "tta" => SimProfile::Tta,
                            "xsel2003" | "xsel" => SimProfile::Xsel2003,
                            p => return Err(format!("unknown profile {p:?} (tta or xsel2003)")),
                        }
                    }
                    "--station" => opts.station = station(value(&mut it, a)?)?,
                    "--connections" => {
                        let v = value(&mut it, a)?;
                        opts.connections = Some(v.parse().map_err(|_| format!("count {v:?}"))?);
                    }
                    other => return Err(format!("simulate: unexpected {other:?}")),
                }
            }
            simulate::command(&opts, &mut stdout).map_err(|e| e.to_string())?;
            Ok(ExitCode::SUCCESS)
        }
        "help" | "--help" | "-h" => {
            print!("{USAGE}");
            Ok(ExitCode::SUCCESS)
        }
        other => Err(format!("unknown command {other:?}")),
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(code) => code,
        Err(msg) => fail(&msg),
    }
}
