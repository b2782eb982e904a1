//! A `no_std`, allocation-free, panic-free implementation of IAI's
//! "protocol B" serial interface of TTA, X-SEL, SSEL, ASEL and PSEL
//! controllers. Start with the [`guide`]: three runnable walkthroughs.
//!
//! Modules, lowest layer first (each imports only those before it):
//! - [`error`], [`limits`], [`clock`]: `Error` (what a frame or value is)
//!   and `Failure` (how an exchange ended); the controllers' buffer
//!   limits; the millisecond clock
//! - [`checksum`], [`field`], [`hex`], [`axis`]: SC; fixed-width hex and
//!   decimal fields; 2, 4 or 8 hex digits per call (the fast paths); axis
//!   patterns
//! - [`catalogue`]: every message's ID, name, kind, families, resend
//!   safety and reply kind, written once
//! - [`frame`], [`decoder`]: `Frame`, a checked zero-copy view of one
//!   frame, and the emitter; `FrameDecoder<N>`: push bytes in, frames out,
//!   resynchronising after noise
//! - [`message`], [`position`]: typed messages, each a short field
//!   declaration bound to its catalogue entry; `PositionRecord` and the
//!   position-stream layouts they share
//! - [`profile`], [`table`]: what each kind of controller accepts;
//!   position tables of any size, encoded and decoded record by record
//! - [`line`](mod@line): one line to a controller: the command on it, how
//!   a reply is matched, chapter 5's timeouts and resends, and every reply
//!   that may still arrive
//! - [`engine`], [`io`]: the one shape every engine has and the one driver
//!   that moves its bytes (non-blocking, blocking, `nb`, async); `embedded-io`
//!   and `nb` glue
//! - [`client`], [`transfer`], [`readback`], [`relay`], [`upload`]: any
//!   command and its typed reply; a table written in confirmed, verified
//!   commands; a table read back in confirmed windows; a command passed on
//!   as it came; a table sent as one command to a bridge that splits it
//!
//! Every public type has one path, the public module that holds it
//! (`iai_protocol_b::line::Line`): the root re-exports nothing; a module
//! re-exports only from its own private submodules. Features, none by
//! default: `async` (the engines over `embedded-io-async`), `defmt`
//! (`defmt::Format` on the public types), `std` (`hosted`: the engines
//! over a TCP socket or a serial port, blocking without spinning). No
//! function panics on any input: the lints below forbid `unwrap`,
//! `expect`, `panic!` and indexing.
#![no_std]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]

pub mod axis;
pub mod catalogue;
pub mod checksum;
pub mod client;
pub mod clock;
mod codec;
pub mod decoder;
pub mod engine;
pub mod error;
pub mod field;
pub mod frame;
pub mod guide;
mod header;
pub mod hex;
#[cfg(feature = "std")]
pub mod hosted;
pub mod io;
pub mod limits;
pub mod line;
pub mod message;
pub mod position;
pub mod profile;
pub mod readback;
pub mod relay;
pub mod table;
pub mod transfer;
pub mod upload;
mod window;

#[cfg(test)]
mod testing;
