//! The settings table: every setting of the configuration page, declared
//! once ([`TABLE`]): its key, its kind and range (the blocks' own range
//! constants), its help line, and the block field it reads and writes.
//! `iai bridge config get/set/apply/block`, the web page's form and the
//! page the gateway writes all come from it.
//!
//! Values are text both ways ([`parse`], [`format`]): numbers in decimal,
//! stations in two hex digits, message IDs in three (`212,215-217,26D`),
//! choices as words, addresses dotted (`10.0.2.15/24`).
//!
//! [`Settings`] is the page's blocks decoded (each at its defaults when
//! blank or invalid); a change marks its block, and only marked blocks are
//! written back ([`Settings::overlay`]): a block this firmware does not
//! know, or did not change, keeps its bytes. A block is added with a field
//! in [`Settings`], a line in [`Settings::from_page`] and
//! [`Settings::overlay`], and its entries in [`TABLE`].

use iai_protocol_b::frame::Station;

use super::access::{Reads, WebConfig, WEB_LEN};
use super::page::{BRIDGE_AT, NET_AT, WEB_AT};
use super::store::{PageStore, StoreError};
use super::{
    AllowList, Config, Parity, Policy, UpstreamProtocol, AXES, BAUD_RATES, BLOCK_LEN,
    DUPLICATE_WINDOWS_MS, POLL_PERIODS_MS, UNITS, XOFF_HOLDS_MS,
};
use crate::net::config::{Addressing, NetConfig, BLOCK_LEN as NET_LEN, PREFIXES};
use crate::serial::FlowControl;
use crate::text::{self, Sink};

/// The blocks settings live in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Block {
    /// The bridge's block ([`Config`]).
    Bridge,
    /// The network block ([`NetConfig`]).
    Net,
    /// The web block ([`WebConfig`]).
    Web,
    /// The password's verifier (written by the gateway only).
    Access,
}

impl Block {
    const fn bit(self) -> u8 {
        match self {
            Block::Bridge => 1,
            Block::Net => 2,
            Block::Web => 4,
            Block::Access => 8,
        }
    }
}

/// What a setting's value is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A decimal number in `min..=max`.
    Int {
        /// Least.
        min: u32,
        /// Most.
        max: u32,
    },
    /// One of these words (the value is its index).
    Choice(&'static [&'static str]),
    /// One of [`BAUD_RATES`].
    Baud,
    /// A station, two hex digits.
    Station,
    /// `on` or `off`.
    Bool,
    /// Message IDs 200H..2FFH, three hex digits each, `,` between them,
    /// `-` for a range; `none` for none.
    Ids,
    /// An IPv4 address and its prefix length (`a.b.c.d/p`).
    Cidr,
    /// An IPv4 address, or `none`.
    Gateway,
    /// The password: set only (read, it says whether one is set).
    Password,
}

/// A setting's value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Value {
    /// A number, a choice's index, a baud rate, a station, a flag (0, 1).
    Int(u32),
    /// Message IDs.
    Ids(AllowList),
    /// An address and its prefix length.
    Cidr([u8; 4], u8),
    /// An address or none.
    Ip(Option<[u8; 4]>),
    /// Whether a password is set.
    PasswordSet(bool),
}

/// One setting.
#[derive(Debug)]
pub struct Setting {
    /// `block.name`: what `iai bridge config set` and the form call it.
    pub key: &'static str,
    /// What its value is, and its range.
    pub kind: Kind,
    /// The block it lives in.
    pub block: Block,
    /// What it does, in a few words.
    pub help: &'static str,
    /// Its value in `Settings`.
    pub get: fn(&Settings) -> Value,
    /// Sets it (the value is of its kind and in range).
    pub set: fn(&mut Settings, Value),
}

/// Why a setting was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SetError {
    /// The setting (`None`: no setting has that key).
    pub key: Option<&'static str>,
    /// Why, in a few words.
    pub reason: &'static str,
}

/// The page's blocks, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Settings {
    /// The bridge's block.
    pub bridge: Config,
    /// The allow-list (kept apart from the policy, so that the order in
    /// which the two are set does not matter; stored only with the
    /// allow-list policy).
    pub allow: AllowList,
    /// The network block.
    pub net: NetConfig,
    /// The web block.
    pub web: WebConfig,
    /// Whether a password is set.
    pub password_set: bool,
    /// The blocks changed ([`Block`] bits).
    changed: u8,
}

