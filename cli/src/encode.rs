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

use std::collections::BTreeMap;

use iai_protocol_b::catalogue;
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::field::{encode_signed, encode_unsigned, FieldSpec, Radix};
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::message::{decode_any, AnyMessage, GroupInfo};

use super::fields::{tree, Node, Val};

/// Digits tried, in order, at an offset the decoder refuses.
const DIGITS: &[u8] = b"1023456789ABCDEF ";

fn frame_bytes(
    header: Header,
    station: Station,
    id: u16,
    body: &[u8],
    mode: ChecksumMode,
) -> Vec<u8> {
    let mut buf = vec![0u8; body.len() + 16];
    let n = emit_frame(&mut buf, header, station, id, mode, |w| w.put(body)).unwrap_or(0);
    buf.truncate(n);
    buf
}

/// The `n`-th rewrite tried at a refused offset.
fn rewrite(n: usize) -> Option<Vec<u8>> {
    let small = 3 * 8;
    if n < small {
        let w = n / 3 + 1;
        let mut v = vec![b'0'; w];
        *v.last_mut()? = [b'1', b'8', b'0'][n % 3];
        return Some(v);
    }
    let k = n - small;
    let pos = k / DIGITS.len();
    if pos >= 8 {
        return None;
    }
    let mut v = vec![b'0'; pos + 1];
    *v.last_mut()? = *DIGITS.get(k % DIGITS.len())?;
    Some(v)
}

/// A body the core decodes for message `id` in direction `header`, with
/// every repeat group holding at least one item where the decoder allows.
pub fn sample_body(header: Header, id: u16) -> Option<Vec<u8>> {
    use iai_protocol_b::Error as E;
    let mut body: Vec<u8> = Vec::new();
    let mut tries: BTreeMap<usize, usize> = BTreeMap::new();
    for _ in 0..20_000 {
        let bytes = frame_bytes(header, Station(0x99), id, &body, ChecksumMode::Compute);
        let err = match Frame::new_checked(&bytes, BypassPolicy::Accept) {
            Ok(f) => match decode_any(&f) {
                Ok(_) => return Some(body),
                Err(e) => e,
            },
            Err(e) => e,
        };
        let bad_at = match err {
            E::BodyTooShort { .. } => {
                let grow = (body.len() / 2).max(8);
                body.extend(std::iter::repeat_n(b'1', grow));
                continue;
            }
            E::TrailingBytes { offset } => {
                body.truncate(offset.checked_sub(6)?);
                continue;
            }
            E::InvalidHexDigit { offset, .. }
            | E::InvalidDecimalDigit { offset, .. }
            | E::ValueOutOfRange { offset }
            | E::InvalidFixedField { offset } => offset.checked_sub(6)?,
            E::CountTooLarge { count, .. } => {
                // No offset: lower the first count field that says `count`.
                let digits = format!("{count:X}");
                let at = body
                    .windows(digits.len())
                    .position(|w| w == digits.as_bytes())?;
                *body.get_mut(at)? = b'0';
                continue;
            }
            _ => return None,
        };
        // Try the next rewrite of the field at the offset the decoder
        // refused: small values of growing width first (a count of 1, a
        // fixed "00"), then every digit at each of its first characters.
        let n = tries.entry(bad_at).or_insert(0);
        let candidate = rewrite(*n)?;
        *n += 1;
        let end = bad_at + candidate.len();
        if end > body.len() {
            body.resize(end, b'1');
        }
        body.get_mut(bad_at..end)?.copy_from_slice(&candidate);
    }
    None
}

