//! Recorded and constructed frames (`fixtures/frames.txt`): each one is
//! checked as an envelope, decoded into its typed message where one exists,
//! compared with the value the fixture says it means, and emitted again.
//!
//! The second half spells out the most important frames as the manual
//! would: the bytes on the wire, the value they carry, and back.

#[path = "../fixtures/fixture_file.rs"]
mod fixture_file;

use fixture_file::{escape, Fixture};
use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::checksum::{BypassPolicy, Checksum, ChecksumField, ChecksumMode};
use iai_protocol_b::error::Error;
use iai_protocol_b::frame::{emit_frame, Frame, Header, Station};
use iai_protocol_b::message::*;
use iai_protocol_b::position::PositionRecord;

// ---------------------------------------------------------------------------
// Rendering a decoded message in the `means:` notation of the fixture file.

/// Renders a decoded message as the `means:` text of `fixtures/frames.txt`.
trait Describe {
    fn describe(&self) -> String;
}

fn text(bytes: &[u8]) -> String {
    format!("\"{}\"", escape(bytes))
}

/// Joins `name=value` pairs; `-` when there are none.
fn pairs(items: Vec<String>) -> String {
    if items.is_empty() {
        "-".to_string()
    } else {
        items.join(" ")
    }
}

impl Describe for TestCall {
    fn describe(&self) -> String {
        format!("test_string={}", text(&self.test_string))
    }
}

impl Describe for TestCallResponse {
    fn describe(&self) -> String {
        format!("test_string={}", text(&self.test_string))
    }
}

impl Describe for AxisStatusQuery {
    fn describe(&self) -> String {
        format!(
            "query_axis_pattern=0x{:02X}",
            self.query_axis_pattern.bits()
        )
    }
}

impl Describe for AxisStatusResponse {
    fn describe(&self) -> String {
        let mut v = vec![format!("axis_pattern=0x{:02X}", self.axis_pattern.bits())];
        assert_eq!(self.axes.len(), self.axis_pattern.count());
        for (axis, s) in self.axis_pattern.iter().zip(self.axes.iter()) {
            v.push(format!("axis{axis}.axis_status=0x{:02X}", s.axis_status));
            v.push(format!(
                "axis{axis}.sensor_input_status=0x{:01X}",
                s.sensor_input_status
            ));
            v.push(format!("axis{axis}.error_code=0x{:03X}", s.error_code));
            v.push(format!(
                "axis{axis}.encoder_status=0x{:02X}",
                s.encoder_status
            ));
            v.push(format!(
                "axis{axis}.current_position={}",
                s.current_position
            ));
        }
        pairs(v)
    }
}

impl Describe for SystemStatusQuery {
    fn describe(&self) -> String {
        pairs(vec![])
    }
}

impl Describe for SystemStatusResponse {
    fn describe(&self) -> String {
        pairs(vec![
            format!("system_mode={}", self.system_mode),
            format!("critical_system_error=0x{:03X}", self.critical_system_error),
            format!("latest_system_error=0x{:03X}", self.latest_system_error),
            format!("status_byte_1=0x{:02X}", self.status_byte_1),
            format!("status_byte_2=0x{:02X}", self.status_byte_2),
            format!("status_byte_3=0x{:02X}", self.status_byte_3),
            format!("status_byte_4=0x{:02X}", self.status_byte_4),
        ])
    }
}

impl Describe for ErrorDetailQuery {
    fn describe(&self) -> String {
        format!(
            "type_1={} type_2={} record_number={}",
            self.type_1, self.type_2, self.record_number
        )
    }
}