const FLOWS: &[&str] = &["none", "xonxoff", "rtscts"];
const POLICIES: &[&str] = &["forward-all", "read-only", "allow-list"];
const UPSTREAMS: &[&str] = &["protocol-b", "modbus-rtu"];
const PARITIES: &[&str] = &["none", "even", "odd"];
const ADDRESSINGS: &[&str] = &["dhcp", "static"];
const READS: &[&str] = &["open", "password"];

const fn int(min: u32, max: u32) -> Kind {
    Kind::Int { min, max }
}

fn n(v: Value) -> u32 {
    match v {
        Value::Int(n) => n,
        _ => 0,
    }
}

fn b(n: u32) -> u8 {
    u8::try_from(n).unwrap_or(u8::MAX)
}

fn w(n: u32) -> u16 {
    u16::try_from(n).unwrap_or(u16::MAX)
}

/// Every setting, in the order `iai bridge config get` and the form show
/// them.
pub static TABLE: [Setting; 23] = [
    Setting {
        key: "bridge.station",
        kind: Kind::Station,
        block: Block::Bridge,
        help: "the bridge's own station (status, configuration)",
        get: |s| Value::Int(s.bridge.bridge_station.0.into()),
        set: |s, v| s.bridge.bridge_station = Station(b(n(v))),
    },
    Setting {
        key: "bridge.controller_station",
        kind: Kind::Station,
        block: Block::Bridge,
        help: "the controller's station (its I/O parameter No. 91)",
        get: |s| Value::Int(s.bridge.controller_station.0.into()),
        set: |s, v| s.bridge.controller_station = Station(b(n(v))),
    },
    Setting {
        key: "bridge.host_baud",
        kind: Kind::Baud,
        block: Block::Bridge,
        help: "the host port's baud rate",
        get: |s| Value::Int(s.bridge.upstream_baud),
        set: |s, v| s.bridge.upstream_baud = n(v),
    },
    Setting {
        key: "bridge.controller_baud",
        kind: Kind::Baud,
        block: Block::Bridge,
        help: "the controller port's baud rate (the controller's I/O parameter No. 90)",
        get: |s| Value::Int(s.bridge.downstream_baud),
        set: |s, v| s.bridge.downstream_baud = n(v),
    },
    Setting {
        key: "bridge.flow",
        kind: Kind::Choice(FLOWS),
        block: Block::Bridge,
        help: "the host port's flow control",
        get: |s| Value::Int(s.bridge.flow.code().into()),
        set: |s, v| s.bridge.flow = FlowControl::from_code(b(n(v))).unwrap_or(FlowControl::None),
    },
    Setting {
        key: "bridge.policy",
        kind: Kind::Choice(POLICIES),
        block: Block::Bridge,
        help: "which commands reach the controller",
        get: |s| Value::Int(s.bridge.policy.code().into()),
        set: |s, v| {
            s.bridge.policy = match n(v) {
                0 => Policy::ForwardAll,
                1 => Policy::ReadOnly,
                _ => Policy::Allow(s.allow),
            }
        },
    },
    Setting {
        key: "bridge.allow",
        kind: Kind::Ids,
        block: Block::Bridge,
        help: "the IDs the allow-list policy forwards",
        get: |s| Value::Ids(s.allow),
        set: |s, v| {
            if let Value::Ids(list) = v {
                s.allow = list;
                if let Policy::Allow(_) = s.bridge.policy {
                    s.bridge.policy = Policy::Allow(list);
                }
            }
        },
    },
    Setting {
        key: "bridge.upstream",
        kind: Kind::Choice(UPSTREAMS),
        block: Block::Bridge,
        help: "what a two-UART board's host port speaks",
        get: |s| Value::Int(u32::from(s.bridge.upstream == UpstreamProtocol::ModbusRtu)),
        set: |s, v| {
            s.bridge.upstream = if n(v) == 1 {
                UpstreamProtocol::ModbusRtu
            } else {
                UpstreamProtocol::ProtocolB
            }
        },
    },
    Setting {
        key: "bridge.duplicate_window_ms",
        kind: int(*DUPLICATE_WINDOWS_MS.start(), *DUPLICATE_WINDOWS_MS.end()),
        block: Block::Bridge,
        help: "how long after a reply a copy of it may arrive on the controller line, ms",
        get: |s| Value::Int(s.bridge.duplicate_window_ms),
        set: |s, v| s.bridge.duplicate_window_ms = n(v),
    },
    Setting {
        key: "bridge.xoff_hold_ms",
        kind: int(*XOFF_HOLDS_MS.start(), *XOFF_HOLDS_MS.end()),
        block: Block::Bridge,
        help: "the longest an XOFF from the host holds the bridge's transmitter, ms",
        get: |s| Value::Int(s.bridge.xoff_hold_ms),
        set: |s, v| s.bridge.xoff_hold_ms = n(v),
    },
    Setting {
        key: "bridge.quit_sequence",
        kind: Kind::Bool,
        block: Block::Bridge,
        help: "end the run on ESC Q ! from the host (QEMU test runs only)",
        get: |s| Value::Int(s.bridge.quit_sequence.into()),
        set: |s, v| s.bridge.quit_sequence = n(v) != 0,
    },
    Setting {
        key: "modbus.unit",
        kind: int(*UNITS.start() as u32, *UNITS.end() as u32),
        block: Block::Bridge,
        help: "the Modbus gateway's unit ID",
        get: |s| Value::Int(s.bridge.modbus.unit.into()),
        set: |s, v| s.bridge.modbus.unit = b(n(v)),
    },
    Setting {
        key: "modbus.baud",
        kind: Kind::Baud,
        block: Block::Bridge,
        help: "the Modbus RTU port's baud rate",
        get: |s| Value::Int(s.bridge.modbus.baud),
        set: |s, v| s.bridge.modbus.baud = n(v),
    },
    Setting {
        key: "modbus.parity",
        kind: Kind::Choice(PARITIES),
        block: Block::Bridge,
        help: "the Modbus RTU port's parity (none: 2 stop bits)",
        get: |s| Value::Int(s.bridge.modbus.parity.code().into()),
        set: |s, v| s.bridge.modbus.parity = Parity::from_code(b(n(v))).unwrap_or(Parity::Even),
    },
    Setting {
        key: "modbus.poll_ms",
        kind: int(
            *POLL_PERIODS_MS.start() as u32,
            *POLL_PERIODS_MS.end() as u32,
        ),
        block: Block::Bridge,
        help: "how often the gateway polls the controller, ms",
        get: |s| Value::Int(s.bridge.modbus.poll_period_ms.into()),
        set: |s, v| s.bridge.modbus.poll_period_ms = w(n(v)),
    },
    Setting {
        key: "modbus.axes",
        kind: int(*AXES.start() as u32, *AXES.end() as u32),
        block: Block::Bridge,
        help: "axes the gateway polls and maps",
        get: |s| Value::Int(s.bridge.modbus.axes.into()),
        set: |s, v| s.bridge.modbus.axes = b(n(v)),
    },
    Setting {
        key: "net.addressing",
        kind: Kind::Choice(ADDRESSINGS),
        block: Block::Net,
        help: "DHCP (net.address meanwhile if no lease comes), or net.address always",
        get: |s| Value::Int(u32::from(s.net.addressing == Addressing::Static)),
        set: |s, v| {
            s.net.addressing = if n(v) == 1 {
                Addressing::Static
            } else {
                Addressing::Dhcp
            }
        },
    },
    Setting {
        key: "net.address",
        kind: Kind::Cidr,
        block: Block::Net,
        help: "the static address and prefix, or DHCP's fallback",
        get: |s| Value::Cidr(s.net.address.address, s.net.address.prefix),
        set: |s, v| {
            if let Value::Cidr(address, prefix) = v {
                s.net.address.address = address;
                s.net.address.prefix = prefix;
            }
        },
    },
    Setting {
        key: "net.gateway",
        kind: Kind::Gateway,
        block: Block::Net,
        help: "the default gateway with a static address",
        get: |s| Value::Ip(s.net.address.gateway),
        set: |s, v| {
            if let Value::Ip(g) = v {
                s.net.address.gateway = g;
            }
        },
    },
    Setting {
        key: "net.port",
        kind: int(1, 65_535),
        block: Block::Net,
        help: "protocol B's TCP port",
        get: |s| Value::Int(s.net.port.into()),
        set: |s, v| s.net.port = w(n(v)),
    },
    Setting {
        key: "web.port",
        kind: int(1, 65_535),
        block: Block::Web,
        help: "the web page's TCP port",
        get: |s| Value::Int(s.web.port.into()),
        set: |s, v| s.web.port = w(n(v)),
    },
    Setting {
        key: "web.reads",
        kind: Kind::Choice(READS),
        block: Block::Web,
        help: "who may read the web page: anyone, or who gives the password",
        get: |s| Value::Int(u32::from(s.web.reads == Reads::Password)),
        set: |s, v| {
            s.web.reads = if n(v) == 1 {
                Reads::Password
            } else {
                Reads::Open
            }
        },
    },
    Setting {
        key: "access.password",
        kind: Kind::Password,
        block: Block::Access,
        help: "the password every change needs (8 to 64 characters)",
        get: |s| Value::PasswordSet(s.password_set),
        set: |_, _| {},
    },
];

