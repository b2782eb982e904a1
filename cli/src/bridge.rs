//! The bridge firmware (`firmware-example`) as seen from the host: its
//! status query and reply, and a whole table sent to it as one 26DH.
//!
//! **Status** (`firmware-example/src/status.rs`): `!` + bridge station +
//! `B00` + SC CR LF; the reply `#` + station + `B00` carries fixed-width
//! hex fields, split by the firmware's own [`status::parse`] and named
//! here with what they mean ([`describe_status`]).
//!
//! **A table through the bridge** ([`parts`], sent each by the core's
//! upload engine, `table::upload`): the bridge takes a 26DH
//! of any legal size (up to 20,000 records), writes it to the controller
//! in 2,051-byte commands, reads each back with 21FH before it takes more,
//! and answers once: `#` with the count means the controller holds every
//! record, read back and compared, and the message's checksum was right;
//! `&` says only that it failed, not how far it went (any prefix of the
//! records may be written; position writes are idempotent, so sending the
//! whole message again puts every one of its records right). See the
//! README, "What a 26DH reply tells the host".
//!
//! **The configuration page** ([`read_page`], [`write_page`],
//! [`set_password`], [`restart`]): the bridge's messages B20..B24
//! (`firmware-example/src/config/wire.rs`); the page is decoded and built
//! here with the firmware's own settings table
//! (`firmware_example::config::settings`), shown as TOML or JSON
//! ([`settings_toml`], [`settings_json`]) and changed from `key=value`
//! pairs or a TOML file ([`settings_from_toml`]).

use std::time::Duration;

use firmware_example::codes as bridge_codes;
use firmware_example::config::access::{PasswordError, Verifier, ACCESS_LEN};
use firmware_example::config::editor::{host_crc, Applied};
use firmware_example::config::page::{ACCESS_AT, HOST_LEN, PAGE_LEN, WINDOW};
use firmware_example::config::settings::{self, Kind, Setting, Settings, Value};
use firmware_example::config::{store, wire};
use firmware_example::status;
use firmware_example::text::Sink;
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::error::Failure;
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::line::LineConfig;
use iai_protocol_b::position::{PositionRecord, PositionStream};

use crate::codes;
use crate::link::Link;
use crate::table::{self, Hooks, TableError};

/// The bridge's own station by default (its configuration block's
/// default, `firmware-example/src/config.rs`).
pub const DEFAULT_STATION: u8 = 0xBB;

/// The status query to the bridge at `station`.
pub fn status_query(station: u8) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = emit_frame(
        &mut buf,
        Header::Command,
        Station(station),
        bridge_codes::STATUS_QUERY,
        ChecksumMode::Compute,
        |_| Ok(()),
    )
    .unwrap_or(0);
    buf.get(..n).unwrap_or(&[]).to_vec()
}

/// One field of the status reply: name, value, what it means.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StatusField {
    /// The firmware's name for it.
    pub name: &'static str,
    /// Its value.
    pub value: u64,
    /// What the value means (a station in hex, a code's name, a duration).
    pub meaning: Option<String>,
}

/// The bridge's status, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BridgeStatus {
    /// The station that answered.
    pub station: u8,
    /// Every field, in the reply's order.
    pub fields: Vec<StatusField>,
}

impl BridgeStatus {
    /// The value of field `name` (0 if absent).
    pub fn get(&self, name: &str) -> u64 {
        self.fields
            .iter()
            .find(|f| f.name == name)
            .map_or(0, |f| f.value)
    }
}

/// `1 h 02 min 03.456 s`.
fn duration_text(ms: u64) -> String {
    let (h, m, s, milli) = (ms / 3_600_000, ms / 60_000 % 60, ms / 1000 % 60, ms % 1000);
    match (h, m) {
        (0, 0) => format!("{s}.{milli:03} s"),
        (0, _) => format!("{m} min {s:02}.{milli:03} s"),
        _ => format!("{h} h {m:02} min {s:02}.{milli:03} s"),
    }
}

