//! The decoded fields of one message as a tree (leaves and repeat groups),
//! built from the core's field visitor, and how the tree is shown.

use iai_protocol_b::field::{FieldSpec, Radix};
use iai_protocol_b::message::{Fields, GroupInfo, Value, Visitor};

use super::text::{escape, json_str};

/// A value as the tree keeps it (owned).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Val {
    /// Unsigned number.
    Unsigned(u64),
    /// Signed number.
    Signed(i64),
    /// Raw characters.
    Text(Vec<u8>),
}

/// One node of the field tree.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Node {
    /// A leaf field.
    Leaf {
        /// Field name.
        name: &'static str,
        /// Unit (`""` if none).
        unit: &'static str,
        /// Wire format.
        spec: FieldSpec,
        /// Decoded value.
        value: Val,
    },
    /// A repeat group: its items, each a list of nodes.
    Group {
        /// Group name.
        name: &'static str,
        /// Wire facts of the group.
        info: GroupInfo,
        /// The items.
        items: Vec<Vec<Node>>,
    },
}

impl Node {
    /// The node's name.
    pub fn name(&self) -> &'static str {
        match self {
            Node::Leaf { name, .. } | Node::Group { name, .. } => name,
        }
    }
}

struct Open {
    name: &'static str,
    info: GroupInfo,
    items: Vec<Vec<Node>>,
    first: Option<&'static str>,
}

/// Builds the tree from visitor calls.
#[derive(Default)]
struct Builder {
    top: Vec<Node>,
    open: Vec<Open>,
}

impl Builder {
    fn add(&mut self, node: Node) {
        let Some(g) = self.open.last_mut() else {
            self.top.push(node);
            return;
        };
        // A new item starts whenever the item's first field comes again.
        let name = node.name();
        match g.first {
            None => {
                g.first = Some(name);
                g.items.push(Vec::new());
            }
            Some(f) if f == name => g.items.push(Vec::new()),
            Some(_) => {}
        }
        if let Some(item) = g.items.last_mut() {
            item.push(node);
        }
    }
}

impl Visitor for Builder {
    fn field(&mut self, name: &'static str, unit: &'static str, spec: FieldSpec, value: Value<'_>) {
        let value = match value {
            Value::Unsigned(v) => Val::Unsigned(v),
            Value::Signed(v) => Val::Signed(v),
            Value::Text(t) => Val::Text(t.to_vec()),
        };
        self.add(Node::Leaf {
            name,
            unit,
            spec,
            value,
        });
    }
    fn enter_group(&mut self, name: &'static str, info: GroupInfo) {
        self.open.push(Open {
            name,
            info,
            items: Vec::new(),
            first: None,
        });
    }
    fn leave_group(&mut self) {
        if let Some(g) = self.open.pop() {
            self.add(Node::Group {
                name: g.name,
                info: g.info,
                items: g.items,
            });
        }
    }
}

/// The field tree of a decoded message.
pub fn tree(msg: &dyn Fields) -> Vec<Node> {
    let mut b = Builder::default();
    msg.fields(&mut b);
    while !b.open.is_empty() {
        b.leave_group();
    }
    b.top
}

/// Whether every item of a group is one leaf named like the group (a run
/// of plain values such as per-axis coordinates).
pub fn is_scalar_group(items: &[Vec<Node>], name: &str) -> bool {
    items
        .iter()
        .all(|i| matches!(i.as_slice(), [Node::Leaf { name: n, .. }] if *n == name))
}

/// The characters of a group of one-character text items (a counted text
/// such as 216H's message), joined; `None` for any other group.
pub fn joined_text(items: &[Vec<Node>], name: &str) -> Option<Vec<u8>> {
    // An empty group shows as an empty list, whatever its items would be.
    if items.is_empty() || !is_scalar_group(items, name) {
        return None;
    }
    let mut out = Vec::new();
    for item in items {
        match item.first() {
            Some(Node::Leaf {
                spec,
                value: Val::Text(t),
                ..
            }) if spec.radix == Radix::Text && spec.width == 1 => out.extend_from_slice(t),
            _ => return None,
        }
    }
    Some(out)
}

/// A value as the listing shows it: hex fields as `0x…` and decimal,
/// signed and decimal fields in decimal, text quoted.
pub fn show_value(spec: FieldSpec, v: &Val) -> String {
    match v {
        Val::Unsigned(n) if spec.radix == Radix::Hex => {
            format!("0x{n:0w$X} ({n})", w = usize::from(spec.width))
        }
        Val::Unsigned(n) => n.to_string(),
        Val::Signed(n) => n.to_string(),
        Val::Text(t) => format!("\"{}\"", escape(t)),
    }
}

/// `sep` + `unit`, or nothing for a field without a unit.
pub fn unit_suffix(sep: &str, unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!("{sep}{unit}")
    }
}

/// What a leaf means beside its raw value (name, unit, value), if known.
pub type Explain<'a> = &'a dyn Fn(&str, &str, &Val) -> Option<String>;

/// ` -> meaning`, or nothing.
fn meaning_suffix(explain: Explain<'_>, name: &str, unit: &str, value: &Val) -> String {
    explain(name, unit, value).map_or_else(String::new, |m| format!(" -> {m}"))
}

