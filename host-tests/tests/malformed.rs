//! Catalogue of malformed input (issue 6).
//!
//! Part 1, the stream: each row is the bytes a receiver might get and the
//! exact events the decoder must report for them. The harness appends one
//! valid frame ([`NEXT`]) to every row and expects it to come out after the
//! row's events: whatever the fault, the next frame still decodes. Every
//! row runs byte by byte with `push`, in one `decode` call and split in two
//! at every position, with the same events each time, and every byte must
//! be accounted for (in a frame, discarded, or pending).
//!
//! Part 2, the messages: valid frames whose body does not fit the message
//! layout, each with the exact [`Error`] of `Message::parse`; and values that
//! cannot be emitted.
//!
//! Part 3: regression tests for core defects this catalogue found (fixed).

mod replay;

use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status, DEFAULT_CAPACITY};
use iai_protocol_b::error::Error;
use iai_protocol_b::error::Error::*;
use iai_protocol_b::field::{decode_signed, encode_signed, FieldSpec};
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::message::*;
use iai_protocol_b::position::PositionRecord;
use replay::{decode_chunks, push_bytes, Out};

/// The valid frame appended to every row.
const NEXT: &[u8] = b"#992322C\r\n";

fn fr(bytes: &[u8]) -> Out {
    Out::Frame(bytes.to_vec())
}

fn er(e: Error) -> Out {
    Out::Error(e)
}