impl Describe for ErrorDetailResponse<'_> {
    fn describe(&self) -> String {
        pairs(vec![
            format!("error_number=0x{:03X}", self.error_number),
            format!("detail_1=0x{:08X}", self.detail_1),
            format!("detail_2=0x{:08X}", self.detail_2),
            format!("detail_3=0x{:08X}", self.detail_3),
            format!("detail_4={}", self.detail_4),
            format!("detail_5=0x{:08X}", self.detail_5),
            format!("detail_6=0x{:08X}", self.detail_6),
            format!("detail_7=0x{:08X}", self.detail_7),
            format!("detail_8=0x{:08X}", self.detail_8),
            format!(
                "reserved={},{},{},{},{},{},{}",
                self.reserved_1,
                self.reserved_2,
                self.reserved_3,
                self.reserved_4,
                self.reserved_5,
                self.reserved_6,
                self.reserved_7
            ),
            format!("message={}", text(self.message)),
        ])
    }
}

/// A position record as `recordN.` pairs (coordinates as `axisA=value`).
fn describe_record(n: usize, r: &PositionRecord) -> Vec<String> {
    let mut v = vec![
        format!("record{n}.number={}", r.number),
        format!("record{n}.axes=0x{:02X}", r.axes.bits()),
        format!("record{n}.acceleration={}", r.acceleration),
        format!("record{n}.deceleration={}", r.deceleration),
        format!("record{n}.speed={}", r.speed),
    ];
    for (axis, p) in r.axes.iter().zip(r.positions.iter()) {
        v.push(format!("record{n}.axis{axis}={p}"));
    }
    v
}

impl Describe for ChangePositionData2<'_> {
    fn describe(&self) -> String {
        let mut v = vec![format!("records={}", self.records.len())];
        for (i, r) in self.records.iter().enumerate() {
            v.extend(describe_record(i + 1, &r));
        }
        pairs(v)
    }
}

impl Describe for ChangePositionData2Response {
    fn describe(&self) -> String {
        format!(
            "number_of_changed_positions={}",
            self.number_of_changed_positions
        )
    }
}

// ---------------------------------------------------------------------------
// The table of typed messages.

/// What decoding a frame as its typed message produced.
struct Outcome {
    /// The value in `means:` notation.
    means: String,
    /// The frame emitted from the value with a computed checksum.
    emitted: Vec<u8>,
    /// The frame emitted from the value with `@@`.
    emitted_bypass: Vec<u8>,
}

/// Parses `frame` as `M`, renders it, and emits it both ways.
fn run<'a, M: Message<'a> + Describe>(frame: &Frame<'a>) -> Result<Outcome, Error> {
    let msg = M::parse(frame)?;
    let mut buf = [0u8; 4096];
    let n = msg.emit(frame.station(), &mut buf)?;
    let emitted = buf[..n].to_vec();
    let n = msg.emit_with(frame.station(), ChecksumMode::Bypass, &mut buf)?;
    Ok(Outcome {
        means: msg.describe(),
        emitted,
        emitted_bypass: buf[..n].to_vec(),
    })
}

/// Messages without data read `-`.
macro_rules! describe_empty {
    ($($t:ty),*) => {$(
        impl Describe for $t {
            fn describe(&self) -> String {
                "-".to_string()
            }
        }
    )*};
}
describe_empty!(
    EffectivePositionCountQuery,
    ServoOnOffResponse,
    HomeReturnResponse,
    AbsoluteMoveResponse,
    AlarmReset,
    SoftwareReset
);

impl Describe for EffectivePositionCountResponse {
    fn describe(&self) -> String {
        format!(
            "number_of_effective_positions={}",
            self.number_of_effective_positions
        )
    }
}

impl Describe for EffectivePositionQuery {
    fn describe(&self) -> String {
        format!(
            "query_head_position_number={} number_of_query_records={}",
            self.query_head_position_number, self.number_of_query_records
        )
    }
}

impl Describe for ServoOnOff {
    fn describe(&self) -> String {
        format!(
            "axis_pattern=0x{:02X} operation_type={}",
            self.axis_pattern.bits(),
            self.operation_type
        )
    }
}

impl Describe for HomeReturn {
    fn describe(&self) -> String {
        format!(
            "axis_pattern=0x{:02X} end_search_speed={} creep_speed={}",
            self.axis_pattern.bits(),
            self.end_search_speed,
            self.creep_speed
        )
    }
}