/// What the value of status field `name` means.
fn status_meaning(name: &str, v: u64) -> Option<String> {
    Some(match name {
        "layout" if v == u64::from(status::LAYOUT) => format!("layout {v}"),
        "layout" => format!("layout {v}; this iai knows layout {}", status::LAYOUT),
        "uptime_ms" | "last_error_ms" if name == "last_error_ms" && v == 0 => "never".into(),
        "uptime_ms" | "last_error_ms" => duration_text(v),
        "config_source" => match v {
            0 => "built-in defaults",
            1 => "the configuration block",
            2 => "defaults (the configuration block is blank)",
            3 => "defaults (the configuration block is invalid)",
            _ => "unknown",
        }
        .into(),
        "controller_station" | "bridge_station" => format!("{v:02X}"),
        "upstream_baud" | "downstream_baud" => format!("{v} baud"),
        "flow_control" => match v {
            0 => "none",
            1 => "XON/XOFF",
            2 => "RTS/CTS",
            _ => "unknown",
        }
        .into(),
        "policy" => match v {
            0 => "forward all",
            1 => "read-only (the catalogue's reading messages)",
            2 => "allow-list",
            _ => "unknown",
        }
        .into(),
        "last_error" if v == 0 => "none".into(),
        "last_error" => format!(
            "{v:03X}: {}",
            u16::try_from(v)
                .ok()
                .and_then(bridge_codes::meaning)
                .unwrap_or("a code this iai does not know")
        ),
        _ => return None,
    })
}

/// Decodes a status reply (a whole frame): the fields and what they mean,
/// or why it is not one.
pub fn decode_status(frame: &[u8]) -> Result<BridgeStatus, String> {
    let f = Frame::new_checked(frame, BypassPolicy::Reject)
        .map_err(|e| format!("the status reply is not a valid frame: {e}"))?;
    if f.header() == Header::Error {
        return Err(format!(
            "the bridge answered & {:03X}{}",
            f.code(),
            codes::meaning(f.code()).map_or(String::new(), |m| format!(" ({m})"))
        ));
    }
    if f.header() != Header::Response || f.code() != bridge_codes::STATUS_QUERY {
        return Err(format!(
            "the answer is {:03X}H, not the bridge's status reply B00H",
            f.code()
        ));
    }
    let pairs = status::parse(f.body()).ok_or_else(|| {
        format!(
            "the status reply's data is {} characters, layout {} has {}",
            f.body().len(),
            status::LAYOUT,
            status::DATA_LEN
        )
    })?;
    Ok(BridgeStatus {
        station: f.station().0,
        fields: pairs
            .iter()
            .map(|&(name, value)| StatusField {
                name,
                value,
                meaning: status_meaning(name, value),
            })
            .collect(),
    })
}

/// The status as text lines: `name = value -> meaning`.
pub fn describe_status(s: &BridgeStatus) -> Vec<String> {
    let mut out = vec![format!("bridge at station {:02X}:", s.station)];
    for f in &s.fields {
        match &f.meaning {
            Some(m) => out.push(format!("  {} = {} -> {m}", f.name, f.value)),
            None => out.push(format!("  {} = {}", f.name, f.value)),
        }
    }
    out
}

/// The status as one JSON object: `fields` (raw values) and `meanings`.
pub fn status_json(s: &BridgeStatus) -> serde_json::Value {
    let mut fields = serde_json::Map::new();
    let mut meanings = serde_json::Map::new();
    for f in &s.fields {
        fields.insert(f.name.to_string(), serde_json::json!(f.value));
        if let Some(m) = &f.meaning {
            meanings.insert(f.name.to_string(), serde_json::json!(m));
        }
    }
    serde_json::json!({
        "type": "bridge_status",
        "station": format!("{:02X}", s.station),
        "fields": fields,
        "meanings": meanings,
    })
}

/// Asks the bridge at `station` for its status over `link`, on a line of
/// its own to that station (the core's client: fence, resends, reply
/// matching), each send answered within `wait`, at most `sends` sends:
/// the reply frame; an `&` is `Engine(Failure::Controller)`, no answer
/// `Engine(Failure::Timeout)`.
pub fn query_status(
    link: &mut Link,
    station: u8,
    wait: Duration,
    sends: u8,
    hooks: &Hooks<'_>,
) -> Result<Vec<u8>, TableError> {
    let cfg = LineConfig {
        timeout_ms: u32::try_from(wait.as_millis()).unwrap_or(u32::MAX),
        max_sends: sends.max(1),
        // The bridge answers its own station at once: a line to it waits
        // for nothing late.
        late_window_ms: 0,
        // B00H only reads: sent again as a query is (its code is the
        // bridge's, outside the catalogue, which the line counts unsafe to
        // send again).
        resend_unsafe: true,
        ..LineConfig::new(Station(station))
    };
    table::command_to(link, cfg, &status_query(station), hooks).map_err(|e| match e {
        // Unanswered, and nothing ran: a timeout, as for any query.
        TableError::Engine(Failure::OutcomeUnknown { sends }) => {
            TableError::Engine(Failure::Timeout { sends })
        }
        e => e,
    })
}

