//! What users type: JSON messages in the form `inspect --json` prints,
//! strict numbers, clear errors, closed pipes, bad ports, and the
//! simulator's connections and axes driven with `iai send`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::io::{Read, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

use common::{fixture_file, fixtures, iai, iai_stdin, stderr, stdout, temp, Sim};

/// The frame in normal form: upper-case digits (outside text fields) and
/// the SC computed.
fn normal_form(json_line: &serde_json::Value) -> Vec<String> {
    let kind = json_line["kind"].as_str().unwrap();
    let message = if kind == "error" {
        "error"
    } else {
        json_line["id"].as_str().unwrap()
    };
    let mut args = vec![
        "encode".to_string(),
        message.to_string(),
        "--station".into(),
        json_line["station"].as_str().unwrap().to_string(),
        "--fields-json".into(),
        json_line["fields"].to_string(),
    ];
    if kind == "response" {
        args.push("--response".into());
    }
    args
}

#[test]
fn every_fixture_frame_comes_back_from_its_inspected_fields() {
    let fixtures = fixtures();
    let mut checked = 0;
    for f in &fixtures {
        let out = iai_stdin(&["inspect", "--json", "--format", "raw", "-"], &f.frame);
        let line: serde_json::Value =
            serde_json::from_str(stdout(&out).lines().next().unwrap()).unwrap();
        let args = normal_form(&line);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = iai(&args);
        assert!(
            out.status.success(),
            "{}: {args:?}: {}",
            f.name,
            stderr(&out)
        );
        let got = stdout(&out).lines().next().unwrap().to_string();
        let got = fixture_file::unescape(&got);
        // The same bytes, in normal form: what the core emits for the
        // fixture's value.
        let mut want = f.expected_emission().to_vec();
        if want.len() >= 4 && &want[want.len() - 4..want.len() - 2] == b"@@" {
            let n = want.len();
            let sum: u32 = want[..n - 4].iter().map(|&b| u32::from(b)).sum();
            let sc = format!("{:02X}", sum as u8);
            want[n - 4..n - 2].copy_from_slice(sc.as_bytes());
        }
        assert_eq!(
            String::from_utf8_lossy(&got),
            String::from_utf8_lossy(&want),
            "{}",
            f.name
        );
        checked += 1;
    }
    println!("{checked} fixture frames encoded back from their fields");
    assert!(checked > 20);
}

