//! `iai encode`: one frame from `field=value` arguments.
//!
//! The layout comes from the core itself, not from a second copy of the
//! catalogue: a sample frame of the message is found by letting the core's
//! decoder say what is wrong with a candidate body and fixing that (too
//! short: add digits; trailing bytes: cut; a digit or value refused: try
//! another digit at that offset), until [`decode_any`] accepts it. The
//! field visitor then shows the sample's fields, widths and repeat groups;
//! the new body is written from those with the user's values, and the
//! result must decode again before it is printed.
//!
//! Values: decimal or `0x` hex, negative for signed fields, text for text
//! fields. A field inside a repeat group takes one value per item,
//! comma-separated (`position=1000,-2000`); inside a group nested in a
//! group, items of the outer group are separated by `/`
//! (`position=1000,2000/3000`). A field left out is 0, except an axis
//! pattern followed by a per-axis group, which defaults to the first N
//! axes for N values given.

mod args;
mod json;
mod layout;

pub use args::{describe, range_of};
pub use layout::{find_message, layout, sample_body, type_name};

use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::message::decode_any;

use args::{leaf_names, write_level, Args, Rules};
use json::write_json_level;
use layout::frame_bytes;

use super::fields::{tree, Node, Val};
use iai_protocol_b::field::Radix;

/// Options of `iai encode`.
#[derive(Debug, Clone)]
pub struct EncodeOptions {
    /// Message ID or name.
    pub message: String,
    /// `field=value` pairs.
    pub assignments: Vec<String>,
    /// Station.
    pub station: u8,
    /// Build the normal response instead of the command.
    pub response: bool,
    /// Send `@@` instead of the checksum.
    pub bypass: bool,
    /// The fields as a JSON object (instead of `assignments`).
    pub json: Option<serde_json::Value>,
}

/// Builds the frame. Returns it, or a message saying what is wrong.
pub fn encode(opts: &EncodeOptions) -> Result<Vec<u8>, String> {
    if opts.message.eq_ignore_ascii_case("error") {
        return encode_error(opts);
    }
    let header = if opts.response {
        Header::Response
    } else {
        Header::Command
    };
    let id = find_message(&opts.message, header)?;
    let nodes = layout(header, id).ok_or_else(|| {
        format!(
            "{id:03X}H has no {} this tool can build",
            if opts.response {
                "normal response"
            } else {
                "command"
            }
        )
    })?;
    let rules = Rules { id, header };
    let mut body = Vec::new();
    if let Some(json) = &opts.json {
        if !opts.assignments.is_empty() {
            return Err("give the fields either as field=value or as JSON, not both".into());
        }
        let obj = json
            .as_object()
            .ok_or_else(|| format!("the JSON must be an object of fields, found {json}"))?;
        let mut missing = Vec::new();
        write_json_level(&nodes, obj, "", rules, &mut missing, &mut body)?;
        refuse_missing(id, &missing)?;
        return finish_frame(opts, header, id, &body);
    }
    let mut args = Args::parse(&opts.assignments, rules)?;
    // A name the message does not have is reported first: a misspelled
    // field would otherwise show as a missing one.
    let mut known = Vec::new();
    leaf_names(&nodes, "", &mut known);
    let names: Vec<String> = known
        .iter()
        .map(|(g, n)| {
            if g.is_empty() || g == n {
                n.clone()
            } else {
                format!("{g}.{n}")
            }
        })
        .collect();
    let unknown: Vec<String> = args
        .values
        .keys()
        .filter(|k| {
            !known
                .iter()
                .any(|(g, n)| *k == n || **k == format!("{g}.{n}"))
        })
        .map(|k| match closest(k, &names) {
            Some(c) => format!("{k} (did you mean {c}?)"),
            None => k.clone(),
        })
        .collect();
    if !unknown.is_empty() {
        return Err(format!(
            "{id:03X}H has no field {}; its fields: {}",
            unknown.join(", "),
            names.join(" ")
        ));
    }
    write_level(&nodes, &[], &[], &mut args, &mut body)?;
    refuse_missing(id, &args.missing)?;
    finish_frame(opts, header, id, &body)
}

/// The fields that must be given and were not, named.
fn refuse_missing(id: u16, missing: &[String]) -> Result<(), String> {
    if missing.is_empty() {
        return Ok(());
    }
    Err(format!(
        "{id:03X}H needs {}: give {} (`iai encode {id:03X} --fields` lists the fields and which may be left out)",
        if missing.len() == 1 { "a field that is missing" } else { "fields that are missing" },
        missing.join(", ")
    ))
}

