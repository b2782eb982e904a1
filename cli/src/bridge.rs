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

use std::time::Duration;

use firmware_example::codes as bridge_codes;
use firmware_example::status;
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
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
        ..LineConfig::new(Station(station))
    };
    table::command_to(link, cfg, &status_query(station), hooks)
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
