//! What field values mean: status bits, enumerated codes and units, shown
//! beside the raw values, and the names `iai encode`/`iai send` accept in
//! place of a code. The facts are copied from the TTA manual ("TTA p. N")
//! and the 2003 X-SEL specification ("2003 p. N"), as catalogued in the
//! project's `messages.toml`; where neither states it, the entry says
//! **inferred**.
//!
//! | message, field | meaning | source |
//! |---|---|---|
//! | 212H/2A1H/2A3H `axis_status` | bit 0 servo axis in use (moving, servo switching, paused); bits 1-2 home return 0 not done, 1 returning, 2 completed; bit 3 servo on; bit 4 operation command completed normally; bit 5 push error | TTA pp. 27, 66, 70; 2003 pp. 26, 55 |
//! | same, `sensor_input_status` | bit 0 creep sensor, bit 1 overrun sensor, bit 2 home sensor | same |
//! | same, `encoder_status` | bit 0 overspeed, 1 full absolute, 2 count error, 3 counter overflow, 5 multi-rotation error, 6 battery error, 7 battery alarm | same |
//! | same, `error_code` | 0: no error (**inferred**: the manuals give the field as "axis error number" only) | same |
//! | 213H `status` | bit 0 program started/running | TTA p. 29, 2003 p. 28 |
//! | 215H `system_mode` | 0 indeterminable, 1 AUTO, 2 MANUAL, 3 slave update, 4 core update | TTA p. 30, 2003 p. 29 |
//! | 215H `status_byte_1..3` | see [`STATUS_BYTES`] | TTA pp. 30-31, 2003 pp. 29-30 |
//! | 201H `unit_type` | 0 main CPU application, 1 main CPU core, 2 driver CPU, 3 mounted SIO (TTA only) | TTA p. 17, 2003 p. 16 |
//! | 216H `type_1` | 0 system, 1 axis, 2 program, 3 error-list record, 5 error-list record with extended count (TTA) | TTA p. 32, 2003 p. 31 |
//! | 216H `type_2` | with type 1 = 0: 0 critical-level error, 1 latest error (other types: a number) | TTA p. 32, 2003 p. 31 |
//! | 232H `operation_type` | bit 0: 1 servo on, 0 off | TTA p. 37, 2003 p. 33 |
//! | 236H `operation_type` | bit 0 direction: 0 negative, 1 positive | TTA p. 41, 2003 p. 37 |
//! | 238H `appended_command_byte` | bit 0: 1 cancel OUT-port output held by an interlock | TTA p. 43, 2003 p. 39 |
//! | 24AH, 24BH `change_type` | bit 0: 1 on, 0 off | TTA pp. 47-48, 2003 pp. 43-44 |
//! | 2A0H, 2A4H `type` | 0 work, 1 tool coordinate systems | TTA pp. 65, 72; 2003 p. 54 |
//! | 0 in acceleration, deceleration, speed (moves, position records), 233H's speeds | the controller's parameter (or the position's stored value) | TTA pp. 38-44, 58; 2003 pp. 34-40 |
//! | 0 in 236H `inching_distance` | jog (no distance) | TTA p. 41, 2003 p. 37 |
//! | 216H `record_number` | 000 except for type 1 = 5 | TTA p. 32 |
//!
//! Units: `0.001mm` fields are shown in mm with 3 decimals and `0.01G`
//! fields in G with 2, as the CSV tables write them (on a rotary axis the
//! same digits are degrees).

use iai_protocol_b::catalogue::{self, MessageInfo};
use iai_protocol_b::frame::Header;

use crate::csvtable::format_scaled;
use crate::fields::Val;

/// A code of an enumerated field: the name accepted on input, its value,
/// what it means.
pub type Code = (&'static str, u64, &'static str);

/// An enumerated field.
struct Enum {
    /// The messages that carry it.
    messages: &'static [&'static MessageInfo],
    /// Commands (`true`) or responses.
    command: bool,
    field: &'static str,
    codes: &'static [Code],
}

