//! Host-side tools and test support for `iai-protocol-b`.
pub mod qemu;
pub mod table;
