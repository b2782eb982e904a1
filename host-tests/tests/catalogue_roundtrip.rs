//! Every message both ways: hand-built fixture frames (checksums computed
//! here from the ASCII), generated round trips, boundary values and the
//! controller profiles' frame limits.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::*;
use iai_protocol_b::axis::AxisPattern;
use iai_protocol_b::error::Error;
use iai_protocol_b::frame::Station;
use iai_protocol_b::message::{
    decode_any, AnyMessage, ChangePositionData, ChangePositionData2, ChangePositionData3, Command,
    ErrorDetailQuery, Fields, Message, RangeWritePositionData, RangeWritePositionData2, RealValue,
    RealVariableChange, RealWire, Repeated, Reserved, StringVariableChange, TestCall, VersionQuery,
    WordOrder,
};
use iai_protocol_b::position::{PositionRecord, RecordLayout};
use iai_protocol_b::profile::Profile;
use proptest::prelude::*;
use V::{S, T, U};

/// Decodes `head` + computed SC + CR LF and returns the reported leaves.
fn leaves(head: &str) -> Vec<(String, V)> {
    let bytes = frame_text(head.as_bytes()[0] as char, &head[3..6], &head[6..]);
    assert_eq!(&bytes[..head.len()], head.as_bytes());
    let frame = check(&bytes);
    let d = decode_any(&frame).unwrap_or_else(|e| panic!("{head}: {e}"));
    let mut rec = Recorder::default();
    d.message.fields(&mut rec);
    // The typed value emits the same frame.
    let mut out = vec![0u8; bytes.len()];
    let n = match &d.message {
        AnyMessage::Command(c) => c.emit(Station(0x99), &mut out).unwrap(),
        AnyMessage::Response(r) => r.emit(Station(0x99), &mut out).unwrap(),
        AnyMessage::Error(e) => e.emit(Station(0x99), &mut out).unwrap(),
    };
    assert_eq!(&out[..n], &bytes[..], "{head}");
    rec.events
        .into_iter()
        .filter_map(|e| match e {
            Ev::Leaf { name, value, .. } => Some((name, value)),
            _ => None,
        })
        .collect()
}

fn t(s: &str) -> V {
    T(s.as_bytes().to_vec())
}

/// (frame without SC/CR/LF, the leaf values it must decode to, in order).
type Fixture = (&'static str, Vec<(&'static str, V)>);

