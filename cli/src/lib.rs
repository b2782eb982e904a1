//! `iai`, a host tool for IAI protocol B controllers, as a library: the
//! capture inspector, the message encoder, CSV position tables and the
//! links (serial port, TCP).
//!
//! The protocol facts (message layouts, limits, engines) all come from the
//! core crate `iai-protocol-b`; this crate only drives them. The
//! controller simulator is the crate `iai-simulator`; [`simulate`] adds
//! the `iai simulate` frame log.

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
pub mod simulate;
pub mod table;
pub mod text;