impl Describe for AbsoluteMove {
    fn describe(&self) -> String {
        let mut v = vec![
            format!("axis_pattern=0x{:02X}", self.axis_pattern.bits()),
            format!("acceleration={}", self.acceleration),
            format!("deceleration={}", self.deceleration),
            format!("speed={}", self.speed),
        ];
        for (axis, c) in self
            .axis_pattern
            .iter()
            .zip(self.absolute_coordinate.iter())
        {
            v.push(format!("axis{axis}.absolute_coordinate={c}"));
        }
        pairs(v)
    }
}

/// One typed message: the header and ID it answers to, and its decoder.
struct Typed {
    header: Header,
    id: u16,
    name: &'static str,
    run: fn(&Frame<'_>) -> Result<Outcome, Error>,
}

macro_rules! typed {
    ($header:ident, $id:literal, $ty:ident) => {
        Typed {
            header: Header::$header,
            id: $id,
            name: stringify!($ty),
            run: |f| run::<$ty>(f),
        }
    };
}

/// ===================== TYPED MESSAGES (extend here) =====================
///
/// Every fixture frame whose header and ID appear here is parsed with the
/// message type, compared with its `means:` line, and emitted from the
/// parsed value. Frames of other IDs get the envelope checks only.
///
/// To add a message: implement `Describe` for it above (field names and
/// number notation as in the `means:` lines of `fixtures/frames.txt`) and
/// add one `typed!` row. The test
/// `every_typed_fixture_frame_decodes_to_its_meaning` then covers it.
fn typed_messages() -> Vec<Typed> {
    vec![
        typed!(Command, 0x200, TestCall),
        typed!(Response, 0x200, TestCallResponse),
        typed!(Command, 0x212, AxisStatusQuery),
        typed!(Response, 0x212, AxisStatusResponse),
        typed!(Command, 0x215, SystemStatusQuery),
        typed!(Response, 0x215, SystemStatusResponse),
        typed!(Command, 0x216, ErrorDetailQuery),
        typed!(Response, 0x216, ErrorDetailResponse),
        typed!(Command, 0x26D, ChangePositionData2),
        typed!(Response, 0x26D, ChangePositionData2Response),
        typed!(Command, 0x208, EffectivePositionCountQuery),
        typed!(Response, 0x208, EffectivePositionCountResponse),
        typed!(Command, 0x209, EffectivePositionQuery),
        typed!(Command, 0x232, ServoOnOff),
        typed!(Response, 0x232, ServoOnOffResponse),
        typed!(Command, 0x233, HomeReturn),
        typed!(Response, 0x233, HomeReturnResponse),
        typed!(Command, 0x234, AbsoluteMove),
        typed!(Response, 0x234, AbsoluteMoveResponse),
        typed!(Command, 0x252, AlarmReset),
        typed!(Command, 0x25B, SoftwareReset),
    ]
}
// =========================================================================

fn typed_for(frame: &Frame<'_>) -> Option<Typed> {
    typed_messages()
        .into_iter()
        .find(|t| t.header == frame.header() && Some(t.id) == frame.message_id().map(|m| m.0))
}

fn check(f: &Fixture) -> Frame<'_> {
    Frame::new_checked(&f.frame, BypassPolicy::default())
        .unwrap_or_else(|e| panic!("{} (line {}): {e}", f.name, f.line))
}

// ---------------------------------------------------------------------------
// Table-driven tests over every fixture.

