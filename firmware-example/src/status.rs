//! The status query: the bridge's counters, configuration and last error,
//! read from the host.
//!
//! Query (to the bridge's own station, [`crate::config::Config::bridge_station`]):
//! `!` station `B00` SC CR LF (no data).
//!
//! Reply: `#` station `B00` then the fields of [`FIELDS`] in order, each
//! fixed-width upper-case hex, then SC CR LF ([`REPLY_LEN`] bytes):
//!
//! | field | digits | meaning |
//! |---|---|---|
//! | `layout` | 2 | 01 |
//! | `uptime_ms` | 8 | the bridge's millisecond tick (wraps after 49.7 days) |
//! | `config_source` | 1 | 0 built-in defaults, 1 configuration block, 2 blank block (defaults), 3 invalid block (defaults) |
//! | `controller_station` | 2 | |
//! | `bridge_station` | 2 | |
//! | `upstream_baud`, `downstream_baud` | 6 each | bit/s |
//! | `flow_control` | 1 | 0 none, 1 XON/XOFF, 2 RTS/CTS |
//! | `policy` | 1 | 0 forward all, 1 read-only, 2 allow-list |
//! | `allow_list_len` | 3 | IDs in the allow-list |
//! | 16 counters | 8 each | see [`crate::bridge::Stats`], in its field order up to `downstream_overruns` |
//! | `last_error` | 3 | the last `&` code the bridge sent itself, 000 if none |
//! | `last_error_ms` | 8 | when (tick), 0 if none |

use iai_protocol_b::field::{FieldSpec, Writer};
use iai_protocol_b::frame::{emit_frame, Header, Station, ENVELOPE_LEN};

use crate::bridge::{LastError, Stats};
use crate::codes;
use crate::config::{Config, Policy, Source};

/// Name and width (hex digits) of every field of the reply, in order.
pub const FIELDS: [(&str, u8); 28] = [
    ("layout", 2),
    ("uptime_ms", 8),
    ("config_source", 1),
    ("controller_station", 2),
    ("bridge_station", 2),
    ("upstream_baud", 6),
    ("downstream_baud", 6),
    ("flow_control", 1),
    ("policy", 1),
    ("allow_list_len", 3),
    ("forwarded", 8),
    ("relayed", 8),
    ("reply_timeouts", 8),
    ("rejected", 8),
    ("refused", 8),
    ("other_station", 8),
    ("own_queries", 8),
    ("streams_ok", 8),
    ("streams_failed", 8),
    ("records", 8),
    ("chunks_sent", 8),
    ("retries", 8),
    ("chunk_timeouts", 8),
    ("chunk_error_replies", 8),
    ("upstream_overruns", 8),
    ("downstream_overruns", 8),
    ("last_error", 3),
    ("last_error_ms", 8),
];

/// Digits of the reply's data.
// Evaluated at compile time: an index out of bounds is a build error.
#[allow(clippy::indexing_slicing)]
pub const DATA_LEN: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < FIELDS.len() {
        n += FIELDS[i].1 as usize;
        i += 1;
    }
    n
};

/// Bytes of the whole reply, header through LF.
pub const REPLY_LEN: usize = ENVELOPE_LEN + DATA_LEN + 4;

/// Layout version sent in the first field.
pub const LAYOUT: u8 = 1;

/// What the status reply reports.
pub struct Report<'a> {
    /// The tick now.
    pub now_ms: u32,
    /// The configuration in force.
    pub config: &'a Config,
    /// Where it came from.
    pub source: Source,
    /// The counters.
    pub stats: &'a Stats,
    /// The last error.
    pub last_error: Option<LastError>,
}

impl Report<'_> {
    /// The values of [`FIELDS`], in order.
    pub fn values(&self) -> [u64; 28] {
        let c = self.config;
        let s = self.stats;
        let allow = match c.policy {
            Policy::Allow(l) => l.len(),
            _ => 0,
        };
        let (code, at) = self.last_error.map_or((0, 0), |e| (e.code, e.at_ms));
        [
            u64::from(LAYOUT),
            u64::from(self.now_ms),
            u64::from(self.source.code()),
            u64::from(c.controller_station.0),
            u64::from(c.bridge_station.0),
            u64::from(c.upstream_baud),
            u64::from(c.downstream_baud),
            u64::from(c.flow.code()),
            u64::from(c.policy.code()),
            u64::from(allow),
            u64::from(s.forwarded),
            u64::from(s.relayed),
            u64::from(s.reply_timeouts),
            u64::from(s.rejected),
            u64::from(s.refused),
            u64::from(s.other_station),
            u64::from(s.own_queries),
            u64::from(s.streams_ok),
            u64::from(s.streams_failed),
            u64::from(s.records),
            u64::from(s.chunks_sent),
            u64::from(s.retries),
            u64::from(s.chunk_timeouts),
            u64::from(s.chunk_error_replies),
            u64::from(s.upstream_overruns),
            u64::from(s.downstream_overruns),
            u64::from(code),
            u64::from(at),
        ]
    }

    /// Writes the reply into `buf`; returns its length.
    pub fn emit(&self, station: Station, buf: &mut [u8]) -> iai_protocol_b::Result<usize> {
        let values = self.values();
        emit_frame(
            buf,
            Header::Response,
            station,
            codes::STATUS_QUERY,
            Default::default(),
            |w: &mut Writer<'_>| {
                for (&(_, width), &v) in FIELDS.iter().zip(values.iter()) {
                    // Counters wrap to their width.
                    let max = FieldSpec::hex(width).max_unsigned();
                    w.unsigned(FieldSpec::hex(width), v & max)?;
                }
                Ok(())
            },
        )
    }
}

/// Splits a status reply's data (the frame body) into `(name, value)`
/// pairs in [`FIELDS`] order; `None` if the length is wrong or a digit is
/// not hex.
pub fn parse(body: &[u8]) -> Option<[(&'static str, u64); 28]> {
    if body.len() != DATA_LEN {
        return None;
    }
    let mut out = [("", 0u64); 28];
    let mut at = 0;
    for (slot, &(name, width)) in out.iter_mut().zip(FIELDS.iter()) {
        let w = usize::from(width);
        let digits = body.get(at..at + w)?;
        let v = iai_protocol_b::field::decode_unsigned(FieldSpec::hex(width), digits, at).ok()?;
        *slot = (name, v);
        at += w;
    }
    Some(out)
}
