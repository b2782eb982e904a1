//! Shared by the catalogue tests: `spec/messages.toml` as a tree, a frame
//! generator driven by it, and a visitor that records what the Rust types
//! report about a decoded frame.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use iai_protocol_b::checksum::{BypassPolicy, Checksum};
use iai_protocol_b::field::{FieldSpec, Radix};
use iai_protocol_b::frame::Frame;
use iai_protocol_b::message::{GroupInfo, Value, Visitor};
use serde::Deserialize;

#[derive(Debug, Deserialize)]
pub struct Catalogue {
    pub message: Vec<Msg>,
}

#[derive(Debug, Clone, Deserialize)]
pub struct Msg {
    pub id: String,
    pub name: String,
    pub status: String,
    pub layout_source: String,
    pub has_normal_response: Option<bool>,
    pub command_frame_max: Option<usize>,
    pub response_frame_max: Option<usize>,
    #[serde(default)]
    pub command: Vec<Field>,
    #[serde(default)]
    pub response: Vec<Field>,
    #[serde(default)]
    pub group: Vec<Group>,
}

#[derive(Debug, Clone, Deserialize)]
pub struct Field {
    pub name: String,
    pub width: usize,
    pub radix: String,
    pub signed: bool,
    #[serde(default)]
    pub unit: String,
    pub fixed: Option<String>,
    pub group: Option<String>,
    pub source: Option<String>,
    /// `"FIELD == N"`: must be 0 when that earlier field holds N.
    pub zero_when: Option<String>,
    /// `"FIELD == N"`: must be 0 unless that earlier field holds N.
    pub zero_unless: Option<String>,
}

impl Field {
    /// Whether an earlier field (in `scope`) forces this one to 0.
    pub fn forced_zero(&self, scope: &[(String, u64)]) -> bool {
        let holds = |rule: &str| {
            let (name, n) = rule.split_once("==").expect("FIELD == N");
            let n: u64 = n.trim().parse().expect("a number");
            scope
                .iter()
                .rev()
                .find(|(f, _)| f == name.trim())
                .is_some_and(|(_, v)| *v == n)
        };
        self.zero_when.as_deref().is_some_and(holds)
            || self.zero_unless.as_deref().is_some_and(|r| !holds(r))
    }
}

#[derive(Debug, Clone, Deserialize)]
pub struct Group {
    pub name: String,
    pub part: String,
    pub parent: String,
    pub count_rule: String,
    pub max: Option<usize>,
}

pub fn catalogue() -> Catalogue {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/spec/messages.toml"))
        .expect("spec/messages.toml");
    toml::from_str(&text).expect("valid catalogue")
}

impl Msg {
    pub fn code(&self) -> u16 {
        u16::from_str_radix(&self.id, 16).unwrap()
    }
    pub fn fields(&self, part: Part) -> &[Field] {
        match part {
            Part::Command => &self.command,
            Part::Response => &self.response,
        }
    }
    pub fn frame_max(&self, part: Part) -> Option<usize> {
        match part {
            Part::Command => self.command_frame_max,
            Part::Response => self.response_frame_max,
        }
    }
    pub fn groups(&self, part: Part) -> Vec<Group> {
        self.group
            .iter()
            .filter(|g| g.part == part.name())
            .cloned()
            .collect()
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    Command,
    Response,
}

impl Part {
    pub fn name(self) -> &'static str {
        match self {
            Part::Command => "command",
            Part::Response => "response",
        }
    }
    pub fn header(self) -> char {
        match self {
            Part::Command => '!',
            Part::Response => '#',
        }
    }
}

/// The catalogue's field list as a tree of leaves and repeat groups.
#[derive(Debug, Clone)]
pub enum Node {
    Leaf(Field),
    Group(Group, Vec<Node>),
}