/// Records per 26DH message at most (its format's limit, TTA p. 60).
pub const MAX_RECORDS: usize = PositionStream::CHANGE_2.max_records as usize;

/// The table as 26DH messages of at most [`MAX_RECORDS`] records each (one
/// message for any table the format allows).
pub fn parts(records: &[PositionRecord]) -> std::slice::Chunks<'_, PositionRecord> {
    records.chunks(MAX_RECORDS.max(1))
}

/// How a 26DH through the bridge ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// `#` with this count.
    Written(u16),
    /// `&` with this code.
    Refused(u16),
    /// No answer within the wait.
    NoAnswer,
}

/// Whether sending the same message again after `code` can help: the
/// bridge's transport failures (malformed or lost bytes, a stalled host,
/// an unconfirmed chunk, a chunk that read back different); not a
/// refusal by policy, nor a controller's own code.
pub fn worth_resending(code: u16) -> bool {
    matches!(
        code,
        bridge_codes::UPSTREAM_FRAME
            | bridge_codes::CONTROLLER_TIMEOUT
            | bridge_codes::UPSTREAM_STALLED
            | bridge_codes::UPSTREAM_OVERRUN
            | bridge_codes::VERIFY_MISMATCH
    )
}

/// What the verdict means, in the README's words.
pub fn verdict_text(v: &Verdict, records: u16) -> String {
    match v {
        Verdict::Written(n) if *n == records => format!(
            "the bridge answered # with {n}: the controller holds all {n} records of the message, each read back by the bridge and compared, and the message's checksum was right"
        ),
        Verdict::Written(n) => format!(
            "the bridge answered # with {n}, but the message held {records} records"
        ),
        Verdict::Refused(code) => format!(
            "the bridge answered & {code:03X} ({}): an & cannot say how far the write went; any prefix of the message's records may be written{}",
            codes::meaning(*code).unwrap_or_else(|| "the controller refused a chunk with its own code".into()),
            if matches!(*code, bridge_codes::UPSTREAM_FRAME | bridge_codes::UPSTREAM_STALLED | bridge_codes::UPSTREAM_OVERRUN) {
                ", and records decoded from the corrupted bytes before the error showed"
            } else {
                ""
            }
        ),
        Verdict::NoAnswer => "the bridge did not answer: how far the write went is unknown".into(),
    }
}

/// How a configuration message fared.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigError {
    /// The bridge answered `&` with this code.
    Refused(u16),
    /// No answer within the wait.
    NoAnswer,
    /// The line failed, or the answer is not laid out as it should be.
    Other(String),
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ConfigError::Refused(code) => write!(
                f,
                "the bridge answered & {code:03X} ({})",
                bridge_codes::meaning(*code).unwrap_or("a code this iai does not know")
            ),
            ConfigError::NoAnswer => f.write_str("the bridge did not answer"),
            ConfigError::Other(m) => f.write_str(m),
        }
    }
}

/// Upper-case hex of `bytes`.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect()
}

/// A command to the bridge at `station`: message `id` with `body`.
pub fn config_frame(station: u8, id: u16, body: &[u8]) -> Vec<u8> {
    let mut buf = vec![0u8; body.len() + 16];
    let n = emit_frame(
        &mut buf,
        Header::Command,
        Station(station),
        id,
        ChecksumMode::Compute,
        |w| w.put(body),
    )
    .unwrap_or(0);
    buf.truncate(n);
    buf
}

