//! `iai bridge status` and `iai table write --bridge`: the bridge
//! firmware on the line, its status decoded, and a whole table sent to it
//! as one 26DH; `iai bridge config get/set/apply/block` and `iai bridge
//! restart`: its configuration page (see `iai_cli::bridge`).

use std::io::{self, Write};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use iai_cli::bridge::{
    board_image, decode_status, describe_status, host_page_with, parts, query_status, read_page,
    read_verifier, restart, set_password, set_text, settings_from_toml, settings_json,
    settings_toml, status_json, verdict_text, verifier_block, worth_resending, write_page,
    BoardSlots, BridgePage, BridgeStatus, ConfigError, Verdict, BOARDS,
};
use iai_cli::link::{Flow, Link, Target};
use iai_cli::table::{self, Hooks, TableError};
use iai_protocol_b::error::Failure as CoreFailure;
use iai_protocol_b::frame::{Header, Station};
use iai_protocol_b::line::LineConfig;
use iai_protocol_b::position::{PositionRecord, PositionStream};

use super::{out_err, progress_bar, stop_flag, table_failure, Failure, Run, EXIT_INTERRUPTED};
use crate::{
    BoardArg, BridgeAt, BridgeRestartArgs, BridgeStatusArgs, ConfigApplyArgs, ConfigBlockArgs,
    ConfigGetArgs, ConfigSetArgs, PasswordArgs, WriteArgs,
};
use firmware_example::codes as bridge_codes;
use firmware_example::config::settings::Settings;

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

/// The bridge at `at`: its link and station.
fn open_bridge(at: &BridgeAt) -> Result<(Link, Duration, u8), Failure> {
    let target = at.link.resolve(Flow::XonXoff);
    let link = Link::open(&target, LineConfig::new(Station(at.bridge_station)))?;
    Ok((
        link,
        Duration::from_millis(u64::from(at.timeout)),
        at.retries.saturating_add(1),
    ))
}

/// The password given, if any: --password, the first line of
/// --password-file, or IAI_BRIDGE_PASSWORD.
fn password_of(p: &PasswordArgs) -> Result<Option<String>, Failure> {
    if let Some(pw) = &p.password {
        return Ok(Some(pw.clone()));
    }
    if let Some(file) = &p.password_file {
        let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
        let line = text.lines().next().unwrap_or("").to_string();
        return Ok(Some(line));
    }
    Ok(std::env::var("IAI_BRIDGE_PASSWORD")
        .ok()
        .filter(|p| !p.is_empty()))
}

const NEEDS_PASSWORD: &str = "this change needs the gateway's password: --password-file FILE, IAI_BRIDGE_PASSWORD, or --password";

/// A configuration failure as the tool says it.
fn config_failure(link: &Link, what: &str, e: ConfigError) -> Failure {
    let target = link.target().clone();
    let mut m = format!("{target}: {what}: {e}");
    match e {
        ConfigError::Refused(code) if code == bridge_codes::NO_PASSWORD => m.push_str(
            "\n  a fresh gateway takes a password first: iai bridge config set access.password=NEW ...",
        ),
        ConfigError::Refused(code) if code == bridge_codes::UNKNOWN_QUERY => m.push_str(
            "\n  this bridge firmware has no configuration messages (an older image?)",
        ),
        ConfigError::NoAnswer => {
            m.push_str(" (is the bridge firmware on this line, at this station: --bridge-station?)");
            if let Some(h) = link.hint() {
                m.push_str(&format!("\n  hint: {h}"));
            }
        }
        _ => {}
    }
    m.into()
}