#[test]
fn fixture_file_is_well_formed() {
    let all = fixture_file::load();
    assert!(all.len() >= 45, "only {} fixtures", all.len());
    let mut names: Vec<&str> = all.iter().map(|f| f.name.as_str()).collect();
    names.sort_unstable();
    let before = names.len();
    names.dedup();
    assert_eq!(before, names.len(), "fixture names must be unique");
    for f in &all {
        assert!(
            f.frame.ends_with(b"\r\n"),
            "{}: a frame ends with CR LF",
            f.name
        );
        let expected_dir = match f.frame[0] {
            b'!' => "host>controller",
            _ => "controller>host",
        };
        assert_eq!(f.dir, expected_dir, "{}: direction vs header", f.name);
        assert!(!f.source.is_empty() && !f.means.is_empty(), "{}", f.name);
        // Escaping round-trips, so the file shows every byte faithfully.
        assert_eq!(fixture_file::unescape(&escape(&f.frame)), f.frame);
    }
}

#[test]
fn fixture_checksums_follow_the_rule_independently_of_the_core() {
    // The checksum rule of 2003 p. 10, written out again here.
    for f in fixture_file::load() {
        let sc_at = f.frame.len() - 4;
        let sc = &f.frame[sc_at..sc_at + 2];
        for bytes in [&f.frame[..], f.expected_emission()] {
            let sc_at = bytes.len() - 4;
            let sum = bytes[..sc_at].iter().fold(0u8, |s, &b| s.wrapping_add(b));
            let sc = &bytes[sc_at..sc_at + 2];
            if sc == b"@@" {
                continue;
            }
            let text = std::str::from_utf8(sc).unwrap();
            assert_eq!(
                u8::from_str_radix(text, 16).unwrap(),
                sum,
                "{}: SC {text}",
                f.name
            );
        }
        if sc != b"@@" {
            assert_eq!(
                Checksum::of(&f.frame[..sc_at]),
                u8::from_str_radix(std::str::from_utf8(sc).unwrap(), 16).unwrap()
            );
        }
    }
}

#[test]
fn every_fixture_frame_passes_the_envelope_check() {
    for f in fixture_file::load() {
        let frame = check(&f);
        let kind = match frame.header() {
            Header::Command => "command",
            Header::Response => "response",
            Header::Error => "error",
        };
        let sc = match frame.checksum() {
            ChecksumField::Sum(s) => format!("{s:02X}"),
            ChecksumField::Bypass => "@@".to_string(),
        };
        let envelope = format!(
            "{kind} station={:02X} code={:03X} sc={sc}",
            frame.station().0,
            frame.code()
        );
        assert_eq!(envelope, f.envelope, "{} (line {})", f.name, f.line);
        assert_eq!(frame.as_bytes(), &f.frame[..]);
        assert_eq!(frame.len(), f.frame.len());
        assert_eq!(frame.body(), &f.frame[6..f.frame.len() - 4]);
        match frame.header() {
            Header::Error => {
                assert_eq!(frame.message_id(), None);
                assert_eq!(frame.error_code(), Some(frame.code()));
            }
            _ => {
                assert_eq!(frame.message_id().map(|m| m.0), Some(frame.code()));
                assert_eq!(frame.error_code(), None);
            }
        }
    }
}

#[test]
fn every_typed_fixture_frame_decodes_to_its_meaning() {
    let mut typed = 0;
    let mut envelope_only = std::collections::BTreeSet::new();
    for f in fixture_file::load() {
        let frame = check(&f);
        if frame.header() == Header::Error {
            let means = format!("error_code=0x{:03X}", frame.error_code().unwrap());
            assert_eq!(means, f.means, "{}", f.name);
            typed += 1;
            continue;
        }
        match typed_for(&frame) {
            Some(t) => {
                let out =
                    (t.run)(&frame).unwrap_or_else(|e| panic!("{} as {}: {e}", f.name, t.name));
                assert_eq!(out.means, f.means, "{} decoded as {}", f.name, t.name);
                typed += 1;
            }
            None => {
                envelope_only.insert(format!("{:?} {:03X}H", frame.header(), frame.code()));
            }
        }
    }
    eprintln!("{typed} fixture frames decoded as typed messages; envelope only: {envelope_only:?}");
    assert!(typed >= 30, "only {typed} typed fixture frames");
}