fn fixtures() -> Vec<Fixture> {
    let pos = |n: u64, p: u64, a: u64, d: u64, s: u64, c: &[i64]| {
        let mut v = vec![
            ("position_number", U(n)),
            ("axis_pattern", U(p)),
            ("acceleration", U(a)),
            ("deceleration", U(d)),
            ("speed", U(s)),
        ];
        v.extend(c.iter().map(|&x| ("position", S(x))));
        v
    };
    let cat = |parts: Vec<Vec<(&'static str, V)>>| parts.into_iter().flatten().collect::<Vec<_>>();
    let axis_block = |st: u64, sen: u64, err: u64, enc: u64, p: i64| {
        vec![
            ("axis_status", U(st)),
            ("axis_sensor_input_status", U(sen)),
            ("axis_error_code", U(err)),
            ("encoder_status", U(enc)),
            ("current_position", S(p)),
        ]
    };
    vec![
        ("!992000123456789", vec![("test_string", t("0123456789"))]),
        ("#992000123456789", vec![("test_string", t("0123456789"))]),
        ("!99201030", vec![("unit_type", U(3)), ("device_number", U(0))]),
        (
            "#9920102012A0102007E80C1F173B3A",
            vec![
                ("unit_type", U(2)),
                ("device_number", U(0)),
                ("model_code", U(0x12)),
                ("unit_code", U(0xA0)),
                ("version_number", U(0x1020)),
                ("year", U(2024)),
                ("month", U(12)),
                ("day", U(31)),
                ("hour", U(23)),
                ("minute", U(59)),
                ("second", U(58)),
            ],
        ),
        ("!99208", vec![]),
        ("#9920800A", vec![("number_of_effective_positions", U(10))]),
        ("!99209001005", vec![("query_head_position_number", U(1)), ("number_of_query_records", U(5))]),
        (
            "#9920900100103001E001E0064000186A0FFFF9C64",
            pos(1, 3, 30, 30, 100, &[100_000, -25_500]),
        ),
        ("!9920B00100020", vec![("query_start_port_number", U(0x10)), ("number_of_query_ports", U(0x20))]),
        (
            "#9920B001000100FA5",
            vec![("response_start_port_number", U(0x10)), ("input_port_data", U(0x0F)), ("input_port_data", U(0xA5))],
        ),
        ("!9920C03E80008", vec![("query_start_port_number", U(1000)), ("number_of_query_ports", U(8))]),
        ("#9920C03E8000880", vec![("response_start_port_number", U(1000)), ("output_port_data", U(0x80))]),
        (
            "!9920D0102580010",
            vec![("program_number", U(1)), ("query_start_flag_number", U(600)), ("number_of_query_flags", U(16))],
        ),
        (
            "#9920D010258001001FF",
            vec![
                ("program_number", U(1)),
                ("response_start_flag_number", U(600)),
                ("flag_data", U(1)),
                ("flag_data", U(0xFF)),
            ],
        ),
        (
            "!9920E0012C02",
            vec![("program_number", U(0)), ("query_start_variable_number", U(300)), ("number_of_query_variables", U(2))],
        ),
        (
            "#9920E0012C02FFFFFFFF7FFFFFFF",
            vec![
                ("program_number", U(0)),
                ("response_start_variable_number", U(300)),
                ("integer_variable_data", S(-1)),
                ("integer_variable_data", S(i32::MAX as i64)),
            ],
        ),
        ("!9920F0A06401", vec![("program_number", U(10)), ("query_start_variable_number", U(100)), ("number_of_query_variables", U(1))]),
        (
            "#9920F0A0640189ABCDEF01234567",
            vec![
                ("program_number", U(10)),
                ("response_start_variable_number", U(100)),
                ("real_variable_data", U(0x89AB_CDEF_0123_4567)),
            ],
        ),
        ("!992100032C03", vec![("program_number", U(0)), ("query_start_variable_number", U(0x32C)), ("number_of_query_variables", U(3))]),
        (
            "#992100032C03414243",
            vec![
                ("program_number", U(0)),
                ("response_start_variable_number", U(0x32C)),
                ("string_variable_data", U(0x41)),
                ("string_variable_data", U(0x42)),
                ("string_variable_data", U(0x43)),
            ],
        ),
        ("!9921207", vec![("query_axis_pattern", U(7))]),
        (
            "#99212021C00000000002715",
            cat(vec![vec![("axis_pattern", U(2))], axis_block(0x1C, 0, 0, 0, 10_005)]),
        ),
        ("!9921305", vec![("program_number", U(5))]),
        (
            "#992130520012C740012",
            vec![
                ("program_number", U(5)),
                ("status", U(2)),
                ("executing_step_number", U(0x12)),
                ("program_error_code", U(0xC74)),
                ("error_step_number", U(0x12)),
            ],
        ),
        ("!99215", vec![]),
        (
            "#992150C7400A10204008",
            vec![
                ("system_mode", U(0)),
                ("critical_system_error_number", U(0xC74)),
                ("latest_system_error_number", U(0x00A)),
                ("system_status_byte_1", U(0x10)),
                ("system_status_byte_2", U(0x20)),
                ("system_status_byte_3", U(0x40)),
                ("system_status_byte_4", U(0x08)),
            ],
        ),
        ("!99216001000", vec![("type_1", U(0)), ("type_2", U(1)), ("record_number", U(0))]),
        (
            "#99216C74000000010000000500000002FFFFFFFD0000000000000000000000000000000000000000000000002OK",
            vec![
                ("error_number", U(0xC74)),
                ("detail_1", U(1)),
                ("detail_2", U(5)),
                ("detail_3", U(2)),
                ("detail_4", S(-3)),
                ("detail_5", U(0)),
                ("detail_6", U(0)),
                ("detail_7", U(0)),
                ("detail_8", U(0)),
                ("reserved_1", U(0)),
                ("reserved_2", U(0)),
                ("reserved_3", U(0)),
                ("reserved_4", U(0)),
                ("reserved_5", U(0)),
                ("reserved_6", U(0)),
                ("reserved_7", U(0)),
                ("message_char", t("O")),
                ("message_char", t("K")),
            ],
        ),
        ("!9921F4E200002", vec![("query_head_position_number", U(20_000)), ("number_of_query_records", U(2))]),
        ("#9921F00014E200100000000000000000000", pos(20_000, 1, 0, 0, 0, &[0])),
        (
            "!9922D0000010001",
            vec![("reserved", t("00")), ("query_head_position_number", U(1)), ("number_of_query_records", U(1))],
        ),
        (
            "#9922D00000100050100100010000AFFFFFFFF20",
            cat(vec![vec![("reserved", t("00"))], pos(5, 1, 16, 16, 10, &[-1]), vec![("extended_data", U(0x20))]]),
        ),
        ("!992320F1", vec![("axis_pattern", U(0x0F)), ("operation_type", U(1))]),
        ("#99232", vec![]),
        ("!9923307000000", vec![("axis_pattern", U(7)), ("end_search_speed", U(0)), ("creep_speed", U(0))]),
        ("#99233", vec![]),
        (
            "!9923403001E001E006400061A80FFF9E580",
            vec![
                ("axis_pattern", U(3)),
                ("acceleration", U(30)),
                ("deceleration", U(30)),
                ("speed", U(100)),
                ("absolute_coordinate", S(400_000)),
                ("absolute_coordinate", S(-400_000)),
            ],
        ),
        ("#99234", vec![]),
        (
            "!9923580000A000A0032FFFFFC18",
            vec![
                ("axis_pattern", U(0x80)),
                ("acceleration", U(10)),
                ("deceleration", U(10)),
                ("speed", U(50)),
                ("relative_distance", S(-1000)),
            ],
        ),
        ("#99235", vec![]),
        (
            "!9923601001E001E0064000003E81",
            vec![
                ("axis_pattern", U(1)),
                ("acceleration", U(30)),
                ("deceleration", U(30)),
                ("speed", U(100)),
                ("inching_distance", U(1000)),
                ("operation_type", U(1)),
            ],
        ),
        ("#99236", vec![]),
        (
            "!9923703000000000000FFF",
            vec![
                ("axis_pattern", U(3)),
                ("acceleration", U(0)),
                ("deceleration", U(0)),
                ("speed", U(0)),
                ("position_number", U(0xFFF)),
            ],
        ),
        ("#99237", vec![]),
        ("!99238FF00", vec![("stop_axis_pattern", U(0xFF)), ("appended_command_byte", U(0))]),
        ("#99238", vec![]),
        (
            "!992440640010100000000000000000064",
            vec![
                ("change_start_position_number", U(100)),
                ("axis_pattern", U(1)),
                ("acceleration", U(0)),
                ("deceleration", U(0)),
                ("speed", U(0)),
                ("position", S(100)),
            ],
        ),
        ("#99244064001", vec![("change_start_position_number", U(100)), ("number_of_changed_positions", U(1))]),
        ("!9924500100103001E001E0064000186A0FFFF9C64", pos(1, 3, 30, 30, 100, &[100_000, -25_500])),
        ("#99245001", vec![("number_of_changed_positions", U(1))]),
        ("!99246001BB8", vec![("clear_start_position_number", U(1)), ("number_of_clear_positions", U(3000))]),
        ("#99246", vec![]),
        ("!9924A012C1", vec![("output_port_number", U(300)), ("change_type", U(1))]),
        ("#9924A", vec![]),
        ("!9924B0002580", vec![("program_number", U(0)), ("flag_number", U(600)), ("change_type", U(0))]),
        ("#9924B", vec![]),
        (
            "!9924C0100101FFFFFF9C",
            vec![
                ("program_number", U(1)),
                ("change_start_variable_number", U(1)),
                ("integer_variable_data", S(-100)),
            ],
        ),
        (
            "#9924C0100101",
            vec![("program_number", U(1)), ("change_start_variable_number", U(1)), ("number_of_changed_variables", U(1))],
        ),
        (
            "!9924D00001010123456789ABCDEF",
            vec![
                ("program_number", U(0)),
                ("change_start_variable_number", U(1)),
                ("real_variable_data", U(0x0123_4567_89AB_CDEF)),
            ],
        ),
        (
            "#9924D0000101",
            vec![("program_number", U(0)), ("change_start_variable_number", U(1)), ("number_of_changed_variables", U(1))],
        ),
        (
            "!9924E00001024849",
            vec![
                ("program_number", U(0)),
                ("change_start_variable_number", U(1)),
                ("string_variable_data", U(0x48)),
                ("string_variable_data", U(0x49)),
            ],
        ),
        ("#9924E", vec![]),
        ("!99252", vec![]),
        ("#99252", vec![]),
        ("!9925301", vec![("program_number", U(1))]),
        ("#99253", vec![]),
        ("!9925402", vec![("program_number", U(2))]),
        ("#99254", vec![]),
        ("!9925503", vec![("program_number", U(3))]),
        ("#99255", vec![]),
        ("!9925604", vec![("program_number", U(4))]),
        ("#99256", vec![]),
        ("!9925705", vec![("program_number", U(5))]),
        ("#99257", vec![]),
        ("!9925B", vec![]),
        ("!9925C", vec![]),
        ("#9925C", vec![]),
        ("!9925E", vec![]),
        ("#9925E", vec![]),
        ("!99262030064", vec![("axis_pattern", U(3)), ("speed", U(100))]),
        ("#99262", vec![]),
        (
            "!9926B01001E001E00644E20",
            vec![
                ("axis_pattern", U(1)),
                ("acceleration", U(30)),
                ("deceleration", U(30)),
                ("speed", U(100)),
                ("position_number", U(20_000)),
            ],
        ),
        ("#9926B", vec![]),
        ("!9926D0001000103001E001E0064000186A0FFFF9C64", pos(1, 3, 30, 30, 100, &[100_000, -25_500])),
        ("#9926D0001", vec![("number_of_changed_positions", U(1))]),
        (
            "!99271ABCD0000000000000000000000000000",
            cat(vec![
                vec![("function_word_9", U(0xABCD))],
                (10..=16)
                    .map(|i| (["function_word_10", "function_word_11", "function_word_12", "function_word_13", "function_word_14", "function_word_15", "function_word_16"][i - 10], t("0000")))
                    .collect(),
            ]),
        ),
        ("#99271", vec![]),
        (
            "!992900000C8000101000000000000000003E810",
            vec![
                ("reserved", t("00")),
                ("change_start_position_number", U(200)),
                ("axis_pattern", U(1)),
                ("acceleration", U(0)),
                ("deceleration", U(0)),
                ("speed", U(0)),
                ("position", S(1000)),
                ("extended_data", U(0x10)),
            ],
        ),
        (
            "#992900000C80001",
            vec![("reserved", t("00")), ("change_start_position_number", U(200)), ("number_of_changed_positions", U(1))],
        ),
        (
            "!9929100000100C801000000000000FFFFFC1820",
            cat(vec![vec![("reserved", t("00"))], pos(200, 1, 0, 0, 0, &[-1000]), vec![("extended_data", U(0x20))]]),
        ),
        ("#99291000001", vec![("reserved", t("00")), ("number_of_changed_positions", U(1))]),
        (
            "!992A010101",
            vec![("type", U(1)), ("query_head_definition_number", U(1)), ("number_of_query_records", U(1))],
        ),
        (
            "#992A010101000186A0FFFE7960000000000000EA60",
            vec![
                ("type", U(1)),
                ("response_start_definition_number", U(1)),
                ("coordinate_offset", S(100_000)),
                ("coordinate_offset", S(-100_000)),
                ("coordinate_offset", S(0)),
                ("coordinate_offset", S(60_000)),
            ],
        ),
        ("!992A1031", vec![("query_axis_pattern", U(3)), ("type", U(1))]),
        (
            "#992A1010204011C00000000002715",
            cat(vec![
                vec![
                    ("work_coordinate_selection", U(1)),
                    ("tool_coordinate_selection", U(2)),
                    ("common_axis_status", U(4)),
                    ("axis_pattern", U(1)),
                ],
                axis_block(0x1C, 0, 0, 0, 10_005),
            ]),
        ),
        ("!992A20102", vec![("query_zone_number", U(1)), ("number_of_query_records", U(2))]),
        (
            "#992A2030103FFFFFC18FFFFFC18000003E8000003E8012C01000000",
            vec![
                ("zone_number", U(3)),
                ("coordinate_axis_pattern", U(3)),
                ("corner_1", S(-1000)),
                ("corner_1", S(-1000)),
                ("corner_2", S(1000)),
                ("corner_2", S(1000)),
                ("output_port_or_flag_number", U(300)),
                ("entry_error_type", U(1)),
                ("reserved_1", U(0)),
                ("reserved_2", U(0)),
                ("reserved_3", U(0)),
            ],
        ),
        ("!992A30F11", vec![("query_axis_pattern", U(0x0F)), ("type", U(0x11))]),
        (
            "#992A303010201000000018000000000000000",
            cat(vec![
                vec![
                    ("scara_axis_pattern", U(3)),
                    ("work_coordinate_selection_1_4", U(1)),
                    ("tool_coordinate_selection_1_4", U(2)),
                    ("common_status_1_4", U(1)),
                    ("work_coordinate_selection_5_8", U(0)),
                    ("tool_coordinate_selection_5_8", U(0)),
                    ("common_status_5_8", U(0)),
                    ("axis_pattern", U(1)),
                ],
                axis_block(0x80, 0, 0, 0, 0),
            ]),
        ),
        (
            "!992A40300010",
            vec![("query_axis_pattern", U(3)), ("type", U(0)), ("query_head_definition_number", U(0)), ("number_of_query_records", U(0x10))],
        ),
        (
            "#992A403000010000000AFFFFFFF6",
            vec![
                ("response_axis_pattern", U(3)),
                ("type", U(0)),
                ("response_start_definition_number", U(0)),
                ("coordinate_offset", S(10)),
                ("coordinate_offset", S(-10)),
            ],
        ),
        (
            "!992D40100320032006401000186A0",
            vec![
                ("axis_pattern", U(1)),
                ("acceleration", U(50)),
                ("deceleration", U(50)),
                ("speed", U(100)),
                ("positioning_operation_type", U(1)),
                ("absolute_coordinate", S(100_000)),
            ],
        ),
        ("#992D4", vec![]),
        (
            "!992D50800320032006400FFFEA070",
            vec![
                ("axis_pattern", U(8)),
                ("acceleration", U(50)),
                ("deceleration", U(50)),
                ("speed", U(100)),
                ("positioning_operation_type", U(0)),
                ("relative_distance", S(-90_000)),
            ],
        ),
        ("#992D5", vec![]),
        (
            "!992D60F0032003200640200A",
            vec![
                ("axis_pattern", U(0x0F)),
                ("acceleration", U(50)),
                ("deceleration", U(50)),
                ("speed", U(100)),
                ("positioning_operation_type", U(2)),
                ("position_number", U(10)),
            ],
        ),
        ("#992D6", vec![]),
    ]
    .into_iter()
    .filter(|(head, _)| !head.is_empty())
    .collect()
}

#[test]
fn fixture_frames_decode_to_the_tabled_values() {
    let mut seen = std::collections::BTreeSet::new();
    let mut failures = Vec::new();
    for (head, want) in fixtures() {
        let got = std::panic::catch_unwind(|| leaves(head));
        let want: Vec<(String, V)> = want.into_iter().map(|(n, v)| (n.to_string(), v)).collect();
        match got {
            Ok(got) if got == want => {}
            Ok(got) => failures.push(format!("{head}: got {got:?}")),
            Err(_) => failures.push(format!("{head}: does not decode")),
        }
        seen.insert((
            head.as_bytes()[0],
            u16::from_str_radix(&head[3..6], 16).unwrap(),
        ));
    }
    assert!(failures.is_empty(), "{failures:#?}");
    eprintln!(
        "{} catalogue fixture frames decoded to their tabled values",
        fixtures().len()
    );
    // One fixture per message and direction (25BH has no normal response).
    for id in iai_protocol_b::catalogue::ALL.iter().map(|m| m.id) {
        assert!(
            seen.contains(&(b'!', id)),
            "no command fixture for {id:03X}H"
        );
        if id != 0x25B {
            assert!(
                seen.contains(&(b'#', id)),
                "no response fixture for {id:03X}H"
            );
        }
    }
}

#[test]
fn error_response_fixture() {
    let bytes = frame_text('&', "ABC", "");
    assert_eq!(bytes, b"&99ABC5E\r\n");
    let f = check(&bytes);
    match decode_any(&f).unwrap().message {
        AnyMessage::Error(e) => assert_eq!(e.code, 0xABC),
        other => panic!("{other:?}"),
    }
}

fn roundtrip(m: &Msg, part: Part, mode: Mode) {
    let nodes = tree(m.fields(part), &m.groups(part));
    let mut gen = Gen::new(mode);
    let (mut body, mut ev) = (String::new(), Vec::new());
    generate(&nodes, &mut gen, &mut body, &mut ev);
    let bytes = frame_text(part.header(), &m.id, &body);
    let frame = check(&bytes);
    let first = decode_any(&frame).unwrap().message;
    let mut out = vec![0u8; bytes.len()];
    let n = match &first {
        AnyMessage::Command(c) => c.emit(Station(0x99), &mut out).unwrap(),
        AnyMessage::Response(r) => r.emit(Station(0x99), &mut out).unwrap(),
        AnyMessage::Error(e) => e.emit(Station(0x99), &mut out).unwrap(),
    };
    assert_eq!(&out[..n], &bytes[..]);
    let again = check(&out[..n]);
    assert_eq!(decode_any(&again).unwrap().message, first);
}

proptest! {
    #[test]
    fn generated_values_round_trip(seed in any::<u64>(), which in 0usize..108) {
        let cat = catalogue();
        let msgs: Vec<&Msg> = cat.message.iter().filter(|m| m.id != "ERR").collect();
        let m = msgs[which % msgs.len()];
        let part = if which / msgs.len() == 0 || m.has_normal_response == Some(false) {
            Part::Command
        } else {
            Part::Response
        };
        roundtrip(m, part, Mode::Random(seed));
    }

    #[test]
    fn position_records_round_trip(
        recs in prop::collection::vec(
            (any::<u16>(), any::<u8>(), any::<u16>(), any::<u16>(), any::<u16>(),
             prop::collection::vec(any::<i32>(), 8), any::<u8>()),
            0..6),
    ) {
        let records: Vec<PositionRecord> = recs
            .iter()
            .map(|(n, axes, a, d, s, pos, ext)| {
                let axes = AxisPattern::from_bits(*axes);
                PositionRecord {
                    number: n % 0x1000,
                    axes,
                    acceleration: *a,
                    deceleration: *d,
                    speed: *s,
                    positions: pos.iter().take(axes.count()).copied().collect(),
                    extended: *ext,
                }
            })
            .collect();
        let cmd = ChangePositionData3 { reserved: Reserved, records: Repeated::from_slice(&records) };
        let mut buf = vec![0u8; 4096];
        let n = cmd.emit(Station(0x99), &mut buf).unwrap();
        let frame = check(&buf[..n]);
        prop_assert_eq!(ChangePositionData3::parse(&frame).unwrap(), cmd);
        let plain: Vec<PositionRecord> =
            records.iter().cloned().map(|r| PositionRecord { extended: 0, ..r }).collect();
        let cmd = ChangePositionData { records: Repeated::from_slice(&plain) };
        let n = cmd.emit(Station(0x99), &mut buf).unwrap();
        prop_assert_eq!(ChangePositionData::parse(&check(&buf[..n])).unwrap(), cmd);
    }

    #[test]
    fn real_values_round_trip_in_both_orders(bits in prop::collection::vec(any::<u64>(), 0..10), legacy: bool) {
        let order = if legacy { WordOrder::LowWordFirst } else { WordOrder::MostSignificantFirst };
        let wires: Vec<RealWire> = bits.iter().map(|&b| RealValue(b).to_wire(order)).collect();
        let cmd = RealVariableChange {
            program_number: 0,
            change_start_variable_number: 1,
            real_variable_data: Repeated::from_slice(&wires),
        };
        let mut buf = [0u8; 256];
        let n = cmd.emit(Station(0x99), &mut buf).unwrap();
        let back = RealVariableChange::parse(&check(&buf[..n])).unwrap();
        let values: Vec<u64> = back.real_variable_data.iter().map(|w| w.value(order).0).collect();
        prop_assert_eq!(values, bits);
    }
}

#[test]
fn boundary_values_of_every_field() {
    let cat = catalogue();
    for m in cat.message.iter().filter(|m| m.id != "ERR") {
        for part in [Part::Command, Part::Response] {
            if part == Part::Response && m.has_normal_response == Some(false) {
                continue;
            }
            for mode in [Mode::Min, Mode::Max] {
                roundtrip(m, part, mode);
            }
        }
    }
}

#[test]
fn values_beyond_their_field_are_refused() {
    let mut buf = [0u8; 64];
    // 1 hex digit holds at most 15.
    let q = VersionQuery {
        unit_type: 0,
        device_number: 16,
    };
    assert!(matches!(
        q.emit(Station(0x99), &mut buf),
        Err(Error::ValueOutOfRange { .. })
    ));
    // 12 ports take 2 bytes (ceil(12 / 8)): one byte is too few.
    let bytes = frame_text('#', "20B", "0000000CFF");
    assert!(matches!(
        decode_any(&check(&bytes)),
        Err(Error::BodyTooShort { .. })
    ));
    let bytes = frame_text('#', "20B", "0000000CFF0F");
    assert!(decode_any(&check(&bytes)).is_ok());
    // A port count and a number of bytes that disagree cannot be emitted.
    let data = iai_protocol_b::message::PortData {
        units: 12,
        items: iai_protocol_b::message::Repeated::from_slice(&[0xFF]),
    };
    let resp = iai_protocol_b::message::InputPortResponse {
        response_start_port_number: 0,
        input_port_data: data,
    };
    assert!(matches!(
        resp.emit(Station(0x99), &mut buf),
        Err(Error::CountMismatch {
            expected: 2,
            found: 1
        })
    ));
    // 2A2H zones have at most 4 coordinate axes.
    let bytes = frame_text(
        '#',
        "2A2",
        &format!("00011F{}{}012C01000000", "0".repeat(40), "0".repeat(40)),
    );
    assert!(matches!(
        decode_any(&check(&bytes)),
        Err(Error::CountTooLarge { count: 5, max: 4 })
    ));
    // 216H message longer than FFh cannot be written.
    let long = [b'A'; 256];
    let frame = frame_text('#', "216", &format!("{}00", "0".repeat(82)));
    let mut resp = iai_protocol_b::message::ErrorDetailResponse::parse(&check(&frame)).unwrap();
    resp.message = &long;
    let mut big = [0u8; 512];
    assert!(matches!(
        resp.emit(Station(0x99), &mut big),
        Err(Error::CountTooLarge { .. })
    ));
    // A 291H frame in the printed (start number, count) order is refused.
    let printed = frame_text('!', "291", "0000C8000101000000000000000003E810");
    assert!(decode_any(&check(&printed)).is_err());
}

fn records(n: usize, axes: usize) -> Vec<PositionRecord> {
    let coords: Vec<(u8, i32)> = (1..=axes as u8)
        .map(|a| (a, -1_000 * i32::from(a)))
        .collect();
    (0..n)
        .map(|i| {
            let mut r = PositionRecord::new(i as u16 % 0x1000, 30, 30, 100, &coords).unwrap();
            r.extended = 0x10;
            r
        })
        .collect()
}

fn table_command<'a>(id: u16, recs: &'a [PositionRecord]) -> Command<'a> {
    let records = Repeated::from_slice(recs);
    match id {
        0x244 => Command::RangeWritePositionData(RangeWritePositionData {
            change_start_position_number: 1,
            records,
        }),
        0x245 => Command::ChangePositionData(ChangePositionData { records }),
        0x26D => Command::ChangePositionData2(ChangePositionData2 { records }),
        0x290 => Command::RangeWritePositionData2(RangeWritePositionData2 {
            reserved: Reserved,
            change_start_position_number: 1,
            records,
        }),
        0x291 => Command::ChangePositionData3(ChangePositionData3 {
            reserved: Reserved,
            records,
        }),
        _ => unreachable!(),
    }
}