/// The setting called `key`.
pub fn find(key: &str) -> Option<&'static Setting> {
    TABLE.iter().find(|s| s.key == key)
}

/// Parses `text` as a value of `kind`; the reason if it is not one.
pub fn parse(kind: Kind, text: &str) -> Result<Value, &'static str> {
    let t = text.trim().as_bytes();
    match kind {
        Kind::Int { min, max } => match text::parse_dec(t) {
            Some(v) if (min..=max).contains(&v) => Ok(Value::Int(v)),
            Some(_) => Err("out of range"),
            None => Err("not a decimal number"),
        },
        Kind::Choice(words) => words
            .iter()
            .position(|w| w.as_bytes().eq_ignore_ascii_case(t))
            .map(|i| Value::Int(i as u32))
            .ok_or("not one of the choices"),
        Kind::Baud => match text::parse_dec(t) {
            Some(v) if BAUD_RATES.contains(&v) => Ok(Value::Int(v)),
            _ => Err("not a baud rate a TTA offers (9600, 19200, 38400, 57600, 115200)"),
        },
        Kind::Station => match text::parse_hex(t) {
            Some(v) if t.len() == 2 => Ok(Value::Int(v)),
            _ => Err("not a station (two hex digits)"),
        },
        Kind::Bool => match t {
            b"on" | b"true" | b"yes" | b"1" => Ok(Value::Int(1)),
            b"off" | b"false" | b"no" | b"0" => Ok(Value::Int(0)),
            _ => Err("not on or off"),
        },
        Kind::Ids => parse_ids(t).map(Value::Ids),
        Kind::Cidr => {
            let mut parts = t.splitn(2, |&c| c == b'/');
            let address = parts.next().and_then(text::parse_ipv4);
            let prefix = parts.next().and_then(text::parse_dec);
            match (address, prefix) {
                (Some(a), Some(_)) if !crate::net::config::is_host_address(a) => {
                    Err("not a host's address")
                }
                (Some(a), Some(p)) if PREFIXES.contains(&b(p)) => Ok(Value::Cidr(a, b(p))),
                (Some(_), Some(_)) => Err("a prefix length out of range (1 to 30)"),
                _ => Err("not an address and prefix (a.b.c.d/p)"),
            }
        }
        Kind::Gateway => {
            if t.eq_ignore_ascii_case(b"none") {
                return Ok(Value::Ip(None));
            }
            match text::parse_ipv4(t) {
                Some(a) if crate::net::config::is_host_address(a) => Ok(Value::Ip(Some(a))),
                Some(_) => Err("not a host's address"),
                None => Err("not an address (a.b.c.d) or none"),
            }
        }
        Kind::Password => Err("the password is set by itself, not as a value"),
    }
}

