//! What an `&` code means, where the tool can know: the bridge's own codes
//! (its range and meanings are the bridge firmware's, reused here) and
//! the simulator's (`iai simulate`'s refusals, its module's constants). A
//! controller's codes are in its manual, not in the protocol documents
//! (TTA p. 15, 2003 p. 13), so a code outside these is only named.

use firmware_example::codes as bridge;

use iai_simulator as sim;

/// The simulator's codes and what each means (see `cli/src/sim`). They
/// are its own: a real controller may use the same numbers for something
/// else.
pub const SIMULATOR: &[(u16, &str)] = &[
    (sim::INJECTED_ERROR_CODE, "an error injected on purpose (--faults error=P)"),
    (
        sim::UNSUPPORTED_ERROR_CODE,
        "the body does not fit the message's layout, the ID is unknown or not of this profile, or a position past FFFFH",
    ),
    (
        sim::NOT_MODELLED_CODE,
        "a message the simulator does not model (or 208H with more than FFFH records)",
    ),
    (sim::SERVO_OFF_CODE, "the servo of an axis concerned is off"),
    (sim::NOT_HOMED_CODE, "a coordinate move before the axis was homed"),
    (sim::AXIS_BUSY_CODE, "the axis is still moving or homing"),
    (
        sim::NO_POSITION_CODE,
        "the position is not defined, or shares no axis with the pattern",
    ),
];

/// What the simulator means by `code`.
pub fn simulator_meaning(code: u16) -> Option<&'static str> {
    SIMULATOR.iter().find(|(c, _)| *c == code).map(|(_, m)| *m)
}

/// Who sent `code` and what it means, in a few words, when known.
pub fn meaning(code: u16) -> Option<String> {
    if let Some(m) = bridge::meaning(code) {
        return Some(format!("bridge: {m}"));
    }
    if bridge::is_bridge_code(code) {
        return Some("bridge: a code of the bridge's range this tool does not know".into());
    }
    simulator_meaning(code).map(|m| {
        format!(
            "if the controller is iai simulate: {m}; a real controller's codes are in its manual"
        )
    })
}

/// "the controller answered with error code XXX", or the bridge's code
/// with its meaning, or the simulator's.
pub fn answered_with(code: u16) -> String {
    match bridge::meaning(code) {
        Some(m) => format!("the bridge on the line answered with its code {code:03X} ({m})"),
        None if bridge::is_bridge_code(code) => {
            format!("the bridge on the line answered with its code {code:03X}")
        }
        None => match simulator_meaning(code) {
            Some(m) => format!(
                "the controller answered with error code {code:03X} (iai simulate's code: {m})"
            ),
            None => format!("the controller answered with error code {code:03X}"),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_the_project_defines_has_a_meaning() {
        for &code in bridge::ALL.iter() {
            assert!(
                meaning(code).is_some_and(|m| m.starts_with("bridge: ")),
                "{code:03X}"
            );
            assert!(answered_with(code).contains("the bridge"), "{code:03X}");
        }
        for &(code, m) in SIMULATOR {
            assert!(answered_with(code).contains(m), "{code:03X}");
        }
        assert_eq!(
            answered_with(0x0E4),
            "the controller answered with error code 0E4 (iai simulate's code: the servo of an axis concerned is off)"
        );
        assert_eq!(
            answered_with(0x123),
            "the controller answered with error code 123"
        );
        assert_eq!(meaning(0x123), None);
    }
}
