//! `iai ports` (the serial ports this machine has) and `iai probe` (which
//! baud rate and station answer on a line).

use std::collections::{BTreeSet, VecDeque};
use std::io::{self, Write};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use firmware_example::config::BAUD_RATES;
use iai_cli::bridge::{decode_status, query_status, status_json};
use iai_cli::link::{Flow, Link, Target};
use iai_cli::probe::{nonce, observe, test_call, Observation};
use iai_cli::table::{Hooks, TableError};
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::Station;
use iai_protocol_b::line::LineConfig;

use super::line::DEFAULT_STATION;
use super::{out_err, Run};
use crate::ProbeArgs;

/// The stations `iai probe` tries when none is given: the default one and
/// 00.
pub(crate) const PROBE_STATIONS: [u8; 2] = [DEFAULT_STATION, 0x00];

/// One port as `iai ports` shows it: name, kind, details.
fn port_line(p: &serialport::SerialPortInfo) -> (String, String, String) {
    use serialport::SerialPortType as T;
    match &p.port_type {
        T::UsbPort(u) => {
            let mut d = format!("{:04x}:{:04x}", u.vid, u.pid);
            for s in [&u.manufacturer, &u.product].into_iter().flatten() {
                d.push(' ');
                d.push_str(s);
            }
            if let Some(sn) = &u.serial_number {
                d.push_str(&format!(" (serial {sn})"));
            }
            (p.port_name.clone(), "usb".into(), d)
        }
        T::PciPort => (p.port_name.clone(), "pci".into(), String::new()),
        T::BluetoothPort => (p.port_name.clone(), "bluetooth".into(), String::new()),
        T::Unknown => (p.port_name.clone(), "unknown".into(), String::new()),
    }
}

pub(crate) fn ports_cmd(json: bool) -> Run {
    // serialport's scan of /sys/class/tty assumes the directory exists.
    #[cfg(target_os = "linux")]
    if !std::path::Path::new("/sys/class/tty").is_dir() {
        return Err(
            "cannot list serial ports: /sys/class/tty is missing (no sysfs here)"
                .to_string()
                .into(),
        );
    }
    let ports =
        serialport::available_ports().map_err(|e| format!("cannot list serial ports: {e}"))?;
    let mut out = io::stdout().lock();
    for p in &ports {
        let (name, kind, detail) = port_line(p);
        if json {
            let v = serde_json::json!({"port": name, "kind": kind, "detail": detail});
            writeln!(out, "{v}").map_err(out_err)?;
        } else {
            writeln!(out, "{name}  {kind}  {detail}").map_err(out_err)?;
        }
    }
    if ports.is_empty() {
        eprintln!("no serial ports found (a pseudo-terminal such as iai simulate --pty is not listed; give it to --port directly)");
    }
    Ok(ExitCode::SUCCESS)
}

/// Reads what arrives for `wait` and drops it (what an earlier try left).
fn drain(link: &mut Link, wait: Duration) -> io::Result<()> {
    let end = Instant::now() + wait;
    let mut buf = [0u8; 4096];
    while Instant::now() < end {
        link.read_for(&mut buf, end.saturating_duration_since(Instant::now()))?;
    }
    link.take_pending();
    Ok(())
}

/// One try: a test call to `station`; what came back within `wait`.
fn try_station(link: &mut Link, station: u8, seed: u64, wait: Duration) -> io::Result<Observation> {
    let n = nonce(seed);
    let sent = test_call(station, &n);
    link.write_all(&sent)?;
    let mut got = link.take_pending();
    let end = Instant::now() + wait;
    let mut buf = [0u8; 4096];
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        let k = link.read_for(&mut buf, left.min(Duration::from_millis(20)))?;
        got.extend_from_slice(buf.get(..k).unwrap_or(&[]));
        // An answer from the station tried ends the wait.
        if observe(&sent, station, &n, &got).reply.is_some() {
            break;
        }
    }
    Ok(observe(&sent, station, &n, &got))
}

