//! `iai bridge status` and `iai table write --bridge`: the bridge
//! firmware on the line, its status decoded, and a whole table sent to it
//! as one 26DH (see `iai_cli::bridge`).

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

use iai_cli::bridge::{
    decode_status, describe_status, parts, query_status, status_json, verdict_text,
    worth_resending, BridgeStatus, Verdict,
};
use iai_cli::link::{Flow, Link, Target};
use iai_cli::table::{self, Hooks, TableError};
use iai_protocol_b::error::Failure as CoreFailure;
use iai_protocol_b::frame::{Header, Station};
use iai_protocol_b::line::LineConfig;
use iai_protocol_b::position::{PositionRecord, PositionStream};

use super::{out_err, progress_bar, stop_flag, table_failure, Failure, Run, EXIT_INTERRUPTED};
use crate::{BridgeStatusArgs, WriteArgs};

/// Asks the bridge for its status over `link`; the error says what came
/// back instead.
fn status_of(
    link: &mut Link,
    station: u8,
    wait: Duration,
    sends: u8,
    hooks: &Hooks<'_>,
) -> Result<BridgeStatus, Failure> {
    let target = link.target().clone();
    match query_status(link, station, wait, sends, hooks) {
        Ok(reply) => decode_status(&reply).map_err(|e| Failure::Failed(format!("{target}: {e}"))),
        Err(TableError::Interrupted) => Err(Failure::Exit(EXIT_INTERRUPTED, "interrupted".into())),
        Err(TableError::Engine(CoreFailure::Controller { code, .. })) => Err(format!(
            "{target}: {}",
            decode_status(&error_frame(station, code))
                .err()
                .unwrap_or_default()
        )
        .into()),
        Err(TableError::Engine(CoreFailure::Timeout { sends })) => {
            let mut m = format!(
                "{target}: no bridge answered its status query (B00H to station {station:02X}, {sends} send(s)); is the bridge firmware on this line, at this station (--bridge-station)?"
            );
            if let Some(h) = link.hint() {
                m.push_str(&format!("\n  hint: {h}"));
            }
            Err(m.into())
        }
        Err(e) => Err(format!("{target}: the status query failed: {e}").into()),
    }
}

/// The `&` frame the bridge at `station` answered with `code`, as sent.
fn error_frame(station: u8, code: u16) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = iai_protocol_b::frame::emit_frame(
        &mut buf,
        Header::Error,
        Station(station),
        code,
        Default::default(),
        |_| Ok(()),
    )
    .unwrap_or(0);
    buf[..n].to_vec()
}

