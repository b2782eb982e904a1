//! The protocol-B bridge as a `no_std` library: board-independent, never
//! blocking, allocation-free and panic-free, so that the same code runs on
//! a Cortex-M board and in the host model of `host-tests` (virtual time).
//!
//! - [`bridge`]: the bridge itself ([`bridge::Bridge::poll`]) and a board loop
//!   ([`bridge::run`]);
//! - [`serial`]: the rings between a UART interrupt handler and the bridge,
//!   overrun counting and receive-side flow control (XON/XOFF, RTS/CTS);
//! - [`config`]: the configuration page (its blocks, the settings table,
//!   the two-slot store, the password) and the command policy;
//! - [`status`]: the status query the bridge answers on its own station;
//! - [`codes`]: the bridge's own `&` codes and message IDs (B00..BFF);
//! - [`text`]: numbers as text without `core::fmt`;
//! - [`modbus`]: the PLC gateway, a Modbus RTU server in front of protocol
//!   B sharing the bridge's controller line.
//! - `net` (feature `ethernet`): the bridge's host side on TCP (smoltcp,
//!   the Stellaris Ethernet MAC), and the web page; without the feature
//!   only its network block ([`net::config`]), which every build's
//!   configuration page holds.
//! - `board` (a Cortex-M target and a `board-*` feature): the boards'
//!   clock, UART drivers, watchdogs, configuration store and start-up, one
//!   module per family, on top of the rest; the binaries (`src/bin/*.rs`)
//!   only say which UART is which and call their family's `run`.
//! - `bench` and `bench_line` (feature `icount-bench`): the
//!   instruction-count bench, the core's paths and the firmware's line.
//!
//! Every public type has one path, its module's (`bridge::Bridge`,
//! `serial::Port`); the crate root re-exports nothing, as in the core.
//!
//! # Panic freedom
//! Like the core: buffer accesses use `get`, arithmetic on untrusted values
//! is checked, saturating or wrapping, and the lints below forbid `unwrap`,
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

mod log;

#[cfg(all(target_os = "none", feature = "icount-bench"))]
pub mod bench;
#[cfg(all(target_os = "none", feature = "icount-bench"))]
pub mod bench_line;
#[cfg(all(
    target_os = "none",
    not(feature = "no-panic-proof"),
    any(
        feature = "board-lm3s6965",
        feature = "board-mps2-an386",
        feature = "board-stm32g030",
        feature = "board-stm32g070",
        feature = "board-b-l475e-iot01a"
    )
))]
pub mod board;
pub mod bridge;
pub mod codes;
pub mod config;
pub mod modbus;
#[cfg(feature = "ethernet")]
pub mod net;
/// The network block alone (the rest of `net` needs the `ethernet`
/// feature): the settings table reads and writes it in every build.
#[cfg(not(feature = "ethernet"))]
pub mod net {
    pub mod config;
}
pub mod serial;
pub mod status;
pub mod text;
