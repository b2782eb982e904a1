//! The configuration messages the bridge answers on its own station: their
//! bodies, for the bridge and for a host (`iai bridge config`). Fields are
//! upper-case hex digits; a password travels as the hex of its bytes (it
//! may hold `!`, `#` or `&`, which a frame's text may not), in the clear as
//! on the web page without TLS: keep the host port on the plant's network.
//!
//! | ID | command body | reply body |
//! |---|---|---|
//! | B20 read | offset (3), and for the verifier block the password | offset (3), sequence (8; `FFFFFFFF`: no page), flags (1: bit 0 password set, bit 1 restart pending), the 64 bytes at offset (fewer at the end of the host part) |
//! | B21 stage | offset (3), 8 to 64 bytes (a multiple of 8) | the next offset (3) |
//! | B22 apply | CRC-32C of the staged host part (8, `config::editor::host_crc`), password | sequence (8), restart needed (1) |
//! | B23 restart | password | none; the gateway restarts 200 ms later |
//! | B24 password | current password's length in bytes (2; 00 when none is set), current password, new password | sequence (8) |
//!
//! Offsets are within the page's host part ([`HOST_LEN`] bytes), 64 bytes
//! apart ([`WINDOW`]); a host stages the whole host part in order from 0
//! and applies it. B20 also reads the verifier block ([`ACCESS_AT`]) for a
//! host that gives the password (to carry a whole page to a programmer). Refusals are `&` codes: [`codes::WRONG_PASSWORD`],
//! [`codes::NO_PASSWORD`], [`codes::STAGING`], [`codes::INVALID_PAGE`],
//! [`codes::STORE_FAILED`], [`codes::MALFORMED`].

use iai_protocol_b::field::{FieldSpec, Writer};
use iai_protocol_b::frame::{emit_frame, Header, Station};

use super::access::ACCESS_LEN;
use super::editor::Refusal;
use super::page::{ACCESS_AT, HOST_LEN, WINDOW};
use crate::codes;

/// Bytes of a password at most.
pub const PASSWORD_MAX: usize = 64;

/// A configuration command, as the bridge reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request<'a> {
    /// Read the page at this offset.
    Read {
        /// Offset within the host part, or of the verifier block.
        at: usize,
        /// The password's hex digits (needed for the verifier block).
        password: &'a [u8],
    },
    /// Stage these bytes (as hex digits) at this offset.
    Stage {
        /// Offset.
        at: usize,
        /// Two hex digits per byte.
        digits: &'a [u8],
    },
    /// Apply the staged page.
    Apply {
        /// CRC-32 of the staged host part.
        crc: u32,
        /// The password's hex digits.
        password: &'a [u8],
    },
    /// Restart.
    Restart {
        /// The password's hex digits.
        password: &'a [u8],
    },
    /// Set a new password.
    Password {
        /// The current password's hex digits (empty when none is set).
        current: &'a [u8],
        /// The new password's hex digits.
        new: &'a [u8],
    },
}

impl<'a> Request<'a> {
    /// The command with message ID `id` and body `body`: `None` if `id` is
    /// not a configuration message, `Some(Err(()))` if its body is
    /// malformed.
    pub fn parse(id: u16, body: &'a [u8]) -> Option<Result<Request<'a>, ()>> {
        let hex = |s: &[u8]| s.iter().all(u8::is_ascii_hexdigit);
        let field = |at: usize, len: usize| {
            body.get(at..at + len)
                .filter(|d| hex(d))
                .and_then(crate::text::parse_hex)
        };
        let offset = || field(0, 3).map(|v| v as usize);
        let password = |d: &'a [u8]| {
            (d.len().is_multiple_of(2) && d.len() <= 2 * PASSWORD_MAX && hex(d)).then_some(d)
        };
        let r = match id {
            codes::CONFIG_READ => match (offset(), password(body.get(3..).unwrap_or(&[]))) {
                (Some(at), Some(password)) => Some(Request::Read { at, password }),
                _ => None,
            },
            codes::CONFIG_STAGE => {
                let digits = body.get(3..).unwrap_or(&[]);
                let whole =
                    digits.len().is_multiple_of(16) && (16..=2 * WINDOW).contains(&digits.len());
                match (offset(), whole && hex(digits)) {
                    (Some(at), true) => Some(Request::Stage { at, digits }),
                    _ => None,
                }
            }
            codes::CONFIG_APPLY => match (field(0, 8), password(body.get(8..).unwrap_or(&[]))) {
                (Some(crc), Some(password)) => Some(Request::Apply { crc, password }),
                _ => None,
            },
            codes::RESTART => password(body).map(|password| Request::Restart { password }),
            codes::CONFIG_PASSWORD => field(0, 2).and_then(|n| {
                let split = 2 + 2 * n as usize;
                let current = password(body.get(2..split)?)?;
                let new = password(body.get(split..)?)?;
                Some(Request::Password { current, new })
            }),
            _ => return None,
        };
        Some(r.ok_or(()))
    }
}