pub fn tree(fields: &[Field], groups: &[Group]) -> Vec<Node> {
    fn path(g: &str, groups: &[Group]) -> Vec<String> {
        let mut p = vec![g.to_string()];
        let mut cur = g.to_string();
        loop {
            let grp = groups.iter().find(|x| x.name == cur).expect("group listed");
            if grp.parent.is_empty() {
                break;
            }
            cur = grp.parent.clone();
            p.insert(0, cur.clone());
        }
        p
    }
    // Build with an explicit stack of open groups.
    let mut root: Vec<Node> = Vec::new();
    let mut open: Vec<(Group, Vec<Node>)> = Vec::new();
    let close = |open: &mut Vec<(Group, Vec<Node>)>, root: &mut Vec<Node>| {
        let (g, kids) = open.pop().unwrap();
        match open.last_mut() {
            Some((_, parent)) => parent.push(Node::Group(g, kids)),
            None => root.push(Node::Group(g, kids)),
        }
    };
    for f in fields {
        let want = f
            .group
            .as_deref()
            .map(|g| path(g, groups))
            .unwrap_or_default();
        let common = open
            .iter()
            .zip(want.iter())
            .take_while(|((g, _), w)| &g.name == *w)
            .count();
        while open.len() > common {
            close(&mut open, &mut root);
        }
        for name in want.iter().skip(common) {
            let g = groups.iter().find(|x| &x.name == name).unwrap().clone();
            open.push((g, Vec::new()));
        }
        match open.last_mut() {
            Some((_, kids)) => kids.push(Node::Leaf(f.clone())),
            None => root.push(Node::Leaf(f.clone())),
        }
    }
    while !open.is_empty() {
        close(&mut open, &mut root);
    }
    root
}

/// One observation: a leaf field or a group boundary.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ev {
    Leaf {
        name: String,
        width: usize,
        radix: &'static str,
        signed: bool,
        value: V,
    },
    Enter {
        count: usize,
        count_width: Option<usize>,
        per_item: usize,
        units: usize,
        max: usize,
    },
    Leave,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum V {
    U(u64),
    S(i64),
    T(Vec<u8>),
}

/// Rust names that predate the full catalogue (see the declarations' docs).
pub fn catalogue_name(rust: &str) -> &str {
    match rust {
        "sensor_input_status" => "axis_sensor_input_status",
        "error_code" => "axis_error_code",
        "critical_system_error" => "critical_system_error_number",
        "latest_system_error" => "latest_system_error_number",
        "status_byte_1" => "system_status_byte_1",
        "status_byte_2" => "system_status_byte_2",
        "status_byte_3" => "system_status_byte_3",
        "status_byte_4" => "system_status_byte_4",
        "message" => "message_char",
        other => other,
    }
}

/// Records what a decoded message reports about itself.
#[derive(Default)]
pub struct Recorder {
    pub events: Vec<Ev>,
    pub units: Vec<(String, String)>,
}

fn radix_name(r: Radix) -> &'static str {
    match r {
        Radix::Hex => "hex",
        Radix::Dec => "dec",
        Radix::Text => "text",
    }
}

impl Visitor for Recorder {
    fn field(&mut self, name: &'static str, unit: &'static str, spec: FieldSpec, value: Value<'_>) {
        let name = catalogue_name(name).to_string();
        self.units.push((name.clone(), unit.to_string()));
        self.events.push(Ev::Leaf {
            name,
            width: spec.len(),
            radix: radix_name(spec.radix),
            signed: spec.signed,
            value: match value {
                Value::Unsigned(u) => V::U(u),
                Value::Signed(s) => V::S(s),
                Value::Text(t) => V::T(t.to_vec()),
            },
        });
    }
    fn enter_group(&mut self, _: &'static str, g: GroupInfo) {
        self.events.push(Ev::Enter {
            count: g.count,
            count_width: g.count_field.map(|s| s.len()),
            per_item: g.per_item,
            units: g.units,
            max: g.max,
        });
    }
    fn leave_group(&mut self) {
        self.events.push(Ev::Leave);
    }
}

/// How the generator picks values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Pseudo-random digits from the seed.
    Random(u64),
    /// Every numeric field at its minimum (signed: most negative).
    Min,
    /// Every numeric field at its maximum, every axis pattern full.
    Max,
}

pub struct Gen {
    mode: Mode,
    state: u64,
    /// Items per counted group (Min/Max modes; Random picks 0..=3).
    pub fixed_count: usize,
}