#[test]
fn every_fixture_frame_re_emits_identically_or_normalised() {
    for f in fixture_file::load() {
        let frame = check(&f);
        let emitted = match typed_for(&frame) {
            Some(t) => (t.run)(&frame).unwrap().emitted,
            None => {
                // Envelope only: emit the same header, station, code and body
                // (body hex digits in upper case) with a computed checksum.
                let mut buf = [0u8; 4096];
                let body = frame.body().to_ascii_uppercase();
                let n = emit_frame(
                    &mut buf,
                    frame.header(),
                    frame.station(),
                    frame.code(),
                    ChecksumMode::Compute,
                    |w| w.put(&body),
                )
                .unwrap();
                buf[..n].to_vec()
            }
        };
        assert_eq!(
            escape(&emitted),
            escape(f.expected_emission()),
            "{} (line {})",
            f.name,
            f.line
        );
        // The emission is itself a valid frame with a real checksum.
        let again = Frame::new_checked(&emitted, BypassPolicy::Reject).unwrap();
        assert!(matches!(again.checksum(), ChecksumField::Sum(_)));
    }
}

#[test]
fn bypass_frames_re_emit_with_bypass_byte_for_byte() {
    let mut seen = 0;
    for f in fixture_file::load() {
        let frame = check(&f);
        if frame.checksum() != ChecksumField::Bypass {
            continue;
        }
        seen += 1;
        match typed_for(&frame) {
            Some(t) => assert_eq!((t.run)(&frame).unwrap().emitted_bypass, f.frame),
            None => {
                let mut buf = [0u8; 64];
                let n = emit_frame(
                    &mut buf,
                    frame.header(),
                    frame.station(),
                    frame.code(),
                    ChecksumMode::Bypass,
                    |w| w.put(frame.body()),
                )
                .unwrap();
                assert_eq!(&buf[..n], &f.frame[..], "{}", f.name);
            }
        }
    }
    assert_eq!(seen, 5);
}

#[test]
fn every_fixture_frame_is_refused_by_other_typed_messages() {
    // A frame parses only as its own message: every other typed message
    // reports the header or ID that does not fit.
    for f in fixture_file::load() {
        let frame = check(&f);
        for t in typed_messages() {
            if t.header == frame.header() && Some(t.id) == frame.message_id().map(|m| m.0) {
                continue;
            }
            let e = (t.run)(&frame).err().unwrap();
            let expected = if t.header != frame.header() {
                Error::UnexpectedHeader {
                    expected: t.header,
                    found: frame.header(),
                }
            } else {
                Error::UnexpectedMessageId {
                    expected: t.id,
                    found: frame.code(),
                }
            };
            assert_eq!(e, expected, "{} as {}", f.name, t.name);
        }
    }
}

// ---------------------------------------------------------------------------
// The frames the manual would print, spelled out.

fn frame(bytes: &[u8]) -> Frame<'_> {
    Frame::new_checked(bytes, BypassPolicy::default()).unwrap()
}

fn emit<'a, M: Message<'a>>(m: &M, station: u8) -> Vec<u8> {
    let mut buf = [0u8; 2100];
    let n = m.emit(Station(station), &mut buf).unwrap();
    buf[..n].to_vec()
}

fn axis_status(
    axis_status: u8,
    sensor_input_status: u8,
    error_code: u16,
    encoder_status: u8,
    current_position: i32,
) -> AxisStatus {
    AxisStatus {
        axis_status,
        sensor_input_status,
        error_code,
        encoder_status,
        current_position,
    }
}

#[test]
fn p10_checksum_example_209h_sums_to_254h() {
    // 2003 p. 10: "!99209001005" sums to 254H, so SC is "54".
    let wire = b"!9920900100554\r\n";
    assert_eq!(Checksum::of(&wire[..12]), 0x54);
    let f = frame(wire);
    assert_eq!(f.header(), Header::Command);
    assert_eq!(f.station(), Station(0x99));
    assert_eq!(f.code(), 0x209);
    assert_eq!(f.body(), b"001005");
    assert_eq!(f.checksum(), ChecksumField::Sum(0x54));
}