pub(crate) fn config_get(a: &ConfigGetArgs) -> Run {
    let (mut link, wait, sends) = open_bridge(&a.at)?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let page = read_page(&mut link, a.at.bridge_station, wait, sends, &stopped)
        .map_err(|e| config_failure(&link, "reading the configuration page", e))?;
    let settings = page.settings();
    if let Some(file) = &a.image {
        let password = password_of(&a.password)?;
        let verifier = match &password {
            Some(pw) => Some(
                read_verifier(
                    &mut link,
                    a.at.bridge_station,
                    pw.as_bytes(),
                    wait,
                    &stopped,
                )
                .map_err(|e| config_failure(&link, "reading the verifier block", e))?,
            ),
            None => {
                eprintln!("iai: no password given: the image holds no password (the gateway that boots it asks for a new one)");
                None
            }
        };
        let board = board_of(a.board);
        let image = board_image(board, &page.host, verifier.as_deref());
        std::fs::write(file, &image).map_err(|e| format!("{}: {e}", file.display()))?;
        eprintln!(
            "iai: {} written: {} bytes for {}'s slots at {:#x}",
            file.display(),
            image.len(),
            board.name,
            board.address
        );
    }
    let mut out = io::stdout().lock();
    if a.json {
        writeln!(out, "{}", settings_json(&settings, &page.info)).map_err(out_err)?;
    } else {
        write!(out, "{}", settings_toml(&settings, page.info.seq)).map_err(out_err)?;
        if page.info.restart_pending {
            writeln!(
                out,
                "# changes applied wait for a restart (iai bridge restart)"
            )
            .map_err(out_err)?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The board's slots.
fn board_of(b: BoardArg) -> &'static BoardSlots {
    let name = match b {
        BoardArg::Lm3s6965 => "lm3s6965",
        BoardArg::Mps2An386 => "mps2-an386",
        BoardArg::Stm32g030 => "stm32g030",
        BoardArg::Stm32g070 => "stm32g070",
    };
    BOARDS.iter().find(|s| s.name == name).unwrap_or(&BOARDS[0])
}

/// A change of the configuration page.
struct Change<'a> {
    /// The page read.
    page: &'a BridgePage,
    /// Its settings, changed.
    settings: &'a Settings,
    /// A new password, if one is set.
    new_password: Option<String>,
    /// The password given.
    given: Option<String>,
}

/// Applies `c` to the bridge; prints the result.
fn apply_settings(link: &mut Link, station: u8, wait: Duration, c: Change<'_>, json: bool) -> Run {
    let Change {
        page,
        settings,
        new_password,
        given,
    } = c;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let changed = host_page_with(&page.host, settings) != page.host;
    let mut password = given;
    let mut seq = None;
    let mut restart_needed = false;
    if let Some(new) = new_password {
        verifier_block(&new)?;
        let current = match (page.info.password_set, &password) {
            (false, _) => None,
            (true, Some(p)) => Some(p.as_bytes()),
            (true, None) => return Err(NEEDS_PASSWORD.to_string().into()),
        };
        seq = Some(
            set_password(link, station, current, new.as_bytes(), wait, &stopped)
                .map_err(|e| config_failure(link, "setting the password", e))?,
        );
        password = Some(new);
    } else if !page.info.password_set {
        return Err(
            "a fresh gateway takes no change before a password: add access.password=NEW (8 to 64 characters)"
                .to_string()
                .into(),
        );
    }
    if changed {
        let Some(pw) = &password else {
            return Err(NEEDS_PASSWORD.to_string().into());
        };
        // What the gateway holds now (a new password changed the page).
        let host = host_page_with(
            &read_page(link, station, wait, 3, &stopped)
                .map_err(|e| config_failure(link, "reading the configuration page", e))?
                .host,
            settings,
        );
        let applied = write_page(link, station, &host, pw.as_bytes(), wait, &stopped)
            .map_err(|e| config_failure(link, "applying the page", e))?;
        seq = Some(applied.seq);
        restart_needed = applied.restart_needed;
    }
    let mut out = io::stdout().lock();
    match seq {
        None => writeln!(out, "nothing to change: the gateway holds these settings already"),
        Some(seq) if json => writeln!(
            out,
            "{}",
            serde_json::json!({"type": "bridge_config_applied", "sequence": seq, "restart_needed": restart_needed})
        ),
        Some(seq) if restart_needed => writeln!(
            out,
            "applied as sequence {seq}; takes effect at the next start (iai bridge restart)"
        ),
        Some(seq) => writeln!(out, "applied as sequence {seq}; in effect now"),
    }
    .map_err(out_err)?;
    Ok(ExitCode::SUCCESS)
}

pub(crate) fn config_set(a: &ConfigSetArgs) -> Run {
    let given = password_of(&a.password)?;
    let (mut link, wait, sends) = open_bridge(&a.at)?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let page = read_page(&mut link, a.at.bridge_station, wait, sends, &stopped)
        .map_err(|e| config_failure(&link, "reading the configuration page", e))?;
    let mut settings = page.settings();
    let mut new_password = None;
    let mut errors = Vec::new();
    for pair in &a.settings {
        let Some((key, value)) = pair.split_once('=') else {
            errors.push(format!("{pair}: give key=value (modbus.unit=5)"));
            continue;
        };
        if key == "access.password" {
            new_password = Some(value.to_string());
        } else if let Err(e) = set_text(&mut settings, key, value) {
            errors.push(e);
        }
    }
    if let Err(e) = settings.check() {
        errors.push(format!("{}: {}", e.key.unwrap_or("?"), e.reason));
    }
    if !errors.is_empty() {
        return Err(Failure::Exit(
            2,
            format!("nothing was sent:\n  {}", errors.join("\n  ")),
        ));
    }
    let change = Change {
        page: &page,
        settings: &settings,
        new_password,
        given,
    };
    apply_settings(&mut link, a.at.bridge_station, wait, change, a.json)
}

pub(crate) fn config_apply(a: &ConfigApplyArgs) -> Run {
    let text =
        std::fs::read_to_string(&a.file).map_err(|e| format!("{}: {e}", a.file.display()))?;
    let given = password_of(&a.password)?;
    let (mut link, wait, sends) = open_bridge(&a.at)?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let page = read_page(&mut link, a.at.bridge_station, wait, sends, &stopped)
        .map_err(|e| config_failure(&link, "reading the configuration page", e))?;
    let mut settings = page.settings();
    let new_password = settings_from_toml(&mut settings, &text).map_err(|e| {
        Failure::Exit(
            2,
            format!(
                "{}: nothing was sent:\n  {}",
                a.file.display(),
                e.replace('\n', "\n  ")
            ),
        )
    })?;
    let change = Change {
        page: &page,
        settings: &settings,
        new_password,
        given,
    };
    apply_settings(&mut link, a.at.bridge_station, wait, change, a.json)
}

pub(crate) fn config_block(a: &ConfigBlockArgs) -> Run {
    let text =
        std::fs::read_to_string(&a.file).map_err(|e| format!("{}: {e}", a.file.display()))?;
    let mut settings = Settings::DEFAULT;
    let password = settings_from_toml(&mut settings, &text).map_err(|e| {
        Failure::Exit(
            2,
            format!(
                "{}: nothing was written:\n  {}",
                a.file.display(),
                e.replace('\n', "\n  ")
            ),
        )
    })?;
    let verifier = match &password {
        Some(p) => Some(verifier_block(p)?),
        None => None,
    };
    let host = host_page_with(&[], &settings);
    let board = board_of(a.board);
    let image = board_image(board, &host, verifier.as_deref());
    std::fs::write(&a.output, &image).map_err(|e| format!("{}: {e}", a.output.display()))?;
    let file = a.output.display().to_string();
    eprintln!(
        "iai: {file}: {} bytes, {}'s two {}-byte slots at {:#x}{}",
        image.len(),
        board.name,
        board.slot_len,
        board.address,
        if verifier.is_none() {
            " (no password: the gateway asks for one before any change)"
        } else {
            ""
        }
    );
    eprintln!(
        "iai: write it with {}",
        board.flash_with.replace("FILE", &file)
    );
    Ok(ExitCode::SUCCESS)
}

pub(crate) fn restart_cmd(a: &BridgeRestartArgs) -> Run {
    let Some(pw) = password_of(&a.password)? else {
        return Err(NEEDS_PASSWORD.to_string().into());
    };
    let (mut link, wait, sends) = open_bridge(&a.at)?;
    let stop = stop_flag();
    let stopped = || stop.load(Ordering::SeqCst);
    let note = |m: &str| eprintln!("{m}");
    let hooks = Hooks {
        note: &note,
        stop: &stopped,
    };
    let before = status_of(&mut link, a.at.bridge_station, wait, sends, &hooks)?.get("uptime_ms");
    restart(
        &mut link,
        a.at.bridge_station,
        pw.as_bytes(),
        wait,
        &stopped,
    )
    .map_err(|e| config_failure(&link, "restarting", e))?;
    eprintln!("iai: the gateway restarts");
    if a.wait == 0 {
        return Ok(ExitCode::SUCCESS);
    }
    drop(link);
    let start = Instant::now();
    let limit = Duration::from_secs(u64::from(a.wait));
    std::thread::sleep(Duration::from_millis(500));
    loop {
        if stopped() {
            return Err(Failure::Exit(EXIT_INTERRUPTED, "interrupted".into()));
        }
        let target = a.at.link.target_with(Flow::XonXoff);
        let up = Link::open(&target, LineConfig::new(Station(a.at.bridge_station)))
            .ok()
            .and_then(|mut l| {
                status_of(
                    &mut l,
                    a.at.bridge_station,
                    Duration::from_millis(1_000),
                    1,
                    &hooks,
                )
                .ok()
            });
        if let Some(s) = up {
            let uptime = s.get("uptime_ms");
            if uptime < before || uptime < start.elapsed().as_millis() as u64 + 1_000 {
                println!(
                    "restarted: the gateway answers again after {:.1} s (uptime {} ms)",
                    start.elapsed().as_secs_f64(),
                    uptime
                );
                return Ok(ExitCode::SUCCESS);
            }
        }
        if start.elapsed() >= limit {
            return Err(format!(
                "the gateway did not answer its status query within {} s of the restart",
                a.wait
            )
            .into());
        }
        std::thread::sleep(Duration::from_millis(300));
    }
}