/// The name in `names` closest to `k` by edit distance, if close enough
/// to be a misspelling.
fn closest<'n>(k: &str, names: &'n [String]) -> Option<&'n str> {
    let dist = |a: &str, b: &str| {
        let b: Vec<char> = b.chars().collect();
        let mut row: Vec<usize> = (0..=b.len()).collect();
        for (i, ca) in a.chars().enumerate() {
            let mut prev = row[0];
            row[0] = i + 1;
            for (j, cb) in b.iter().enumerate() {
                let cur = row[j + 1];
                row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
                prev = cur;
            }
        }
        row[b.len()]
    };
    names
        .iter()
        .map(|n| (dist(k, n), n))
        .filter(|(d, n)| *d <= (n.len() / 3).max(2))
        .min_by_key(|(d, _)| *d)
        .map(|(_, n)| n.as_str())
}

fn finish_frame(
    opts: &EncodeOptions,
    header: Header,
    id: u16,
    body: &[u8],
) -> Result<Vec<u8>, String> {
    let mode = if opts.bypass {
        ChecksumMode::Bypass
    } else {
        ChecksumMode::Compute
    };
    let bytes = frame_bytes(header, Station(opts.station), id, body, mode);
    let frame = Frame::new_checked(&bytes, BypassPolicy::Accept).map_err(|e| e.to_string())?;
    decode_any(&frame).map_err(|e| format!("the frame does not decode: {e}"))?;
    Ok(bytes)
}

/// An error response (`&`, station, 3-digit code): MESSAGE `error`, the
/// code as `error_code=…` or `{"error_code": …}`.
fn encode_error(opts: &EncodeOptions) -> Result<Vec<u8>, String> {
    let sample = frame_bytes(Header::Error, Station(0x99), 0, &[], ChecksumMode::Compute);
    let nodes = Frame::new_checked(&sample, BypassPolicy::Accept)
        .ok()
        .and_then(|f| decode_any(&f).ok())
        .map(|d| tree(&d.message))
        .ok_or("error responses cannot be built")?;
    let rules = Rules {
        id: 0,
        header: Header::Error,
    };
    let mut digits = Vec::new();
    match &opts.json {
        Some(json) => {
            let obj = json
                .as_object()
                .ok_or_else(|| format!("the JSON must be an object of fields, found {json}"))?;
            let mut missing = Vec::new();
            write_json_level(&nodes, obj, "", rules, &mut missing, &mut digits)?;
            if !missing.is_empty() {
                return Err("an error response needs its error_code".into());
            }
        }
        None => {
            let mut args = Args::parse(&opts.assignments, rules)?;
            if let Some(k) = args.values.keys().find(|k| *k != "error_code") {
                return Err(format!(
                    "an error response has no field {k}; its field: error_code"
                ));
            }
            write_level(&nodes, &[], &[], &mut args, &mut digits)?;
            if !args.missing.is_empty() {
                return Err("an error response needs its error_code (error_code=0x0E4)".into());
            }
        }
    }
    let code = std::str::from_utf8(&digits)
        .ok()
        .and_then(|d| u16::from_str_radix(d, 16).ok())
        .ok_or("error_code: not a 3-digit code")?;
    finish_frame(opts, Header::Error, code, &[])
}

/// The usage lines of a message's fields (for `iai encode MESSAGE --help`).
pub fn field_help(header: Header, id: u16) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(nodes) = layout(header, id) {
        help_level(&nodes, 0, Rules { id, header }, &mut out);
    }
    out
}

fn help_level(nodes: &[Node], depth: usize, rules: Rules, out: &mut Vec<String>) {
    let pad = "  ".repeat(depth + 1);
    for n in nodes {
        match n {
            Node::Leaf {
                name,
                unit,
                spec,
                value,
            } => {
                let fixed = matches!(value, Val::Text(_)) && spec.radix != Radix::Text;
                let unit = super::fields::unit_suffix(", ", unit);
                let mut note = if fixed {
                    ", fixed".to_string()
                } else {
                    String::new()
                };
                if let Some(d) = crate::meaning::default_meaning(rules.id, name) {
                    note.push_str(&format!(", optional: {d}"));
                }
                let codes = rules.codes(name);
                if !codes.is_empty() {
                    note.push_str(&format!(", names: {}", args::code_list(codes)));
                }
                out.push(format!("{pad}{name} ({}{unit}{note})", describe(*spec)));
            }
            Node::Group { name, info, items } => {
                out.push(format!("{pad}{name}: repeated, up to {} item(s)", info.max));
                if let Some(first) = items.first() {
                    help_level(first, depth + 1, rules, out);
                }
            }
        }
    }
}