const ENUMS: &[Enum] = &[
    Enum {
        messages: &[&catalogue::VERSION_QUERY],
        command: true,
        field: "unit_type",
        codes: UNIT_TYPES,
    },
    Enum {
        messages: &[&catalogue::VERSION_QUERY],
        command: false,
        field: "unit_type",
        codes: UNIT_TYPES,
    },
    Enum {
        messages: &[&catalogue::SYSTEM_STATUS_QUERY],
        command: false,
        field: "system_mode",
        codes: &[
            ("indeterminable", 0, "indeterminable"),
            ("auto", 1, "AUTO mode"),
            ("manual", 2, "MANUAL mode"),
            ("slave-update", 3, "slave update mode"),
            ("core-update", 4, "core update mode"),
        ],
    },
    Enum {
        messages: &[&catalogue::ERROR_DETAIL_QUERY],
        command: true,
        field: "type_1",
        codes: &[
            ("system", 0, "system error"),
            ("axis", 1, "axis-specific error"),
            ("program", 2, "program-specific error"),
            ("error-list", 3, "error-list record"),
            (
                "error-list-extended",
                5,
                "error-list record with extended record count",
            ),
        ],
    },
    Enum {
        messages: &[&catalogue::ERROR_DETAIL_QUERY],
        command: true,
        field: "type_2",
        codes: &[
            ("critical", 0, "critical-level error (with type_1 = system)"),
            ("latest", 1, "latest error (with type_1 = system)"),
        ],
    },
    Enum {
        messages: &[&catalogue::SERVO_ON_OFF],
        command: true,
        field: "operation_type",
        codes: &[("off", 0, "servo off"), ("on", 1, "servo on")],
    },
    Enum {
        messages: &[&catalogue::JOG_INCH],
        command: true,
        field: "operation_type",
        codes: &[
            ("negative", 0, "negative direction"),
            ("positive", 1, "positive direction"),
        ],
    },
    Enum {
        messages: &[&catalogue::OPERATION_STOP],
        command: true,
        field: "appended_command_byte",
        codes: &[
            ("none", 0, "no appended command"),
            (
                "cancel-held-output",
                1,
                "cancel OUT-port output held by an interlock",
            ),
        ],
    },
    Enum {
        messages: &[&catalogue::OUTPUT_PORT_CHANGE, &catalogue::FLAG_CHANGE],
        command: true,
        field: "change_type",
        codes: &[("off", 0, "off"), ("on", 1, "on")],
    },
    Enum {
        messages: COORDINATE_QUERIES,
        command: true,
        field: "type",
        codes: COORDINATE_TYPES,
    },
    Enum {
        messages: COORDINATE_QUERIES,
        command: false,
        field: "type",
        codes: COORDINATE_TYPES,
    },
];

const UNIT_TYPES: &[Code] = &[
    ("main-application", 0, "main CPU application"),
    ("main-core", 1, "main CPU core"),
    ("driver", 2, "driver CPU"),
    ("sio", 3, "mounted SIO (TTA)"),
];

/// The coordinate system queries (their `type` codes are alike).
const COORDINATE_QUERIES: &[&MessageInfo] = &[
    &catalogue::COORDINATE_SYSTEM_QUERY,
    &catalogue::COORDINATE_SYSTEM_QUERY_2,
];

const COORDINATE_TYPES: &[Code] = &[
    ("work", 0, "work coordinate systems"),
    ("tool", 1, "tool coordinate systems"),
];

/// 215H's status bytes: (field, [(bit, meaning when set)]); bits not
/// listed are reserved. TTA pp. 30-31, 2003 pp. 29-30; on a TTA bit 2 of
/// byte 1 is the enable switch and bit 1 always 0 (TTA p. 30).
pub const STATUS_BYTES: &[(&str, &[(u8, &str)])] = &[
    (
        "status_byte_1",
        &[
            (0, "mode switch MANUAL"),
            (1, "TP enable switch off"),
            (2, "safety gate open (TTA: enable switch)"),
            (3, "emergency stop"),
            (4, "power error"),
            (5, "battery voltage low"),
            (6, "battery voltage error"),
        ],
    ),
    (
        "status_byte_2",
        &[
            (0, "writing flash ROM"),
            (1, "writing slave parameters"),
            (2, "servo interlock"),
            (3, "I/O interlock"),
            (4, "waiting for restart"),
            (5, "program running"),
        ],
    ),
    (
        "status_byte_3",
        &[
            (0, "drive source cut off"),
            (1, "operating in AUTO mode"),
            (2, "system ready"),
            (4, "positioner operation mode (TTA)"),
        ],
    ),
];

