//! The pages, each a sequence of parts rendered one at a time straight
//! into the socket's transmit buffer when it has room for the whole part
//! (so no page is ever held in RAM): the response head, then HTML or text
//! from what the gateway knows at that moment. No framework, no script
//! needed to read; the status page's script only fetches its live part
//! again every 2 s (`/live`), and without it a `<noscript>` refresh does.
//!
//! Positions print as millimetres from 0.001 mm ([`text::mm`]), without
//! floats.

use iai_protocol_b::message::{AxisStatus, Homing, MoveOutcome};

use super::Status;
use crate::bridge::history::Dir;
use crate::bridge::Bridge;
use crate::config::editor::Applied;
use crate::config::settings::{self, Kind, Setting, Settings, TABLE};
use crate::config::BAUD_RATES;
use crate::modbus::Gateway;
use crate::net::host::HostStats;
use crate::net::modbus::ModbusTcpStats;
use crate::net::{AddressSource, NetView};
use crate::status::Stats;
use crate::text::{self, Sink};

/// What the pages show: read at the moment a part is rendered.
pub struct View<'a> {
    /// The bridge (counters, configuration, frames, the page's editor).
    pub bridge: &'a mut Bridge,
    /// The Modbus gateway (its polled cache of the controller).
    pub gateway: Option<&'a mut Gateway>,
    /// The network side.
    pub net: NetView,
    /// The tick.
    pub now: u32,
}

/// A page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Page {
    /// The status page.
    Status,
    /// Its live part alone.
    Live,
    /// The configuration form.
    Config,
    /// The last frames, as text to download.
    Frames,
    /// A change written.
    Saved(Applied),
    /// A form that changed nothing.
    Unchanged,
    /// A restart granted.
    Restarting,
    /// A refusal.
    Refused(Refusal),
}

/// A refusal: its status, why, and the setting it is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refusal {
    /// The status.
    pub status: Status,
    /// Why, in a few words.
    pub reason: &'static str,
    /// The setting it is about.
    pub key: Option<&'static str>,
}

impl Page {
    /// A refusal with `status` and `reason`.
    pub const fn refused(status: Status, reason: &'static str) -> Page {
        Page::Refused(Refusal {
            status,
            reason,
            key: None,
        })
    }
}