#[test]
fn most_records_that_fit_each_profile_and_one_more() {
    let tables = [
        (0x244, RecordLayout::RANGE),
        (0x245, RecordLayout::NUMBER_3),
        (0x26D, RecordLayout::NUMBER_4),
        (0x290, RecordLayout::RANGE_EXTENDED),
        (0x291, RecordLayout::NUMBER_4_EXTENDED),
    ];
    let mut buf = vec![0u8; 8192];
    for profile in [Profile::TTA, Profile::XSEL_2003] {
        for (id, layout) in tables {
            for axes in 1..=8 {
                let n = profile.max_records_per_command(layout, axes).unwrap();
                let recs = records(n + 1, axes);
                let fits = table_command(id, &recs[..n]);
                let over = table_command(id, &recs);
                if !profile.supports(id) {
                    assert_eq!(
                        profile.emit_command(&fits, Station(0x99), &mut buf),
                        Err(Error::NotSupportedByProfile { id })
                    );
                    continue;
                }
                let len = profile
                    .emit_command(&fits, Station(0x99), &mut buf)
                    .unwrap();
                assert!(len <= profile.max_command_frame());
                assert!(len + layout.record_len(axes) > profile.max_command_frame());
                assert_eq!(
                    profile.emit_command(&over, Station(0x99), &mut buf),
                    Err(Error::FrameTooLong {
                        limit: profile.max_command_frame()
                    }),
                    "{id:03X}H {axes} axes"
                );
            }
        }
    }
    // The buffer arithmetic of TTA p. 15 and p. 60 (4 / 8 axes).
    let p = Profile::TTA;
    assert_eq!(
        p.max_records_per_command(RecordLayout::NUMBER_4, 4),
        Some(40)
    );
    assert_eq!(
        p.max_records_per_command(RecordLayout::NUMBER_4, 8),
        Some(24)
    );
    assert_eq!(
        p.max_records_per_command(RecordLayout::NUMBER_3, 8),
        Some(25)
    );
    assert_eq!(p.max_records_per_command(RecordLayout::RANGE, 4), Some(44));
    assert_eq!(
        p.max_records_per_command(RecordLayout::NUMBER_4_EXTENDED, 4),
        Some(39)
    );
    assert_eq!(
        p.max_records_per_command(RecordLayout::RANGE_EXTENDED, 8),
        Some(25)
    );
    assert_eq!(
        p.max_records_per_response(RecordLayout::NUMBER_3, 4),
        Some(41)
    );
    let x = Profile::XSEL_2003;
    assert_eq!(
        x.max_records_per_command(RecordLayout::NUMBER_3, 4),
        Some(20)
    );
    assert_eq!(x.max_records_per_command(RecordLayout::RANGE, 8), Some(12));
}