#[test]
fn captured_212h_reply_means_axis_2_homed_at_10_005_mm() {
    let wire = b"#99212021C00000000002715AF\r\n";
    let value = AxisStatusResponse {
        axis_pattern: AxisPattern::from_axes(&[2]).unwrap(),
        axes: PerAxis::from_slice(&[axis_status(0x1C, 0, 0, 0, 10_005)]).unwrap(),
    };
    assert_eq!(AxisStatusResponse::parse(&frame(wire)).unwrap(), value);
    assert_eq!(emit(&value, 0x99), wire);
}

#[test]
fn constructed_212h_reply_carries_negative_positions_as_twos_complement() {
    let wire = b"#99212071C000000000186A00D40A300FFF9E580081000C0FFFFFFFF2A\r\n";
    let value = AxisStatusResponse {
        axis_pattern: AxisPattern::first(3),
        axes: PerAxis::from_slice(&[
            axis_status(0x1C, 0x0, 0x000, 0x00, 100_000),
            axis_status(0x0D, 0x4, 0x0A3, 0x00, -400_000),
            axis_status(0x08, 0x1, 0x000, 0xC0, -1),
        ])
        .unwrap(),
    };
    assert_eq!(AxisStatusResponse::parse(&frame(wire)).unwrap(), value);
    assert_eq!(emit(&value, 0x99), wire);
}

#[test]
fn host_212h_query_with_bypass_means_axes_1_to_3() {
    let wire = b"!9921207@@\r\n";
    let value = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(3),
    };
    let f = frame(wire);
    assert_eq!(f.checksum(), ChecksumField::Bypass);
    assert_eq!(AxisStatusQuery::parse(&f).unwrap(), value);
    assert_eq!(emit(&value, 0x99), b"!99212078F\r\n");
    let mut buf = [0u8; 16];
    let n = value
        .emit_with(Station(0x99), ChecksumMode::Bypass, &mut buf)
        .unwrap();
    assert_eq!(&buf[..n], wire);
}

#[test]
fn test_call_200h_echoes_ten_raw_characters() {
    let cmd = TestCall {
        test_string: *b"0123456789",
    };
    assert_eq!(emit(&cmd, 0x99), b"!99200012345678932\r\n");
    let reply = TestCallResponse::parse(&frame(b"#99200012345678934\r\n")).unwrap();
    assert_eq!(reply.test_string, cmd.test_string);
    // Header bytes inside the text are text, not a new frame.
    let odd = TestCall {
        test_string: *b"#!&%@ a~\\x",
    };
    let wire = emit(&odd, 0x99);
    assert_eq!(wire, b"!99200#!&%@ a~\\xC7\r\n");
    assert_eq!(TestCall::parse(&frame(&wire)).unwrap(), odd);
}

#[test]
fn system_status_215h_reply_in_auto_mode() {
    assert_eq!(emit(&SystemStatusQuery {}, 0x99), b"!992152B\r\n");
    let wire = b"#9921510000A1042016001D\r\n";
    let value = SystemStatusResponse {
        system_mode: 1,
        critical_system_error: 0,
        latest_system_error: 0x0A1,
        status_byte_1: 0x04,
        status_byte_2: 0x20,
        status_byte_3: 0x16,
        status_byte_4: 0x00,
    };
    assert_eq!(SystemStatusResponse::parse(&frame(wire)).unwrap(), value);
    assert_eq!(emit(&value, 0x99), wire);
}