/// Sends message `id` with `body` to the bridge at `station` (up to
/// `sends` times while no answer comes: only for messages safe to repeat)
/// and returns its reply's body: the core's client on a line of its own to
/// the bridge's station, as for the status query.
pub fn config_exchange(
    link: &mut Link,
    station: u8,
    id: u16,
    body: &[u8],
    wait: Duration,
    sends: u8,
    stop: &dyn Fn() -> bool,
) -> Result<Vec<u8>, ConfigError> {
    let cfg = LineConfig {
        timeout_ms: u32::try_from(wait.as_millis()).unwrap_or(u32::MAX),
        max_sends: sends.max(1),
        // The caller says whether the message is safe to repeat.
        resend_unsafe: sends > 1,
        late_window_ms: 0,
        ..LineConfig::new(Station(station))
    };
    let quiet = |_: &str| {};
    let hooks = Hooks { note: &quiet, stop };
    match table::command_to(link, cfg, &config_frame(station, id, body), &hooks) {
        Ok(reply) => {
            let f = Frame::new_checked(&reply, BypassPolicy::Reject)
                .map_err(|e| ConfigError::Other(format!("a broken answer: {e}")))?;
            Ok(f.body().to_vec())
        }
        Err(TableError::Engine(Failure::Controller { code, .. })) => {
            Err(ConfigError::Refused(code))
        }
        Err(TableError::Engine(Failure::Timeout { .. } | Failure::OutcomeUnknown { .. })) => {
            Err(ConfigError::NoAnswer)
        }
        Err(e) => Err(ConfigError::Other(e.to_string())),
    }
}

/// The page's host part as the bridge holds it, and what it says of it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BridgePage {
    /// The page's first `HOST_LEN` bytes.
    pub host: Vec<u8>,
    /// Its sequence number, whether a password is set, whether changes
    /// wait for a restart.
    pub info: wire::PageInfo,
}

impl BridgePage {
    /// The settings it holds.
    pub fn settings(&self) -> Settings {
        Settings::from_page(&self.host, self.info.password_set)
    }
}

/// Reads the page's host part, window by window (each read sent up to
/// `sends` times); the same page throughout, or an error.
pub fn read_page(
    link: &mut Link,
    station: u8,
    wait: Duration,
    sends: u8,
    stop: &dyn Fn() -> bool,
) -> Result<BridgePage, ConfigError> {
    let mut host = Vec::with_capacity(HOST_LEN);
    let mut first: Option<wire::PageInfo> = None;
    let mut at = 0;
    while at < HOST_LEN {
        let body = format!("{at:03X}");
        let reply = config_exchange(
            link,
            station,
            bridge_codes::CONFIG_READ,
            body.as_bytes(),
            wait,
            sends,
            stop,
        )?;
        let mut out = [0u8; WINDOW];
        let (got_at, info, data) = wire::parse_read_reply(&reply, &mut out)
            .ok_or_else(|| ConfigError::Other("a read reply not laid out as B20's".into()))?;
        if got_at != at || Some(data.len()) != wire::window_at(at) {
            return Err(ConfigError::Other(format!(
                "asked for offset {at:03X}, the bridge answered {got_at:03X} with {} bytes",
                data.len()
            )));
        }
        if first.is_some_and(|f| f.seq != info.seq) {
            return Err(ConfigError::Other(
                "the page changed while it was read (another change was applied): read it again"
                    .into(),
            ));
        }
        first = Some(info);
        host.extend_from_slice(data);
        at += data.len();
    }
    Ok(BridgePage {
        host,
        info: first.unwrap_or(wire::PageInfo {
            seq: None,
            password_set: false,
            restart_pending: false,
        }),
    })
}

/// Reads the verifier block of the page in force (with the password).
pub fn read_verifier(
    link: &mut Link,
    station: u8,
    password: &[u8],
    wait: Duration,
    stop: &dyn Fn() -> bool,
) -> Result<Vec<u8>, ConfigError> {
    let body = format!("{ACCESS_AT:03X}{}", hex(password));
    let reply = config_exchange(
        link,
        station,
        bridge_codes::CONFIG_READ,
        body.as_bytes(),
        wait,
        1,
        stop,
    )?;
    let mut out = [0u8; WINDOW];
    let (_, _, data) = wire::parse_read_reply(&reply, &mut out)
        .ok_or_else(|| ConfigError::Other("a read reply not laid out as B20's".into()))?;
    Ok(data.to_vec())
}