/// The bytes of `digits` (two hex digits each) into `out`; `None` if they
/// do not fit or are not hex.
pub fn unhex<'b>(digits: &[u8], out: &'b mut [u8]) -> Option<&'b [u8]> {
    let n = digits.len() / 2;
    let dst = out.get_mut(..n)?;
    for (d, pair) in dst.iter_mut().zip(digits.chunks_exact(2)) {
        *d = u8::try_from(crate::text::parse_hex(pair)?).ok()?;
    }
    Some(dst)
}

/// The `&` code for a refusal.
pub fn refusal_code(r: &Refusal) -> u16 {
    match r {
        Refusal::WrongPassword | Refusal::Shut => codes::WRONG_PASSWORD,
        Refusal::NoPassword => codes::NO_PASSWORD,
        Refusal::Staging => codes::STAGING,
        Refusal::Invalid(_) | Refusal::Setting(_) | Refusal::BadPassword(_) => codes::INVALID_PAGE,
        Refusal::Store(_) => codes::STORE_FAILED,
    }
}

/// What a B20 reply says besides the bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PageInfo {
    /// The sequence number of the page in force.
    pub seq: Option<u32>,
    /// A password is set.
    pub password_set: bool,
    /// Changes were written that take effect at the next start.
    pub restart_pending: bool,
}

/// Emits the B20 reply for `bytes` read at `at` into `buf`; its length.
pub fn emit_read_reply(
    buf: &mut [u8],
    station: Station,
    at: usize,
    info: PageInfo,
    bytes: &[u8],
) -> iai_protocol_b::error::Result<usize> {
    emit_frame(
        buf,
        Header::Response,
        station,
        codes::CONFIG_READ,
        Default::default(),
        |w: &mut Writer<'_>| {
            w.unsigned(FieldSpec::hex(3), at as u64)?;
            w.unsigned(FieldSpec::hex(8), u64::from(info.seq.unwrap_or(u32::MAX)))?;
            let flags = u64::from(info.password_set) | u64::from(info.restart_pending) << 1;
            w.unsigned(FieldSpec::hex(1), flags)?;
            for &b in bytes {
                w.unsigned(FieldSpec::hex(2), u64::from(b))?;
            }
            Ok(())
        },
    )
}

/// Emits a reply with message ID `id` and fixed-width hex fields
/// `(value, digits)` into `buf`; its length.
pub fn emit_reply(
    buf: &mut [u8],
    station: Station,
    id: u16,
    fields: &[(u64, u8)],
) -> iai_protocol_b::error::Result<usize> {
    emit_frame(
        buf,
        Header::Response,
        station,
        id,
        Default::default(),
        |w: &mut Writer<'_>| {
            for &(v, digits) in fields {
                w.unsigned(FieldSpec::hex(digits), v)?;
            }
            Ok(())
        },
    )
}

/// The window read at `at`: its length ([`WINDOW`], fewer at the end of
/// the host part; the verifier block at [`ACCESS_AT`]).
pub fn window_at(at: usize) -> Option<usize> {
    if at == ACCESS_AT {
        return Some(ACCESS_LEN);
    }
    (at < HOST_LEN && at.is_multiple_of(WINDOW)).then(|| WINDOW.min(HOST_LEN - at))
}

