//! `field=value` arguments written into a body along the layout.

use std::collections::BTreeMap;

use iai_protocol_b::field::{encode_signed, encode_unsigned, FieldSpec, Radix};
use iai_protocol_b::frame::Header;
use iai_protocol_b::message::GroupInfo;

use crate::fields::{Node, Val};
use crate::meaning::{self, Code};

/// The message a body is written for: which fields take names and which
/// may be left out.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rules {
    pub(crate) id: u16,
    pub(crate) header: Header,
}

impl Rules {
    /// The names field `name` accepts for its codes.
    pub(crate) fn codes(&self, name: &str) -> &'static [Code] {
        meaning::codes(self.id, self.header, name)
    }

    /// Whether `name` may be left out (it has a documented meaning for 0).
    pub(crate) fn optional(&self, name: &str) -> bool {
        meaning::default_meaning(self.id, name).is_some()
    }
}

/// User values by field name, each split into items.
pub(crate) struct Args {
    pub(crate) values: BTreeMap<String, String>,
    pub(crate) used: BTreeMap<String, bool>,
    pub(crate) rules: Rules,
    /// Fields that must be given and were not, as the user would name them.
    pub(crate) missing: Vec<String>,
}

impl Args {
    /// `field=value` arguments; a field given twice is an error.
    pub(crate) fn parse(assignments: &[String], rules: Rules) -> Result<Self, String> {
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
            rules,
            missing: Vec::new(),
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
pub(crate) fn item_value(raw: &str, index: &[usize]) -> Option<String> {
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

pub(crate) fn item_count(raw: &str, outer: &[usize]) -> usize {
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
pub(crate) fn leaf_names(nodes: &[Node], group: &str, out: &mut Vec<(String, String)>) {
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

pub(crate) fn write_value(
    spec: FieldSpec,
    text: Option<&str>,
    fixed: Option<&[u8]>,
    name: &str,
    codes: &[Code],
    out: &mut Vec<u8>,
) -> Result<(), String> {
    write_value_as(spec, text, fixed, name, true, codes, out)
}

/// The value of `name` among `codes` (case, `_` and `-` alike).
pub(crate) fn code_value(codes: &[Code], name: &str) -> Option<u64> {
    let norm = |s: &str| s.to_ascii_lowercase().replace('_', "-");
    codes
        .iter()
        .find(|(n, _, _)| norm(n) == norm(name))
        .map(|(_, v, _)| *v)
}

/// "off=0, on=1".
pub(crate) fn code_list(codes: &[Code]) -> String {
    codes
        .iter()
        .map(|(n, v, _)| format!("{n}={v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

pub(crate) fn write_value_as(
    spec: FieldSpec,
    text: Option<&str>,
    fixed: Option<&[u8]>,
    name: &str,
    escaped: bool,
    codes: &[Code],
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
            crate::text::unescape(raw.as_bytes())
        } else {
            crate::fields::from_latin1(raw).ok_or_else(|| {
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
        Some(t) => match crate::text::parse_int(t).or_else(|| code_value(codes, t).map(i128::from)) {
            Some(v) => v,
            None if !codes.is_empty() => {
                return Err(format!(
                    "{name}: {t:?} is neither a name of this field ({}) nor a number (decimal or 0x hex; {} {})",
                    code_list(codes),
                    describe(spec),
                    range_of(spec)
                ))
            }
            None => {
                return Err(format!(
                    "{name}: {t:?} is not a number (decimal or 0x hex, one optional '-'; {} {})",
                    describe(spec),
                    range_of(spec)
                ))
            }
        },
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
pub(crate) fn char_group(n: &Node) -> Option<(&'static str, FieldSpec)> {
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
pub(crate) fn write_level(
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
            counts.push(crate::text::unescape(text.as_bytes()).len());
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
                let defaulted = !given && name.ends_with("pattern") && next_is_axes;
                if defaulted {
                    let n = counts.get(group_no).copied().unwrap_or(0).min(8);
                    text = Some(((1u32 << n) - 1).to_string());
                    if n == 0 {
                        // No values, no pattern: the axes are not given.
                        let group =
                            nodes
                                .get(i + 1..)
                                .unwrap_or(&[])
                                .iter()
                                .find_map(|n| match n {
                                    Node::Group { name, .. } => Some(*name),
                                    _ => None,
                                });
                        args.missing.push(format!(
                            "{} (one value per axis; {name} follows from their number)",
                            group.unwrap_or("the axis values")
                        ));
                    }
                } else if !given && fixed.is_none() && !args.rules.optional(name) {
                    args.missing.push(match (path.last(), index) {
                        (Some(g), [.., k]) => format!("{name} of {g}[{k}]"),
                        _ => name.to_string(),
                    });
                }
                if given && name.ends_with("pattern") && next_is_axes {
                    let bits = text
                        .as_deref()
                        .and_then(crate::text::parse_int)
                        .unwrap_or(0);
                    pattern = Some((name, u64::try_from(bits).unwrap_or(0)));
                }
                let codes = args.rules.codes(name);
                write_value(*spec, text.as_deref(), fixed, name, codes, out)?;
            }
            Node::Group { name, info, items } => {
                let count = counts.get(group_no).copied().unwrap_or(0);
                group_no += 1;
                check_count(name, info, count, pattern.take())?;
                if let Some(cf) = info.count_field {
                    let units = (count * info.per_item).to_string();
                    write_value(cf, Some(&units), None, name, &[], out)?;
                }
                if char_group(n).is_some() {
                    let text = args.get(path, name).unwrap_or_default();
                    out.extend_from_slice(&crate::text::unescape(text.as_bytes()));
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
pub(crate) fn check_count(
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
