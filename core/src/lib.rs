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
//! - [`position`]: position-table records shared by the position messages.
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
pub mod checksum;
pub mod decoder;
pub mod error;
mod exchange;
pub mod field;
pub mod frame;
pub mod io;
pub mod message;
pub mod position;
pub mod profile;
pub mod readback;
pub mod stream;
pub mod transfer;

pub use error::{Error, Result};
