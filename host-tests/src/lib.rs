//! Host-side tools and test support for `iai-protocol-b`: the controller
//! simulator, generated position tables, the QEMU runner.
pub mod bridge;
pub mod cli;
pub mod link;
pub mod naive;
pub mod qemu;
pub mod sim;
pub mod table;
