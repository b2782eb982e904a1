//! The `iai` command-line tool: capture inspector, frame encoder and the
//! controller simulator on a TCP port. `src/bin/iai.rs` parses the
//! arguments and calls these modules.

pub mod encode;
pub mod fields;
pub mod inspect;
pub mod simulate;
pub mod text;
