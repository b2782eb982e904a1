//! The `iai` binary, run as a user would: `inspect` over the recorded
//! fixtures and over a broken capture, `encode` → `inspect` round trips,
//! a 1.6 MB position stream, and `simulate` answering over TCP.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use common::{fixture_file, fixtures, iai, iai_stdin, record, stderr, stdout, temp, Sim};

use std::io::Write;

use iai_protocol_b::frame::Station;
use iai_protocol_b::position::PositionStream;
use iai_protocol_b::table::PositionStreamEncoder;

/// The value of `"key":` in a JSON line (strings without quotes).
fn get<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    let pat = format!("\"{key}\":");
    let at = line.find(&pat)? + pat.len();
    let rest = &line[at..];
    if let Some(s) = rest.strip_prefix('"') {
        return s.split('"').next();
    }
    rest.split([',', '}']).next()
}

#[test]
fn inspect_json_decodes_every_fixture_frame() {
    let fixtures = fixtures();
    assert!(fixtures.len() > 20);
    // As a text log, one escaped frame per line, alternating prefixes.
    let log: String = fixtures
        .iter()
        .map(|f| {
            let p = if f.dir.starts_with("host") {
                "> "
            } else {
                "< "
            };
            format!("{p}{}\n", fixture_file::escape(&f.frame))
        })
        .collect();
    let path = temp("fixtures.log", log.as_bytes());
    let out = iai(&["inspect", "--json", path.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = stdout(&out);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), fixtures.len(), "{text}");
    let mut checked = 0;
    for (f, line) in fixtures.iter().zip(&lines) {
        assert_eq!(get(line, "type"), Some("frame"), "{}: {line}", f.name);
        assert!(!line.contains("decode_error"), "{}: {line}", f.name);
        let kind = f.envelope.split_whitespace().next().unwrap();
        assert_eq!(get(line, "kind"), Some(kind), "{}: {line}", f.name);
        let sc = f.envelope.split("sc=").nth(1).unwrap();
        assert_eq!(get(line, "sc"), Some(sc), "{}: {line}", f.name);
        let dir = if f.dir.starts_with("host") {
            "tx"
        } else {
            "rx"
        };
        assert_eq!(get(line, "dir"), Some(dir), "{}", f.name);
        // Every named integer of the fixture's meaning appears in the JSON.
        for pair in f.means.split_whitespace().filter(|p| p.contains('=')) {
            let (name, value) = pair.split_once('=').unwrap();
            let Ok(v) = (if let Some(h) = value.strip_prefix("0x") {
                i64::from_str_radix(h, 16)
            } else {
                value.parse::<i64>()
            }) else {
                continue;
            };
            if name.contains('.') {
                continue;
            }
            // Groups and text are arrays or strings in the JSON.
            if let Some(Ok(got)) = get(line, name).map(str::parse::<i64>) {
                assert_eq!(got, v, "{} field {name}: {line}", f.name);
                checked += 1;
            }
        }
    }
    assert!(checked > 60, "only {checked} fields compared");
    // The same frames as one raw capture: same count, offsets add up.
    let frames: Vec<Vec<u8>> = fixtures.iter().map(|f| f.frame.clone()).collect();
    let raw = frames.concat();
    let path = temp("fixtures.bin", &raw);
    let out = iai(&[
        "inspect",
        "--json",
        "--format",
        "raw",
        path.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let mut offset = 0;
    for (frame, line) in frames.iter().zip(stdout(&out).lines()) {
        assert_eq!(
            get(line, "offset"),
            Some(offset.to_string().as_str()),
            "{line}"
        );
        assert_eq!(get(line, "len"), Some(frame.len().to_string().as_str()));
        offset += frame.len();
    }
}

#[test]
fn every_error_of_a_mixed_capture_is_at_its_offset() {
    let mut cap = Vec::new();
    let mut expect: Vec<(usize, &str)> = Vec::new();
    let mut add = |cap: &mut Vec<u8>, bytes: &[u8], what: &'static str| {
        expect.push((cap.len(), what));
        cap.extend_from_slice(bytes);
    };
    add(&mut cap, b"\x00\xFFnoise", "Noise");
    add(&mut cap, b"!99212038B\r\n", "frame");
    add(&mut cap, b"#992322D\r\n", "ChecksumMismatch");
    add(&mut cap, b"#99232", "Truncated");
    add(&mut cap, b"#992322C\r\n", "frame");
    add(&mut cap, b"#99232X2C\r\n", "InvalidHexDigit");
    add(&mut cap, b"&99ABC5E\r\n", "frame");
    add(&mut cap, b"#992322C\rX", "MissingLineFeed");
    add(&mut cap, b"!99212038B", "Truncated");
    let path = temp("mixed.bin", &cap);
    let out = iai(&["inspect", "--json", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "errors give exit status 1");
    let text = stdout(&out);
    let got: Vec<(usize, String)> = text
        .lines()
        .map(|l| {
            let what = match get(l, "type").unwrap() {
                "frame" => "frame",
                _ => get(l, "error").unwrap(),
            };
            (get(l, "offset").unwrap().parse().unwrap(), what.to_string())
        })
        .collect();
    let want: Vec<(usize, String)> = expect.iter().map(|(o, w)| (*o, w.to_string())).collect();
    assert_eq!(got, want, "{text}");
    // The human listing says the same.
    let out = iai(&["inspect", path.to_str().unwrap()]);
    let text = stdout(&out);
    assert!(
        text.contains("0x00000007  command  st 99  212H Axis Status Query"),
        "{text}"
    );
    assert!(text.contains("query_axis_pattern = 0x03 (3)"), "{text}");
    assert!(
        text.contains("0x00000013  ERROR    ChecksumMismatch"),
        "{text}"
    );
    assert!(text.contains("-- 3 frame(s), 6 error(s)"), "{text}");
}

/// In a text log each line holds one frame: a 200H whose fixed-width
/// text (10 characters, 2003 p. 15) runs past its line is reported on that
/// line, and the frames of the next lines stand on their own.
#[test]
fn in_a_text_log_each_line_starts_afresh() {
    let log = "> !99200HELLO\n< #99212021C00000000002715AF\\r\\n\n> !99212038B\n";
    let path = temp("text-200h.log", log.as_bytes());
    let out = iai(&["inspect", "--json", path.to_str().unwrap()]);
    let text = stdout(&out);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 3, "{text}");
    assert_eq!(get(lines[0], "error"), Some("Truncated"), "{text}");
    assert_eq!(get(lines[0], "line"), Some("1"), "{text}");
    for (line, n, code) in [(lines[1], "2", "212"), (lines[2], "3", "212")] {
        assert_eq!(get(line, "type"), Some("frame"), "{text}");
        assert_eq!(get(line, "line"), Some(n), "{text}");
        assert_eq!(get(line, "id"), Some(code), "{text}");
    }
}

fn encode_then_inspect(args: &[&str]) -> String {
    let out = iai(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = stdout(&out);
    let frame = text.lines().next().unwrap();
    let again = iai_stdin(&["inspect", "--json", "-"], format!("{frame}\n").as_bytes());
    assert!(again.status.success(), "{frame}: {}", stdout(&again));
    let json = stdout(&again);
    assert_eq!(json.lines().count(), 1, "{json}");
    json
}

#[test]
fn encode_round_trips_through_inspect() {
    // The X-SEL 2003 spec's worked example.
    let out = iai(&[
        "encode",
        "209",
        "query_head_position_number=1",
        "number_of_query_records=5",
    ]);
    // Only the frame on stdout; its checksum and length on stderr.
    assert_eq!(stdout(&out), "!9920900100554\\r\\n\n");
    assert_eq!(stderr(&out), "checksum 54, 16 bytes\n");

    let j = encode_then_inspect(&["encode", "AxisStatusQuery", "query_axis_pattern=0x3"]);
    assert_eq!(get(&j, "id"), Some("212"));
    assert_eq!(get(&j, "query_axis_pattern"), Some("3"));

    let j = encode_then_inspect(&[
        "encode",
        "234",
        "acceleration=30",
        "deceleration=30",
        "speed=100",
        "absolute_coordinate=100000,-25500",
    ]);
    assert!(j.contains("\"axis_pattern\":3"), "{j}");
    assert!(j.contains("\"absolute_coordinate\":[100000,-25500]"), "{j}");

    let j = encode_then_inspect(&[
        "encode",
        "Change Position Data Continuous Write 2",
        "position_number=1,2",
        "speed=100,200",
        "position=100000,-25500/7",
        "--station",
        "05",
    ]);
    assert_eq!(get(&j, "station"), Some("05"));
    assert!(j.contains("\"position\":[100000,-25500]"), "{j}");
    assert!(j.contains("\"position\":[7]"), "{j}");

    let j = encode_then_inspect(&["encode", "232", "--response"]);
    assert_eq!(get(&j, "kind"), Some("response"));

    let j = encode_then_inspect(&["encode", "212", "query_axis_pattern=1", "--bypass"]);
    assert_eq!(get(&j, "checksum"), Some("bypass"));

    // Values that do not fit are refused with the field's range.
    let out = iai(&["encode", "212", "query_axis_pattern=0x100"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("0..=255"));
    let out = iai(&["encode", "212", "no_such_field=1"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("query_axis_pattern"));
}

#[test]
fn a_position_stream_larger_than_the_decoder_is_summarised() {
    let records = (0..20_000).map(|i| record(i, 8, 7));
    let mut enc =
        PositionStreamEncoder::new(PositionStream::CHANGE_2, Station(0x99), 0, 20_000, records)
            .unwrap();
    let mut cap = b"#992322C\r\n".to_vec();
    let mut chunk = [0u8; 4096];
    loop {
        let n = enc.read(&mut chunk).unwrap();
        if n == 0 {
            break;
        }
        cap.extend_from_slice(&chunk[..n]);
    }
    let big = cap.len() - 10;
    assert!(big > 1_600_000);
    cap.extend_from_slice(b"#9926D4E201C\r\n");
    let path = temp("big.bin", &cap);
    let out = iai(&["inspect", "--json", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stdout(&out));
    let text = stdout(&out);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 3, "{text}");
    let s = lines[1];
    assert_eq!(get(s, "type"), Some("stream"));
    assert_eq!(get(s, "id"), Some("26D"));
    assert_eq!(get(s, "offset"), Some("10"));
    assert_eq!(get(s, "len"), Some(big.to_string().as_str()));
    assert_eq!(get(s, "count"), Some("20000"));
    assert_eq!(get(s, "records"), Some("20000"));
    assert_eq!(get(s, "checksum"), Some("ok"));
    let first = record(0, 8, 7);
    assert!(
        s.contains(&format!("\"first\":{{\"position_number\":{}", first.number)),
        "{s}"
    );
    assert_eq!(
        get(lines[2], "offset"),
        Some((10 + big).to_string().as_str())
    );
}

#[test]
fn simulate_answers_an_axis_status_query_over_tcp() {
    let mut sim = Sim::tcp(&[]);
    let mut conn = sim.connect();
    conn.write_all(b"!99212038B\r\n").unwrap();
    let reply = common::read_frame(&mut conn);
    assert!(
        reply.starts_with(b"#9921203"),
        "{}",
        String::from_utf8_lossy(&reply)
    );
    drop(conn);
    // It logs what it received and sent, and the connection's end.
    sim.wait_for("1 command(s), 1 reply(ies)");
    let log = sim.stop();
    assert!(
        log.contains("< 0x00000000 rx  command  st 99  212H"),
        "{log}"
    );
    assert!(
        log.contains("> 0x00000000 tx  response st 99  212H"),
        "{log}"
    );
    assert!(log.contains("1 command(s), 1 reply(ies)"), "{log}");
}