#[test]
fn profile_differences() {
    let mut buf = [0u8; 64];
    let sio = Command::VersionQuery(VersionQuery {
        unit_type: 3,
        device_number: 0,
    });
    assert!(Profile::TTA
        .emit_command(&sio, Station(0x99), &mut buf)
        .is_ok());
    assert_eq!(
        Profile::XSEL_2003.emit_command(&sio, Station(0x99), &mut buf),
        Err(Error::ValueOutOfRange { offset: 6 })
    );
    let ext = Command::ErrorDetailQuery(ErrorDetailQuery {
        type_1: 5,
        type_2: 0,
        record_number: 1,
    });
    assert!(Profile::TTA
        .emit_command(&ext, Station(0x99), &mut buf)
        .is_ok());
    assert!(Profile::XSEL_2003
        .emit_command(&ext, Station(0x99), &mut buf)
        .is_err());
    let cat = catalogue();
    for m in &cat.message {
        if m.id == "ERR" {
            continue;
        }
        // The 2003 message list (pp. 11-12): Cartesian-only and SCARA-only IDs.
        let cartesian_only = [0x212, 0x233, 0x234, 0x235, 0x237, 0x262, 0x26B];
        let scara_only = [0x2A0, 0x2A1, 0x2A2, 0x2A3, 0x2A4, 0x2D4, 0x2D5, 0x2D6];
        let id = m.code();
        let tta_generation = m.layout_source == "tta";
        assert_eq!(
            Profile::TTA.supports(id),
            !scara_only.contains(&id),
            "{}",
            m.id
        );
        assert_eq!(
            Profile::XSEL_2003.supports(id),
            !tta_generation && !scara_only.contains(&id),
            "{}",
            m.id
        );
        assert_eq!(
            Profile::XSEL_2003_SCARA.supports(id),
            !tta_generation && !cartesian_only.contains(&id),
            "{}",
            m.id
        );
    }
    // The real-variable word order must be chosen.
    assert!(Profile::TTA.real_word_order().is_err());
    let legacy = Profile::TTA.with_real_word_order(WordOrder::LowWordFirst);
    assert_eq!(legacy.real_word_order(), Ok(WordOrder::LowWordFirst));
    // Response limit: 2048 bytes on the TTA, 1024 on the old X-SEL.
    assert_eq!(Profile::TTA.check_response_len(2048), Ok(()));
    assert_eq!(
        Profile::TTA.check_response_len(2049),
        Err(Error::FrameTooLong { limit: 2048 })
    );
    assert_eq!(
        Profile::XSEL_2003.check_response_len(1025),
        Err(Error::FrameTooLong { limit: 1024 })
    );
    assert_eq!(Profile::XSEL_2003.max_command_frame(), 1023);
}