#[test]
fn error_detail_216h_latest_system_error_and_its_94_byte_reply() {
    let query = ErrorDetailQuery {
        type_1: 0,
        type_2: 1,
        record_number: 0,
    };
    assert_eq!(emit(&query, 0x99), b"!992160010004D\r\n");
    let wire: &[u8] = b"#99216C74000000010000000500000002FFFFFFFD0000000000000000000000000000000000000000000000000C2\r\n";
    assert_eq!(wire.len(), 94);
    let value = ErrorDetailResponse {
        error_number: 0xC74,
        detail_1: 1,
        detail_2: 5,
        detail_3: 2,
        detail_4: -3,
        detail_5: 0,
        detail_6: 0,
        detail_7: 0,
        detail_8: 0,
        reserved_1: 0,
        reserved_2: 0,
        reserved_3: 0,
        reserved_4: 0,
        reserved_5: 0,
        reserved_6: 0,
        reserved_7: 0,
        message: b"",
    };
    assert_eq!(ErrorDetailResponse::parse(&frame(wire)).unwrap(), value);
    assert_eq!(emit(&value, 0x99), wire);
}

#[test]
fn error_detail_216h_reply_with_a_message_containing_header_bytes() {
    let wire: &[u8] = b"#992160A10000000C0000012300000003FFFFFFFF000000000000000000000000FFFFFFFF0102034050607890FServo #1 error!AD\r\n";
    let value = ErrorDetailResponse::parse(&frame(wire)).unwrap();
    assert_eq!(value.message, b"Servo #1 error!");
    assert_eq!(value.detail_4, -1);
    assert_eq!(value.detail_8, u32::MAX);
    assert_eq!(
        (value.reserved_1, value.reserved_4, value.reserved_7),
        (1, 4, 789)
    );
    assert_eq!(emit(&value, 0x99), wire);
}

#[test]
fn change_position_26dh_two_records_of_different_length() {
    let wire: &[u8] =
        b"!9926D0002000103001E001E0064000186A0FFFF9C64000201000000000000000030392B\r\n";
    let records = [
        PositionRecord::new(1, 30, 30, 100, &[(1, 100_000), (2, -25_500)]).unwrap(),
        PositionRecord::new(2, 0, 0, 0, &[(1, 12_345)]).unwrap(),
    ];
    let value = ChangePositionData2 {
        records: Repeated::from_slice(&records),
    };
    assert_eq!(emit(&value, 0x99), wire);
    let parsed = ChangePositionData2::parse(&frame(wire)).unwrap();
    assert_eq!(parsed, value);
    assert!(parsed.records.iter().eq(records.iter().cloned()));
    assert_eq!(
        parsed.records.iter().nth(1).unwrap().position(1),
        Some(12_345)
    );

    let reply = ChangePositionData2Response {
        number_of_changed_positions: 2,
    };
    assert_eq!(emit(&reply, 0x99), b"#9926D000203\r\n");
}

#[test]
fn change_position_26dh_largest_four_axis_write_fits_the_tta_buffer() {
    // 40 records of 4 axes make a 2014-byte frame (TTA p. 60 arithmetic).
    let records: Vec<PositionRecord> = (0..40)
        .map(|i| PositionRecord::new(i, 30, 30, 100, &[(1, 1), (2, -2), (3, 3), (4, -4)]).unwrap())
        .collect();
    let value = ChangePositionData2 {
        records: Repeated::from_slice(&records),
    };
    let wire = emit(&value, 0x99);
    assert_eq!(wire.len(), 2014);
    let parsed = ChangePositionData2::parse(&frame(&wire)).unwrap();
    assert_eq!(parsed.records.len(), 40);
    assert_eq!(parsed, value);
}

#[test]
fn error_response_carries_a_code_not_a_message_id() {
    let f = frame(b"&99ABC5E\r\n");
    assert_eq!(f.header(), Header::Error);
    assert_eq!(f.error_code(), Some(0xABC));
    assert_eq!(f.message_id(), None);
    // '%' (2003 p. 65) is read as an error header too.
    let f = frame(b"%99ABC5D\r\n");
    assert_eq!(f.header(), Header::Error);
    assert_eq!(f.error_code(), Some(0xABC));
}