pub(crate) fn probe_cmd(a: &ProbeArgs) -> Run {
    let tcp = a.target.tcp.is_some();
    for w in a.serial.warnings(&a.target, !a.baud.is_empty()) {
        eprintln!("iai: warning: {w}");
    }
    let bauds: Vec<Option<u32>> = if tcp {
        vec![None]
    } else if a.baud.is_empty() {
        BAUD_RATES.iter().map(|b| Some(*b)).collect()
    } else {
        a.baud.iter().map(|b| Some(*b)).collect()
    };
    let stations = a.station.clone();
    let wait = Duration::from_millis(u64::from(a.timeout));
    let base = a.serial.target(&a.target, BAUD_RATES[0], Flow::None);
    let where_ = match &base {
        Target::Serial { path, .. } => format!("serial port {path}"),
        Target::Tcp { addr, .. } => format!("tcp {addr}"),
    };
    let mut out = io::stdout().lock();
    if !a.json {
        writeln!(
            out,
            "probing {where_}: {}, stations {}; a 200H test call with a nonce, {} ms each",
            if tcp {
                "no baud rate (TCP)".to_string()
            } else {
                format!("{} baud rate(s)", bauds.len())
            },
            stations
                .iter()
                .map(|s| format!("{s:02X}"))
                .collect::<Vec<_>>()
                .join(", "),
            a.timeout
        )
        .map_err(out_err)?;
    }
    let mut seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(1, |d| d.as_nanos() as u64);
    let mut found: Vec<(Option<u32>, u8)> = Vec::new();
    let mut bridges: Vec<(Option<u32>, u8)> = Vec::new();
    let mut seen_kinds: BTreeSet<&'static str> = BTreeSet::new();
    for baud in bauds {
        let target = match (&base, baud) {
            (Target::Serial { path, settings, .. }, Some(b)) => Target::Serial {
                path: path.clone(),
                baud: b,
                settings: *settings,
            },
            (t, _) => t.clone(),
        };
        let mut link = Link::open(&target, LineConfig::new(Station(DEFAULT_STATION)))?;
        let mut queue: VecDeque<u8> = stations.iter().copied().collect();
        let mut tried = BTreeSet::new();
        let rate = baud.map_or_else(|| "tcp".to_string(), |b| format!("{b} baud"));
        // A bridge says which station its controller has.
        drain(&mut link, Duration::from_millis(30)).map_err(|e| format!("{target}: {e}"))?;
        let quiet = |_: &str| {};
        let hooks = Hooks {
            note: &quiet,
            stop: &|| false,
        };
        let bridge = match query_status(&mut link, a.bridge_station, wait, 1, &hooks) {
            Ok(r) => Some(decode_status(&r)),
            Err(TableError::Engine(Failure::Controller { code, .. })) => Some(Err(format!(
                "the bridge answered & {code:03X}{}",
                iai_cli::codes::meaning(code).map_or(String::new(), |m| format!(" ({m})"))
            ))),
            Err(TableError::Engine(Failure::Timeout { .. })) => None,
            Err(e) => return Err(format!("{target}: {e}").into()),
        };
        let said = match &bridge {
            Some(Ok(s)) => {
                let c = s.get("controller_station") as u8;
                if !queue.contains(&c) {
                    queue.push_front(c);
                }
                bridges.push((baud, a.bridge_station));
                format!(
                    "a bridge answers its status query: controller station {c:02X}, {} baud to the controller, flow control {}",
                    s.get("downstream_baud"),
                    ["none", "XON/XOFF", "RTS/CTS"].get(s.get("flow_control") as usize).unwrap_or(&"?")
                )
            }
            Some(Err(e)) => format!("something answered the bridge's status query: {e}"),
            None => "no bridge answers".to_string(),
        };
        if a.json {
            let v = serde_json::json!({
                "type": "bridge",
                "baud": baud,
                "station": format!("{:02X}", a.bridge_station),
                "result": match &bridge { Some(Ok(_)) => "answered", Some(Err(_)) => "other", None => "silent" },
                "status": match &bridge { Some(Ok(s)) => status_json(s), _ => serde_json::Value::Null },
                "detail": said,
            });
            writeln!(out, "{v}").map_err(out_err)?;
        } else {
            writeln!(out, "  {rate:>12}, bridge {:02X}: {said}", a.bridge_station)
                .map_err(out_err)?;
        }
        while let Some(st) = queue.pop_front() {
            if !tried.insert(st) {
                continue;
            }
            drain(&mut link, Duration::from_millis(30)).map_err(|e| format!("{target}: {e}"))?;
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            let o = try_station(&mut link, st, seed >> 20, wait)
                .map_err(|e| format!("{target}: {e}"))?;
            seen_kinds.insert(o.kind());
            if o.kind() == "answered" {
                found.push((baud, st));
            }
            // A reply from another station is worth a try at that station.
            queue.extend(o.foreign.iter().copied().filter(|s| !tried.contains(s)));
            if a.json {
                let v = serde_json::json!({
                    "type": "try",
                    "baud": baud,
                    "station": format!("{st:02X}"),
                    "result": o.kind(),
                    "bytes": o.bytes,
                    "garbage": o.garbage,
                    "echo": o.echo,
                    "stations_seen": o.foreign.iter().map(|s| format!("{s:02X}")).collect::<Vec<_>>(),
                    "detail": o.describe(st),
                });
                writeln!(out, "{v}").map_err(out_err)?;
            } else {
                writeln!(out, "  {rate:>12}, station {st:02X}: {}", o.describe(st))
                    .map_err(out_err)?;
            }
        }
        // A controller listens at one rate: the others need no try.
        if !found.is_empty() || !bridges.is_empty() {
            break;
        }
    }
    let advice = |(b, s): &(Option<u32>, u8)| match b {
        Some(b) => format!("--baud {b} --station {s:02X}"),
        None => format!("--station {s:02X}"),
    };
    if a.json {
        let v = serde_json::json!({
            "type": "result",
            "found": found.iter().map(|(b, s)| serde_json::json!({"baud": b, "station": format!("{s:02X}")})).collect::<Vec<_>>(),
            "bridges": bridges.iter().map(|(b, s)| serde_json::json!({"baud": b, "station": format!("{s:02X}")})).collect::<Vec<_>>(),
        });
        writeln!(out, "{v}").map_err(out_err)?;
    } else if !found.is_empty() {
        writeln!(
            out,
            "found: a controller answers; use {}",
            found.iter().map(advice).collect::<Vec<_>>().join(", or ")
        )
        .map_err(out_err)?;
        if !bridges.is_empty() {
            writeln!(out, "through a bridge: `iai bridge status` shows it, `iai table write --bridge` sends it whole tables").map_err(out_err)?;
        }
    } else if !bridges.is_empty() {
        writeln!(out, "found a bridge, but its controller did not answer through it: `iai bridge status` shows the bridge's counters").map_err(out_err)?;
    } else {
        let why = if seen_kinds.contains("echo") {
            "our own frames came back: a loopback or an echoing converter, no controller"
        } else if seen_kinds.contains("other_station") {
            "replies came from other stations, but none sent the test call back"
        } else if seen_kinds.contains("garbage") {
            "only bytes that are not protocol B came back: framing (--data-bits, --parity, --stop-bits) or a rate not tried"
        } else {
            "nothing answered: check the cable, the port, power, AUTO mode and I/O parameter No. 90 = 2; give --station if it is neither 99 nor 00"
        };
        writeln!(out, "not found: {why}").map_err(out_err)?;
    }
    out.flush().map_err(out_err)?;
    Ok(if found.is_empty() && bridges.is_empty() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
