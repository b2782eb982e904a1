//! The configuration page: 1 KiB of independent blocks, each with its own
//! magic, version and CRC-32, each decoded to its defaults when blank or
//! invalid, so that one block can change (or be added) without the others.
//!
//! | offset | bytes | block | module |
//! |---|---|---|---|
//! | 0 | up to 256 | the bridge (`IAIB`) | [`crate::config`] |
//! | 256 | up to 256 | the Sparkplug node (`IAIS`) | `net::sparkplug` |
//! | 512 | 32 | the network (`IAIN`) | [`crate::net::config`] |
//! | 576 | 16 | the web page (`IAIW`) | [`crate::config::access`] |
//! | 952 | 64 | the password verifier (`IAIA`) | [`crate::config::access`] |
//! | 1016 | 8 | the store's sequence number and the page's CRC | [`crate::config::store`] |
//!
//! A host reads and writes the page's first [`HOST_LEN`] bytes: the
//! verifier block is the firmware's alone (it never leaves the gateway; a
//! new password is sent, and the gateway computes its verifier), and the
//! trailer is the store's.

/// Bytes of the page.
pub const PAGE_LEN: usize = 1024;
/// Where the bridge's block starts.
pub const BRIDGE_AT: usize = 0;
/// Where the Sparkplug node's block starts.
pub const SPARKPLUG_AT: usize = 256;
/// Bytes of the Sparkplug node's block (the Ethernet build's; other builds
/// leave its place alone).
pub const SPARKPLUG_LEN: usize = 256;
/// Where the network block starts.
pub const NET_AT: usize = crate::net::config::BLOCK_OFFSET;
/// Where the web block starts.
pub const WEB_AT: usize = 576;
/// Where the password verifier's block starts.
pub const ACCESS_AT: usize = 952;
/// The bytes a host reads and writes: `0..HOST_LEN`.
pub const HOST_LEN: usize = ACCESS_AT;
/// Where the store's trailer starts: the sequence number (4 bytes), then
/// the CRC-32 of everything before it (4 bytes).
pub const TRAILER_AT: usize = 1016;
/// Bytes a host reads or writes per message (so that 64 bytes of a
/// flash that writes 8 at a time are always whole writes).
pub const WINDOW: usize = 64;

// The blocks do not overlap, and every boundary a host writes up to is a
// whole number of 8-byte flash writes.
const _: () = assert!(BRIDGE_AT + crate::config::BLOCK_LEN <= SPARKPLUG_AT);
const _: () = assert!(SPARKPLUG_AT + SPARKPLUG_LEN <= NET_AT);
const _: () = assert!(NET_AT + 32 <= WEB_AT && WEB_AT + 16 <= ACCESS_AT);
const _: () = assert!(ACCESS_AT + 64 == TRAILER_AT && TRAILER_AT + 8 == PAGE_LEN);
const _: () = assert!(HOST_LEN.is_multiple_of(8) && WINDOW.is_multiple_of(8));