/// Stages `host` (the page's host part) window by window and applies it
/// with `password`: what the bridge answered.
pub fn write_page(
    link: &mut Link,
    station: u8,
    host: &[u8],
    password: &[u8],
    wait: Duration,
    stop: &dyn Fn() -> bool,
) -> Result<Applied, ConfigError> {
    if host.len() != HOST_LEN {
        return Err(ConfigError::Other(format!(
            "a page's host part is {HOST_LEN} bytes, not {}",
            host.len()
        )));
    }
    for (i, window) in host.chunks(WINDOW).enumerate() {
        let at = i * WINDOW;
        let body = format!("{at:03X}{}", hex(window));
        let reply = config_exchange(
            link,
            station,
            bridge_codes::CONFIG_STAGE,
            body.as_bytes(),
            wait,
            1,
            stop,
        )?;
        let next = std::str::from_utf8(&reply)
            .ok()
            .and_then(|t| usize::from_str_radix(t, 16).ok());
        if next != Some(at + window.len()) {
            return Err(ConfigError::Other(format!(
                "staged at {at:03X}, the bridge expects the next bytes at {}",
                String::from_utf8_lossy(&reply)
            )));
        }
    }
    let crc = host_crc(host);
    let body = format!("{crc:08X}{}", hex(password));
    let reply = config_exchange(
        link,
        station,
        bridge_codes::CONFIG_APPLY,
        body.as_bytes(),
        wait,
        1,
        stop,
    )?;
    let text = std::str::from_utf8(&reply).unwrap_or("");
    match (
        text.get(..8).and_then(|t| u32::from_str_radix(t, 16).ok()),
        text.get(8..),
    ) {
        (Some(seq), Some(r)) if r == "0" || r == "1" => Ok(Applied {
            seq,
            restart_needed: r == "1",
        }),
        _ => Err(ConfigError::Other(format!(
            "an apply reply not laid out as B22's: {text:?}"
        ))),
    }
}

/// Sets a new password (`current`: `None` on a fresh gateway): the page's
/// new sequence number.
pub fn set_password(
    link: &mut Link,
    station: u8,
    current: Option<&[u8]>,
    new: &[u8],
    wait: Duration,
    stop: &dyn Fn() -> bool,
) -> Result<u32, ConfigError> {
    let current = current.unwrap_or(&[]);
    let body = format!("{:02X}{}{}", current.len(), hex(current), hex(new));
    let reply = config_exchange(
        link,
        station,
        bridge_codes::CONFIG_PASSWORD,
        body.as_bytes(),
        wait,
        1,
        stop,
    )?;
    std::str::from_utf8(&reply)
        .ok()
        .and_then(|t| u32::from_str_radix(t, 16).ok())
        .ok_or_else(|| ConfigError::Other("a password reply not laid out as B24's".into()))
}

/// Restarts the gateway (with the password).
pub fn restart(
    link: &mut Link,
    station: u8,
    password: &[u8],
    wait: Duration,
    stop: &dyn Fn() -> bool,
) -> Result<(), ConfigError> {
    let body = hex(password);
    config_exchange(
        link,
        station,
        bridge_codes::RESTART,
        body.as_bytes(),
        wait,
        1,
        stop,
    )
    .map(|_| ())
}

/// A setting's value as text (the table's form).
pub fn value_text(setting: &Setting, settings: &Settings) -> String {
    struct Text(Vec<u8>);
    impl Sink for Text {
        fn put(&mut self, bytes: &[u8]) {
            self.0.extend_from_slice(bytes);
        }
    }
    let mut t = Text(Vec::new());
    settings::format(setting.kind, &(setting.get)(settings), &mut t);
    String::from_utf8_lossy(&t.0).into_owned()
}

/// A setting's value as JSON (numbers as numbers, on/off as booleans,
/// the rest as the table's text).
fn value_json(setting: &Setting, settings: &Settings) -> serde_json::Value {
    match (setting.kind, (setting.get)(settings)) {
        (Kind::Int { .. } | Kind::Baud, Value::Int(n)) => serde_json::json!(n),
        (Kind::Bool, Value::Int(n)) => serde_json::json!(n != 0),
        _ => serde_json::json!(value_text(setting, settings)),
    }
}

/// `block` and `name` of a key (`modbus.unit`: `modbus`, `unit`).
fn split_key(key: &str) -> (&str, &str) {
    key.split_once('.').unwrap_or(("", key))
}