pub(crate) fn status_cmd(a: &BridgeStatusArgs) -> Run {
    let target = a.link.resolve(Flow::XonXoff);
    let mut link = Link::open(&target, LineConfig::new(Station(a.bridge_station)))?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let note = |m: &str| eprintln!("{m}");
    let hooks = Hooks {
        note: &note,
        stop: &stopped,
    };
    let wait = Duration::from_millis(u64::from(a.timeout));
    let s = status_of(
        &mut link,
        a.bridge_station,
        wait,
        a.retries.saturating_add(1),
        &hooks,
    )?;
    let mut out = io::stdout().lock();
    if a.json {
        writeln!(out, "{}", status_json(&s)).map_err(out_err)?;
    } else {
        for l in describe_status(&s) {
            writeln!(out, "{l}").map_err(out_err)?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// How much of the line rate the bridge takes in while it writes and
/// reads back each chunk, at least: the README measures 31 % to 37 %; a
/// fifth leaves a margin.
const INTAKE_DIVISOR: u64 = 5;

/// How long the bridge may take to take in a message of `bytes` after its
/// first byte left, ms: nothing on a serial line (the bytes reach it at
/// the rate they leave); over TCP (a gateway that buffers them) the time
/// it needs to take them in at `baud` (each chunk is written and read back
/// before it takes more).
fn intake_ms(bytes: usize, baud: u64, tcp: bool) -> u32 {
    if !tcp {
        return 0;
    }
    let wire_ms = (bytes as u64) * 10 * 1000 / baud.max(1) * INTAKE_DIVISOR;
    u32::try_from(wire_ms).unwrap_or(u32::MAX)
}

/// `table write --bridge`: the bridge must answer its status query (for
/// this controller station, a policy that takes 26DH), then each 26DH goes
/// out whole on the link's line (the core's upload engine: fenced first,
/// its reply matched, resent after a timeout within `--retries`); an `&`
/// the bridge gives for a transport failure sends it again, as often.
pub(crate) fn write_table(
    a: &WriteArgs,
    records: &[PositionRecord],
    link: &mut Link,
    hooks: &Hooks<'_>,
) -> Result<(), Failure> {
    let line = &a.line;
    let target = link.target().clone();
    let tcp = matches!(target, Target::Tcp { .. });
    let wait = Duration::from_millis(u64::from(line.timeout));
    let sends = line.retries.saturating_add(1);
    let st = status_of(link, a.bridge_station, wait, sends, hooks)?;
    let controller = st.get("controller_station");
    if controller != u64::from(line.station) {
        return Err(format!(
            "the bridge at station {:02X} forwards to controller station {controller:02X}, not {:02X}: give --station {controller:02X}",
            a.bridge_station, line.station
        )
        .into());
    }
    if st.get("policy") == 1 {
        return Err(format!(
            "the bridge at station {:02X} runs the read-only policy: it refuses 26DH (B06); nothing was sent",
            a.bridge_station
        )
        .into());
    }
    let baud = st.get("upstream_baud");
    eprintln!(
        "bridge at station {:02X}: controller station {controller:02X}, {baud} baud to the host, {} to the controller, flow control {}",
        a.bridge_station,
        st.get("downstream_baud"),
        match st.get("flow_control") {
            0 => "none",
            1 => "XON/XOFF",
            _ => "RTS/CTS",
        }
    );
    let stream = PositionStream::CHANGE_2;
    let sizes: Vec<usize> = parts(records).map(|p| stream.frame_len(p.iter())).collect();
    let total: usize = sizes.iter().sum();
    let bar = progress_bar(total as u64, "26DH to the bridge", "bytes");
    let mut base = 0usize;
    let mut written = 0usize;
    let count = parts(records).count();
    for (k, (part, &size)) in parts(records).zip(&sizes).enumerate() {
        let n = part.len() as u16;
        let mut attempt = 0u8;
        let verdict = loop {
            attempt += 1;
            bar.set_message(format!(
                "26DH {} of {count}{}",
                k + 1,
                if attempt > 1 {
                    format!(", send {attempt}")
                } else {
                    String::new()
                }
            ));
            let sent = table::upload(
                link,
                stream,
                part,
                intake_ms(size, baud, tcp),
                |b| bar.set_position((base as u64 + b).min((base + size) as u64)),
                hooks,
            );
            let verdict = match sent {
                Ok(got) => Verdict::Written(got),
                Err(TableError::Engine(CoreFailure::Controller { code, .. })) => {
                    Verdict::Refused(code)
                }
                Err(TableError::Engine(CoreFailure::Timeout { .. })) => Verdict::NoAnswer,
                Err(TableError::Interrupted) => {
                    bar.abandon();
                    return Err(Failure::Exit(
                        EXIT_INTERRUPTED,
                        format!("interrupted in the middle of a 26DH: the bridge answers it & B01 or B04; {written} records were confirmed before it, how far this one went is unknown; position writes are idempotent, so sending the table again puts it right"),
                    ));
                }
                Err(e) => {
                    bar.abandon();
                    return Err(table_failure(
                        link,
                        e,
                        &format!(
                            "; {written} records were confirmed by the bridge before this message"
                        ),
                    ));
                }
            };
            let again = matches!(&verdict, Verdict::Refused(code) if worth_resending(*code));
            if !again || attempt >= sends {
                break verdict;
            }
            bar.suspend(|| {
                eprintln!(
                    "{}; sending the message again ({} of {sends})",
                    verdict_text(&verdict, n),
                    attempt + 1
                )
            });
        };
        match verdict {
            Verdict::Written(got) if got == n => {
                bar.suspend(|| eprintln!("{}", verdict_text(&verdict, n)));
                written += usize::from(got);
            }
            v => {
                bar.abandon();
                let mut m = format!(
                    "{target}: {}; {written} records were confirmed by the bridge before this message; send the table again (position writes are idempotent)",
                    verdict_text(&v, n)
                );
                if v == Verdict::NoAnswer {
                    if let Some(h) = link.hint() {
                        m.push_str(&format!("\n  hint: {h}"));
                    }
                }
                return Err(m.into());
            }
        }
        base += size;
    }
    bar.finish_and_clear();
    if let Some(note) = link.repeats_note() {
        eprintln!("{note}");
    }
    println!(
        "verified by the bridge: the controller holds all {written} records ({count} 26DH message(s) of {total} bytes; the bridge wrote each in 2,051-byte commands, read every one back with 21FH and compared it, and answered # with the count)"
    );
    Ok(())
}