/// `212,215-217,26D`: the IDs of 200H..2FFH.
fn parse_ids(t: &[u8]) -> Result<AllowList, &'static str> {
    let mut list = AllowList::new();
    if t.is_empty() || t.eq_ignore_ascii_case(b"none") {
        return Ok(list);
    }
    let id = |s: &[u8]| -> Result<u16, &'static str> {
        let s = s.trim_ascii();
        match text::parse_hex(s) {
            Some(v) if s.len() == 3 && (0x200..=0x2FF).contains(&v) => Ok(v as u16),
            _ => {
                Err("not a list of IDs 200 to 2FF (three hex digits, `,` between, `-` for a range)")
            }
        }
    };
    for item in t.split(|&c| c == b',') {
        let mut ends = item.splitn(2, |&c| c == b'-');
        let first = id(ends.next().unwrap_or(&[]))?;
        let last = match ends.next() {
            Some(l) => id(l)?,
            None => first,
        };
        if last < first {
            return Err("a range of IDs that ends before it starts");
        }
        for i in first..=last {
            list.insert(i);
        }
    }
    Ok(list)
}

/// Writes `value` (of `kind`) as text.
pub fn format(kind: Kind, value: &Value, out: &mut dyn Sink) {
    match (kind, *value) {
        (Kind::Choice(words), Value::Int(i)) => {
            out.str(words.get(i as usize).copied().unwrap_or("?"));
        }
        (Kind::Station, Value::Int(v)) => text::hex(out, v, 2),
        (Kind::Bool, Value::Int(v)) => out.str(if v != 0 { "on" } else { "off" }),
        (_, Value::Int(v)) => text::dec(out, v.into()),
        (_, Value::Ids(list)) => format_ids(&list, out),
        (_, Value::Cidr(a, p)) => {
            text::ipv4(out, a);
            out.str("/");
            text::dec(out, p.into());
        }
        (_, Value::Ip(None)) => out.str("none"),
        (_, Value::Ip(Some(a))) => text::ipv4(out, a),
        (_, Value::PasswordSet(set)) => out.str(if set { "set" } else { "not set" }),
    }
}

