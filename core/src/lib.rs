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
//! Layers, lowest first:
//! - [`checksum`], [`field`], [`axis`]: checksum, fixed-width digits, axis patterns;
//! - [`frame`]: a checked zero-copy view of one frame and the emitter;
//! - [`decoder`]: a push decoder that finds frames in a byte stream;
//! - [`message`]: typed messages declared field by field;
//! - [`position`]: position-table records shared by the position messages;
//! - [`stream`]: position tables of any size, encoded and decoded record by
//!   record through fixed buffers;
//! - [`transfer`], [`readback`]: write a table in confirmed, controller-sized
//!   commands and read it back, with timeouts and retries;
//! - [`profile`]: the limits of each kind of controller;
//! - [`io`]: glue to `embedded-io` and `nb` drivers.
//!
//! Start with the [`guide`]: three runnable walkthroughs (receive a frame,
//! send a command and read the reply, stream a position table).
//!
//! # Cargo features
//! - `async`: `Transfer::run_async` and the `AsyncClock` trait in
//!   [`transfer`], the transfer engine over an `embedded-io-async` UART.
//! - `defmt`: `defmt::Format` for the public types.
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
pub mod codec;
pub mod decoder;
pub mod drive;
pub mod error;
pub mod exchange;
pub mod field;
pub mod frame;
pub mod guide;
pub mod header;
pub mod hex;
pub mod io;
pub mod limits;
pub mod message;
pub mod position;
pub mod profile;
pub mod readback;
pub mod stream;
pub mod transfer;

pub use error::{Error, Result};