/// The listing lines of a tree, each indented by `indent`; `explain` adds
/// what a value means after it.
pub fn text_lines(
    nodes: &[Node],
    prefix: &str,
    indent: &str,
    out: &mut Vec<String>,
    explain: Explain<'_>,
) {
    for node in nodes {
        match node {
            Node::Leaf {
                name,
                unit,
                spec,
                value,
            } => {
                out.push(format!(
                    "{indent}{prefix}{name} = {}{}{}",
                    show_value(*spec, value),
                    unit_suffix(" ", unit),
                    meaning_suffix(explain, name, unit, value)
                ));
            }
            Node::Group { name, items, .. } if joined_text(items, name).is_some() => {
                let text = joined_text(items, name).unwrap_or_default();
                out.push(format!("{indent}{prefix}{name} = \"{}\"", escape(&text)));
            }
            Node::Group { name, items, .. } => {
                out.push(format!("{indent}{prefix}{name}: {} item(s)", items.len()));
                for (i, item) in items.iter().enumerate() {
                    let p = format!("{prefix}{name}[{i}].");
                    if let [Node::Leaf {
                        unit, spec, value, ..
                    }] = item.as_slice()
                    {
                        if is_scalar_group(items, name) {
                            out.push(format!(
                                "{indent}  {prefix}{name}[{i}] = {}{}{}",
                                show_value(*spec, value),
                                unit_suffix(" ", unit),
                                meaning_suffix(explain, name, unit, value)
                            ));
                            continue;
                        }
                    }
                    text_lines(item, &p, &format!("{indent}  "), out, explain);
                }
            }
        }
    }
}

/// The meanings of a tree's leaves, by path (`name`, `group[i].name`,
/// `group[i]` for a group of plain values), for JSON.
pub fn meanings(
    nodes: &[Node],
    prefix: &str,
    explain: Explain<'_>,
    out: &mut Vec<(String, String)>,
) {
    for node in nodes {
        match node {
            Node::Leaf {
                name, unit, value, ..
            } => {
                if let Some(m) = explain(name, unit, value) {
                    out.push((format!("{prefix}{name}"), m));
                }
            }
            Node::Group { name, items, .. } if joined_text(items, name).is_some() => {}
            Node::Group { name, items, .. } => {
                let scalar = is_scalar_group(items, name);
                for (i, item) in items.iter().enumerate() {
                    match item.as_slice() {
                        [Node::Leaf { unit, value, .. }] if scalar => {
                            if let Some(m) = explain(name, unit, value) {
                                out.push((format!("{prefix}{name}[{i}]"), m));
                            }
                        }
                        _ => meanings(item, &format!("{prefix}{name}[{i}]."), explain, out),
                    }
                }
            }
        }
    }
}

/// A JSON object of `(path, meaning)` pairs.
pub fn json_meanings(pairs: &[(String, String)]) -> String {
    let parts: Vec<String> = pairs
        .iter()
        .map(|(k, v)| format!("{}:{}", json_str(k), json_str(v)))
        .collect();
    format!("{{{}}}", parts.join(","))
}

/// Raw text bytes as a string, one character per byte (Latin-1), so that
/// 8-bit text survives a trip through JSON.
pub fn latin1(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

/// The inverse of [`latin1`]; `None` for a character above U+00FF.
pub fn from_latin1(s: &str) -> Option<Vec<u8>> {
    s.chars().map(|c| u8::try_from(u32::from(c)).ok()).collect()
}

/// A JSON value: numbers as integers, text as strings (one character per
/// byte).
pub fn json_value(v: &Val) -> String {
    match v {
        Val::Unsigned(n) => n.to_string(),
        Val::Signed(n) => n.to_string(),
        Val::Text(t) => json_str(&latin1(t)),
    }
}

/// A JSON object of a list of nodes: leaves by name, groups as arrays
/// (of values for groups of one scalar, of objects otherwise).
pub fn json_object(nodes: &[Node]) -> String {
    let parts: Vec<String> = nodes
        .iter()
        .map(|node| match node {
            Node::Leaf { name, value, .. } => format!("{}:{}", json_str(name), json_value(value)),
            Node::Group { name, items, .. } if joined_text(items, name).is_some() => {
                let text = joined_text(items, name).unwrap_or_default();
                format!("{}:{}", json_str(name), json_str(&latin1(&text)))
            }
            Node::Group { name, items, .. } => {
                let elems: Vec<String> = if is_scalar_group(items, name) {
                    items
                        .iter()
                        .filter_map(|i| match i.first() {
                            Some(Node::Leaf { value, .. }) => Some(json_value(value)),
                            _ => None,
                        })
                        .collect()
                } else {
                    items.iter().map(|i| json_object(i)).collect()
                };
                format!("{}:[{}]", json_str(name), elems.join(","))
            }
        })
        .collect();
    format!("{{{}}}", parts.join(","))
}

/// The field tree of one position record as `layout` puts it on the wire.
pub fn record_tree(
    layout: iai_protocol_b::position::RecordLayout,
    rec: &iai_protocol_b::position::PositionRecord,
) -> Vec<Node> {
    use iai_protocol_b::message::Inspect;
    let mut b = Builder::default();
    layout.inspect(rec, "record", "", &mut b);
    b.top
}
