//! What an `&` code means, where the tool can know: the bridge's own codes
//! (its range and meanings are the bridge firmware's, reused here) and
//! the simulator's. A controller's codes are in its manual, not in the
//! protocol documents (TTA p. 15, 2003 p. 13).

use firmware_example::codes as bridge;

/// "the controller answered with error code XXX", or the bridge's code
/// with its meaning.
pub fn answered_with(code: u16) -> String {
    match bridge::meaning(code) {
        Some(m) => format!("the bridge on the line answered with its code {code:03X} ({m})"),
        None if bridge::is_bridge_code(code) => {
            format!("the bridge on the line answered with its code {code:03X}")
        }
        None => format!("the controller answered with error code {code:03X}"),
    }
}