/// The axis status queries (their per-axis blocks are alike).
const AXIS_QUERIES: &[&MessageInfo] = &[
    &catalogue::AXIS_STATUS_QUERY,
    &catalogue::SCARA_AXIS_STATUS_QUERY,
    &catalogue::SCARA_AXIS_STATUS_QUERY_2,
];

/// The position-number moves (their 0 speeds fall back to the position's).
const POSITION_NUMBER_MOVES: &[&MessageInfo] = &[
    &catalogue::POSITION_NUMBER_MOVE,
    &catalogue::POSITION_NUMBER_MOVE_2,
    &catalogue::SCARA_POSITION_NUMBER_MOVE,
];

/// Whether message `id` is one of `messages`.
fn is_one_of(id: u16, messages: &[&MessageInfo]) -> bool {
    messages.iter().any(|m| m.id == id)
}

fn enum_of(id: u16, header: Header, field: &str) -> Option<&'static Enum> {
    let command = header == Header::Command;
    ENUMS
        .iter()
        .find(|e| e.command == command && e.field == field && is_one_of(id, e.messages))
}

/// The codes of an enumerated field (`&[]` if it is not one).
pub fn codes(id: u16, header: Header, field: &str) -> &'static [Code] {
    enum_of(id, header, field).map_or(&[], |e| e.codes)
}

/// The value of `name` in an enumerated field (case and `_`/`-` ignored).
pub fn named(id: u16, header: Header, field: &str, name: &str) -> Option<u64> {
    let norm = |s: &str| s.to_ascii_lowercase().replace('_', "-");
    let want = norm(name);
    codes(id, header, field)
        .iter()
        .find(|(n, _, _)| norm(n) == want)
        .map(|(_, v, _)| *v)
}

/// What 0 means in a field whose value may be left out (`None`: the field
/// must be given). Patterns and counts are derived elsewhere.
pub fn default_meaning(id: u16, field: &str) -> Option<&'static str> {
    Some(match field {
        "record_number" if id == catalogue::ERROR_DETAIL_QUERY.id => {
            "000 (used only with type_1 = 5)"
        }
        "end_search_speed" | "creep_speed" if id == catalogue::HOME_RETURN.id => {
            "0 = the parameter's value"
        }
        "inching_distance" if id == catalogue::JOG_INCH.id => "0 = jog (no distance)",
        "acceleration" | "deceleration" | "speed" if is_one_of(id, POSITION_NUMBER_MOVES) => {
            "0 = the position's stored value, then the parameter"
        }
        "acceleration" | "deceleration" | "speed" => "0 = the controller's parameter",
        "appended_command_byte" if id == catalogue::OPERATION_STOP.id => "0 = none",
        f if f.starts_with("reserved") => "0 (reserved)",
        _ => return None,
    })
}

fn bits(v: u64, table: &[(u8, &str)]) -> Vec<String> {
    table
        .iter()
        .filter(|(b, _)| v >> b & 1 == 1)
        .map(|(_, m)| m.to_string())
        .collect()
}

fn list(parts: Vec<String>, none: &str) -> String {
    if parts.is_empty() {
        none.to_string()
    } else {
        parts.join(", ")
    }
}

/// 212H's axis status byte in words: "servo on, homed, idle, positioning
/// complete".
pub fn axis_status(v: u64) -> String {
    let mut p = vec![if v & 0x08 != 0 {
        "servo on"
    } else {
        "servo off"
    }
    .to_string()];
    p.push(
        match v >> 1 & 3 {
            0 => "not homed",
            1 => "homing",
            2 => "homed",
            _ => "home state 3 (reserved)",
        }
        .to_string(),
    );
    p.push(
        if v & 1 != 0 {
            "in use (moving)"
        } else {
            "idle"
        }
        .to_string(),
    );
    if v & 0x10 != 0 {
        p.push("positioning complete".into());
    }
    if v & 0x20 != 0 {
        p.push("push error".into());
    }
    p.join(", ")
}