/// The settings as TOML: one table per key's first part, each value with
/// its help as a comment; the password says only whether one is set (as
/// a comment, so that the output applied again changes no password).
pub fn settings_toml(settings: &Settings, seq: Option<u32>) -> String {
    let mut out = String::new();
    out.push_str(&match seq {
        Some(s) => format!("# the gateway's configuration page, sequence {s}\n"),
        None => "# the gateway's configuration page: none written yet (every default)\n".into(),
    });
    let mut section = "";
    for s in settings::TABLE.iter() {
        let (block, name) = split_key(s.key);
        if block != section {
            out.push_str(&format!("\n[{block}]\n"));
            section = block;
        }
        let line = match value_json(s, settings) {
            serde_json::Value::String(t) if s.kind == Kind::Password => {
                format!("# {name}: {t}")
            }
            serde_json::Value::String(t) => format!("{name} = {}", serde_json::json!(t)),
            v => format!("{name} = {v}"),
        };
        out.push_str(&format!("{line:<40} # {}\n", s.help));
    }
    out
}

/// The settings as one JSON object: `{"bridge": {"station": "BB", ...},
/// ...}`, with `sequence` and `restart_pending`.
pub fn settings_json(settings: &Settings, info: &wire::PageInfo) -> serde_json::Value {
    let mut top = serde_json::Map::new();
    top.insert("type".into(), serde_json::json!("bridge_config"));
    top.insert("sequence".into(), serde_json::json!(info.seq));
    top.insert(
        "restart_pending".into(),
        serde_json::json!(info.restart_pending),
    );
    for s in settings::TABLE.iter() {
        let (block, name) = split_key(s.key);
        let entry = top
            .entry(block.to_string())
            .or_insert_with(|| serde_json::json!({}));
        if let Some(m) = entry.as_object_mut() {
            m.insert(name.to_string(), value_json(s, settings));
        }
    }
    serde_json::Value::Object(top)
}

/// Sets `key` to `text` in `settings`, or says which key and why not.
pub fn set_text(settings: &mut Settings, key: &str, text: &str) -> Result<(), String> {
    settings
        .set(key, text)
        .map(|_| ())
        .map_err(|e| match e.key {
            Some(k) => format!("{k} = {text:?}: {}", e.reason),
            None => {
                let near = settings::TABLE
                    .iter()
                    .map(|s| s.key)
                    .filter(|k| {
                        let (b, n) = split_key(k);
                        key.contains(n) || key.starts_with(b)
                    })
                    .collect::<Vec<_>>();
                if near.is_empty() {
                    format!("{key}: no setting has this key (`iai bridge config get` lists them)")
                } else {
                    format!(
                        "{key}: no setting has this key; did you mean {}?",
                        near.join(", ")
                    )
                }
            }
        })
}

/// Applies a TOML file's settings (`[modbus] unit = 5` is `modbus.unit`)
/// to `settings`; a new password, if the file gives `[access] password`.
/// Every error is named (all of them, not the first only).
pub fn settings_from_toml(settings: &mut Settings, text: &str) -> Result<Option<String>, String> {
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| format!("not TOML: {e}"))?;
    let mut errors = Vec::new();
    let mut password = None;
    for (block, items) in &table {
        let Some(items) = items.as_table() else {
            errors.push(format!(
                "{block}: settings go in tables ([{block}] then name = value), not at the top"
            ));
            continue;
        };
        for (name, value) in items {
            let key = format!("{block}.{name}");
            let kind = settings::find(&key).map(|s| s.kind);
            let text = match (value, kind) {
                (toml::Value::String(s), Some(Kind::Password)) => {
                    password = Some(s.clone());
                    continue;
                }
                (toml::Value::String(s), _) => s.clone(),
                (toml::Value::Integer(_), Some(Kind::Station)) => {
                    errors.push(format!(
                        "{key} = {value}: give a station as a string of two hex digits (\"99\")"
                    ));
                    continue;
                }
                (toml::Value::Integer(n), _) => n.to_string(),
                (toml::Value::Boolean(b), _) => if *b { "on" } else { "off" }.into(),
                (v, _) => {
                    errors.push(format!("{key} = {v}: not a value a setting takes"));
                    continue;
                }
            };
            if let Err(e) = set_text(settings, &key, &text) {
                errors.push(e);
            }
        }
    }
    if let Err(e) = settings.check() {
        errors.push(format!("{}: {}", e.key.unwrap_or("?"), e.reason));
    }
    if errors.is_empty() {
        Ok(password)
    } else {
        Err(errors.join("\n"))
    }
}

