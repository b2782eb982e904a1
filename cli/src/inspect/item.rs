//! The entries of a listing: a checked frame with its decoded fields, a
//! position stream summarised, or an error, each with its byte offset,
//! length and, in a text log, its line and direction.

use iai_protocol_b::checksum::ChecksumField;
use iai_protocol_b::frame::{Frame, Header};
use iai_protocol_b::message::{decode_any, AnyMessage};
use iai_protocol_b::position::PositionStream;

use crate::fields::{tree, Node};

/// Where a byte came from in a text log: line number and direction prefix.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Origin {
    /// 1-based line of a text log (`None` for raw captures).
    pub line: Option<usize>,
    /// `"tx"` for `> ` / `TX ` lines, `"rx"` for `< ` / `RX ` lines.
    pub dir: Option<&'static str>,
}

/// A frame that decoded (envelope and checksum valid).
#[derive(Debug, Clone)]
pub struct FrameItem {
    /// Header kind.
    pub header: Header,
    /// Station code.
    pub station: u8,
    /// Message ID or error code.
    pub code: u16,
    /// The checksum field carried.
    pub checksum: ChecksumField,
    /// The typed message's Rust name and fields, or why it did not decode.
    pub decoded: Result<(String, Vec<Node>), String>,
}

/// A position-stream command, summarised.
#[derive(Debug, Clone)]
pub struct StreamItem {
    /// The stream's kind.
    pub kind: PositionStream,
    /// Station code.
    pub station: u8,
    /// Start number (0 where the message has none).
    pub start: u16,
    /// Records announced.
    pub count: u16,
    /// Records read.
    pub records: u16,
    /// First record read.
    pub first: Option<Vec<Node>>,
    /// Last record read.
    pub last: Option<Vec<Node>>,
    /// The checksum field carried.
    pub checksum: ChecksumField,
}

/// What one entry of the listing is.
#[derive(Debug, Clone)]
pub enum What {
    /// A checked frame.
    Frame(FrameItem),
    /// A position stream too long for the frame decoder.
    Stream(StreamItem),
    /// A broken frame or stray bytes: error kind, message and the first
    /// bytes involved.
    Error {
        /// Error kind (`Noise` for bytes outside any frame).
        kind: String,
        /// Human-readable text.
        message: String,
        /// The first bytes involved (at most 64).
        bytes: Vec<u8>,
    },
}

/// One entry of the listing.
#[derive(Debug, Clone)]
pub struct Item {
    /// Byte offset in the capture (in a text log: in the unescaped bytes).
    pub offset: u64,
    /// Length in bytes.
    pub len: u64,
    /// Where in a text log it started.
    pub origin: Origin,
    /// What it is.
    pub what: What,
}

impl Item {
    /// Whether this entry is an error: a broken frame, noise, or a frame
    /// whose body does not decode as its message.
    pub fn is_error(&self) -> bool {
        match &self.what {
            What::Error { .. } => true,
            What::Frame(f) => f.decoded.is_err(),
            What::Stream(_) => false,
        }
    }
}

/// The listing entry of a checked frame.
pub fn frame_item(f: &Frame<'_>) -> FrameItem {
    let decoded = decode_any(f).map_err(|e| e.to_string()).map(|d| {
        let name = match &d.message {
            AnyMessage::Command(c) => variant_name(&format!("{c:?}")),
            AnyMessage::Response(r) => variant_name(&format!("{r:?}")),
            AnyMessage::Error(_) => "ErrorResponse".to_string(),
        };
        (name, tree(&d.message))
    });
    FrameItem {
        header: f.header(),
        station: f.station().0,
        code: f.code(),
        checksum: f.checksum(),
        decoded,
    }
}

fn variant_name(debug: &str) -> String {
    debug
        .split(['(', ' ', '{'])
        .next()
        .unwrap_or("")
        .to_string()
}