/// Finds a message ID from `212`, `212H`, `0x212`, a catalogue name or a
/// Rust type name (case, spaces and punctuation ignored).
pub fn find_message(name: &str, header: Header) -> Result<u16, String> {
    let hex = name
        .strip_prefix("0x")
        .or_else(|| name.strip_suffix(['H', 'h']))
        .unwrap_or(name);
    if let Ok(id) = u16::from_str_radix(hex, 16) {
        if catalogue::lookup(id).is_some() {
            return Ok(id);
        }
    }
    let norm = |s: &str| -> String {
        s.chars()
            .filter(char::is_ascii_alphanumeric)
            .map(|c| c.to_ascii_lowercase())
            .collect()
    };
    let want = norm(name);
    let mut hits: Vec<u16> = Vec::new();
    for id in catalogue::ALL.iter().map(|m| m.id) {
        let names = [
            catalogue::lookup(id)
                .map(|m| m.name)
                .map(norm)
                .unwrap_or_default(),
            type_name(header, id).map(|t| norm(&t)).unwrap_or_default(),
        ];
        if names.contains(&want) {
            return Ok(id);
        }
        if names.iter().any(|n| n.contains(&want)) {
            hits.push(id);
        }
    }
    match hits.as_slice() {
        [id] => Ok(*id),
        [] => Err(format!("no message is called {name:?}")),
        many => Err(format!(
            "{name:?} is ambiguous: {}",
            many.iter()
                .map(|id| format!(
                    "{id:03X}H {}",
                    catalogue::lookup(*id).map(|m| m.name).unwrap_or("")
                ))
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// The Rust type name of message `id` in this direction.
pub fn type_name(header: Header, id: u16) -> Option<String> {
    let body = sample_body(header, id)?;
    let bytes = frame_bytes(header, Station(0x99), id, &body, ChecksumMode::Compute);
    let f = Frame::new_checked(&bytes, BypassPolicy::Accept).ok()?;
    let d = decode_any(&f).ok()?;
    let debug = match &d.message {
        AnyMessage::Command(c) => format!("{c:?}"),
        AnyMessage::Response(r) => format!("{r:?}"),
        AnyMessage::Error(_) => return None,
    };
    debug.split(['(', ' ', '{']).next().map(str::to_string)
}

/// The field layout of message `id` (a decoded sample's tree).
pub fn layout(header: Header, id: u16) -> Option<Vec<Node>> {
    let body = sample_body(header, id)?;
    let bytes = frame_bytes(header, Station(0x99), id, &body, ChecksumMode::Compute);
    let f = Frame::new_checked(&bytes, BypassPolicy::Accept).ok()?;
    let d = decode_any(&f).ok()?;
    Some(tree(&d.message))
}

/// User values by field name, each split into items.
struct Args {
    values: BTreeMap<String, String>,
    used: BTreeMap<String, bool>,
}

impl Args {
    /// `field=value` arguments; a field given twice is an error.
    fn parse(assignments: &[String]) -> Result<Self, String> {
        let mut values = BTreeMap::new();
        for a in assignments {
            let (k, v) = a
                .split_once('=')
                .ok_or_else(|| format!("{a:?}: expected field=value"))?;
            if values.insert(k.to_string(), v.to_string()).is_some() {
                return Err(format!("{k}: given twice"));
            }
        }
        Ok(Args {
            values,
            used: BTreeMap::new(),
        })
    }

    /// The raw value for a field (`name` or `group.name`).
    fn get(&mut self, path: &[&str], name: &str) -> Option<String> {
        let mut keys = vec![name.to_string()];
        if let Some(g) = path.last() {
            keys.insert(0, format!("{g}.{name}"));
        }
        for k in keys {
            if let Some(v) = self.values.get(&k) {
                self.used.insert(k, true);
                return Some(v.clone());
            }
        }
        None
    }
}

/// The value of one item of a field: `depth` is the number of repeat
/// groups around it, `index` the item numbers from the outermost.
fn item_value(raw: &str, index: &[usize]) -> Option<String> {
    match index {
        [] => Some(raw.to_string()),
        [i] => raw.split(',').nth(*i).map(str::to_string),
        [o, i] => raw
            .split('/')
            .nth(*o)?
            .split(',')
            .nth(*i)
            .map(str::to_string),
        _ => None,
    }
}

fn item_count(raw: &str, outer: &[usize]) -> usize {
    let part = match outer {
        [] => Some(raw),
        [o] => raw.split('/').nth(*o),
        _ => None,
    };
    match part {
        Some(p) if !p.is_empty() => p.split(',').count(),
        _ => 0,
    }
}

/// Names of the leaves of a group's sample item, with the group they are in.
fn leaf_names(nodes: &[Node], group: &str, out: &mut Vec<(String, String)>) {
    for n in nodes {
        match n {
            Node::Leaf { name, .. } => out.push((group.to_string(), name.to_string())),
            Node::Group { name, items, .. } => {
                if let Some(first) = items.first() {
                    leaf_names(first, name, out);
                }
            }
        }
    }
}

fn write_value(
    spec: FieldSpec,
    text: Option<&str>,
    fixed: Option<&[u8]>,
    name: &str,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    write_value_as(spec, text, fixed, name, true, out)
}

fn write_value_as(
    spec: FieldSpec,
    text: Option<&str>,
    fixed: Option<&[u8]>,
    name: &str,
    escaped: bool,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let width = usize::from(spec.width);
    let mut digits = vec![b'0'; width];
    if let Some(lit) = fixed {
        return match text {
            Some(t) if t.as_bytes() != lit => Err(format!(
                "{name}: the field is fixed to {:?}",
                String::from_utf8_lossy(lit)
            )),
            _ => {
                out.extend_from_slice(lit);
                Ok(())
            }
        };
    }
    if spec.radix == Radix::Text {
        let raw = text.unwrap_or("");
        let t = if escaped {
            super::text::unescape(raw.as_bytes())
        } else {
            super::fields::from_latin1(raw).ok_or_else(|| {
                format!(
                    "{name}: {raw:?} has a character above U+00FF (text is one byte per character)"
                )
            })?
        };
        if t.len() > width {
            return Err(format!("{name}: at most {width} characters"));
        }
        let mut t = t;
        t.resize(width, b' ');
        out.extend_from_slice(&t);
        return Ok(());
    }
    let v = match text {
        None => 0,
        Some(t) => super::text::parse_int(t).ok_or_else(|| {
            format!(
                "{name}: {t:?} is not a number (decimal or 0x hex, one optional '-'; {} {})",
                describe(spec),
                range_of(spec)
            )
        })?,
    };
    let res = if spec.signed {
        let v = i64::try_from(v).map_err(|_| {
            format!(
                "{name}: {v} does not fit {} ({})",
                describe(spec),
                range_of(spec)
            )
        })?;
        encode_signed(spec, v, &mut digits)
    } else {
        let v = u64::try_from(v).map_err(|_| {
            format!(
                "{name}: {v} is negative, the field is unsigned ({})",
                range_of(spec)
            )
        })?;
        encode_unsigned(spec, v, &mut digits)
    };
    res.map_err(|_| {
        format!(
            "{name}: {v} does not fit {} ({})",
            describe(spec),
            range_of(spec)
        )
    })?;
    out.extend_from_slice(&digits);
    Ok(())
}

/// The values a numeric field takes: `0..=255`, `-2147483648..=2147483647`.
pub fn range_of(spec: FieldSpec) -> String {
    if spec.signed {
        let (lo, hi) = spec.signed_range();
        format!("{lo}..={hi}")
    } else {
        format!("0..={}", spec.max_unsigned())
    }
}

/// `hex 4`, `signed hex 8`, `dec 2`, `text 10`.
pub fn describe(spec: FieldSpec) -> String {
    let r = match (spec.radix, spec.signed) {
        (Radix::Hex, false) => "hex",
        (Radix::Hex, true) => "signed hex",
        (Radix::Dec, _) => "dec",
        (Radix::Text, _) => "text",
    };
    format!("{r} {}", spec.width)
}

/// A group of single characters (a counted text such as 216H's message):
/// its value is one string, not a list.
fn char_group(n: &Node) -> Option<(&'static str, FieldSpec)> {
    let Node::Group { name, items, .. } = n else {
        return None;
    };
    match items.first().map(Vec::as_slice) {
        Some(
            [Node::Leaf {
                name: leaf, spec, ..
            }],
        ) if leaf == name && spec.radix == Radix::Text && spec.width == 1 => Some((name, *spec)),
        _ => None,
    }
}

/// Writes one level (a list of nodes) of the layout.
fn write_level(
    nodes: &[Node],
    path: &[&str],
    index: &[usize],
    args: &mut Args,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    // Items of each group of this level, known before its pattern is written.
    let mut counts: Vec<usize> = Vec::new();
    for n in nodes {
        if let Some((name, _)) = char_group(n) {
            let text = args.get(path, name).unwrap_or_default();
            counts.push(super::text::unescape(text.as_bytes()).len());
            continue;
        }
        if let Node::Group { name, items, .. } = n {
            let mut leaves = Vec::new();
            if let Some(first) = items.first() {
                leaf_names(first, name, &mut leaves);
            }
            let mut count = 0;
            for (group, leaf) in leaves {
                if group != *name {
                    continue;
                }
                let mut p = path.to_vec();
                p.push(name);
                if let Some(raw) = args.get(&p, &leaf) {
                    count = count.max(item_count(&raw, index));
                }
            }
            counts.push(count);
        }
    }
    let mut group_no = 0;
    let mut pattern: Option<(&str, u64)> = None;
    for (i, n) in nodes.iter().enumerate() {
        match n {
            Node::Leaf {
                name, spec, value, ..
            } => {
                let fixed = match value {
                    Val::Text(t) if spec.radix != Radix::Text => Some(t.as_slice()),
                    _ => None,
                };
                let raw = args.get(path, name);
                let mut text = raw.and_then(|r| item_value(&r, index));
                // The pattern that sizes the next per-axis group of this level.
                let next_is_axes = matches!(
                    nodes.get(i + 1..).unwrap_or(&[]).iter().find(|n| matches!(n, Node::Group { .. })),
                    Some(Node::Group { info, .. }) if info.count_field.is_none()
                );
                // A pattern the user gave is checked against the values; a
                // defaulted one only covers them (the group's maximum is
                // checked then).
                let given = text.is_some();
                if !given && name.ends_with("pattern") && next_is_axes {
                    let n = counts.get(group_no).copied().unwrap_or(0).min(8);
                    text = Some(((1u32 << n) - 1).to_string());
                }
                if given && name.ends_with("pattern") && next_is_axes {
                    let bits = text
                        .as_deref()
                        .and_then(super::text::parse_int)
                        .unwrap_or(0);
                    pattern = Some((name, u64::try_from(bits).unwrap_or(0)));
                }
                write_value(*spec, text.as_deref(), fixed, name, out)?;
            }
            Node::Group { name, info, items } => {
                let count = counts.get(group_no).copied().unwrap_or(0);
                group_no += 1;
                check_count(name, info, count, pattern.take())?;
                if let Some(cf) = info.count_field {
                    let units = (count * info.per_item).to_string();
                    write_value(cf, Some(&units), None, name, out)?;
                }
                if char_group(n).is_some() {
                    let text = args.get(path, name).unwrap_or_default();
                    out.extend_from_slice(&super::text::unescape(text.as_bytes()));
                    continue;
                }
                let Some(sample) = items.first() else {
                    if count > 0 {
                        return Err(format!("{name}: no sample item to encode from"));
                    }
                    continue;
                };
                let mut p = path.to_vec();
                p.push(name);
                for k in 0..count {
                    let mut idx = index.to_vec();
                    idx.push(k);
                    write_level(sample, &p, &idx, args, out)?;
                }
            }
        }
    }
    Ok(())
}

/// Checks a group's item count: at most the declared maximum, and one
/// value per axis of the pattern that precedes a per-axis group.
fn check_count(
    name: &str,
    info: &GroupInfo,
    count: usize,
    pattern: Option<(&str, u64)>,
) -> Result<(), String> {
    if info.count_field.is_none() {
        if let Some((pname, bits)) = pattern {
            let axes = bits.count_ones() as usize;
            if axes != count {
                return Err(format!(
                    "{name}: {count} value(s) given, but {pname} = 0x{bits:02X} selects {axes} axis(es); give one value per axis (at most {})",
                    info.max
                ));
            }
            return Ok(());
        }
    }
    if count > info.max {
        return Err(format!(
            "{name}: {count} value(s) given, at most {} allowed",
            info.max
        ));
    }
    Ok(())
}

/// Writes one level of the layout from a JSON object in the form that
/// `iai inspect --json` prints under `fields`.
fn write_json_level(
    nodes: &[Node],
    obj: &serde_json::Map<String, serde_json::Value>,
    path: &str,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    use serde_json::Value as J;
    let known: Vec<&str> = nodes.iter().map(Node::name).collect();
    if let Some(k) = obj.keys().find(|k| !known.contains(&k.as_str())) {
        return Err(format!(
            "{path}{k}: no such field here; the fields are: {}",
            known.join(", ")
        ));
    }
    let text_of = |name: &str, v: &J, spec: Option<FieldSpec>| -> Result<String, String> {
        match v {
            J::Number(n) => Ok(n.to_string()),
            J::String(s) if spec.is_none_or(|s| s.radix == Radix::Text) => Ok(s.clone()),
            J::String(s) => Ok(s.clone()),
            other => Err(format!(
                "{path}{name}: expected a number or a string, found {other}"
            )),
        }
    };
    let mut pattern: Option<(&str, u64)> = None;
    for (i, n) in nodes.iter().enumerate() {
        match n {
            Node::Leaf {
                name, spec, value, ..
            } => {
                let fixed = match value {
                    Val::Text(t) if spec.radix != Radix::Text => Some(t.as_slice()),
                    _ => None,
                };
                let given = obj.get(*name);
                let mut text = given.map(|v| text_of(name, v, Some(*spec))).transpose()?;
                if let (Some(J::String(s)), None, true) = (given, fixed, spec.radix != Radix::Text)
                {
                    return Err(format!(
                        "{path}{name}: expected a number, found the string {s:?}"
                    ));
                }
                let next_is_axes = matches!(
                    nodes.get(i + 1..).unwrap_or(&[]).iter().find(|n| matches!(n, Node::Group { .. })),
                    Some(Node::Group { info, .. }) if info.count_field.is_none()
                );
                if name.ends_with("pattern") && next_is_axes {
                    if text.is_none() {
                        // Default: the first N axes for N values.
                        let count = nodes
                            .get(i + 1..)
                            .unwrap_or(&[])
                            .iter()
                            .find_map(|n| match n {
                                Node::Group { name, .. } => {
                                    obj.get(*name).and_then(J::as_array).map(Vec::len)
                                }
                                _ => None,
                            })
                            .unwrap_or(0)
                            .min(8);
                        text = Some(((1u32 << count) - 1).to_string());
                    }
                    let bits = text
                        .as_deref()
                        .and_then(super::text::parse_int)
                        .unwrap_or(0);
                    pattern = Some((name, u64::try_from(bits).unwrap_or(0)));
                }
                let full = format!("{path}{name}");
                write_value_as(*spec, text.as_deref(), fixed, &full, false, out)?;
            }
            Node::Group { name, info, items } => {
                let full = format!("{path}{name}");
                let given = obj.get(*name);
                if char_group(n).is_some() {
                    let t = match given {
                        None => String::new(),
                        Some(J::String(s)) => s.clone(),
                        Some(J::Array(a)) if a.is_empty() => String::new(),
                        Some(other) => {
                            return Err(format!("{full}: expected a string, found {other}"))
                        }
                    };
                    let t = super::fields::from_latin1(&t).ok_or_else(|| {
                        format!("{full}: {t:?} has a character above U+00FF (text is one byte per character)")
                    })?;
                    check_count(&full, info, t.len(), None)?;
                    if let Some(cf) = info.count_field {
                        write_value(
                            cf,
                            Some(&(t.len() * info.per_item).to_string()),
                            None,
                            &full,
                            out,
                        )?;
                    }
                    out.extend_from_slice(&t);
                    continue;
                }
                let list: &[J] = match given {
                    None => &[],
                    Some(J::Array(a)) => a,
                    Some(other) => return Err(format!("{full}: expected an array, found {other}")),
                };
                check_count(&full, info, list.len(), pattern.take())?;
                if let Some(cf) = info.count_field {
                    write_value(
                        cf,
                        Some(&(list.len() * info.per_item).to_string()),
                        None,
                        &full,
                        out,
                    )?;
                }
                let Some(sample) = items.first() else {
                    if !list.is_empty() {
                        return Err(format!("{full}: no sample item to encode from"));
                    }
                    continue;
                };
                let scalar = super::fields::is_scalar_group(items, name);
                for (k, item) in list.iter().enumerate() {
                    let p = format!("{full}[{k}].");
                    match (scalar, item) {
                        (true, v) if !v.is_object() => {
                            let mut one = serde_json::Map::new();
                            one.insert(name.to_string(), v.clone());
                            write_json_level(sample, &one, "", out).map_err(|e| {
                                e.replacen(&format!("{name}: "), &format!("{full}[{k}]: "), 1)
                            })?;
                        }
                        (_, J::Object(o)) => write_json_level(sample, o, &p, out)?,
                        (_, other) => {
                            return Err(format!("{full}[{k}]: expected an object, found {other}"))
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

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
    let mut body = Vec::new();
    if let Some(json) = &opts.json {
        if !opts.assignments.is_empty() {
            return Err("give the fields either as field=value or as JSON, not both".into());
        }
        let obj = json
            .as_object()
            .ok_or_else(|| format!("the JSON must be an object of fields, found {json}"))?;
        write_json_level(&nodes, obj, "", &mut body)?;
        return finish_frame(opts, header, id, &body);
    }
    let mut args = Args::parse(&opts.assignments)?;
    write_level(&nodes, &[], &[], &mut args, &mut body)?;
    let unknown: Vec<&String> = args
        .values
        .keys()
        .filter(|k| !args.used.contains_key(*k))
        .collect();
    if !unknown.is_empty() {
        let mut known = Vec::new();
        leaf_names(&nodes, "", &mut known);
        return Err(format!(
            "{id:03X}H has no field {}; its fields: {}",
            unknown
                .iter()
                .map(|s| s.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            known
                .iter()
                .map(|(g, n)| if g.is_empty() || g == n {
                    n.clone()
                } else {
                    format!("{g}.{n}")
                })
                .collect::<Vec<_>>()
                .join(" ")
        ));
    }
    finish_frame(opts, header, id, &body)
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
    let mut digits = Vec::new();
    match &opts.json {
        Some(json) => {
            let obj = json
                .as_object()
                .ok_or_else(|| format!("the JSON must be an object of fields, found {json}"))?;
            write_json_level(&nodes, obj, "", &mut digits)?;
        }
        None => {
            let mut args = Args::parse(&opts.assignments)?;
            write_level(&nodes, &[], &[], &mut args, &mut digits)?;
            if let Some(k) = args.values.keys().find(|k| !args.used.contains_key(*k)) {
                return Err(format!(
                    "an error response has no field {k}; its field: error_code"
                ));
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
        help_level(&nodes, 0, &mut out);
    }
    out
}

fn help_level(nodes: &[Node], depth: usize, out: &mut Vec<String>) {
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
                let note = if fixed { ", fixed" } else { "" };
                out.push(format!("{pad}{name} ({}{unit}{note})", describe(*spec)));
            }
            Node::Group { name, info, items } => {
                out.push(format!("{pad}{name}: repeated, up to {} item(s)", info.max));
                if let Some(first) = items.first() {
                    help_level(first, depth + 1, out);
                }
            }
        }
    }
}