/// The IDs as runs: `212,215-217,26D`, or `none`.
fn format_ids(list: &AllowList, out: &mut dyn Sink) {
    let mut run: Option<(u16, u16)> = None;
    let mut first = true;
    let mut flush = |run: (u16, u16), out: &mut dyn Sink| {
        if !first {
            out.str(",");
        }
        first = false;
        text::hex(out, run.0.into(), 3);
        if run.1 > run.0 {
            out.str("-");
            text::hex(out, run.1.into(), 3);
        }
    };
    for id in list.ids() {
        run = match run {
            Some((a, z)) if z + 1 == id => Some((a, id)),
            Some(r) => {
                flush(r, out);
                Some((id, id))
            }
            None => Some((id, id)),
        };
    }
    match run {
        Some(r) => flush(r, out),
        None => out.str("none"),
    }
}

/// The bytes the bridge's block takes in the page, at most.
const BRIDGE_READ: usize = BLOCK_LEN;

impl Settings {
    /// Every block at its defaults, no password.
    pub const DEFAULT: Settings = Settings {
        bridge: Config::DEFAULT,
        allow: AllowList::new(),
        net: NetConfig::DEFAULT,
        web: WebConfig::DEFAULT,
        password_set: false,
        changed: 0,
    };

    /// The blocks of `page` (the page's first [`super::page::HOST_LEN`]
    /// bytes at least; what is missing reads as blank), each at its
    /// defaults when blank or invalid; `password_set` as given.
    pub fn from_page(page: &[u8], password_set: bool) -> Settings {
        let at = |offset: usize, len: usize| page.get(offset..offset + len).unwrap_or(&[]);
        let (bridge, _) = Config::from_block(page.get(BRIDGE_AT..).unwrap_or(&[]));
        let (net, _) = NetConfig::from_block(at(NET_AT, NET_LEN));
        let web = WebConfig::from_block(at(WEB_AT, WEB_LEN));
        let allow = match bridge.policy {
            Policy::Allow(list) => list,
            _ => AllowList::new(),
        };
        Settings {
            bridge,
            allow,
            net,
            web,
            password_set,
            changed: 0,
        }
    }