impl Gen {
    pub fn new(mode: Mode) -> Self {
        let state = match mode {
            Mode::Random(s) => s ^ 0x9E37_79B9_7F4A_7C15,
            _ => 1,
        };
        Gen {
            mode,
            state,
            fixed_count: 1,
        }
    }
    fn next(&mut self) -> u64 {
        // xorshift64*
        let mut x = self.state.max(1);
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.state = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// The count rules of a part: which field drives which group.
fn count_field_of(g: &Group, siblings: &[Node]) -> Option<String> {
    if let Some(f) = g.count_rule.strip_prefix("field:") {
        return Some(f.to_string());
    }
    if g.count_rule == "see_note" {
        // 20BH/20CH/20DH: the number of ports/flags, just before the group.
        return siblings.iter().rev().find_map(|n| match n {
            Node::Leaf(f) if f.name.starts_with("number_of_response") => Some(f.name.clone()),
            _ => None,
        });
    }
    None
}

fn digits_value(f: &Field, text: &str) -> V {
    match f.radix.as_str() {
        "text" => V::T(text.as_bytes().to_vec()),
        "dec" => V::U(text.parse().unwrap()),
        _ => {
            let raw = u64::from_str_radix(text, 16).unwrap();
            if f.signed && f.width < 16 {
                let shift = 64 - 4 * f.width as u32;
                V::S(((raw << shift) as i64) >> shift)
            } else if f.signed {
                V::S(raw as i64)
            } else {
                V::U(raw)
            }
        }
    }
}

fn fmt_value(f: &Field, v: u64) -> String {
    match f.radix.as_str() {
        "dec" => format!("{:0w$}", v, w = f.width),
        _ => format!("{:0w$X}", v, w = f.width),
    }
}

/// Generates the body for `nodes` and the events the Rust types must report.
pub fn generate(nodes: &[Node], gen: &mut Gen, body: &mut String, ev: &mut Vec<Ev>) {
    let mut scope: Vec<(String, u64)> = Vec::new();
    gen_seq(nodes, gen, body, ev, &mut scope, &[]);
}

fn gen_seq(
    nodes: &[Node],
    gen: &mut Gen,
    body: &mut String,
    ev: &mut Vec<Ev>,
    scope: &mut Vec<(String, u64)>,
    outer: &[Node],
) {
    // Groups of this sequence and the fields that drive them.
    let mut drives: Vec<(String, Group)> = Vec::new();
    for n in nodes {
        if let Node::Group(g, _) = n {
            if let Some(f) = count_field_of(g, nodes) {
                drives.push((f, g.clone()));
            }
            if let Some(p) = g.count_rule.strip_prefix("popcount:") {
                drives.push((p.to_string(), g.clone()));
            }
        }
    }
    let _ = outer;
    for n in nodes {
        match n {
            Node::Leaf(f) => {
                let driven = drives
                    .iter()
                    .find(|(name, _)| name == &f.name)
                    .map(|(_, g)| g.clone());
                let text = if let Some(lit) = &f.fixed {
                    lit.clone()
                } else if f.forced_zero(scope) {
                    "0".repeat(f.width)
                } else if let Some(g) = &driven {
                    let max = g.max.unwrap_or(8);
                    if g.count_rule.starts_with("popcount:") {
                        let pattern: u64 = match gen.mode {
                            Mode::Max => (1u64 << max) - 1,
                            Mode::Min => 1,
                            Mode::Random(_) => {
                                let mut p = gen.below(256);
                                while p.count_ones() as usize > max {
                                    p &= p - 1;
                                }
                                p
                            }
                        };
                        fmt_value(f, pattern)
                    } else {
                        let count = match gen.mode {
                            Mode::Random(_) => gen.below(4) as usize,
                            _ => gen.fixed_count,
                        }
                        .min(max);
                        // Ports and flags: any number, ceil(n / 8) bytes.
                        let units = if g.count_rule == "see_note" && count > 0 {
                            count * 8 - gen.below(8) as usize
                        } else if g.count_rule == "see_note" {
                            0
                        } else {
                            count
                        };
                        fmt_value(f, units as u64)
                    }
                } else {
                    match (gen.mode, f.radix.as_str()) {
                        (_, "text") => (0..f.width)
                            .map(|_| (b'G' + gen.below(20) as u8) as char)
                            .collect(),
                        (Mode::Min, _) if f.signed => format!("8{}", "0".repeat(f.width - 1)),
                        (Mode::Max, _) if f.signed => format!("7{}", "F".repeat(f.width - 1)),
                        (Mode::Min, _) => "0".repeat(f.width),
                        (Mode::Max, "dec") => "9".repeat(f.width),
                        (Mode::Max, _) => "F".repeat(f.width),
                        (Mode::Random(_), "dec") => (0..f.width)
                            .map(|_| (b'0' + gen.below(10) as u8) as char)
                            .collect(),
                        (Mode::Random(_), _) => (0..f.width)
                            .map(|_| b"0123456789ABCDEF"[gen.below(16) as usize] as char)
                            .collect(),
                    }
                };
                body.push_str(&text);
                let value = digits_value(f, &text);
                if let V::U(u) = value {
                    scope.push((f.name.clone(), u));
                }
                let is_count = driven
                    .as_ref()
                    .is_some_and(|g| !g.count_rule.starts_with("popcount:"));
                if !is_count {
                    ev.push(Ev::Leaf {
                        name: f.name.clone(),
                        width: f.width,
                        radix: match f.radix.as_str() {
                            "hex" => "hex",
                            "dec" => "dec",
                            _ => "text",
                        },
                        signed: f.signed,
                        value: if f.fixed.is_some() {
                            V::T(text.as_bytes().to_vec())
                        } else {
                            value
                        },
                    });
                }
            }
            Node::Group(g, kids) => {
                let lookup = |name: &str, scope: &Vec<(String, u64)>| {
                    scope
                        .iter()
                        .rev()
                        .find(|(n, _)| n == name)
                        .map(|(_, v)| *v)
                        .unwrap()
                };
                let (count, count_width, per_item) =
                    if let Some(p) = g.count_rule.strip_prefix("popcount:") {
                        (lookup(p, scope).count_ones() as usize, None, 1)
                    } else if let Some(n) = g.count_rule.strip_prefix("fixed:") {
                        (n.parse().unwrap(), None, 1)
                    } else {
                        let f = count_field_of(g, nodes).unwrap();
                        let width = nodes
                            .iter()
                            .find_map(|n| match n {
                                Node::Leaf(x) if x.name == f => Some(x.width),
                                _ => None,
                            })
                            .unwrap();
                        let per = if g.count_rule == "see_note" { 8 } else { 1 };
                        (
                            lookup(&f, scope).div_ceil(per) as usize,
                            Some(width),
                            per as usize,
                        )
                    };
                let units = match count_width {
                    Some(_) if per_item > 1 => lookup(&count_field_of(g, nodes).unwrap(), scope),
                    _ => count as u64,
                } as usize;
                ev.push(Ev::Enter {
                    count,
                    count_width,
                    per_item,
                    units,
                    max: g.max.unwrap_or(8),
                });
                for _ in 0..count {
                    let mark = scope.len();
                    gen_seq(kids, gen, body, ev, scope, nodes);
                    scope.truncate(mark);
                }
                ev.push(Ev::Leave);
            }
        }
    }
}

/// A whole frame with the checksum computed here from the ASCII.
pub fn frame_text(header: char, id: &str, body: &str) -> Vec<u8> {
    let head = format!("{header}99{id}{body}");
    let sc = Checksum::of(head.as_bytes());
    format!("{head}{sc:02X}\r\n").into_bytes()
}

pub fn check(bytes: &[u8]) -> Frame<'_> {
    Frame::new_checked(bytes, BypassPolicy::default()).expect("well-formed frame")
}

/// Longest frame the reported layout allows: envelope + leaves + every
/// group at its maximum (items assumed alike, as generated in Max mode).
pub fn max_len(events: &[Ev]) -> usize {
    fn seq(ev: &[Ev], i: &mut usize) -> usize {
        let mut total = 0;
        while *i < ev.len() {
            match &ev[*i] {
                Ev::Leaf { width, .. } => {
                    total += width;
                    *i += 1;
                }
                Ev::Enter {
                    count,
                    count_width,
                    max,
                    ..
                } => {
                    *i += 1;
                    let inner = seq(ev, i);
                    *i += 1; // Leave
                    let per_item = if *count == 0 { 0 } else { inner / count };
                    total += count_width.unwrap_or(0) + max * per_item;
                }
                Ev::Leave => return total,
            }
        }
        total
    }
    let mut i = 0;
    10 + seq(events, &mut i)
}
