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
//! | `layout` | 2 | 02 (01 had no `xoff_released`) |
//! | `uptime_ms` | 8 | the bridge's millisecond tick (wraps after 49.7 days) |
//! | `config_source` | 1 | 0 built-in defaults, 1 configuration block, 2 blank block (defaults), 3 invalid block (defaults) |
//! | `controller_station` | 2 | |
//! | `bridge_station` | 2 | |
//! | `upstream_baud`, `downstream_baud` | 6 each | bit/s |
//! | `flow_control` | 1 | 0 none, 1 XON/XOFF, 2 RTS/CTS |
//! | `policy` | 1 | 0 forward all, 1 read-only, 2 allow-list |
//! | `allow_list_len` | 3 | IDs in the allow-list |
//! | 17 counters | 8 each | see [`Stats`], in its field order up to `xoff_released` |
//! | `last_error` | 3 | the last `&` code the bridge sent itself, 000 if none |
//! | `last_error_ms` | 8 | when (tick), 0 if none |

use iai_protocol_b::field::{FieldSpec, Writer};
use iai_protocol_b::frame::{emit_frame, Header, Station, ENVELOPE_LEN};

use crate::codes;
use crate::config::{Config, Policy, Source};

/// What the bridge counted since start.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stats {
    /// Commands forwarded downstream as they were.
    pub forwarded: u32,
    /// Replies relayed upstream.
    pub relayed: u32,
    /// Forwarded commands that got no valid reply in time.
    pub reply_timeouts: u32,
    /// Upstream frames dropped as malformed (never forwarded).
    pub rejected: u32,
    /// Commands refused by the policy (answered `&` B06).
    pub refused: u32,
    /// Commands for a station other than the controller's and the bridge's.
    pub other_station: u32,
    /// Commands the bridge answered itself (its own station).
    pub own_queries: u32,
    /// 26DH commands completed (`#` sent).
    pub streams_ok: u32,
    /// 26DH commands answered with `&`.
    pub streams_failed: u32,
    /// Records confirmed by the controller in 26DH chunks.
    pub records: u32,
    /// 26DH chunks sent downstream, retries included.
    pub chunks_sent: u32,
    /// Chunks sent again.
    pub retries: u32,
    /// Chunk replies that timed out.
    pub chunk_timeouts: u32,
    /// `&` replies to chunks.
    pub chunk_error_replies: u32,
    /// Upstream bytes lost (receive overruns).
    pub upstream_overruns: u32,
    /// Downstream bytes lost (receive overruns).
    pub downstream_overruns: u32,
    /// XOFFs from the host let go after [`Config::xoff_hold_ms`]: noise
    /// that looked like XOFF, or a host that never sent XON.
    pub xoff_released: u32,
    /// Bytes read from the upstream.
    pub upstream_in: u64,
    /// Bytes written to the upstream.
    pub upstream_out: u64,
    /// Bytes read from the downstream.
    pub downstream_in: u64,
    /// Bytes written to the downstream.
    pub downstream_out: u64,
}

impl Stats {
    /// The field names, in declaration order: with [`Stats::values`], what
    /// a board prints at the end of a run in the `Debug` layout without
    /// linking `core::fmt`.
    pub const NAMES: [&'static str; 21] = [
        "forwarded",
        "relayed",
        "reply_timeouts",
        "rejected",
        "refused",
        "other_station",
        "own_queries",
        "streams_ok",
        "streams_failed",
        "records",
        "chunks_sent",
        "retries",
        "chunk_timeouts",
        "chunk_error_replies",
        "upstream_overruns",
        "downstream_overruns",
        "xoff_released",
        "upstream_in",
        "upstream_out",
        "downstream_in",
        "downstream_out",
    ];

