//! `iai bridge status` and `iai table write --bridge`: the bridge
//! firmware on the line, its status decoded, and a whole table sent to it
//! as one 26DH (see `iai_cli::bridge`).

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use iai_cli::bridge::{
    await_frame, decode_status, describe_status, messages, query_status, status_json, verdict_text,
    worth_resending, BridgeStatus, Verdict,
};
use iai_cli::link::{Flow, Link, Target};
use iai_cli::probe::nonce;
use iai_cli::table::{self, Hooks};
use iai_protocol_b::frame::{Header, Station};
use iai_protocol_b::line::LineConfig;
use iai_protocol_b::message::TestCall;
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
    stop: &dyn Fn() -> bool,
) -> Result<BridgeStatus, Failure> {
    let target = link.target().clone();
    let reply = query_status(link, station, wait, sends, stop)
        .map_err(|e| format!("{target}: the line failed: {e}"))?;
    if stop() {
        return Err(Failure::Exit(EXIT_INTERRUPTED, "interrupted".into()));
    }
    let Some(reply) = reply else {
        let mut m = format!(
            "{target}: no bridge answered its status query (B00H to station {station:02X}, {} send(s)); is the bridge firmware on this line, at this station (--bridge-station)?",
            sends.max(1)
        );
        if let Some(h) = link.hint() {
            m.push_str(&format!("\n  hint: {h}"));
        }
        return Err(m.into());
    };
    decode_status(&reply).map_err(|e| Failure::Failed(format!("{target}: {e}")))
}

pub(crate) fn status_cmd(a: &BridgeStatusArgs) -> Run {
    let target = a.link.resolve(Flow::XonXoff);
    let mut link = Link::open(&target, LineConfig::new(Station(a.bridge_station)))?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let wait = Duration::from_millis(u64::from(a.timeout));
    let s = status_of(
        &mut link,
        a.bridge_station,
        wait,
        a.retries.saturating_add(1),
        &stopped,
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

/// How long to wait for the bridge's answer after a write of `bytes` that
/// started at `start` and ended at `end`: the reply timeout after the
/// last byte left, or, where the link may hold the bytes back (a TCP
/// server or gateway that buffers them), after the time the bridge needs
/// to take them all in at `baud`.
fn deadline(
    start: Instant,
    end: Instant,
    bytes: usize,
    baud: u64,
    timeout: Duration,
    tcp: bool,
) -> Instant {
    let after_end = end + timeout;
    if !tcp {
        return after_end;
    }
    let wire_ms = (bytes as u64) * 10 * 1000 / baud.max(1) * INTAKE_DIVISOR;
    after_end.max(start + timeout + Duration::from_millis(wire_ms))
}

/// `table write --bridge`: the bridge must answer its status query (for
/// this controller station, a policy that takes 26DH), a 200H through it
/// fences the line, then each 26DH goes out whole and its `#` or `&` is
/// awaited; a transport failure or no answer sends it again, up to
/// `--retries` times.
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
    let st = status_of(link, a.bridge_station, wait, sends, hooks.stop)?;
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
    // Settles what the line may still owe, and shows the controller answers.
    let text = nonce(u64::from(link.now()) ^ u64::from(std::process::id()) << 16);
    table::command(link, &TestCall { test_string: text }, hooks)
        .map_err(|e| table_failure(link, e, " (200H through the bridge); nothing was written"))?;
    let msgs = messages(records, line.station)?;
    let total: usize = msgs.iter().map(|(m, _)| m.len()).sum();
    let bar = progress_bar(total as u64, "26DH to the bridge", "bytes");
    let mut base = 0usize;
    let mut written = 0usize;
    for (k, (msg, count)) in msgs.iter().enumerate() {
        let mut attempt = 0u8;
        let verdict = loop {
            attempt += 1;
            bar.set_message(format!(
                "26DH {} of {}{}",
                k + 1,
                msgs.len(),
                if attempt > 1 {
                    format!(", send {attempt}")
                } else {
                    String::new()
                }
            ));
            let start = Instant::now();
            for (i, piece) in msg.chunks(4096).enumerate() {
                if (hooks.stop)() {
                    bar.abandon();
                    return Err(Failure::Exit(
                        EXIT_INTERRUPTED,
                        format!("interrupted in the middle of a 26DH: the bridge answers it & B01 or B04; {written} records were confirmed before it, how far this one went is unknown"),
                    ));
                }
                link.write_all(piece)
                    .map_err(|e| format!("{target}: the line failed: {e}"))?;
                bar.set_position((base + i * 4096 + piece.len()) as u64);
            }
            bar.set_message(format!(
                "26DH {} of {}: waiting for the bridge's answer",
                k + 1,
                msgs.len()
            ));
            let until = deadline(start, Instant::now(), msg.len(), baud, wait, tcp);
            let st = Station(line.station);
            let reply = await_frame(link, until, hooks.stop, |f| {
                f.station() == st
                    && (f.header() == Header::Error
                        || (f.header() == Header::Response
                            && f.code() == PositionStream::CHANGE_2.id))
            })
            .map_err(|e| format!("{target}: the line failed: {e}"))?;
            let verdict = match reply.as_deref().map(|r| {
                iai_protocol_b::frame::Frame::new_checked(
                    r,
                    iai_protocol_b::checksum::BypassPolicy::Reject,
                )
            }) {
                Some(Ok(f)) if f.header() == Header::Error => Verdict::Refused(f.code()),
                Some(Ok(f)) => Verdict::Written(
                    std::str::from_utf8(f.body())
                        .ok()
                        .and_then(|b| u16::from_str_radix(b, 16).ok())
                        .unwrap_or(0),
                ),
                _ if (hooks.stop)() => {
                    bar.abandon();
                    return Err(Failure::Exit(
                        EXIT_INTERRUPTED,
                        "interrupted while the bridge was writing: how far it went is unknown; position writes are idempotent, so sending the table again puts it right".into(),
                    ));
                }
                _ => Verdict::NoAnswer,
            };
            let again = match &verdict {
                Verdict::Refused(code) => worth_resending(*code),
                Verdict::NoAnswer => true,
                Verdict::Written(_) => false,
            };
            if !again || attempt >= sends {
                break verdict;
            }
            bar.suspend(|| {
                eprintln!(
                    "{}; sending the message again ({} of {sends})",
                    verdict_text(&verdict, *count),
                    attempt + 1
                )
            });
            // A late answer to this send is let pass before the next.
            let _ = await_frame(link, Instant::now() + wait, hooks.stop, |_| false);
        };
        match verdict {
            Verdict::Written(n) if n == *count => {
                bar.suspend(|| eprintln!("{}", verdict_text(&verdict, *count)));
                written += usize::from(n);
            }
            v => {
                bar.abandon();
                let mut m = format!(
                    "{target}: {}; {written} records were confirmed by the bridge before this message; send the table again (position writes are idempotent)",
                    verdict_text(&v, *count)
                );
                if v == Verdict::NoAnswer {
                    if let Some(h) = link.hint() {
                        m.push_str(&format!("\n  hint: {h}"));
                    }
                }
                return Err(m.into());
            }
        }
        base += msg.len();
    }
    bar.finish_and_clear();
    println!(
        "verified by the bridge: the controller holds all {written} records ({} 26DH message(s) of {total} bytes; the bridge wrote each in 2,051-byte commands, read every one back with 21FH and compared it, and answered # with the count)",
        msgs.len()
    );
    Ok(())
}