/// Renders part `n` of `page` into `out`; `false` once past the last.
pub fn part(page: Page, n: usize, v: &mut View<'_>, out: &mut dyn Sink) -> bool {
    match page {
        Page::Status => match n {
            0 => response_head(out, Status::Ok, "text/html; charset=utf-8", None),
            1 => doc_head(out, "Status", true),
            2 => {
                nav(out);
                out.str("<main id=\"live\">");
            }
            _ if n - 3 < LIVE_PARTS => live(n - 3, v, out),
            _ if n - 3 == LIVE_PARTS => {
                out.str("</main>");
                restart_form(out);
                out.str(LIVE_SCRIPT);
                out.str("</body></html>\n");
            }
            _ => return false,
        },
        Page::Live => match n {
            0 => response_head(out, Status::Ok, "text/html; charset=utf-8", None),
            _ if n - 1 < LIVE_PARTS => live(n - 1, v, out),
            _ => return false,
        },
        Page::Config => match n {
            0 => response_head(out, Status::Ok, "text/html; charset=utf-8", None),
            1 => doc_head(out, "Configuration", false),
            2 => {
                nav(out);
                config_intro(v, out);
            }
            _ => match TABLE.get(n - 3) {
                Some(s) if s.kind == Kind::Password => {}
                Some(s) => {
                    let settings = settings_of(v);
                    setting_row(s, &settings, out);
                }
                None if n - 3 == TABLE.len() => {
                    let password_set = settings_of(v).password_set;
                    config_tail(password_set, out);
                }
                None => return false,
            },
        },
        Page::Frames => match n {
            0 => response_head(
                out,
                Status::Ok,
                "text/plain; charset=utf-8",
                Some("Content-Disposition: attachment; filename=\"frames.txt\"\r\n"),
            ),
            1 => {
                out.str("# the last frames through the bridge, oldest first: uptime (s), ");
                out.str("> from a host, < to it, the frame (its first ");
                text::dec(out, crate::bridge::history::KEPT as u64);
                out.str(" bytes)\n");
            }
            _ => match v.bridge.history().oldest_first().nth(n - 2) {
                Some(e) => {
                    seconds(out, e.at_ms);
                    out.str(if e.dir == Dir::FromHost { " > " } else { " < " });
                    for &b in e.bytes() {
                        match b {
                            b'\r' | b'\n' => {}
                            0x20..=0x7E => out.put(&[b]),
                            _ => {
                                out.str("\\x");
                                text::hex(out, b.into(), 2);
                            }
                        }
                    }
                    if e.len as usize > e.bytes().len() {
                        out.str(" ... (");
                        text::dec(out, e.len.into());
                        out.str(" bytes)");
                    }
                    out.str("\n");
                }
                None => return false,
            },
        },
        Page::Saved(a) => match n {
            0 => response_head(out, Status::Ok, "text/html; charset=utf-8", None),
            1 => doc_head(out, "Saved", false),
            2 => {
                nav(out);
                out.str("<h2 id=\"result\">Saved as sequence ");
                text::dec(out, a.seq.into());
                out.str("</h2>");
                if a.restart_needed {
                    out.str("<p>These settings take effect at the next start.</p>");
                    restart_form(out);
                } else {
                    out.str("<p>In effect now.</p>");
                }
                out.str("</body></html>\n");
            }
            _ => return false,
        },
        Page::Unchanged => match n {
            0 => response_head(out, Status::Ok, "text/html; charset=utf-8", None),
            1 => doc_head(out, "Unchanged", false),
            2 => {
                nav(out);
                out.str("<h2 id=\"result\">Nothing changed</h2><p>The gateway holds these settings already; nothing was written.</p></body></html>\n");
            }
            _ => return false,
        },
        Page::Restarting => {
            match n {
                0 => response_head(out, Status::Ok, "text/html; charset=utf-8", None),
                1 => {
                    out.str("<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">");
                    out.str("<meta http-equiv=\"refresh\" content=\"5;url=/\"><title>Restarting</title>");
                    out.str("<link rel=\"icon\" href=\"data:,\"></head><body><h2 id=\"result\">The gateway restarts</h2>");
                    out.str("<p>This page goes back to the status in 5 s.</p></body></html>\n");
                }
                _ => return false,
            }
        }
        Page::Refused(r) => match n {
            0 => {
                let extra = (r.status == Status::Unauthorized).then_some(
                    "WWW-Authenticate: Basic realm=\"IAI gateway\", charset=\"UTF-8\"\r\n",
                );
                let extra =
                    extra.or((r.status == Status::TooManyRequests).then_some("Retry-After: 1\r\n"));
                response_head(out, r.status, "text/html; charset=utf-8", extra);
            }
            1 => {
                out.str("<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>");
                status_line(out, r.status);
                out.str("</title><link rel=\"icon\" href=\"data:,\"></head><body><h1>");
                status_line(out, r.status);
                out.str("</h1><p id=\"reason\">");
                if let Some(k) = r.key {
                    out.str(k);
                    out.str(": ");
                }
                out.str(r.reason);
                out.str("</p><p><a href=\"/\">Status</a> <a href=\"/config\">Configuration</a></p></body></html>\n");
            }
            _ => return false,
        },
    }
    true
}

/// `HTTP/1.1 CODE REASON` and the headers every answer has.
fn response_head(out: &mut dyn Sink, status: Status, content_type: &str, extra: Option<&str>) {
    out.str("HTTP/1.1 ");
    status_line(out, status);
    out.str("\r\nContent-Type: ");
    out.str(content_type);
    out.str(
        "\r\nCache-Control: no-store\r\nX-Frame-Options: DENY\r\n\
         X-Content-Type-Options: nosniff\r\nReferrer-Policy: same-origin\r\n\
         Connection: close\r\n",
    );
    if let Some(e) = extra {
        out.str(e);
    }
    out.str("\r\n");
}

/// `403 Forbidden`.
fn status_line(out: &mut dyn Sink, s: Status) {
    text::dec(out, u64::from(s.code()));
    out.str(" ");
    out.str(s.reason());
}

const STYLE: &str = "<style>body{font:15px/1.4 sans-serif;margin:1em;max-width:60em}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:.2em .5em;text-align:left}\
td.n{text-align:right;font-family:monospace}.h{color:#555;font-size:90%}.bad{color:#b00}.ok{color:#070}\
.warn{background:#fe8;padding:.4em}nav a{margin-right:1em}input,select{font:inherit}</style>";

/// The document's head and `<body>`.
fn doc_head(out: &mut dyn Sink, title: &str, refresh_without_script: bool) {
    out.str("<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">");
    out.str("<meta name=\"viewport\" content=\"width=device-width\"><title>IAI gateway: ");
    out.str(title);
    out.str("</title><link rel=\"icon\" href=\"data:,\">");
    if refresh_without_script {
        out.str("<noscript><meta http-equiv=\"refresh\" content=\"5\"></noscript>");
    }
    out.str(STYLE);
    out.str("</head><body>");
}

fn nav(out: &mut dyn Sink) {
    out.str("<header><h1>IAI protocol-B gateway</h1><nav><a href=\"/\">Status</a>");
    out.str("<a href=\"/config\">Configuration</a><a href=\"/frames.txt\" id=\"frames\">Last frames (text)</a></nav></header>");
}

const LIVE_SCRIPT: &str = "<script>setInterval(function(){fetch('/live').then(function(r){\
return r.ok?r.text():null}).then(function(t){if(t!==null)document.getElementById('live').innerHTML=t})\
.catch(function(){})},2000)</script>";

fn restart_form(out: &mut dyn Sink) {
    out.str("<form method=\"post\" action=\"/restart\"><p><label>Password ");
    out.str("<input type=\"password\" name=\"password\" id=\"restart-password\" autocomplete=\"current-password\"></label> ");
    out.str("<button type=\"submit\" id=\"restart\">Restart the gateway</button></p></form>");
}

/// Parts of the live section: the gateway, the axes' head, 8 axes, the
/// axes' end, the lines, the counters in two.
const LIVE_PARTS: usize = 14;

fn live(n: usize, v: &mut View<'_>, out: &mut dyn Sink) {
    if let Some(g) = v.gateway.as_deref_mut() {
        // Someone looks: the gateway polls the controller from now on.
        g.regs.active = true;
    }
    match n {
        0 => gateway_part(v, out),
        1 => {
            out.str("<h2>Controller</h2><table id=\"axes\"><tr><th>axis</th><th>status</th>");
            out.str("<th>position (mm)</th><th>alarm</th></tr>");
        }
        2..=9 => axis_row(n - 1, v, out),
        10 => {
            out.str("</table>");
            error_detail(v, out);
        }
        11 => lines(v, out),
        12 => counters(&v.bridge.stats(), 0..10, out),
        _ => {
            counters(&v.bridge.stats(), 10..Stats::NAMES.len(), out);
            out.str("</table>");
        }
    }
}

fn gateway_part(v: &mut View<'_>, out: &mut dyn Sink) {
    out.str("<h2>Gateway</h2><p>Firmware ");
    out.str(env!("CARGO_PKG_VERSION"));
    out.str(", up <span id=\"uptime\">");
    duration(out, v.now);
    out.str("</span>");
    if let Some((a, source)) = v.net.address {
        out.str(", address ");
        text::ipv4(out, a.address);
        out.str(match source {
            AddressSource::Dhcp => " (DHCP)",
            AddressSource::Static => " (static)",
            AddressSource::Fallback => " (DHCP's fallback)",
        });
    }
    match v.bridge.editor() {
        Some(e) => {
            out.str(", configuration ");
            match e.sequence() {
                Some(seq) => {
                    out.str("sequence <span id=\"seq\">");
                    text::dec(out, seq.into());
                    out.str("</span>");
                }
                None => out.str("never written (defaults)"),
            }
            if e.restart_pending() {
                out.str(". <span class=\"warn\">Changes wait for a restart.</span>");
            }
            if e.verifier().is_none() {
                out.str(". <span class=\"warn\">No password yet: <a href=\"/config\">set one</a>.</span>");
            }
        }
        None => out.str(", configuration read only"),
    }
    out.str("</p>");
}

/// Axis `axis` (1..=8): its 212H status, position and alarm, from the
/// gateway's cache; axes the gateway does not poll print nothing.
fn axis_row(axis: usize, v: &mut View<'_>, out: &mut dyn Sink) {
    let Some(g) = v.gateway.as_deref() else {
        if axis == 1 {
            out.str("<tr><td colspan=\"4\">no Modbus gateway on this build</td></tr>");
        }
        return;
    };
    if axis > usize::from(g.regs.cfg.axes) {
        return;
    }
    let c = &g.regs.cache;
    let Some(a) = c.axes.get(axis - 1) else {
        return;
    };
    let never = c.axes_at.age(v.now) == u16::MAX && !c.link_up && c.polls_ok == 0;
    out.str("<tr><td>");
    text::dec(out, axis as u64);
    out.str("</td><td>");
    if never {
        out.str("no reply yet</td><td class=\"n\">-</td><td>-</td></tr>");
        return;
    }
    axis_words(a, out);
    out.str("</td><td class=\"n\" id=\"pos");
    text::dec(out, axis as u64);
    out.str("\">");
    text::mm(out, a.current_position);
    out.str("</td><td");
    if a.error_code == 0 {
        out.str(">none");
    } else {
        out.str(" class=\"bad\">");
        text::hex(out, a.error_code.into(), 3);
        let (number, details) = c.error;
        if number == a.error_code {
            out.str(" (216H: ");
            for (i, d) in details.iter().enumerate() {
                if i > 0 {
                    out.str(", ");
                }
                text::hex(out, *d, 8);
            }
            out.str(")");
        }
    }
    out.str("</td></tr>");
}

/// 212H's status byte in words.
fn axis_words(a: &AxisStatus, out: &mut dyn Sink) {
    out.str(if a.servo_on() {
        "servo on"
    } else {
        "servo off"
    });
    out.str(match a.homing() {
        Homing::Done => ", homed",
        Homing::Returning => ", homing",
        Homing::NotDone => ", not homed",
        Homing::Undefined => ", homing state ?",
    });
    out.str(match a.outcome() {
        None => ", busy",
        Some(MoveOutcome::Completed) => ", idle, completed",
        Some(MoveOutcome::PushError) => ", idle, push error",
        Some(MoveOutcome::Cancelled) => ", idle",
    });
}

/// The controller's latest error, as 216H last answered.
fn error_detail(v: &mut View<'_>, out: &mut dyn Sink) {
    let Some(g) = v.gateway.as_deref() else {
        return;
    };
    let c = &g.regs.cache;
    out.str("<p>Latest controller error (215H, 216H): ");
    let (number, details) = c.error;
    if number == 0 {
        out.str("none");
    } else {
        text::hex(out, number.into(), 3);
        out.str(", details ");
        for (i, d) in details.iter().enumerate() {
            if i > 0 {
                out.str(" ");
            }
            text::hex(out, *d, 8);
        }
    }
    out.str("</p>");
}

fn lines(v: &mut View<'_>, out: &mut dyn Sink) {
    let cfg = *v.bridge.config();
    let s = v.bridge.stats();
    let l = v.bridge.line_stats();
    let HostStats {
        hosts,
        refused,
        cut_short,
        stalled,
    } = v.net.hosts;
    out.str("<h2>Lines</h2><table id=\"lines\"><tr><th>line</th><th>state</th><th>errors</th><th>ages</th></tr>");
    out.str("<tr><td>host: protocol B over TCP, port ");
    text::dec(out, v.net.port.into());
    out.str("</td><td>");
    out.str(if v.net.host_connected {
        "a host is connected"
    } else {
        "no host"
    });
    out.str("; ");
    text::dec(out, hosts.into());
    out.str(" served, ");
    text::dec(out, refused.into());
    out.str(" refused (B0B)</td><td>");
    text::dec(out, cut_short.into());
    out.str(" cut short, ");
    text::dec(out, stalled.into());
    out.str(" stalled, ");
    text::dec(out, s.rejected.into());
    out.str(" malformed</td><td>last frame ");
    match v
        .bridge
        .history()
        .oldest_first()
        .filter(|e| e.dir == Dir::FromHost)
        .last()
    {
        Some(e) => {
            duration(out, v.now.wrapping_sub(e.at_ms));
            out.str(" ago");
        }
        None => out.str("none yet"),
    }
    out.str("</td></tr><tr><td>controller: UART1, ");
    text::dec(out, cfg.downstream_baud.into());
    out.str(" baud, station ");
    text::hex(out, cfg.controller_station.0.into(), 2);
    out.str("</td><td");
    if let Some(g) = v.gateway.as_deref() {
        let c = &g.regs.cache;
        out.str(if c.link_up {
            " class=\"ok\">up"
        } else {
            " class=\"bad\">down"
        });
        out.str("; polls ");
        text::dec(out, c.polls_ok.into());
        out.str(" answered, ");
        text::dec(out, c.polls_failed.into());
        out.str(" not</td>");
    } else {
        out.str(">-</td>");
    }
    out.str("<td>");
    text::dec(out, l.timeouts.into());
    out.str(" timeouts, ");
    text::dec(out, l.resends.into());
    out.str(" resends, ");
    text::dec(out, l.line_errors.into());
    out.str(" broken frames, ");
    text::dec(out, l.stale.into());
    out.str(" late replies, ");
    text::dec(out, s.downstream_overruns.into());
    out.str(" overruns</td><td>");
    if let Some(g) = v.gateway.as_deref() {
        let c = &g.regs.cache;
        for (name, stamp) in [
            ("axes ", &c.axes_at),
            (", system ", &c.system_at),
            (", I/O ", &c.io_at),
            (", variables ", &c.integers_at),
        ] {
            out.str(name);
            match stamp.age(v.now) {
                u16::MAX => out.str("-"),
                ms => {
                    text::dec(out, ms.into());
                    out.str(" ms");
                }
            }
        }
    }
    out.str("</td></tr>");
    if let Some(ModbusTcpStats {
        connections,
        requests,
        ..
    }) = v.net.modbus
    {
        out.str("<tr><td>Modbus TCP, port 502, unit ");
        text::dec(out, cfg.modbus.unit.into());
        out.str("</td><td>");
        text::dec(out, connections.into());
        out.str(" connections, ");
        text::dec(out, requests.into());
        out.str(" requests</td><td>");
        if let Some(g) = v.gateway.as_deref() {
            let m = g.stats();
            text::dec(out, m.exceptions.into());
            out.str(" exceptions, ");
            text::dec(out, m.dropped.into());
            out.str(" dropped");
        }
        out.str("</td><td></td></tr>");
    }
    out.str("</table>");
}

fn counters(s: &Stats, range: core::ops::Range<usize>, out: &mut dyn Sink) {
    if range.start == 0 {
        out.str("<h2>Counters</h2><table id=\"counters\">");
    }
    let values = s.values();
    for i in range {
        let (Some(name), Some(value)) = (Stats::NAMES.get(i), values.get(i)) else {
            continue;
        };
        out.str("<tr><td>");
        out.str(name);
        out.str("</td><td class=\"n\">");
        text::dec(out, *value);
        out.str("</td></tr>");
    }
}

/// The settings in force (the defaults without an editor).
fn settings_of(v: &mut View<'_>) -> Settings {
    match v.bridge.editor() {
        Some(e) => e.settings(),
        None => Settings::DEFAULT,
    }
}

fn config_intro(v: &mut View<'_>, out: &mut dyn Sink) {
    out.str("<h2>Configuration</h2>");
    match v.bridge.editor() {
        Some(e) => {
            match e.sequence() {
                Some(seq) => {
                    out.str("<p>The page in force: sequence ");
                    text::dec(out, seq.into());
                    out.str(".");
                }
                None => out.str("<p>Nothing written yet: every setting at its default."),
            }
            out.str(
                " Settings other than web.* and the password take effect at the next start.</p>",
            );
            if e.verifier().is_none() {
                out.str("<p class=\"warn\" id=\"no-password\">No password is set: choose one below (8 to 64 characters). Nothing else can change until then.</p>");
            }
        }
        None => out.str("<p class=\"warn\">This gateway keeps no configuration it can write.</p>"),
    }
    out.str("<form method=\"post\" action=\"/config\"><table><tr><th>setting</th><th>value</th><th>what it does</th></tr>");
}

fn setting_row(s: &Setting, settings: &Settings, out: &mut dyn Sink) {
    out.str("<tr><td><label for=\"");
    out.str(s.key);
    out.str("\">");
    out.str(s.key);
    out.str("</label></td><td>");
    let value = (s.get)(settings);
    let choice = |out: &mut dyn Sink, word: &str, selected: bool| {
        out.str("<option");
        if selected {
            out.str(" selected");
        }
        out.str(">");
        out.str(word);
        out.str("</option>");
    };
    let select = |out: &mut dyn Sink| {
        out.str("<select id=\"");
        out.str(s.key);
        out.str("\" name=\"");
        out.str(s.key);
        out.str("\">");
    };
    match (s.kind, value) {
        (Kind::Choice(words), settings::Value::Int(i)) => {
            select(out);
            for (n, w) in words.iter().enumerate() {
                choice(out, w, n as u32 == i);
            }
            out.str("</select>");
        }
        (Kind::Bool, settings::Value::Int(i)) => {
            select(out);
            choice(out, "off", i == 0);
            choice(out, "on", i != 0);
            out.str("</select>");
        }
        (Kind::Baud, settings::Value::Int(baud)) => {
            select(out);
            for b in BAUD_RATES {
                out.str("<option");
                if b == baud {
                    out.str(" selected");
                }
                out.str(">");
                text::dec(out, b.into());
                out.str("</option>");
            }
            out.str("</select>");
        }
        _ => {
            out.str("<input id=\"");
            out.str(s.key);
            out.str("\" name=\"");
            out.str(s.key);
            out.str("\" value=\"");
            let mut escaped = Escaped(out);
            settings::format(s.kind, &value, &mut escaped);
            out.str("\">");
        }
    }
    out.str("</td><td class=\"h\">");
    out.str(s.help);
    out.str("</td></tr>");
}

fn config_tail(password_set: bool, out: &mut dyn Sink) {
    out.str("</table>");
    if password_set {
        out.str("<p><label>Password <input type=\"password\" name=\"password\" id=\"password\" autocomplete=\"current-password\"></label></p>");
        out.str("<details><summary>Change the password</summary>");
    } else {
        out.str("<fieldset><legend>The gateway's password</legend>");
    }
    out.str("<p><label>New password <input type=\"password\" name=\"new_password\" id=\"new_password\" autocomplete=\"new-password\"></label> ");
    out.str("<label>again <input type=\"password\" name=\"new_password2\" id=\"new_password2\" autocomplete=\"new-password\"></label></p>");
    out.str(if password_set {
        "</details>"
    } else {
        "</fieldset>"
    });
    out.str("<p><button type=\"submit\" id=\"save\">Save</button></p></form></body></html>\n");
}

/// A sink that escapes HTML's special characters.
struct Escaped<'a>(&'a mut dyn Sink);

impl Sink for Escaped<'_> {
    fn put(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match b {
                b'&' => self.0.str("&amp;"),
                b'<' => self.0.str("&lt;"),
                b'>' => self.0.str("&gt;"),
                b'"' => self.0.str("&quot;"),
                _ => self.0.put(&[b]),
            }
        }
    }
}

/// `1 h 02 min 03 s` from ms.
fn duration(out: &mut dyn Sink, ms: u32) {
    let s = ms / 1000;
    let (h, m, s) = (s / 3600, s / 60 % 60, s % 60);
    if h > 0 {
        text::dec(out, h.into());
        out.str(" h ");
    }
    if h > 0 || m > 0 {
        text::dec(out, m.into());
        out.str(" min ");
    }
    text::dec(out, s.into());
    out.str(" s");
}

/// A tick as seconds with three decimals.
fn seconds(out: &mut dyn Sink, ms: u32) {
    text::dec(out, (ms / 1000).into());
    out.str(".");
    let frac = ms % 1000;
    if frac < 100 {
        out.str("0");
    }
    if frac < 10 {
        out.str("0");
    }
    text::dec(out, frac.into());
}
