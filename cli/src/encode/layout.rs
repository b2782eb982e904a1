//! The layout of a message, found from the core's decoder: a sample body
//! it accepts, and the field tree of that sample. Also the message
//! lookup by ID or name.

use std::collections::BTreeMap;

use iai_protocol_b::catalogue;
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::message::{decode_any, AnyMessage};

use crate::fields::{tree, Node};

/// Digits tried, in order, at an offset the decoder refuses.
const DIGITS: &[u8] = b"1023456789ABCDEF ";

pub(crate) fn frame_bytes(
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
    use iai_protocol_b::error::Error as E;
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