#[test]
fn real_and_string_variables() {
    // TTA p. 24 (2003 p. 23): 0x0123456789ABCDEF in both orders.
    let v = RealValue(0x0123_4567_89AB_CDEF);
    assert_eq!(v.to_wire(WordOrder::LowWordFirst).0, 0x89AB_CDEF_0123_4567);
    let bytes = frame_text('#', "20F", "000010189ABCDEF01234567");
    match decode_any(&check(&bytes)).unwrap().message {
        AnyMessage::Response(iai_protocol_b::message::Response::RealVariableResponse(r)) => {
            let w = r.real_variable_data.iter().next().unwrap();
            assert_eq!(w.value(WordOrder::LowWordFirst), v);
            assert_eq!(
                w.value(WordOrder::MostSignificantFirst).0,
                0x89AB_CDEF_0123_4567
            );
        }
        other => panic!("{other:?}"),
    }
    let s = StringVariableChange {
        program_number: 0,
        change_start_variable_number: 1,
        string_variable_data: Repeated::from_slice(b"HI"),
    };
    let mut buf = [0u8; 32];
    let n = s.emit(Station(0x99), &mut buf).unwrap();
    assert_eq!(&buf[..n], &frame_text('!', "24E", "00001024849")[..]);
    let echo = TestCall {
        test_string: *b"0123456789",
    };
    let n = echo.emit(Station(0x99), &mut buf).unwrap();
    assert_eq!(&buf[..n], b"!99200012345678932\r\n");
}