#[test]
fn nested_records_are_given_as_json() {
    // Two 26DH records, the second with one axis: built from arguments,
    // inspected, and built again from the inspected fields.
    let out = iai(&[
        "encode",
        "26D",
        "position_number=1,2",
        "speed=100,200",
        "position=-400000,1234/7",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let frame = stdout(&out).lines().next().unwrap().to_string();
    let out = iai_stdin(&["inspect", "--json", "-"], format!("{frame}\n").as_bytes());
    let line: serde_json::Value =
        serde_json::from_str(stdout(&out).lines().next().unwrap()).unwrap();
    let fields = line["fields"].to_string();
    assert!(fields.contains("[-400000,1234]"), "{fields}");
    let file = temp("fields.json", fields.as_bytes());
    let out = iai(&["encode", "26D", "--json-file", file.to_str().unwrap()]);
    assert!(out.status.success(), "{fields}: {}", stderr(&out));
    assert_eq!(stdout(&out).lines().next().unwrap(), frame);
}

#[test]
fn numbers_are_parsed_strictly_and_errors_name_the_field() {
    for (args, want) in [
        (
            vec!["encode", "234", "absolute_coordinate=--5000"],
            "absolute_coordinate: \"--5000\" is not a number",
        ),
        (
            vec!["encode", "212", "query_axis_pattern=1__0"],
            "query_axis_pattern: \"1__0\"",
        ),
        (
            vec![
                "encode",
                "212",
                "query_axis_pattern=1",
                "query_axis_pattern=2",
            ],
            "query_axis_pattern: given twice",
        ),
        (vec!["encode", "212", "query_axis_pattern=256"], "0..=255"),
        (vec!["encode", "212", "query_axis_pattern=-1"], "negative"),
        (
            vec!["encode", "234", "absolute_coordinate=1,2,3,4,5,6,7,8,9"],
            "absolute_coordinate: 9 value(s) given, at most 8 allowed",
        ),
        (
            vec![
                "encode",
                "234",
                "axis_pattern=3",
                "absolute_coordinate=1,2,3",
            ],
            "axis_pattern = 0x03 selects 2 axis(es)",
        ),
        (
            vec!["encode", "234", "--fields-json", r#"{"speed":"fast"}"#],
            "speed: expected a number",
        ),
        (
            vec!["encode", "234", "--fields-json", r#"{"sped":1}"#],
            "sped: no such field",
        ),
    ] {
        let out = iai(&args);
        assert_ne!(out.status.code(), Some(0), "{args:?}");
        assert!(stderr(&out).contains(want), "{args:?}: {}", stderr(&out));
    }
    // A leading minus stays a minus.
    let out = iai(&["encode", "234", "absolute_coordinate=-5000"]);
    assert!(stdout(&out).contains("FFFFEC78"), "{}", stdout(&out));
}

#[test]
fn a_bad_port_and_a_closed_pipe_are_named_as_such() {
    let out = iai(&["send", "212", "query_axis_pattern=1", "--port", "99999"]);
    assert_eq!(out.status.code(), Some(1));
    let e = stderr(&out);
    assert!(
        e.contains("--port \"99999\": cannot open it as a serial port"),
        "{e}"
    );
    let out = iai(&[
        "send",
        "212",
        "query_axis_pattern=1",
        "--tcp",
        "127.0.0.1:1",
    ]);
    assert!(
        stderr(&out).contains("--tcp \"127.0.0.1:1\": cannot connect"),
        "{}",
        stderr(&out)
    );
    // `iai inspect big | head -1`: the reader goes away.
    let mut cap = Vec::new();
    for _ in 0..20_000 {
        cap.extend_from_slice(b"!99212038B\r\n");
    }
    let path = temp("pipe.bin", &cap);
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["inspect", path.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = [0u8; 16];
    child
        .stdout
        .as_mut()
        .unwrap()
        .read_exact(&mut first)
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{:?}", out.status);
    assert_eq!(stderr(&out), "");
}

#[test]
fn a_long_frame_is_one_error_and_undecodable_frames_fail_the_run() {
    let mut cap = b"!99212038B\r\n".to_vec();
    cap.push(b'#');
    cap.extend(std::iter::repeat_n(b'0', 2_997));
    cap.extend_from_slice(b"\r\n");
    cap.extend_from_slice(b"#992322C\r\n");
    let path = temp("long.bin", &cap);
    let out = iai(&[
        "inspect",
        "--json",
        "--format",
        "raw",
        path.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let lines: Vec<serde_json::Value> = stdout(&out)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 3, "{}", stdout(&out));
    assert_eq!(lines[1]["error"], "FrameTooLong");
    assert_eq!(lines[1]["offset"], 12);
    assert_eq!(lines[1]["len"], 3_000);
    assert_eq!(lines[2]["offset"], 3_012);
    // A frame whose envelope is fine but whose body does not decode.
    let out = iai_stdin(&["inspect", "-"], b"!99212@@\\r\\n\n");
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    assert!(stdout(&out).contains("not decoded"), "{}", stdout(&out));
}

#[test]
fn connections_have_their_own_state_and_share_the_controller() {
    let sim = Sim::tcp(&["--quiet"]);
    // An idle client holding half a frame...
    let mut idle = sim.connect();
    idle.write_all(b"!99212").unwrap();
    // ...blocks nobody, and its half frame is not prepended to another's.
    let mut a = sim.connect();
    a.write_all(b"!99212038B\r\n").unwrap();
    let reply = common::read_frame(&mut a);
    assert!(
        reply.starts_with(b"#9921203"),
        "{}",
        String::from_utf8_lossy(&reply)
    );
    drop(a);
    // A reply still pending when its client left is not given to the next.
    let sim2 = Sim::tcp(&["--quiet", "--reply-delay-ms", "300"]);
    let mut b = sim2.connect();
    b.write_all(b"!99212038B\r\n").unwrap();
    drop(b);
    let mut c = sim2.connect();
    c.set_read_timeout(Some(Duration::from_millis(700)))
        .unwrap();
    let mut buf = [0u8; 64];
    assert!(
        c.read(&mut buf).is_err(),
        "the next client got the previous reply"
    );
    drop(idle);
    sim.stop();
    sim2.stop();
}

fn send(at: &str, args: &[&str]) -> std::process::Output {
    let mut all = vec!["send"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--tcp", at]);
    iai(&all)
}

#[test]
fn a_homed_axis_moves_and_status_reports_it() {
    let sim = Sim::tcp(&["--quiet"]);
    let at = sim.at.clone();
    let out = send(&at, &["234", "speed=100", "absolute_coordinate=50000"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr(&out).contains("error code 0E4"), "{}", stderr(&out));
    // With --detail the request engine asks 216H for the latest error.
    let out = send(
        &at,
        &["234", "speed=100", "absolute_coordinate=50000", "--detail"],
    );
    assert!(
        stderr(&out).contains("216H latest system error C74 (not the same number"),
        "{}",
        stderr(&out)
    );
    assert!(send(&at, &["232", "axis_pattern=1", "operation_type=1"])
        .status
        .success());
    assert!(send(&at, &["233", "axis_pattern=1"]).status.success());
    std::thread::sleep(Duration::from_millis(300));
    let out = send(&at, &["234", "speed=100", "absolute_coordinate=150000"]);
    assert!(out.status.success(), "{}", stderr(&out));
    // 150 mm at 100 mm/s: about 1.5 s; after 0.2 s it is in use (a busy
    // machine has a second's margin before the move ends).
    std::thread::sleep(Duration::from_millis(200));
    let out = send(&at, &["212", "query_axis_pattern=1", "--output", "json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    let axis = &v["fields"]["axes"][0];
    assert_eq!(axis["axis_status"].as_u64().unwrap() & 1, 1, "{v}");
    let pos = axis["current_position"].as_i64().unwrap();
    assert!(pos > 5_000 && pos < 150_000, "{v}");
    std::thread::sleep(Duration::from_millis(1_600));
    let out = send(&at, &["212", "query_axis_pattern=1", "--output", "json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    let axis = &v["fields"]["axes"][0];
    assert_eq!(axis["current_position"], 150_000, "{v}");
    assert_eq!(axis["axis_status"].as_u64().unwrap() & 0x11, 0x10, "{v}");
    sim.stop();
}

#[test]
fn monitor_lists_frames_as_they_arrive() {
    use std::io::{BufRead, BufReader};
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["monitor", "--tcp", &addr, "--json"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut line, _) = listener.accept().unwrap();
    line.write_all(b"#992322C\r\nxx!99212038B").unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first: serde_json::Value = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
    assert_eq!(first["id"], "232");
    let second: serde_json::Value = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
    assert_eq!(second["error"], "Noise");
    // The rest of the frame comes later: it is listed then.
    std::thread::sleep(Duration::from_millis(200));
    line.write_all(b"\r\n").unwrap();
    let third: serde_json::Value = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
    assert_eq!(third["id"], "212");
    assert_eq!(third["offset"], 12);
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    // Ctrl-C is how a monitor ends: exit 130.
    assert_eq!(child.wait().unwrap().code(), Some(130));
}
