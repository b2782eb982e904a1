//! Host-side tools and test support for `iai-protocol-b`: generated
//! position tables, the QEMU runner, the bridge test harness, the gateway
//! (the bridge under QEMU on a TCP port). The
//! controller simulator is the crate `iai-simulator`.
pub mod bridge;
pub mod gateway;
pub mod link;
pub mod modbus_model;
pub mod naive;
pub mod qemu;
pub mod rtu_relay;
pub mod table;
