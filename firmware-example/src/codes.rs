//! The bridge's own error codes and message IDs.
//!
//! Everything the bridge says for itself uses the range [`RANGE`]
//! (`B00`..`BFF`): `&` error codes, and the message IDs it answers on its
//! own station ([`STATUS_QUERY`], and the configuration messages
//! [`CONFIG_READ`] to [`CONFIG_PASSWORD`], laid out in
//! [`crate::config::wire`]).
//!
//! Assumption: no controller sends an `&` code in this range. The
//! controllers' own code list is published in neither the TTA manual nor
//! the 2003 X-SEL specification (both only say that the number identifies
//! the cause, TTA p. 15, 2003 p. 13), so this cannot be checked; every
//! message ID either document lists is 2xxH. A host that sees a code in
//! [`RANGE`] knows the bridge produced it, so it must not ask the
//! controller for 216H details about it.

use core::ops::RangeInclusive;

/// Codes and IDs reserved for the bridge.
pub const RANGE: RangeInclusive<u16> = 0xB00..=0xBFF;

/// Whether `code` (of an `&` reply) is the bridge's own.
pub const fn is_bridge_code(code: u16) -> bool {
    code >= *RANGE.start() && code <= *RANGE.end()
}

/// Message ID of the status query, sent to the bridge's own station.
pub const STATUS_QUERY: u16 = 0xB00;
/// Message ID: read 64 bytes of the configuration page in force.
pub const CONFIG_READ: u16 = 0xB20;
/// Message ID: stage up to 64 bytes of a new configuration page.
pub const CONFIG_STAGE: u16 = 0xB21;
/// Message ID: apply the staged page (with the password).
pub const CONFIG_APPLY: u16 = 0xB22;
/// Message ID: restart the gateway (with the password).
pub const RESTART: u16 = 0xB23;
/// Message ID: set a new password.
pub const CONFIG_PASSWORD: u16 = 0xB24;

/// `&` B01: the host's 26DH was malformed (wrong checksum, found at its
/// end; bad digit; bad axis pattern; missing CR LF; count mismatch).
pub const UPSTREAM_FRAME: u16 = 0xB01;
/// `&` B02: the controller did not confirm a 26DH chunk after 3 sends.
pub const CONTROLLER_TIMEOUT: u16 = 0xB02;
/// `&` B04: the host's 26DH stopped in its middle for
/// [`crate::bridge::UPSTREAM_STALL_MS`].
pub const UPSTREAM_STALLED: u16 = 0xB04;
/// `&` B05: the 26DH transfer could not be set up.
pub const INTERNAL: u16 = 0xB05;
/// `&` B06: the command policy refuses this message ID; nothing was sent to
/// the controller.
pub const REFUSED: u16 = 0xB06;
/// `&` B07: bytes of the host's 26DH were lost on the way in (receive
/// overrun: the host sent faster than the bridge could take, e.g. with flow
/// control off). Chunks sent before the loss hold only records decoded
/// from bytes received before it.
pub const UPSTREAM_OVERRUN: u16 = 0xB07;
/// `&` B08: the controller's reply carries an XON or XOFF byte in its text
/// (200H, 216H) and XON/XOFF flow control is on: relaying it would stop or
/// start the host's transmitter, so it is not relayed.
pub const XON_XOFF_IN_TEXT: u16 = 0xB08;
/// `&` B09: a command to the bridge's own station with an ID it does not
/// answer.
pub const UNKNOWN_QUERY: u16 = 0xB09;
/// `&` B0A: a 26DH chunk still read back different from what was written
/// after two rewrites (the bridge reads every chunk back with 21FH before
/// it takes more from the host).
pub const VERIFY_MISMATCH: u16 = 0xB0A;
/// `&` B0B (protocol B over TCP, module `net`): another host holds the
/// bridge. A connection made while one is being served is held, unread,
/// for 1 s (`net::host::HOLD_MS`); if that host is still served then, it
/// gets this reply on the bridge's own station, unasked, and is closed.
/// The host being served is not disturbed.
pub const HOST_BUSY: u16 = 0xB0B;
/// `&` B0C: the password is wrong, or a wrong one came less than a second
/// ago (`config::access::LOCKOUT_MS`); nothing was changed.
pub const WRONG_PASSWORD: u16 = 0xB0C;
/// `&` B0D: no password is set yet: a fresh gateway takes no change but
/// a new password ([`CONFIG_PASSWORD`]).
pub const NO_PASSWORD: u16 = 0xB0D;
/// `&` B0E: the staged page is incomplete, out of order, not what the
/// apply describes, or was discarded by another change; stage it again
/// from offset 0.
pub const STAGING: u16 = 0xB0E;
/// `&` B0F: a block of the new page does not check, or the new password
/// is not 8 to 64 characters without control characters; nothing was
/// changed.
pub const INVALID_PAGE: u16 = 0xB0F;
/// `&` B10: the configuration page could not be written (the flash
/// failed, or this board keeps no page it can write).
pub const STORE_FAILED: u16 = 0xB10;
/// `&` B11: a configuration message whose body is not laid out as
/// [`crate::config::wire`] says.
pub const MALFORMED: u16 = 0xB11;