/// A B20 reply's body: its offset, what it says, and its bytes (into
/// `out`).
pub fn parse_read_reply<'b>(body: &[u8], out: &'b mut [u8]) -> Option<(usize, PageInfo, &'b [u8])> {
    let at = crate::text::parse_hex(body.get(..3)?)? as usize;
    let seq = crate::text::parse_hex(body.get(3..11)?)?;
    let flags = crate::text::parse_hex(body.get(11..12)?)?;
    let data = unhex(body.get(12..)?, out)?;
    let info = PageInfo {
        seq: (seq != u32::MAX).then_some(seq),
        password_set: flags & 1 != 0,
        restart_pending: flags & 2 != 0,
    };
    Some((at, info, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_bodies() {
        assert_eq!(
            Request::parse(codes::CONFIG_READ, b"040"),
            Some(Ok(Request::Read {
                at: 0x40,
                password: b""
            }))
        );
        assert_eq!(
            Request::parse(codes::CONFIG_READ, b"3B83132"),
            Some(Ok(Request::Read {
                at: 0x3B8,
                password: b"3132"
            }))
        );
        assert_eq!(Request::parse(codes::CONFIG_READ, b"04"), Some(Err(())));
        assert_eq!(Request::parse(codes::CONFIG_READ, b"0401"), Some(Err(())));
        assert_eq!(window_at(0), Some(64));
        assert_eq!(window_at(896), Some(56));
        assert_eq!(window_at(952), Some(64));
        assert_eq!(window_at(960), None);
        assert_eq!(window_at(65), None);
        assert_eq!(Request::parse(codes::STATUS_QUERY, b""), None);
        let stage = b"0400123456789ABCDEF";
        assert_eq!(
            Request::parse(codes::CONFIG_STAGE, stage),
            Some(Ok(Request::Stage {
                at: 0x40,
                digits: b"0123456789ABCDEF"
            }))
        );
        // Not a whole 8 bytes.
        assert_eq!(Request::parse(codes::CONFIG_STAGE, b"04001"), Some(Err(())));
        assert_eq!(
            Request::parse(codes::CONFIG_APPLY, b"CBF4392631323334"),
            Some(Ok(Request::Apply {
                crc: 0xCBF4_3926,
                password: b"31323334"
            }))
        );
        assert_eq!(
            Request::parse(codes::CONFIG_PASSWORD, b"023132414243"),
            Some(Ok(Request::Password {
                current: b"3132",
                new: b"414243"
            }))
        );
        assert_eq!(
            Request::parse(codes::CONFIG_PASSWORD, b"00414243"),
            Some(Ok(Request::Password {
                current: b"",
                new: b"414243"
            }))
        );
        assert_eq!(
            Request::parse(codes::CONFIG_PASSWORD, b"05414243"),
            Some(Err(()))
        );
        assert_eq!(Request::parse(codes::RESTART, b"313"), Some(Err(())));
        let mut out = [0u8; 4];
        assert_eq!(unhex(b"21232526", &mut out), Some(&b"!#%&"[..]));
    }

    #[test]
    fn a_read_reply_round_trip() {
        let mut buf = [0u8; 200];
        let info = PageInfo {
            seq: Some(7),
            password_set: true,
            restart_pending: false,
        };
        let n = emit_read_reply(&mut buf, Station(0xBB), 0x3C0, info, &[0x49, 0x41, 0xFF]).unwrap();
        assert_eq!(&buf[..n - 4], b"#BBB203C00000000714941FF".as_slice());
        let f = iai_protocol_b::frame::Frame::new_checked(&buf[..n], Default::default()).unwrap();
        let mut out = [0u8; 64];
        let (at, got, data) = parse_read_reply(f.body(), &mut out).unwrap();
        assert_eq!((at, got, data), (0x3C0, info, &[0x49, 0x41, 0xFF][..]));
    }
}