/// `text` plus its checksum (computed here, not by the core) and CR LF.
fn sealed(text: &[u8]) -> Vec<u8> {
    let sum = text.iter().fold(0u8, |s, &b| s.wrapping_add(b));
    let mut v = text.to_vec();
    v.extend_from_slice(format!("{sum:02X}\r\n").as_bytes());
    v
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

struct Case {
    name: &'static str,
    input: Vec<u8>,
    policy: BypassPolicy,
    /// Events for `input` followed by [`NEXT`], without NEXT's own frame.
    expect: Vec<Out>,
}

fn case(name: &'static str, input: impl AsRef<[u8]>, expect: Vec<Out>) -> Case {
    Case {
        name,
        input: input.as_ref().to_vec(),
        policy: BypassPolicy::default(),
        expect,
    }
}

fn with_policy(policy: BypassPolicy, mut c: Case) -> Case {
    c.policy = policy;
    c
}

/// A 212H reply used as a base for body faults.
const AXIS2: &[u8] = b"#99212021C00000000002715AF\r\n";
/// A 94-byte 216H reply as a TTA sends it (TTA p. 33: no message text),
/// without SC, CR, LF.
const DETAIL: &[u8] =
    b"#99216C74000000010000000500000002FFFFFFFD0000000000000000000000000000000000000000000000000";

/// A frame of exactly `len` bytes: 209H with a hex body, correct checksum.
fn long_frame(len: usize) -> Vec<u8> {
    let mut text = b"!99209".to_vec();
    text.extend(std::iter::repeat_n(b'A', len - 10));
    sealed(&text)
}

#[rustfmt::skip]
fn stream_cases() -> Vec<Case> {
    use BypassPolicy::{Accept, CommandsOnly, Reject};
    vec![
        // ---- header -------------------------------------------------------
        case("noise before the header is discarded", b"xyz#992322C\r\n", vec![fr(b"#992322C\r\n")]),
        case("frame without its header is noise", b"992322C\r\n", vec![]),
        case("unknown header byte '$' is noise", b"$992322C\r\n", vec![]),
        case("header 'percent' is an error response", b"%99ABC5D\r\n", vec![fr(b"%99ABC5D\r\n")]),
        case("doubled header cuts a 1-byte frame", b"##992322C\r\n", vec![er(Truncated { len: 1 }), fr(b"#992322C\r\n")]),
        case("every header byte in a row", b"!#&%", vec![er(Truncated { len: 1 }), er(Truncated { len: 1 }), er(Truncated { len: 1 }), er(Truncated { len: 1 })]),
        // ---- station ------------------------------------------------------
        case("station first digit not hex", b"#G92322C\r\n", vec![er(InvalidHexDigit { offset: 1, byte: b'G' })]),
        case("station second digit not hex", b"#9g2322C\r\n", vec![er(InvalidHexDigit { offset: 2, byte: b'g' })]),
        case("station with a space", b"# 92322C\r\n", vec![er(InvalidHexDigit { offset: 1, byte: b' ' })]),
        case("station in lower case is accepted", b"!0a2154A\r\n", vec![fr(b"!0a2154A\r\n")]),
        // ---- message ID / error code -------------------------------------
        case("ID first digit not hex", b"#99G322C\r\n", vec![er(InvalidHexDigit { offset: 3, byte: b'G' })]),
        case("ID last digit not hex", b"#9923X2C\r\n", vec![er(InvalidHexDigit { offset: 5, byte: b'X' })]),
        case("ID in lower case is accepted", b"!9925b5C\r\n", vec![fr(b"!9925b5C\r\n")]),
        case("error code not hex", b"&99ABG5F\r\n", vec![er(InvalidHexDigit { offset: 5, byte: b'G' })]),
        // ---- body fields -------------------------------------------------
        case("body digit not hex", b"#99212021C0000000000271G5AF\r\n", vec![er(InvalidHexDigit { offset: 23, byte: b'G' })]),
        case("body NUL byte", b"#99212021C000000\x0000002715AF\r\n", vec![er(InvalidHexDigit { offset: 16, byte: 0 })]),
        case("body byte >= 0x80", b"#99212021C00000000\xB02715AF\r\n", vec![er(InvalidHexDigit { offset: 18, byte: 0xB0 })]),
        case("body space", b"#99212021C 0000000002715AF\r\n", vec![er(InvalidHexDigit { offset: 10, byte: b' ' })]),
        case("body in lower-case hex is accepted", b"#99212021c00000000002715CF\r\n", vec![fr(b"#99212021c00000000002715CF\r\n")]),
        case("header byte in a 200H test string is text", b"!99200#!&%@ a~\\xC7\r\n", vec![fr(b"!99200#!&%@ a~\\xC7\r\n")]),
        case("CR LF inside a 200H test string is text", b"!99200AB\r\nCDEFGH60\r\n", vec![fr(b"!99200AB\r\nCDEFGH60\r\n")]),
        case("bytes >= 0x80 in a 200H test string are text", b"!99200ABC\xB0\xFF DEFGD0\r\n", vec![fr(b"!99200ABC\xB0\xFF DEFGD0\r\n")]),
        case("header bytes in a 216H message are text",
            b"#992160A10000000C0000012300000003FFFFFFFF000000000000000000000000FFFFFFFF0102034050607890FServo #1 error!AD\r\n",
            vec![fr(b"#992160A10000000C0000012300000003FFFFFFFF000000000000000000000000FFFFFFFF0102034050607890FServo #1 error!AD\r\n")]),
        case("header byte in a hex body cuts the frame", b"#99212#992322C\r\n", vec![er(Truncated { len: 6 }), fr(b"#992322C\r\n")]),
        // ---- length ------------------------------------------------------
        case("frame of 3 bytes", b"#\r\n", vec![er(FrameTooShort { len: 3 })]),
        case("frame of 5 bytes", b"#99\r\n", vec![er(FrameTooShort { len: 5 })]),
        case("frame of 9 bytes (one SC digit lost)", b"#992322\r\n", vec![er(FrameTooShort { len: 9 })]),
        case("shortest frame, 10 bytes", b"&99ABC5E\r\n", vec![fr(b"&99ABC5E\r\n")]),
        case("frame of exactly the capacity", long_frame(DEFAULT_CAPACITY), vec![fr(&long_frame(DEFAULT_CAPACITY))]),
        case("frame one byte over the capacity", long_frame(DEFAULT_CAPACITY + 1), vec![er(FrameTooLong { limit: DEFAULT_CAPACITY })]),
        case("endless frame with no CR LF", cat(&[b"!99209", &[b'0'; 3000]]), vec![er(FrameTooLong { limit: DEFAULT_CAPACITY })]),
        // ---- checksum ----------------------------------------------------
        case("checksum off by one", b"#992322D\r\n", vec![er(ChecksumMismatch { computed: 0x2C, received: 0x2D })]),
        case("checksum digits swapped", b"#99232C2\r\n", vec![er(ChecksumMismatch { computed: 0x2C, received: 0xC2 })]),
        case("checksum not hex", b"#99232ZZ\r\n", vec![er(InvalidHexDigit { offset: 6, byte: b'Z' })]),
        case("checksum in lower case is accepted", b"!00232071b0\r\n", vec![fr(b"!00232071b0\r\n")]),
        case("checksum with one digit lost", b"#99212021C00000000002715A\r\n", vec![er(ChecksumMismatch { computed: 0x7A, received: 0x5A })]),
        case("half a bypass", b"!99252@C\r\n", vec![er(InvalidHexDigit { offset: 6, byte: b'@' })]),
        // ---- '@@' under each policy -------------------------------------
        with_policy(Reject, case("@@ on a command, Reject", b"!99252@@\r\n", vec![er(ChecksumBypassRejected)])),
        with_policy(CommandsOnly, case("@@ on a command, CommandsOnly", b"!99252@@\r\n", vec![fr(b"!99252@@\r\n")])),
        with_policy(Accept, case("@@ on a command, Accept", b"!99252@@\r\n", vec![fr(b"!99252@@\r\n")])),
        with_policy(Reject, case("@@ on a response, Reject", b"#99232@@\r\n", vec![er(ChecksumBypassRejected)])),
        with_policy(CommandsOnly, case("@@ on a response, CommandsOnly", b"#99232@@\r\n", vec![er(ChecksumBypassRejected)])),
        with_policy(Accept, case("@@ on a response, Accept", b"#99232@@\r\n", vec![fr(b"#99232@@\r\n")])),
        with_policy(CommandsOnly, case("@@ on an error response, CommandsOnly", b"&99ABC@@\r\n", vec![er(ChecksumBypassRejected)])),
        with_policy(Accept, case("@@ on an error response, Accept", b"&99ABC@@\r\n", vec![fr(b"&99ABC@@\r\n")])),
        with_policy(Reject, case("real checksum, Reject", b"!992522C\r\n", vec![fr(b"!992522C\r\n")])),
        // ---- terminator --------------------------------------------------
        case("LF without CR", b"#992322C\n", vec![er(MissingCarriageReturn)]),
        case("LF then CR", b"#992322C\n\r", vec![er(MissingCarriageReturn)]),
        case("CR CR LF", b"#992322C\r\r\n", vec![er(MissingLineFeed { byte: b'\r' })]),
        case("CR then a letter", b"#992322C\rX", vec![er(MissingLineFeed { byte: b'X' })]),
        case("CR then the next frame", b"#992322C\r#992322C\r\n", vec![er(MissingLineFeed { byte: b'#' }), fr(b"#992322C\r\n")]),
        case("CR at the end of the input", b"#992322C\r", vec![er(MissingLineFeed { byte: b'#' })]),
        case("no CR LF, then the next frame", b"#992322C#992322C\r\n", vec![er(Truncated { len: 8 }), fr(b"#992322C\r\n")]),
        case("NUL instead of CR LF", b"#992322C\x00", vec![er(Truncated { len: 9 })]),
        case("stray CR LF between frames", b"\r\n\r\n", vec![]),
        // ---- lost bytes, truncation --------------------------------------
        case("a body digit lost", b"#99212021C000000000715AF\r\n", vec![er(ChecksumMismatch { computed: 0x4D, received: 0xAF })]),
        case("frame cut after 13 bytes, then the next", b"#99212021C000", vec![er(Truncated { len: 13 })]),
        case("truncated frame followed by a valid one", b"#99212021C000#992322C\r\n", vec![er(Truncated { len: 13 }), fr(b"#992322C\r\n")]),
        case("only a header at the end of the input", b"!", vec![er(Truncated { len: 1 })]),
        // A 200H cut inside its 10-character text: the next frame's first
        // bytes are read as text; when the 200H fails they are decoded
        // again, and that frame survives.
        case("200H cut inside its text keeps the next frame", b"!99200ABC#992322C\r\n", vec![er(BodyTooShort { offset: 15 }), fr(b"#992322C\r\n")]),
        // A 216H reply whose count promises more text than it carries: the
        // text runs over the next frame, which is decoded again when the
        // 216H fails, and survives.
        case("216H message count overstated keeps the next frame",
            cat(&[&sealed(&cat(&[&DETAIL[..88], b"10ABCD"])), b"#992322C\r\n"]),
            vec![er(BodyTooShort { offset: 104 }), fr(b"#992322C\r\n")]),
        // ---- noise -------------------------------------------------------
        case("noise inside the ID", b"#9923xx22C\r\n", vec![er(InvalidHexDigit { offset: 5, byte: b'x' })]),
        case("binary noise without header bytes", (0x80..=0xFFu8).collect::<Vec<u8>>(), vec![]),
        case("a run of NUL bytes", [0u8; 64], vec![]),
        case("noise, frame, noise, frame", b"\x00\xFF@@#992322C\r\nZZ\r\n#9926D000102\r\n..", vec![fr(b"#992322C\r\n"), fr(b"#9926D000102\r\n")]),
        case("bypass marker alone is noise", b"@@\r\n", vec![]),
    ]
}

/// Runs `input` through a fresh decoder in the given chunks.
fn run(input: &[u8], policy: BypassPolicy, cuts: &[usize]) -> (Vec<Out>, FrameDecoder) {
    let mut dec: FrameDecoder = FrameDecoder::with_policy(policy);
    let out = decode_chunks(&mut dec, input, cuts);
    (out, dec)
}

fn run_push(input: &[u8], policy: BypassPolicy) -> Vec<Out> {
    let mut dec: FrameDecoder = FrameDecoder::with_policy(policy);
    push_bytes(&mut dec, input)
}

fn accounted(dec: &FrameDecoder, events: &[Out], input_len: usize) {
    let s = dec.stats();
    let frame_bytes: usize = events
        .iter()
        .map(|e| match e {
            Out::Frame(f) => f.len(),
            Out::Error(_) => 0,
        })
        .sum();
    let frames = events.iter().filter(|e| matches!(e, Out::Frame(_))).count();
    assert_eq!(s.frames as usize, frames);
    assert_eq!(s.errors as usize, events.len() - frames);
    assert_eq!(
        frame_bytes + s.discarded_bytes as usize + dec.pending(),
        input_len
    );
}

#[test]
fn malformed_stream_catalogue() {
    let cases = stream_cases();
    assert!(cases.len() >= 40, "{} cases", cases.len());
    let mut kinds = std::collections::BTreeSet::new();
    let mut failures = Vec::new();
    for c in &cases {
        let input = cat(&[&c.input, NEXT]);
        let mut expect = c.expect.clone();
        expect.push(fr(NEXT));
        for e in &c.expect {
            if let Out::Error(e) = e {
                kinds.insert(
                    format!("{e:?}")
                        .split([' ', '{'])
                        .next()
                        .unwrap()
                        .to_string(),
                );
            }
        }

        let (got, dec) = run(&input, c.policy, &[]);
        if got != expect {
            failures.push(format!("{}:\n   got {got:?}\n  want {expect:?}", c.name));
            continue;
        }
        accounted(&dec, &got, input.len());
        assert_eq!(dec.pending(), 0, "{}", c.name);

        assert_eq!(run_push(&input, c.policy), expect, "{}: push", c.name);

        let cuts: Vec<usize> = if input.len() <= 400 {
            (0..=input.len()).collect()
        } else {
            (0..=input.len()).step_by(97).collect()
        };
        for cut in cuts {
            let (got, dec) = run(&input, c.policy, &[cut]);
            assert_eq!(got, expect, "{}: split at {cut}", c.name);
            accounted(&dec, &got, input.len());
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    eprintln!(
        "{} malformed stream cases; error kinds: {kinds:?}",
        cases.len()
    );
}

#[test]
fn decoders_with_a_small_buffer_report_their_own_limit() {
    let mut dec: FrameDecoder<16> = FrameDecoder::new();
    let frame = b"!9920900100554\r\n"; // exactly 16 bytes
    let d = dec.decode(frame);
    assert!(matches!(d.status, Status::Complete(Event::Frame(f)) if f.as_bytes() == frame));
    let longer = b"!99212021C00000000002715AF\r\n";
    let d = dec.decode(longer);
    assert_eq!(
        d.status,
        Status::Complete(Event::Error(FrameTooLong { limit: 16 }))
    );
    assert_eq!(d.consumed, 17);
    let rest = &longer[17..];
    let d = dec.decode(rest);
    assert_eq!(d.status, Status::Partial);
    let d = dec.decode(NEXT);
    assert!(matches!(d.status, Status::Complete(Event::Frame(f)) if f.as_bytes() == NEXT));
    assert_eq!(dec.stats().discarded_bytes as usize, longer.len());
}

// ---------------------------------------------------------------------------
// Part 2: message-level faults on frames whose envelope is valid.

type Parse = fn(&Frame<'_>) -> Result<(), Error>;

/// Name, frame bytes, (message type, its parse), the exact error.
type MessageCase = (&'static str, Vec<u8>, (&'static str, Parse), Error);

macro_rules! parse_as {
    ($ty:ident) => {
        (stringify!($ty), (|f| $ty::parse(f).map(|_| ())) as Parse)
    };
}

#[rustfmt::skip]
fn message_cases() -> Vec<MessageCase> {
    let records2 = b"!9926D0002000103001E001E0064000186A0FFFF9C64";
    vec![
        // ---- body length ---------------------------------------------------
        (
            "212H reply: pattern 03 but one axis block",
            sealed(b"#99212031C00000000002715"),
            parse_as!(AxisStatusResponse),
            BodyTooShort { offset: 24 },
        ),
        (
            "212H reply: a block more than the pattern",
            sealed(b"#99212011C000000000027151C00000000002715"),
            parse_as!(AxisStatusResponse),
            TrailingBytes { offset: 24 },
        ),
        (
            "212H reply: pattern 00 with a block",
            sealed(b"#99212001C00000000002715"),
            parse_as!(AxisStatusResponse),
            TrailingBytes { offset: 8 },
        ),
        (
            "212H reply: block cut in its position",
            sealed(b"#99212011C000000000027"),
            parse_as!(AxisStatusResponse),
            BodyTooShort { offset: 16 },
        ),
        (
            "212H query: no pattern",
            sealed(b"!99212"),
            parse_as!(AxisStatusQuery),
            BodyTooShort { offset: 6 },
        ),
        (
            "212H query: pattern of 3 digits",
            sealed(b"!99212007"),
            parse_as!(AxisStatusQuery),
            TrailingBytes { offset: 8 },
        ),
        (
            "215H query with data",
            sealed(b"!9921500"),
            parse_as!(SystemStatusQuery),
            TrailingBytes { offset: 6 },
        ),
        (
            "215H reply: last status byte missing",
            sealed(b"#9921510000A1042016"),
            parse_as!(SystemStatusResponse),
            BodyTooShort { offset: 19 },
        ),
        (
            "215H reply: one byte too many",
            sealed(b"#9921510000A1042016000"),
            parse_as!(SystemStatusResponse),
            TrailingBytes { offset: 21 },
        ),
        (
            "216H query: 5 characters",
            sealed(b"!9921600100"),
            parse_as!(ErrorDetailQuery),
            BodyTooShort { offset: 9 },
        ),
        (
            "216H query: 7 characters",
            sealed(b"!992160010000"),
            parse_as!(ErrorDetailQuery),
            TrailingBytes { offset: 12 },
        ),
        (
            "216H reply: message count 02, 3 characters",
            sealed(&cat(&[&DETAIL[..88], b"02ABC"])),
            parse_as!(ErrorDetailResponse),
            TrailingBytes { offset: 92 },
        ),
        (
            "200H: 11 characters",
            sealed(b"!99200012345678901"),
            parse_as!(TestCall),
            TrailingBytes { offset: 16 },
        ),
        (
            "200H reply: 12 characters",
            sealed(b"#99200012345678901"),
            parse_as!(TestCallResponse),
            TrailingBytes { offset: 16 },
        ),
        (
            "26DH: count 2, one record",
            sealed(&records2[..]),
            parse_as!(ChangePositionData2),
            BodyTooShort { offset: 44 },
        ),
        (
            "26DH: count 0 with a record",
            sealed(b"!9926D0000000103001E001E0064000186A0FFFF9C64"),
            parse_as!(ChangePositionData2),
            TrailingBytes { offset: 10 },
        ),
        (
            "26DH: pattern 03, one coordinate",
            sealed(b"!9926D0001000103001E001E0064000186A0"),
            parse_as!(ChangePositionData2),
            BodyTooShort { offset: 36 },
        ),
        (
            "26DH: no count",
            sealed(b"!9926D"),
            parse_as!(ChangePositionData2),
            BodyTooShort { offset: 6 },
        ),
        (
            "26DH reply: 3-digit count",
            sealed(b"#9926D001"),
            parse_as!(ChangePositionData2Response),
            BodyTooShort { offset: 6 },
        ),
        // ---- field content -----------------------------------------------
        (
            "216H reply: hex letter in a decimal reserved field",
            sealed(&cat(&[&DETAIL[..73], b"A", &DETAIL[74..]])),
            parse_as!(ErrorDetailResponse),
            InvalidDecimalDigit {
                offset: 73,
                byte: b'A',
            },
        ),
        (
            "216H reply: hex letter in the last reserved field",
            sealed(&cat(&[&DETAIL[..87], b"F", &DETAIL[88..]])),
            parse_as!(ErrorDetailResponse),
            InvalidDecimalDigit {
                offset: 87,
                byte: b'F',
            },
        ),
        // ---- counts out of range ------------------------------------------
        (
            "26DH: count 20001",
            sealed(b"!9926D4E21"),
            parse_as!(ChangePositionData2),
            CountTooLarge {
                count: 20_001,
                max: 20_000,
            },
        ),
        (
            "26DH: count FFFF",
            sealed(b"!9926DFFFF"),
            parse_as!(ChangePositionData2),
            CountTooLarge {
                count: 0xFFFF,
                max: 20_000,
            },
        ),
        // ---- wrong header kind ---------------------------------------------
        (
            "200H reply parsed as the command",
            sealed(b"#992000123456789"),
            parse_as!(TestCall),
            UnexpectedHeader {
                expected: Header::Command,
                found: Header::Response,
            },
        ),
        (
            "212H query parsed as the reply",
            sealed(b"!99212078F"),
            parse_as!(AxisStatusResponse),
            UnexpectedHeader {
                expected: Header::Response,
                found: Header::Command,
            },
        ),
        (
            "error response parsed as a reply",
            b"&99ABC5E\r\n".to_vec(),
            parse_as!(SystemStatusResponse),
            UnexpectedHeader {
                expected: Header::Response,
                found: Header::Error,
            },
        ),
        (
            "error response with code 215 parsed as 215H",
            sealed(b"&99215"),
            parse_as!(SystemStatusResponse),
            UnexpectedHeader {
                expected: Header::Response,
                found: Header::Error,
            },
        ),
        // ---- wrong ID ------------------------------------------------------
        (
            "215H query parsed as 212H",
            sealed(b"!99215"),
            parse_as!(AxisStatusQuery),
            UnexpectedMessageId {
                expected: 0x212,
                found: 0x215,
            },
        ),
        (
            "212H reply parsed as 215H",
            AXIS2.to_vec(),
            parse_as!(SystemStatusResponse),
            UnexpectedMessageId {
                expected: 0x215,
                found: 0x212,
            },
        ),
        (
            "26DH reply parsed as 216H",
            b"#9926D000102\r\n".to_vec(),
            parse_as!(ErrorDetailResponse),
            UnexpectedMessageId {
                expected: 0x216,
                found: 0x26D,
            },
        ),
        (
            "245H (3-digit cousin) parsed as 26DH",
            sealed(b"!99245001001"),
            parse_as!(ChangePositionData2),
            UnexpectedMessageId {
                expected: 0x26D,
                found: 0x245,
            },
        ),
    ]
}

#[test]
fn malformed_message_catalogue() {
    let cases = message_cases();
    let mut failures = Vec::new();
    for (name, bytes, (ty, parse), expected) in &cases {
        let frame = Frame::new_checked(bytes, BypassPolicy::default())
            .unwrap_or_else(|e| panic!("{name}: the envelope must be valid, got {e}"));
        if parse(&frame) != Err(*expected) {
            failures.push(format!("{name} (as {ty}): got {:?}", parse(&frame)));
        }
        // The same bytes through the decoder give the frame unchanged.
        let mut dec: FrameDecoder = FrameDecoder::new();
        assert!(
            matches!(dec.decode(bytes).status, Status::Complete(Event::Frame(f)) if f.as_bytes() == &bytes[..]),
            "{name}: decoder"
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    eprintln!("{} malformed message cases", cases.len());
}

#[test]
fn non_hex_in_a_body_never_reaches_the_message_layer() {
    // The envelope check already refuses a non-hex body byte outside the
    // text fields, so `Message::parse` only ever sees hex digits there.
    let cases: &[(&[u8], Error)] = &[
        (
            b"!99212G7",
            InvalidHexDigit {
                offset: 6,
                byte: b'G',
            },
        ),
        (
            b"#9921510000A10420160Z",
            InvalidHexDigit {
                offset: 20,
                byte: b'Z',
            },
        ),
        (
            b"!99216-01000",
            InvalidHexDigit {
                offset: 6,
                byte: b'-',
            },
        ),
        (
            b"!9926D0001000103001E001E0064+00186A0FFFF9C64",
            InvalidHexDigit {
                offset: 28,
                byte: b'+',
            },
        ),
        // Past the 216H message (count 02) the bytes are hex again.
        (
            &cat(&[&DETAIL[..88], b"02AB#!"]),
            InvalidHexDigit {
                offset: 92,
                byte: b'#',
            },
        ),
    ];
    for (text, expected) in cases {
        let bytes = sealed(text);
        assert_eq!(
            Frame::new_checked(&bytes, BypassPolicy::default()),
            Err(*expected),
            "{}",
            String::from_utf8_lossy(text)
        );
    }
}

#[test]
fn values_that_cannot_be_emitted() {
    let mut buf = [0u8; 256];
    let st = Station(0x99);
    let two_axes = AxisPattern::first(2);
    let one_block = PerAxis::from_slice(&[AxisStatus {
        axis_status: 0x1C,
        sensor_input_status: 0,
        error_code: 0,
        encoder_status: 0,
        current_position: 0,
    }])
    .unwrap();
    let reply = AxisStatusResponse {
        axis_pattern: two_axes,
        axes: one_block.clone(),
    };
    assert_eq!(
        reply.emit(st, &mut buf),
        Err(CountMismatch {
            expected: 2,
            found: 1
        })
    );

    let mut block = one_block[0].clone();
    block.error_code = 0x1000; // 3 hex digits hold at most FFF
    let reply = AxisStatusResponse {
        axis_pattern: AxisPattern::first(1),
        axes: PerAxis::from_slice(&[block]).unwrap(),
    };
    // Reported at the field's frame offset: #99212 (6) + pattern (2) + status (2) + sensor (1).
    assert_eq!(
        reply.emit(st, &mut buf),
        Err(ValueOutOfRange { offset: 11 })
    );

    let q = ErrorDetailQuery {
        type_1: 16,
        type_2: 0,
        record_number: 0,
    };
    assert_eq!(q.emit(st, &mut buf), Err(ValueOutOfRange { offset: 6 }));

    let long = [b'x'; 256];
    let detail = ErrorDetailResponse {
        error_number: 1,
        detail_1: 0,
        detail_2: 0,
        detail_3: 0,
        detail_4: 0,
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
        message: &long,
    };
    let mut big = [0u8; 512];
    assert_eq!(
        detail.emit(st, &mut big),
        Err(CountTooLarge {
            count: 256,
            max: 255
        })
    );
    let detail = ErrorDetailResponse {
        reserved_1: 100, // 2 decimal digits hold at most 99
        message: b"",
        ..detail
    };
    // The first reserved field starts at frame offset 73 (after 8 detail words).
    assert_eq!(
        detail.emit(st, &mut big),
        Err(ValueOutOfRange { offset: 73 })
    );

    let mut bad = PositionRecord::new(1, 0, 0, 0, &[(1, 5)]).unwrap();
    bad.axes = two_axes;
    let records = [bad];
    let cmd = ChangePositionData2 {
        records: Repeated::from_slice(&records),
    };
    assert_eq!(
        cmd.emit(st, &mut buf),
        Err(CountMismatch {
            expected: 2,
            found: 1
        })
    );

    let call = TestCall {
        test_string: *b"0123456789",
    };
    assert_eq!(call.emit(st, &mut buf[..19]), Err(BufferTooSmall));
    assert_eq!(call.emit(st, &mut buf[..20]), Ok(20));
}

#[test]
fn frame_check_refuses_every_envelope_fault_with_the_exact_error() {
    // Frame::new_checked on bytes already cut into one frame.
    let cases: &[(&[u8], BypassPolicy, Error)] = &[
        (b"", BypassPolicy::Accept, FrameTooShort { len: 0 }),
        (
            b"#992322C\r",
            BypassPolicy::Accept,
            FrameTooShort { len: 9 },
        ),
        (
            b"$992322C\r\n",
            BypassPolicy::Accept,
            InvalidHeader { byte: b'$' },
        ),
        (
            b"\x00992322C\r\n",
            BypassPolicy::Accept,
            InvalidHeader { byte: 0 },
        ),
        (b"#992322C\n\n", BypassPolicy::Accept, MissingCarriageReturn),
        (
            b"#992322C\r\r",
            BypassPolicy::Accept,
            MissingLineFeed { byte: b'\r' },
        ),
        (b"#992322C  ", BypassPolicy::Accept, MissingCarriageReturn),
        (
            b"#992322CX\r\n",
            BypassPolicy::Accept,
            InvalidHexDigit {
                offset: 8,
                byte: b'X',
            },
        ),
        (
            b"#99232@@\r\n",
            BypassPolicy::CommandsOnly,
            ChecksumBypassRejected,
        ),
        (
            b"!99232@@\r\n",
            BypassPolicy::Reject,
            ChecksumBypassRejected,
        ),
        (
            b"#992322D\r\n",
            BypassPolicy::Accept,
            ChecksumMismatch {
                computed: 0x2C,
                received: 0x2D,
            },
        ),
    ];
    for (bytes, policy, expected) in cases {
        assert_eq!(
            Frame::new_checked(bytes, *policy),
            Err(*expected),
            "{}",
            String::from_utf8_lossy(bytes)
        );
    }
}

// ---------------------------------------------------------------------------
// Part 3: core defects found while writing this catalogue, now fixed; these
// tests keep them fixed.

#[test]
fn signed_field_of_width_zero_does_not_panic() {
    // FieldSpec's fields are public, so width 0 is a value a caller can
    // build; the crate promises no panic on any input.
    let spec = FieldSpec::signed_hex(0);
    let d = std::panic::catch_unwind(|| decode_signed(spec, b"", 0));
    assert!(d.is_ok(), "decode_signed panicked");
    let e = std::panic::catch_unwind(|| {
        let mut out = [0u8; 0];
        encode_signed(spec, 0, &mut out)
    });
    assert!(e.is_ok(), "encode_signed panicked");
}

#[test]
fn frame_check_and_decoder_agree_when_a_text_field_runs_into_the_trailer() {
    // A 200H frame with 3 of its 10 characters: by the text rule the CR LF
    // at offsets 11..13 are still text, so the decoder keeps reading; the
    // one-frame check accepts the same bytes as a complete frame.
    let short_200 = sealed(b"!99200ABC");
    // A 216H reply whose count (06) covers its own CR.
    let over_216 = sealed(&cat(&[&DETAIL[..88], b"06ABC"]));
    // A 216H reply without its message count: the decoder reads SC as the
    // count and CR LF as message text.
    let no_count_216 = sealed(&DETAIL[..88]);
    for bytes in [short_200, over_216, no_count_216] {
        let mut dec: FrameDecoder = FrameDecoder::new();
        let from_decoder = match dec.decode(&bytes).status {
            Status::Complete(Event::Frame(_)) => Ok(()),
            Status::Complete(Event::Error(e)) => Err(e),
            Status::Partial => Err(Truncated { len: bytes.len() }),
        };
        let from_check = Frame::new_checked(&bytes, BypassPolicy::default()).map(|_| ());
        assert_eq!(
            from_check.is_ok(),
            from_decoder.is_ok(),
            "{}: new_checked {from_check:?}, decoder {from_decoder:?}",
            String::from_utf8_lossy(&bytes)
        );
    }
}

#[test]
fn zero_capacity_decoder_accounts_for_every_byte() {
    let mut dec: FrameDecoder<0> = FrameDecoder::new();
    let input = b"#992322C\r\n";
    let mut events = Vec::new();
    for &b in input {
        if let Status::Complete(Event::Error(e)) = dec.push(b) {
            events.push(e);
        }
    }
    let s = dec.stats();
    assert_eq!(
        s.discarded_bytes as usize + dec.pending(),
        input.len(),
        "events {events:?}"
    );
}

#[test]
fn a_parsed_group_received_in_lower_case_re_emits_in_upper_case() {
    // Found by the frame_parse fuzz target: a 24DH whose real value arrived
    // with a lower-case digit was re-emitted with it unchanged.
    let wire = sealed(b"!9924DB24C001F0FE9924dB100FF0");
    let f = Frame::new_checked(&wire, BypassPolicy::Reject).unwrap();
    let cmd = RealVariableChange::parse(&f).unwrap();
    let mut buf = [0u8; 64];
    let n = cmd.emit(Station(0x99), &mut buf).unwrap();
    assert_eq!(&buf[..n - 4], b"!9924DB24C001F0FE9924DB100FF0");
}
