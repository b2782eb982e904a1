//! What `iai` prints: meanings beside raw values, named codes on input,
//! the meanings of the bridge's and the simulator's codes, JSON failures
//! on stdout, `encode` piped into `inspect`, hex offsets, `monitor
//! --timestamps --save`, examples in every `--help`, one flag scheme,
//! required and misspelled fields, exit 130.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

use common::{iai, iai_stdin, stderr, stdout, temp, Sim};

fn send(line: &[&str], args: &[&str]) -> std::process::Output {
    let mut all = vec!["send"];
    all.extend_from_slice(args);
    all.extend_from_slice(line);
    iai(&all)
}

/// Servo on (by name), home, move to 2.300 mm: the status reads in words,
/// the position in mm, in the text listing and under "meanings" in JSON.
fn meanings_on(line: &[&str]) {
    let out = send(line, &["234", "speed=100", "absolute_coordinate=2300"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains(
            "error code 0E4 (iai simulate's code: the servo of an axis concerned is off)"
        ),
        "{}",
        stderr(&out)
    );
    let out = send(
        line,
        &["234", "speed=100", "absolute_coordinate=2300", "--json"],
    );
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    assert_eq!(v["type"], "failure");
    assert_eq!(v["failure"], "error_response");
    assert_eq!(v["code"], "0E4");
    assert!(v["meaning"].as_str().unwrap().contains("servo"), "{v}");
    let on = send(line, &["232", "axis_pattern=1", "operation_type=on"]);
    assert!(on.status.success(), "{}", stderr(&on));
    assert!(send(line, &["233", "axis_pattern=1"]).status.success());
    std::thread::sleep(Duration::from_millis(400));
    assert!(
        send(line, &["234", "speed=100", "absolute_coordinate=2300"])
            .status
            .success()
    );
    std::thread::sleep(Duration::from_millis(300));
    let out = send(line, &["212", "query_axis_pattern=1"]);
    let text = stdout(&out);
    assert!(
        text.contains(
            "axes[0].axis_status = 0x1C (28) -> servo on, homed, idle, positioning complete"
        ),
        "{text}"
    );
    assert!(
        text.contains("axes[0].current_position = 2300 0.001mm -> 2.300 mm"),
        "{text}"
    );
    let out = send(line, &["212", "query_axis_pattern=1", "--json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    assert_eq!(v["fields"]["axes"][0]["current_position"], 2300, "{v}");
    assert_eq!(v["meanings"]["axes[0].current_position"], "2.300 mm", "{v}");
    assert_eq!(
        v["meanings"]["axes[0].axis_status"],
        "servo on, homed, idle, positioning complete"
    );
    let out = send(line, &["215"]);
    assert!(
        stdout(&out).contains("system_mode = 0x1 (1) -> AUTO mode"),
        "{}",
        stdout(&out)
    );
    // A name a field does not have is named with the field's names.
    let out = send(line, &["232", "axis_pattern=1", "operation_type=onn"]);
    assert!(
        stderr(&out).contains("\"onn\" is neither a name of this field (off=0, on=1)"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn values_are_shown_with_their_meaning_tcp() {
    let sim = Sim::tcp(&["--quiet"]);
    let at = sim.at.clone();
    meanings_on(&["--tcp", &at]);
    sim.stop();
}

#[cfg(unix)]
#[test]
fn values_are_shown_with_their_meaning_pty() {
    let sim = Sim::start(&["--pty", "--quiet"]);
    let at = sim.at.clone();
    meanings_on(&["--port", &at, "--baud", "115200"]);
    sim.stop();
}

/// A field without a documented default must be given; a misspelled one
/// is named as unknown first, with the likely name; nothing is sent.
#[test]
fn required_fields_are_required_and_misspellings_named() {
    let sim = Sim::tcp(&[]);
    let at = sim.at.clone();
    let line = ["--tcp", at.as_str()];
    let out = send(&line, &["232"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out)
            .contains("232H needs fields that are missing: give axis_pattern, operation_type"),
        "{}",
        stderr(&out)
    );
    let out = send(&line, &["234", "speed=100", "absolut_coordinate=5"]);
    assert!(
        stderr(&out)
            .contains("234H has no field absolut_coordinate (did you mean absolute_coordinate?)"),
        "{}",
        stderr(&out)
    );
    let out = send(&line, &["234", "speed=100"]);
    assert!(
        stderr(&out).contains("give absolute_coordinate (one value per axis"),
        "{}",
        stderr(&out)
    );
    // JSON input too; and --json prints the refusal as an object.
    let out = iai(&["encode", "232", "--fields-json", r#"{"axis_pattern":1}"#]);
    assert!(
        stderr(&out).contains("give operation_type"),
        "{}",
        stderr(&out)
    );
    let out = send(&line, &["232", "--json"]);
    let v: serde_json::Value = serde_json::from_str(stdout(&out).trim()).unwrap();
    assert_eq!(v["failure"], "command");
    // Fields with a documented default may be left out; names work in JSON.
    let out = iai(&["encode", "234", "absolute_coordinate=1000"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let out = iai(&[
        "encode",
        "216",
        "--fields-json",
        r#"{"type_1":"system","type_2":"latest"}"#,
    ]);
    assert_eq!(stdout(&out), "!992160010004D\\r\\n\n", "{}", stderr(&out));
    let out = iai(&["encode", "232", "--fields"]);
    assert!(
        stdout(&out).contains("operation_type (hex 1, names: off=0, on=1)"),
        "{}",
        stdout(&out)
    );
    let out = iai(&["encode", "234", "--fields"]);
    assert!(
        stdout(&out).contains("speed (hex 4, mm/s, optional: 0 = the controller's parameter)"),
        "{}",
        stdout(&out)
    );
    let log = sim.stop();
    assert!(!log.contains("rx  command"), "something was sent: {log}");
}

/// `encode` writes the frame alone to stdout: escaped, or raw with --raw;
/// both pipe into `inspect -`, whose offsets are hex.
#[test]
fn encode_pipes_into_inspect() {
    let out = iai(&["encode", "212", "query_axis_pattern=3"]);
    assert_eq!(stdout(&out), "!99212038B\\r\\n\n");
    assert_eq!(stderr(&out), "checksum 8B, 12 bytes\n");
    let listed = iai_stdin(&["inspect", "-"], &out.stdout);
    assert!(listed.status.success());
    assert!(
        stdout(&listed).starts_with("0x00000000 L1  command  st 99  212H Axis Status Query"),
        "{}",
        stdout(&listed)
    );
    let raw = iai(&["encode", "212", "query_axis_pattern=3", "--raw"]);
    assert_eq!(raw.stdout, b"!99212038B\r\n");
    let mut two = raw.stdout.clone();
    two.extend_from_slice(&raw.stdout);
    let listed = iai_stdin(&["inspect", "-"], &two);
    assert!(
        stdout(&listed).contains("0x0000000C  command  st 99  212H"),
        "{}",
        stdout(&listed)
    );
    // The codes the project defines are explained in a listing.
    let err = iai(&["encode", "error", "error_code=0xB06", "--raw"]);
    let listed = iai_stdin(&["inspect", "-", "--json"], &err.stdout);
    let v: serde_json::Value = serde_json::from_str(stdout(&listed).trim()).unwrap();
    assert_eq!(v["code"], "B06");
    assert_eq!(
        v["meaning"],
        "bridge: the command policy refuses this message"
    );
}

#[test]
fn monitor_stamps_entries_and_saves_the_raw_bytes() {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let save = temp("monitor-save.bin", b"");
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["monitor", "--tcp", &addr, "--timestamps", "--save"])
        .arg(&save)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut line, _) = listener.accept().unwrap();
    let sent = b"#992322C\r\nxx!99212038B\r\n";
    line.write_all(sent).unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    assert!(
        first.starts_with("[+") && first.contains(" s] 0x00000000  response st 99  232H"),
        "{first}"
    );
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    assert_eq!(std::fs::read(&save).unwrap(), sent);
    // JSON lines carry "t_ms".
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["monitor", "--tcp", &addr, "--timestamps", "--json"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut line, _) = listener.accept().unwrap();
    line.write_all(b"#992322C\r\n").unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let v: serde_json::Value = serde_json::from_str(&lines.next().unwrap().unwrap()).unwrap();
    assert!(v["t_ms"].is_u64(), "{v}");
    assert_eq!(v["id"], "232");
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    assert_eq!(child.wait().unwrap().code(), Some(130));
}

/// Every command's --help has examples; `table write --help` has the CSV
/// format; one flag name, one meaning.
#[test]
fn every_help_has_examples_and_flags_mean_one_thing() {
    for cmd in [
        vec!["--help"],
        vec!["inspect", "--help"],
        vec!["encode", "--help"],
        vec!["monitor", "--help"],
        vec!["send", "--help"],
        vec!["table", "write", "--help"],
        vec!["table", "read", "--help"],
        vec!["table", "clear", "--help"],
        vec!["simulate", "--help"],
        vec!["modbus", "map", "--help"],
    ] {
        let out = iai(&cmd);
        assert!(out.status.success(), "{cmd:?}");
        assert!(
            stdout(&out).contains("Examples:"),
            "{cmd:?}: {}",
            stdout(&out)
        );
    }
    let out = iai(&["table", "write", "--help"]);
    let text = stdout(&out);
    assert!(
        text.contains("number,acceleration,deceleration,speed,axis1,axis2,axis3"),
        "{text}"
    );
    assert!(text.contains("mm with at most 3 decimals"), "{text}");
    // --json is JSON output wherever it appears; input JSON is --fields-json.
    let options = |text: &str| -> Vec<String> {
        text.lines()
            .map(str::trim_start)
            .filter(|l| l.starts_with("--"))
            .map(|l| l.split([' ', ',']).next().unwrap().to_string())
            .collect()
    };
    let encode = options(&stdout(&iai(&["encode", "--help"])));
    assert!(encode.contains(&"--fields-json".to_string()), "{encode:?}");
    assert!(!encode.contains(&"--json".to_string()), "{encode:?}");
    let send = options(&stdout(&iai(&["send", "--help"])));
    assert!(send.contains(&"--json".to_string()), "{send:?}");
    assert!(!send.contains(&"--output".to_string()), "{send:?}");
    // The former spellings still work, unlisted.
    let fields = temp("fields.json", br#"{"query_axis_pattern":1}"#);
    let out = iai(&["encode", "212", "--json-file", fields.to_str().unwrap()]);
    assert_eq!(stdout(&out), "!992120189\\r\\n\n", "{}", stderr(&out));
}

/// `monitor --save` on a serial port: a pseudo-terminal stands for it, the
/// test writes the controller's side (the master) once `iai` has the port
/// open, and the file holds the bytes as they came.
#[cfg(target_os = "linux")]
#[test]
fn monitor_saves_what_a_serial_port_brings() {
    use std::ffi::CStr;
    use std::fs::File;
    use std::os::fd::FromRawFd;

    // SAFETY: plain libc calls on a descriptor this test owns; the name
    // buffer outlives the call that fills it.
    let (mut master, slave) = unsafe {
        let fd = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY);
        assert!(fd >= 0, "posix_openpt");
        assert_eq!(libc::grantpt(fd), 0);
        assert_eq!(libc::unlockpt(fd), 0);
        let mut name = [0 as libc::c_char; 128];
        assert_eq!(libc::ptsname_r(fd, name.as_mut_ptr(), name.len()), 0);
        let slave = CStr::from_ptr(name.as_ptr()).to_str().unwrap().to_owned();
        (File::from_raw_fd(fd), slave)
    };
    let save = temp("monitor-pty-save.bin", b"");
    let mut child = Command::new(env!("CARGO_BIN_EXE_iai"))
        .args([
            "monitor",
            "--port",
            &slave,
            "--baud",
            "38400",
            "--timestamps",
            "--save",
        ])
        .arg(&save)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Write only once iai holds the port (its settings, raw mode, are made
    // when it opens it): then no line discipline touches the bytes.
    let fds = format!("/proc/{}/fd", child.id());
    let opened = (0..100).any(|_| {
        std::thread::sleep(Duration::from_millis(50));
        std::fs::read_dir(&fds)
            .into_iter()
            .flatten()
            .flatten()
            .any(|e| std::fs::read_link(e.path()).is_ok_and(|p| p.to_str() == Some(slave.as_str())))
    });
    assert!(opened, "iai never opened {slave}");
    std::thread::sleep(Duration::from_millis(200));
    let sent = b"#992322C\r\nxx!99212038B\r\n";
    master.write_all(sent).unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    assert!(
        first.starts_with("[+") && first.contains(" s] 0x00000000  response st 99  232H"),
        "{first}"
    );
    let second = lines.next().unwrap().unwrap();
    assert!(second.contains("0x0000000A"), "{second}");
    std::thread::sleep(Duration::from_millis(300));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    assert_eq!(child.wait().unwrap().code(), Some(130));
    assert_eq!(std::fs::read(&save).unwrap(), sent);
}
