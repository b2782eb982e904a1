//! The fields as JSON (the form `iai inspect --json` prints under
//! `fields`) written into a body along the layout.

use iai_protocol_b::field::{FieldSpec, Radix};

use super::args::{
    char_group, check_count, code_list, code_value, write_value, write_value_as, Rules,
};
use crate::fields::{Node, Val};

/// Writes one level of the layout from a JSON object in the form that
/// `iai inspect --json` prints under `fields`.
/// Fields that must be given and are not go to `missing` (the body is
/// written with 0 in their place; the caller refuses it).
pub(crate) fn write_json_level(
    nodes: &[Node],
    obj: &serde_json::Map<String, serde_json::Value>,
    path: &str,
    rules: Rules,
    missing: &mut Vec<String>,
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
                let codes = rules.codes(name);
                if let (Some(J::String(s)), None, true) = (given, fixed, spec.radix != Radix::Text)
                {
                    if code_value(codes, s).is_none() {
                        let names = if codes.is_empty() {
                            String::new()
                        } else {
                            format!(" or one of its names ({})", code_list(codes))
                        };
                        return Err(format!(
                            "{path}{name}: expected a number{names}, found the string {s:?}"
                        ));
                    }
                }
                let next_is_axes = matches!(
                    nodes.get(i + 1..).unwrap_or(&[]).iter().find(|n| matches!(n, Node::Group { .. })),
                    Some(Node::Group { info, .. }) if info.count_field.is_none()
                );
                let pattern_defaulted = name.ends_with("pattern") && next_is_axes && text.is_none();
                if text.is_none() && fixed.is_none() && !pattern_defaulted && !rules.optional(name)
                {
                    missing.push(format!("{path}{name}"));
                }
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
                        if count == 0 {
                            missing.push(format!(
                                "{path}{} (one value per axis; {name} follows from their number)",
                                nodes
                                    .get(i + 1..)
                                    .unwrap_or(&[])
                                    .iter()
                                    .find_map(|n| match n {
                                        Node::Group { name, .. } => Some(*name),
                                        _ => None,
                                    })
                                    .unwrap_or("the axis values")
                            ));
                        }
                        text = Some(((1u32 << count) - 1).to_string());
                    }
                    let bits = text
                        .as_deref()
                        .and_then(crate::text::parse_int)
                        .unwrap_or(0);
                    pattern = Some((name, u64::try_from(bits).unwrap_or(0)));
                }
                let full = format!("{path}{name}");
                write_value_as(*spec, text.as_deref(), fixed, &full, false, codes, out)?;
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
                    let t = crate::fields::from_latin1(&t).ok_or_else(|| {
                        format!("{full}: {t:?} has a character above U+00FF (text is one byte per character)")
                    })?;
                    check_count(&full, info, t.len(), None)?;
                    if let Some(cf) = info.count_field {
                        write_value(
                            cf,
                            Some(&(t.len() * info.per_item).to_string()),
                            None,
                            &full,
                            &[],
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
                        &[],
                        out,
                    )?;
                }
                let Some(sample) = items.first() else {
                    if !list.is_empty() {
                        return Err(format!("{full}: no sample item to encode from"));
                    }
                    continue;
                };
                let scalar = crate::fields::is_scalar_group(items, name);
                for (k, item) in list.iter().enumerate() {
                    let p = format!("{full}[{k}].");
                    match (scalar, item) {
                        (true, v) if !v.is_object() => {
                            let mut one = serde_json::Map::new();
                            one.insert(name.to_string(), v.clone());
                            write_json_level(sample, &one, "", rules, missing, out).map_err(
                                |e| e.replacen(&format!("{name}: "), &format!("{full}[{k}]: "), 1),
                            )?;
                        }
                        (_, J::Object(o)) => write_json_level(sample, o, &p, rules, missing, out)?,
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