/// `host` with `settings`' changed blocks written over it.
pub fn host_page_with(host: &[u8], settings: &Settings) -> Vec<u8> {
    let mut page = host.to_vec();
    page.resize(HOST_LEN, 0xFF);
    settings.overlay(0, &mut page);
    page
}

/// A board's configuration slots, as its memory map places them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardSlots {
    /// The board's name (`--board`).
    pub name: &'static str,
    /// Where slot A starts (`_bridge_config`).
    pub address: u32,
    /// A slot's bytes (a flash erase page).
    pub slot_len: usize,
    /// How to write an image there.
    pub flash_with: &'static str,
}

/// Where each board keeps its two slots (memory-qemu.x,
/// memory-stm32g030.x, memory-stm32g070.x: the last two erase pages of
/// the flash; checked against them by `host-tests/tests/bridge_config.rs`).
pub const BOARDS: [BoardSlots; 4] = [
    BoardSlots {
        name: "lm3s6965",
        address: 0x0003_F800,
        slot_len: 1024,
        flash_with: "qemu-system-arm -machine lm3s6965evb ... -device loader,file=FILE,addr=0x3f800; \
                     on an EK-LM3S6965: openocd -f board/ek-lm3s6965.cfg -c \"program FILE 0x3f800 verify reset exit\"",
    },
    BoardSlots {
        name: "mps2-an386",
        address: 0x0003_F800,
        slot_len: 1024,
        flash_with: "qemu-system-arm -machine mps2-an386 ... -device loader,file=FILE,addr=0x3f800",
    },
    BoardSlots {
        name: "stm32g030",
        address: 0x0800_F000,
        slot_len: 2048,
        flash_with: "probe-rs download --chip STM32G030C8Tx --binary-format bin --base-address 0x0800F000 FILE, \
                     or openocd -f interface/stlink.cfg -f target/stm32g0x.cfg -c \"program FILE 0x0800f000 verify reset exit\"",
    },
    BoardSlots {
        name: "stm32g070",
        address: 0x0801_F000,
        slot_len: 2048,
        flash_with: "probe-rs download --chip STM32G070KBTx --binary-format bin --base-address 0x0801F000 FILE, \
                     or openocd -f interface/stlink.cfg -f target/stm32g0x.cfg -c \"program FILE 0x0801f000 verify reset exit\"",
    },
];

/// The image a programmer writes at `board`'s slots: `host` (the page's
/// host part) and `verifier` (the verifier block, if any) in slot A as
/// sequence 1, slot B erased.
pub fn board_image(board: &BoardSlots, host: &[u8], verifier: Option<&[u8]>) -> Vec<u8> {
    let mut page = [0xFFu8; PAGE_LEN];
    let n = host.len().min(HOST_LEN);
    page[..n].copy_from_slice(&host[..n]);
    if let Some(v) = verifier {
        let n = v.len().min(ACCESS_LEN);
        page[ACCESS_AT..ACCESS_AT + n].copy_from_slice(&v[..n]);
    }
    let mut out = vec![0u8; 2 * board.slot_len];
    store::image(&page, board.slot_len, &mut out);
    out
}