/// What each code says, in a few words (for tools that show them).
pub const fn meaning(code: u16) -> Option<&'static str> {
    Some(match code {
        UPSTREAM_FRAME => "the host's 26DH was malformed",
        CONTROLLER_TIMEOUT => "the controller did not confirm a chunk after 3 sends",
        UPSTREAM_STALLED => "the host's 26DH stopped in its middle",
        INTERNAL => "the transfer could not be set up",
        REFUSED => "the command policy refuses this message",
        UPSTREAM_OVERRUN => "bytes of the host's 26DH were lost on the way in",
        XON_XOFF_IN_TEXT => "the controller's reply carries XON/XOFF in its text",
        UNKNOWN_QUERY => "the bridge does not answer this message ID",
        VERIFY_MISMATCH => {
            "a chunk still read back different after two rewrites, or a record was not stored where it was written"
        }
        HOST_BUSY => "another host is connected to the bridge",
        WRONG_PASSWORD => "the password is wrong (or a wrong one came less than a second ago)",
        NO_PASSWORD => "no password is set yet: set one first",
        STAGING => "the staged configuration is incomplete, out of order or was discarded",
        INVALID_PAGE => "the new configuration or password does not check",
        STORE_FAILED => "the configuration could not be written",
        MALFORMED => "a configuration message with a malformed body",
        _ => return None,
    })
}

/// Every `&` code the bridge sends, for documentation and tests.
pub const ALL: [u16; 16] = [
    UPSTREAM_FRAME,
    CONTROLLER_TIMEOUT,
    UPSTREAM_STALLED,
    INTERNAL,
    REFUSED,
    UPSTREAM_OVERRUN,
    XON_XOFF_IN_TEXT,
    UNKNOWN_QUERY,
    VERIFY_MISMATCH,
    HOST_BUSY,
    WRONG_PASSWORD,
    NO_PASSWORD,
    STAGING,
    INVALID_PAGE,
    STORE_FAILED,
    MALFORMED,
];

/// Bytes that end a QEMU test run: ESC `Q` `!` after
/// [`crate::bridge::QUIT_GUARD_MS`] of upstream silence, outside any frame,
/// when [`crate::config::Config::quit_sequence`] is on.
pub const QUIT: [u8; 3] = [0x1B, b'Q', b'!'];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_is_in_the_range_and_distinct() {
        for (i, c) in ALL.iter().enumerate() {
            assert!(is_bridge_code(*c));
            assert!(!ALL[..i].contains(c));
        }
        assert!(is_bridge_code(STATUS_QUERY));
        for id in [
            CONFIG_READ,
            CONFIG_STAGE,
            CONFIG_APPLY,
            RESTART,
            CONFIG_PASSWORD,
        ] {
            assert!(is_bridge_code(id));
            assert!(!ALL.contains(&id));
        }
        assert!(!is_bridge_code(0x0E1));
    }
}
