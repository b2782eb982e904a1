//! The message catalogue, one short declaration per message, in one
//! module per family: controller state queries (`status`), moves and axis
//! commands (`motion`), the position table (`positions`), ports, flags
//! and variables (`io`), program control and system commands (`program`)
//! and SCARA queries (`scara`). Every type is re-exported here.
//!
//! Field names, widths, radix, signedness and units follow `messages.toml`
//! (TTA manual section 4-3, completed from the 2003 X-SEL specification).
//! Count fields are not stored: a [`Repeated`](crate::codec::Repeated)
//! group writes its own count.
//! Every message ID has a command type and, except 25BH, a response type;
//! messages whose reply carries no data have an empty response struct.
//!
//! A few Rust names predate the full catalogue and differ from its field
//! names: 212H/2A1H/2A3H `sensor_input_status` and `error_code`
//! (catalogue: `axis_sensor_input_status`, `axis_error_code`), 215H
//! `critical_system_error`, `latest_system_error`, `status_byte_N`
//! (catalogue: `…_number`, `system_status_byte_N`) and 216H `message`
//! (catalogue: `message_char`).
//!
//! Layouts marked **inferred** in the family modules are readings the
//! sources do not state outright; `messages.toml` has the reasoning.

mod io;
mod motion;
mod positions;
mod program;
mod scara;
mod status;

pub use io::*;
pub use motion::*;
pub use positions::*;
pub use program::*;
pub use scara::*;
pub use status::*;

use crate::field::FieldSpec;

/// Declares responses that carry no data (the bare 10-byte envelope).
macro_rules! bare_responses {
    ($( $(#[$m:meta])* $name:ident; )*) => {
        $( wire! { $(#[$m])* pub struct $name {} } )*
    };
}

const fn hex(w: u8) -> FieldSpec {
    FieldSpec::hex(w)
}
const fn shex(w: u8) -> FieldSpec {
    FieldSpec::signed_hex(w)
}
const fn dec(w: u8) -> FieldSpec {
    FieldSpec::dec(w)
}
const fn text(w: u8) -> FieldSpec {
    FieldSpec::text(w)
}
use bare_responses;

/// What the tests of every family share: parsing and emitting whole frames.
#[cfg(test)]
mod test_support {
    use crate::checksum::BypassPolicy;
    use crate::frame::{Frame, Station};
    use crate::message::Message;

    pub(super) const ST: Station = Station(0x99);

    pub(super) fn parse<'a, M: Message<'a>>(bytes: &'a [u8]) -> crate::error::Result<M> {
        M::parse(&Frame::new_checked(bytes, BypassPolicy::CommandsOnly)?)
    }

    pub(super) fn emit<'a, M: Message<'a>>(m: &M) -> ([u8; 64], usize) {
        let mut buf = [0u8; 64];
        let n = m.emit(ST, &mut buf).unwrap();
        assert_eq!(n, m.emit_len());
        (buf, n)
    }
}