/// A verifier block for `password` with a salt of this host's making.
pub fn verifier_block(password: &str) -> Result<Vec<u8>, String> {
    use std::hash::{BuildHasher, Hasher};
    let mut entropy = Vec::new();
    for i in 0..2u64 {
        let mut h = std::collections::hash_map::RandomState::new().build_hasher();
        h.write_u64(i);
        entropy.extend_from_slice(&h.finish().to_le_bytes());
    }
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    entropy.extend_from_slice(&now.to_le_bytes());
    let v =
        Verifier::new(password.as_bytes(), Verifier::salt_from(&entropy)).map_err(|e| match e {
            PasswordError::Length => "the password must be 8 to 64 characters".to_string(),
            PasswordError::Control => {
                "the password must hold no control characters (CR, LF, tab...)".to_string()
            }
        })?;
    Ok(v.to_block().to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A status reply recorded from the bridge under QEMU
    /// (`tools/gateway.sh`, lm3s6965, default configuration) after
    /// `iai table write` of 200 records through its pass-through.
    const RECORDED: &[u8] = include_bytes!("../tests/fixtures/bridge-status.bin");

    #[test]
    fn a_recorded_status_reply_decodes() {
        let s = decode_status(RECORDED).unwrap();
        assert_eq!(s.station, 0xBB);
        assert_eq!(s.get("layout"), 1);
        assert_eq!(s.get("controller_station"), 0x99);
        assert_eq!(s.get("bridge_station"), 0xBB);
        assert_eq!(s.get("upstream_baud"), 115_200);
        assert_eq!(s.get("flow_control"), 1);
        let lines = describe_status(&s).join("\n");
        assert!(lines.contains("flow_control = 1 -> XON/XOFF"), "{lines}");
        assert!(lines.contains("policy = 0 -> forward all"), "{lines}");
        assert!(lines.contains("controller_station = 153 -> 99"), "{lines}");
        let v = status_json(&s);
        // The gateway boots the bridge with a configuration block.
        assert_eq!(
            v["meanings"]["config_source"], "the configuration block",
            "{v}"
        );
        assert_eq!(v["fields"]["records"], 200, "{v}");
    }

    #[test]
    fn a_status_reply_from_the_firmware_s_own_writer_decodes() {
        let config = firmware_example::config::Config::DEFAULT;
        let stats = status::Stats {
            streams_ok: 3,
            records: 600,
            ..status::Stats::default()
        };
        let report = status::Report {
            now_ms: 3_723_456,
            config: &config,
            source: firmware_example::config::Source::Blank,
            stats: &stats,
            last_error: Some(status::LastError {
                code: bridge_codes::UPSTREAM_OVERRUN,
                at_ms: 1_000,
            }),
        };
        let mut buf = [0u8; status::REPLY_LEN];
        let n = report.emit(Station(0xBB), &mut buf).unwrap();
        let s = decode_status(&buf[..n]).unwrap();
        assert_eq!(s.get("records"), 600);
        let text = describe_status(&s).join("\n");
        assert!(
            text.contains("uptime_ms = 3723456 -> 1 h 02 min 03.456 s"),
            "{text}"
        );
        assert!(
            text.contains("config_source = 2 -> defaults (the configuration block is blank)"),
            "{text}"
        );
        assert!(
            text.contains("last_error = 2823 -> B07: bytes of the host's 26DH were lost"),
            "{text}"
        );
        // Not a status reply: said so.
        let frame = |h: Header, code: u16| {
            let mut buf = [0u8; 16];
            let n = emit_frame(
                &mut buf,
                h,
                Station(0xBB),
                code,
                ChecksumMode::Compute,
                |_| Ok(()),
            )
            .unwrap();
            buf[..n].to_vec()
        };
        let refused = decode_status(&frame(Header::Error, 0xB06)).unwrap_err();
        assert!(
            refused.contains("& B06 (bridge: the command policy refuses"),
            "{refused}"
        );
        let short = decode_status(&frame(Header::Response, 0xB00)).unwrap_err();
        assert!(short.contains("0 characters"), "{short}");
    }

    #[test]
    fn a_table_is_one_26dh_up_to_its_format_s_limit() {
        let rec = |n: u16| PositionRecord::new(n, 30, 30, 100, &[(1, i32::from(n))]).unwrap();
        let recs: Vec<PositionRecord> = (0..3).map(rec).collect();
        assert_eq!(parts(&recs).map(<[_]>::len).collect::<Vec<_>>(), [3]);
        let many: Vec<PositionRecord> = (0..=20_000).map(|i| rec((i % 60_000) as u16)).collect();
        assert_eq!(
            parts(&many).map(<[_]>::len).collect::<Vec<_>>(),
            vec![20_000, 1]
        );
        assert!(worth_resending(bridge_codes::UPSTREAM_OVERRUN));
        assert!(!worth_resending(bridge_codes::REFUSED));
        assert!(verdict_text(&Verdict::Refused(0xB07), 3).contains("corrupted bytes"));
    }
}