    /// Every counter, in declaration order (see [`Stats::NAMES`]).
    pub fn values(&self) -> [u64; 21] {
        [
            u64::from(self.forwarded),
            u64::from(self.relayed),
            u64::from(self.reply_timeouts),
            u64::from(self.rejected),
            u64::from(self.refused),
            u64::from(self.other_station),
            u64::from(self.own_queries),
            u64::from(self.streams_ok),
            u64::from(self.streams_failed),
            u64::from(self.records),
            u64::from(self.chunks_sent),
            u64::from(self.retries),
            u64::from(self.chunk_timeouts),
            u64::from(self.chunk_error_replies),
            u64::from(self.upstream_overruns),
            u64::from(self.downstream_overruns),
            u64::from(self.xoff_released),
            self.upstream_in,
            self.upstream_out,
            self.downstream_in,
            self.downstream_out,
        ]
    }
}

/// The last `&` code the bridge sent of its own, and when.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LastError {
    /// The code ([`codes`]).
    pub code: u16,
    /// The tick (ms) it was sent.
    pub at_ms: u32,
}

/// Name and width (hex digits) of every field of the reply, in order.
pub const FIELDS: [(&str, u8); 29] = [
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
    ("xoff_released", 8),
    ("last_error", 3),
    ("last_error_ms", 8),
];

/// The widths of [`FIELDS`] alone: what the bridge needs to write the
/// reply, without linking the names into the firmware.
// Indexing in a const initialiser is checked at compile time.
#[allow(clippy::indexing_slicing)]
const WIDTHS: [u8; FIELDS.len()] = {
    let mut w = [0; FIELDS.len()];
    let mut i = 0;
    while i < FIELDS.len() {
        w[i] = FIELDS[i].1;
        i += 1;
    }
    w
};

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

/// Digits of `xoff_released`, the field layout 2 added.
const XOFF_WIDTH: usize = 8;

/// Layout version sent in the first field.
pub const LAYOUT: u8 = 2;

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
    pub fn values(&self) -> [u64; 29] {
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
            u64::from(s.xoff_released),
            u64::from(code),
            u64::from(at),
        ]
    }

    /// Writes the reply into `buf`; returns its length.
    pub fn emit(&self, station: Station, buf: &mut [u8]) -> iai_protocol_b::error::Result<usize> {
        let values = self.values();
        emit_frame(
            buf,
            Header::Response,
            station,
            codes::STATUS_QUERY,
            Default::default(),
            |w: &mut Writer<'_>| {
                for (&width, &v) in WIDTHS.iter().zip(values.iter()) {
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
/// A reply of layout 1 (before `xoff_released`) reads with that field 0.
pub fn parse(body: &[u8]) -> Option<[(&'static str, u64); FIELDS.len()]> {
    let layout_1 = body.get(..2) == Some(b"01") && body.len() == DATA_LEN - XOFF_WIDTH;
    if body.len() != DATA_LEN && !layout_1 {
        return None;
    }
    let mut out = [("", 0u64); FIELDS.len()];
    let mut at = 0;
    for (slot, &(name, width)) in out.iter_mut().zip(FIELDS.iter()) {
        if layout_1 && name == "xoff_released" {
            *slot = (name, 0);
            continue;
        }
        let w = usize::from(width);
        let digits = body.get(at..at + w)?;
        let v = iai_protocol_b::field::decode_unsigned(FieldSpec::hex(width), digits, at).ok()?;
        *slot = (name, v);
        at += w;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;

    #[test]
    fn stats_fields_spell_the_debug_text() {
        use std::format;
        use std::string::String;
        let stats = Stats {
            forwarded: 1,
            streams_ok: 7,
            upstream_in: u64::MAX,
            downstream_out: 42,
            ..Stats::default()
        };
        let mut text = String::from("Stats { ");
        for (i, (name, value)) in Stats::NAMES.iter().zip(stats.values()).enumerate() {
            if i > 0 {
                text.push_str(", ");
            }
            text.push_str(&format!("{name}: {value}"));
        }
        text.push_str(" }");
        assert_eq!(text, format!("{stats:?}"));
    }
}