    /// The page in force in `store`, decoded.
    pub fn load(store: &mut dyn PageStore) -> Result<Settings, StoreError> {
        let mut bridge = [0u8; BRIDGE_READ];
        let mut net = [0u8; NET_LEN];
        let mut web = [0u8; WEB_LEN];
        let mut access = [0u8; super::access::ACCESS_LEN];
        store.read(BRIDGE_AT, &mut bridge)?;
        store.read(NET_AT, &mut net)?;
        store.read(WEB_AT, &mut web)?;
        store.read(super::page::ACCESS_AT, &mut access)?;
        let allow_of = |c: &Config| match c.policy {
            Policy::Allow(list) => list,
            _ => AllowList::new(),
        };
        let (bridge, _) = Config::from_block(&bridge);
        Ok(Settings {
            allow: allow_of(&bridge),
            bridge,
            net: NetConfig::from_block(&net).0,
            web: WebConfig::from_block(&web),
            password_set: super::access::Verifier::from_block(&access).is_some(),
            changed: 0,
        })
    }

    /// Sets the setting called `key` from `text`.
    pub fn set(&mut self, key: &str, text: &str) -> Result<&'static Setting, SetError> {
        let s = find(key).ok_or(SetError {
            key: None,
            reason: "no setting has this key",
        })?;
        if s.kind == Kind::Password {
            return Err(SetError {
                key: Some(s.key),
                reason: "the password is set by itself, not as a value",
            });
        }
        let v = parse(s.kind, text).map_err(|reason| SetError {
            key: Some(s.key),
            reason,
        })?;
        self.set_value(s, v);
        Ok(s)
    }

    /// Sets `setting` to `value` (of its kind, checked) and marks its block
    /// if that changed it.
    pub fn set_value(&mut self, setting: &Setting, value: Value) {
        let before = (setting.get)(self);
        (setting.set)(self, value);
        if (setting.get)(self) != before {
            self.changed |= setting.block.bit();
        }
    }

    /// Whether any block was changed.
    pub fn any_changed(&self) -> bool {
        self.changed != 0
    }

    /// Whether a block of `block`'s settings was changed.
    pub fn changed(&self, block: Block) -> bool {
        self.changed & block.bit() != 0
    }

    /// The settings that depend on each other: the first that does not fit.
    pub fn check(&self) -> Result<(), SetError> {
        if self.bridge.bridge_station == self.bridge.controller_station {
            return Err(SetError {
                key: Some("bridge.station"),
                reason: "must differ from bridge.controller_station",
            });
        }
        if self.changed(Block::Bridge) && Config::parse(&self.bridge.to_block()).is_err() {
            return Err(SetError {
                key: Some("bridge.station"),
                reason: "the bridge's block does not check",
            });
        }
        if self.changed(Block::Net) && NetConfig::parse(&self.net.to_block()).is_err() {
            return Err(SetError {
                key: Some("net.address"),
                reason: "the network block does not check",
            });
        }
        Ok(())
    }

    /// Writes the changed blocks' bytes over `window`, the page's bytes
    /// from `at` (the other bytes are left as they are).
    pub fn overlay(&self, at: usize, window: &mut [u8]) {
        if self.changed(Block::Bridge) {
            copy_into(at, window, BRIDGE_AT, &self.bridge.to_block());
        }
        if self.changed(Block::Net) {
            copy_into(at, window, NET_AT, &self.net.to_block());
        }
        if self.changed(Block::Web) {
            copy_into(at, window, WEB_AT, &self.web.to_block());
        }
    }
}

impl Default for Settings {
    fn default() -> Self {
        Settings::DEFAULT
    }
}

/// Copies the part of `block` (at page offset `block_at`) that falls in
/// `window` (at page offset `at`).
pub fn copy_into(at: usize, window: &mut [u8], block_at: usize, block: &[u8]) {
    let start = at.max(block_at);
    let end = (at + window.len()).min(block_at + block.len());
    if start >= end {
        return;
    }
    if let (Some(dst), Some(src)) = (
        window.get_mut(start - at..end - at),
        block.get(start - block_at..end - block_at),
    ) {
        // Equal lengths, but a zip keeps the length check (and its panic)
        // out of the image.
        for (d, s) in dst.iter_mut().zip(src) {
            *d = *s;
        }
    }
}

#[cfg(test)]
mod tests;
