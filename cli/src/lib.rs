//! `iai`, a host tool for IAI protocol B controllers, as a library: the
//! capture inspector, the message encoder, CSV position tables, the
//! links (serial port, TCP) and the controller simulator.
//!
//! The protocol facts (message layouts, limits, engines) all come from the
//! core crate `iai-protocol-b`; this crate only drives them.

pub mod bridge;
pub mod codes;
pub mod csvtable;
pub mod encode;
pub mod fields;
pub mod inspect;
pub mod link;
pub mod meaning;
pub mod probe;
pub mod resume;
pub mod send;
pub mod sim;
pub mod simulate;
pub mod table;
pub mod text;
