//! # iai-protocol-b
//!
//! A `no_std`, allocation-free, panic-free implementation of IAI's
//! "protocol B" serial interface, spoken by TTA, X-SEL, SSEL, ASEL and PSEL
//! controllers.
//!
//! ```text
//! '!' station(2) ID(3) fields… SC(2) CR LF      command      (host → controller)
//! '#' station(2) ID(3) fields… SC(2) CR LF      normal reply (controller → host)
//! '&' station(2) code(3)       SC(2) CR LF      error reply
//! ```
//!
//! Layers, lowest first (each imports only those before it):
//! - [`checksum`], [`field`], [`hex`], [`axis`]: the checksum, fixed-width
//!   digits, axis patterns; [`catalogue`]: every message's rules, once;
//! - [`frame`]: a checked zero-copy view of one frame, and the emitter;
//! - [`decoder`]: a push decoder that finds frames in a byte stream;
//! - [`message`], [`position`]: typed messages declared field by field,
//!   and the position-table records they share;
//! - [`table`]: position tables of any size, record by record;
//! - [`line`](mod@line): one line to a controller, what is on it and what may still
//!   arrive; [`engine`]: the shape of the engines and their driver loops;
//! - [`client`], [`transfer`], [`readback`], [`relay`]: any command and its
//!   reply; a table written in confirmed, verified commands; a table read
//!   back; a command passed on as it came;
//! - [`profile`], [`io`]: what each controller accepts; UART glue.
//!
//! Start with the [`guide`]: three runnable walkthroughs.
//!
//! # Paths
//! Every public type has one path: the public module that holds it
//! (`iai_protocol_b::line::Line`, `iai_protocol_b::client::Client`). The
//! crate root re-exports nothing; a module re-exports only from its own
//! private submodules.
//!
//! # Cargo features
//! - `async`: the engines over an `embedded-io-async` UART
//!   (`engine::run_async`, `Client::call_async`, `Transfer::run_async`,
//!   `ReadBack::run_async`) and the `AsyncClock` trait in [`clock`].
//! - `defmt`: `defmt::Format` for the public types.
//! - `std`: `hosted::StdLink`, the engines over a TCP
//!   socket or a serial port, blocking without spinning.
//!
//! Neither is on by default. The minimum supported Rust version is 1.87.
//!
//! # Panic freedom
//! No function of this crate panics on any input: buffer accesses use
//! `get`, arithmetic on untrusted values is checked or saturating, and the
//! lints below forbid `unwrap`, `expect`, `panic!` and indexing.
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
mod window;

#[cfg(test)]
mod testing;