/// What `value` of field `field` of message `id` (in direction `header`)
/// means, if the tool knows: a unit conversion, status bits or a code.
pub fn describe(id: u16, header: Header, field: &str, unit: &str, value: &Val) -> Option<String> {
    let v = match value {
        Val::Unsigned(n) => i64::try_from(*n).ok()?,
        Val::Signed(n) => *n,
        Val::Text(_) => return None,
    };
    match unit {
        "0.001mm" => return Some(format!("{} mm", format_scaled(v, 3))),
        "0.01G" => return Some(format!("{} G", format_scaled(v, 2))),
        _ => {}
    }
    let u = v as u64;
    if let Some(e) = enum_of(id, header, field) {
        return Some(e.codes.iter().find(|(_, c, _)| *c == u).map_or_else(
            || format!("code {u} (not documented)"),
            |(_, _, m)| m.to_string(),
        ));
    }
    let response = header == Header::Response;
    if response && is_one_of(id, AXIS_QUERIES) {
        return match field {
            "axis_status" => Some(axis_status(u)),
            "sensor_input_status" => Some(list(
                bits(
                    u,
                    &[
                        (0, "creep sensor on"),
                        (1, "overrun sensor on"),
                        (2, "home sensor on"),
                    ],
                ),
                "no sensor on",
            )),
            "encoder_status" => Some(list(
                bits(
                    u,
                    &[
                        (0, "overspeed"),
                        (1, "full absolute"),
                        (2, "count error"),
                        (3, "counter overflow"),
                        (5, "multi-rotation error"),
                        (6, "battery error"),
                        (7, "battery alarm"),
                    ],
                ),
                "no flag set",
            )),
            "error_code" if u == 0 => Some("no error (inferred)".into()),
            _ => None,
        };
    }
    if !response {
        return None;
    }
    match field {
        "status" if id == catalogue::PROGRAM_STATUS_QUERY.id => Some(
            if u & 1 != 0 {
                "program running"
            } else {
                "program not running"
            }
            .to_string(),
        ),
        f if id == catalogue::SYSTEM_STATUS_QUERY.id => STATUS_BYTES
            .iter()
            .find(|(name, _)| *name == f)
            .map(|(_, table)| list(bits(u, table), "no flag set")),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recorded_axis_status_reads_in_words() {
        // '#99212021C00000000002715AF' (a third-party capture, messages.toml
        // 212H): axis 2, status 1CH, position 0x2715.
        assert_eq!(
            axis_status(0x1C),
            "servo on, homed, idle, positioning complete"
        );
        assert_eq!(axis_status(0x09), "servo on, not homed, in use (moving)");
        let pos = describe(
            0x212,
            Header::Response,
            "current_position",
            "0.001mm",
            &Val::Signed(0x2715),
        );
        assert_eq!(pos.as_deref(), Some("10.005 mm"));
        let acc = describe(
            0x26D,
            Header::Command,
            "acceleration",
            "0.01G",
            &Val::Unsigned(30),
        );
        assert_eq!(acc.as_deref(), Some("0.30 G"));
    }

    #[test]
    fn codes_have_names_both_ways() {
        assert_eq!(
            named(0x232, Header::Command, "operation_type", "ON"),
            Some(1)
        );
        assert_eq!(
            named(0x216, Header::Command, "type_1", "error_list"),
            Some(3)
        );
        assert_eq!(
            named(0x212, Header::Command, "query_axis_pattern", "on"),
            None
        );
        let mode = describe(
            0x215,
            Header::Response,
            "system_mode",
            "",
            &Val::Unsigned(1),
        );
        assert_eq!(mode.as_deref(), Some("AUTO mode"));
        let b3 = describe(
            0x215,
            Header::Response,
            "status_byte_3",
            "",
            &Val::Unsigned(0b110),
        );
        assert_eq!(b3.as_deref(), Some("operating in AUTO mode, system ready"));
    }
}
