//! The listing's two forms: one JSON object per line
//! ([`json_line`]), or a few human-readable lines per entry
//! ([`text_entry`]).

use iai_protocol_b::catalogue;
use iai_protocol_b::checksum::ChecksumField;
use iai_protocol_b::frame::Header;

use super::item::{Item, What};
use crate::fields::{json_meanings, json_object, meanings, text_lines, Val};

/// What a field of message `id` means (units, status bits, codes).
fn explainer(id: u16, header: Header) -> impl Fn(&str, &str, &Val) -> Option<String> {
    move |name: &str, unit: &str, v: &Val| crate::meaning::describe(id, header, name, unit, v)
}
use crate::text::{escape, json_str};

fn kind_name(h: Header) -> &'static str {
    match h {
        Header::Command => "command",
        Header::Response => "response",
        Header::Error => "error",
    }
}

fn checksum_text(c: ChecksumField) -> (&'static str, String) {
    match c {
        ChecksumField::Sum(v) => ("ok", format!("{v:02X}")),
        ChecksumField::Bypass => ("bypass", "@@".into()),
    }
}

/// One entry as a JSON object on one line.
pub fn json_line(item: &Item) -> String {
    let mut parts = vec![
        format!("\"offset\":{}", item.offset),
        format!("\"len\":{}", item.len),
    ];
    if let Some(line) = item.origin.line {
        parts.push(format!("\"line\":{line}"));
    }
    if let Some(dir) = item.origin.dir {
        parts.push(format!("\"dir\":{}", json_str(dir)));
    }
    let head = match &item.what {
        What::Frame(f) => {
            let (status, sc) = checksum_text(f.checksum);
            let mut p = vec![
                "\"type\":\"frame\"".to_string(),
                format!("\"kind\":\"{}\"", kind_name(f.header)),
                format!("\"station\":\"{:02X}\"", f.station),
            ];
            if f.header == Header::Error {
                p.push(format!("\"code\":\"{:03X}\"", f.code));
                if let Some(m) = crate::codes::meaning(f.code) {
                    p.push(format!("\"meaning\":{}", json_str(&m)));
                }
            } else {
                p.push(format!("\"id\":\"{:03X}\"", f.code));
                if let Some(n) = catalogue::lookup(f.code).map(|m| m.name) {
                    p.push(format!("\"name\":{}", json_str(n)));
                }
            }
            p.push(format!("\"checksum\":\"{status}\",\"sc\":\"{sc}\""));
            match &f.decoded {
                Ok((ty, fields)) => {
                    p.push(format!("\"message\":{}", json_str(ty)));
                    p.push(format!("\"fields\":{}", json_object(fields)));
                    let mut m = Vec::new();
                    meanings(fields, "", &explainer(f.code, f.header), &mut m);
                    if !m.is_empty() {
                        p.push(format!("\"meanings\":{}", json_meanings(&m)));
                    }
                }
                Err(e) => p.push(format!("\"decode_error\":{}", json_str(e))),
            }
            p
        }
        What::Stream(s) => {
            let (status, sc) = checksum_text(s.checksum);
            let mut p = vec![
                "\"type\":\"stream\"".to_string(),
                "\"kind\":\"command\"".to_string(),
                format!("\"station\":\"{:02X}\"", s.station),
                format!("\"id\":\"{:03X}\"", s.kind.id),
            ];
            if let Some(n) = catalogue::lookup(s.kind.id).map(|m| m.name) {
                p.push(format!("\"name\":{}", json_str(n)));
            }
            p.push(format!("\"checksum\":\"{status}\",\"sc\":\"{sc}\""));
            p.push(format!(
                "\"start\":{},\"count\":{},\"records\":{}",
                s.start, s.count, s.records
            ));
            if let Some(first) = &s.first {
                p.push(format!("\"first\":{}", json_object(first)));
            }
            if let Some(last) = &s.last {
                p.push(format!("\"last\":{}", json_object(last)));
            }
            p
        }
        What::Error {
            kind,
            message,
            bytes,
        } => vec![
            "\"type\":\"error\"".to_string(),
            format!("\"error\":{}", json_str(kind)),
            format!("\"message\":{}", json_str(message)),
            format!("\"bytes\":{}", json_str(&escape(bytes))),
        ],
    };
    let mut all = head;
    all.extend(parts);
    format!("{{{}}}", all.join(","))
}

/// One entry as listing lines.
pub fn text_entry(item: &Item) -> Vec<String> {
    let mut at = format!("0x{:08X}", item.offset);
    if let Some(line) = item.origin.line {
        at.push_str(&format!(" L{line}"));
    }
    if let Some(dir) = item.origin.dir {
        at.push_str(&format!(" {dir}"));
    }
    let mut out = Vec::new();
    match &item.what {
        What::Frame(f) => {
            let (status, sc) = checksum_text(f.checksum);
            let what = if f.header == Header::Error {
                match crate::codes::meaning(f.code) {
                    Some(m) => format!("error code {:03X} ({m})", f.code),
                    None => format!("error code {:03X}", f.code),
                }
            } else {
                format!(
                    "{:03X}H {}",
                    f.code,
                    catalogue::lookup(f.code)
                        .map(|m| m.name)
                        .unwrap_or("(unknown message)")
                )
            };
            out.push(format!(
                "{at}  {:<8} st {:02X}  {what}  [{} bytes, SC {sc} {status}]",
                kind_name(f.header),
                f.station,
                item.len
            ));
            match &f.decoded {
                Ok((_, fields)) => {
                    text_lines(fields, "", "    ", &mut out, &explainer(f.code, f.header))
                }
                Err(e) => out.push(format!("    (not decoded: {e})")),
            }
        }
        What::Stream(s) => {
            let (status, sc) = checksum_text(s.checksum);
            out.push(format!(
                "{at}  {:<8} st {:02X}  {:03X}H {}  [{} bytes, SC {sc} {status}]",
                "command",
                s.station,
                s.kind.id,
                catalogue::lookup(s.kind.id).map(|m| m.name).unwrap_or(""),
                item.len
            ));
            out.push(format!(
                "    position stream: start {}, {} records announced, {} read",
                s.start, s.count, s.records
            ));
            for (label, rec) in [("first", &s.first), ("last", &s.last)] {
                if let Some(rec) = rec {
                    out.push(format!("    {label} record:"));
                    text_lines(
                        rec,
                        "",
                        "      ",
                        &mut out,
                        &explainer(s.kind.id, Header::Command),
                    );
                }
            }
        }
        What::Error {
            kind,
            message,
            bytes,
        } => {
            out.push(format!(
                "{at}  ERROR    {kind}: {message}  [{} bytes] \"{}\"",
                item.len,
                escape(bytes)
            ));
        }
    }
    out
}
