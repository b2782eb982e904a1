//! CSV position tables written to and read back from `iai simulate`, over
//! TCP and over a pseudo-terminal, with faults on the line and in the
//! controller's memory.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod common;

use std::time::Duration;

use common::{csv_table, iai, stderr, stdout, temp, Sim};

/// Faults that cost a timeout (corrupt, drop, late) are rare, so that the
/// run stays short; the others are frequent.
const FAULTS: &str = "corrupt=0.000005,swap=0.05,drop=0.005,late=0.01:3500,dup=0.05:40,error=0.03";

/// The simulator's duplicates come 40 ms after the reply: a 200 ms guard
/// covers them, and the engines need not wait their default 3 s.
const DUP_WINDOW: [&str; 2] = ["--duplicate-window-ms", "200"];

fn write_then_read(line: &[&str], name: &str, records: u32) {
    let csv = csv_table(records, 8, 11);
    let path = temp(name, csv.as_bytes());
    let mut args = vec!["table", "write", path.to_str().unwrap()];
    args.extend_from_slice(line);
    args.extend_from_slice(&DUP_WINDOW);
    let out = iai(&args);
    assert!(
        out.status.success(),
        "table write: {}\n{}",
        stderr(&out),
        stdout(&out)
    );
    assert!(
        stdout(&out).contains("verified: the controller holds all"),
        "{}",
        stdout(&out)
    );
    let count = records.to_string();
    let mut args = vec!["table", "read", "--first", "1", "--count", &count];
    args.extend_from_slice(line);
    args.extend_from_slice(&DUP_WINDOW);
    let out = iai(&args);
    assert!(out.status.success(), "table read: {}", stderr(&out));
    assert_eq!(stdout(&out), csv, "the CSV read back differs");
}

/// The runs above met faults: the summary lines count them.
fn assert_faults_injected(log: &str) {
    let total: u32 = log
        .lines()
        .filter_map(|l| l.split("; ").nth(1))
        .filter_map(|t| t.split_whitespace().next())
        .filter_map(|n| n.parse::<u32>().ok())
        .sum();
    assert!(total > 0, "no fault was injected:\n{log}");
}

#[test]
fn a_csv_table_survives_a_faulty_tcp_line() {
    let sim = Sim::tcp(&["--quiet", "--faults", FAULTS, "--seed", "7"]);
    let at = sim.at.clone();
    write_then_read(&["--tcp", &at], "tcp.csv", 600);
    assert_faults_injected(&sim.stop());
}

#[cfg(unix)]
#[test]
fn a_csv_table_survives_a_faulty_pseudo_terminal() {
    let sim = Sim::start(&["--pty", "--quiet", "--faults", FAULTS, "--seed", "9"]);
    assert!(sim.at.starts_with("/dev/"), "{}", sim.at);
    let at = sim.at.clone();
    write_then_read(&["--port", &at, "--baud", "115200"], "pty.csv", 600);
    assert_faults_injected(&sim.stop());
}

#[test]
fn only_a_table_read_back_equal_counts_and_off_says_unverified() {
    // Every write has a record stored with swapped digits: confirmed by
    // the controller, wrong in its memory. Without verification the tool
    // says so; with it, the records are found and written again.
    let sim = Sim::tcp(&["--quiet", "--faults", "swap=1", "--seed", "3"]);
    let at = sim.at.clone();
    let path = temp("swap.csv", csv_table(100, 4, 5).as_bytes());
    let p = path.to_str().unwrap();
    let out = iai(&["table", "write", p, "--tcp", &at, "--verify", "off"]);
    assert!(out.status.success());
    assert!(stdout(&out).starts_with("UNVERIFIED"), "{}", stdout(&out));
    let out = iai(&["table", "write", p, "--tcp", &at, "--verify", "after-fault"]);
    assert!(stdout(&out).starts_with("UNVERIFIED"), "{}", stdout(&out));
    // Every rewrite is swapped again: the tool must fail, not claim success.
    let out = iai(&["table", "write", p, "--tcp", &at]);
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    assert!(
        stderr(&out).contains("does NOT hold the table"),
        "{}",
        stderr(&out)
    );
    sim.stop();
}

#[test]
fn a_bad_row_stops_everything_before_sending() {
    let sim = Sim::tcp(&[]);
    let at = sim.at.clone();
    let csv = "number,acceleration,deceleration,speed,axis1,axis2\n\
               1,0.30,0.30,100,1.000,2.000\n\
               2,0.30,0.30,100,1.0001,2.000\n";
    let path = temp("bad.csv", csv.as_bytes());
    let out = iai(&["table", "write", path.to_str().unwrap(), "--tcp", &at]);
    assert_eq!(out.status.code(), Some(1));
    let e = stderr(&out);
    assert!(e.contains("nothing was sent"), "{e}");
    assert!(e.contains("line 3, column axis1"), "{e}");
    assert!(
        e.contains("more than 3 decimal(s); allowed -2147483.648..=2147483.647 mm"),
        "{e}"
    );
    let log = sim.stop();
    assert!(!log.contains("connection"), "the tool connected: {log}");
}

#[test]
fn an_interrupted_write_resumes_after_the_last_confirmed_record() {
    let sim = Sim::tcp(&["--quiet", "--reply-delay-ms", "10"]);
    let at = sim.at.clone();
    let csv = csv_table(1_000, 8, 13);
    let path = temp("resume.csv", csv.as_bytes());
    let p = path.to_str().unwrap().to_string();
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_iai"))
        .args([
            "table",
            "write",
            &p,
            "--tcp",
            &at,
            "--duplicate-window-ms",
            "200",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1_000));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let out = child.wait_with_output().unwrap();
    // Ctrl-C: exit 130, the state kept.
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(stderr(&out).contains("--resume"), "{}", stderr(&out));
    let state = std::fs::read_to_string(format!("{p}.iai-state")).unwrap();
    let out = iai(&[
        "table",
        "write",
        &p,
        "--tcp",
        &at,
        "--resume",
        "--duplicate-window-ms",
        "200",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let e = stderr(&out);
    let after: u32 = e
        .split("resuming after record ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{e}"));
    assert!(after > 0 && after < 1_000, "{e}\n{state}");
    assert!(!std::path::Path::new(&format!("{p}.iai-state")).exists());
    let out = iai(&[
        "table",
        "read",
        "--first",
        "1",
        "--count",
        "1000",
        "--tcp",
        &at,
        "--duplicate-window-ms",
        "200",
    ]);
    assert_eq!(stdout(&out), csv);
    sim.stop();
}

#[test]
fn the_simulator_dumps_its_table_on_sigterm() {
    let dump = temp("dump.csv", b"");
    let sim = Sim::tcp(&["--quiet", "--dump", dump.to_str().unwrap()]);
    let at = sim.at.clone();
    let csv = csv_table(50, 3, 17);
    let path = temp("dumped.csv", csv.as_bytes());
    let out = iai(&["table", "write", path.to_str().unwrap(), "--tcp", &at]);
    assert!(out.status.success(), "{}", stderr(&out));
    let log = sim.stop();
    assert!(log.contains("dumped 50 position(s)"), "{log}");
    assert_eq!(std::fs::read_to_string(&dump).unwrap(), csv);
}

#[test]
fn a_2003_x_sel_takes_3_digit_tables_through_245h_and_209h() {
    let sim = Sim::tcp(&["--quiet", "--profile", "xsel2003"]);
    let at = sim.at.clone();
    let csv = csv_table(60, 3, 19);
    let path = temp("xsel.csv", csv.as_bytes());
    let line = ["--tcp", at.as_str(), "--profile", "xsel2003"];
    let mut args = vec!["table", "write", path.to_str().unwrap()];
    args.extend_from_slice(&line);
    let out = iai(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    let mut args = vec!["table", "read", "--first", "1", "--count", "60"];
    args.extend_from_slice(&line);
    assert_eq!(stdout(&iai(&args)), csv);
    // A number past 245H's three digits is refused before anything is sent.
    let bad = temp(
        "xsel-bad.csv",
        b"number,acceleration,deceleration,speed,axis1\n4096,0.00,0.00,0,1.000\n",
    );
    let mut args = vec!["table", "write", bad.to_str().unwrap()];
    args.extend_from_slice(&line);
    let out = iai(&args);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr(&out).contains("line 2, column number: \"4096\" is outside 0..=4095"),
        "{}",
        stderr(&out)
    );
    let log = sim.stop();
    // The write and the read connected; the refused file did not.
    assert_eq!(log.matches(" opened").count(), 2, "{log}");
    assert!(log.contains("60 position record(s) written"), "{log}");
}

/// Starts `iai table write CSV --tcp AT` and kills it with `signal` after
/// `ms`: what a user's Ctrl-C (SIGINT) or a crash (SIGKILL) leaves behind.
#[cfg(unix)]
fn interrupted_write(p: &str, at: &str, ms: u64, signal: i32) -> std::process::Output {
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_iai"))
        .args(["table", "write", p, "--tcp", at, "--restart"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(ms));
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, signal) };
    child.wait_with_output().unwrap()
}

/// A resume is bound to the line its state file names: on another
/// controller (another address) it is refused, and nothing is sent.
#[cfg(unix)]
#[test]
fn a_resume_on_another_line_is_refused() {
    let sim = Sim::tcp(&["--quiet", "--reply-delay-ms", "10"]);
    let other = Sim::tcp(&["--quiet"]);
    let csv = csv_table(1_000, 8, 23);
    let path = temp("elsewhere.csv", csv.as_bytes());
    let p = path.to_str().unwrap().to_string();
    let out = interrupted_write(&p, &sim.at, 1_000, libc::SIGINT);
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let out = iai(&["table", "write", &p, "--tcp", &other.at, "--resume"]);
    assert_eq!(out.status.code(), Some(1), "{}", stdout(&out));
    let e = stderr(&out);
    assert!(
        e.contains("its records are not on this line's controller"),
        "{e}"
    );
    assert!(e.contains(&sim.at) && e.contains(&other.at), "{e}");
    let log = other.stop();
    assert!(!log.contains("connection"), "the tool connected: {log}");
    sim.stop();
}

/// Issue "one memory of the line", case 3: the controller behind the same
/// address was swapped (a fresh simulator on the same port) after an
/// interrupted write. With full verification the resume reads back the
/// records confirmed before it, finds them missing and writes them again:
/// the table is whole. Without, it says plainly that they are unverified
/// on this controller, with its own exit status.
#[cfg(unix)]
#[test]
fn a_resume_on_a_swapped_controller_reads_back_or_says_unverified() {
    let sim = Sim::tcp(&["--quiet", "--reply-delay-ms", "10"]);
    let at = sim.at.clone();
    let csv = csv_table(1_000, 8, 29);
    let path = temp("swapped.csv", csv.as_bytes());
    let p = path.to_str().unwrap().to_string();
    // Interrupted by Ctrl-C, then (started over with --restart) killed
    // outright.
    for kill in [libc::SIGINT, libc::SIGKILL] {
        let out = interrupted_write(&p, &at, 1_200, kill);
        assert_ne!(out.status.code(), Some(0), "{}", stderr(&out));
    }
    let state = std::fs::read_to_string(format!("{p}.iai-state")).unwrap();
    // The controller is replaced: same address, empty memory.
    drop(sim.stop());
    let fresh = Sim::start(&["--tcp", &at, "--quiet"]);
    assert_eq!(fresh.at, at);
    let out = iai(&[
        "table", "write", &p, "--tcp", &at, "--resume", "--verify", "off",
    ]);
    assert_eq!(out.status.code(), Some(3), "{}\n{}", stderr(&out), state);
    assert!(
        stdout(&out).contains("NOT read back on this controller"),
        "{}",
        stdout(&out)
    );
    // Again, from the start of the state: full verification finds the
    // records confirmed before the resume missing and writes them again.
    drop(fresh.stop());
    let fresh = Sim::start(&["--tcp", &at, "--quiet"]);
    std::fs::write(format!("{p}.iai-state"), &state).unwrap();
    let out = iai(&["table", "write", &p, "--tcp", &at, "--resume"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let e = stderr(&out);
    assert!(e.contains("are not held as the file says"), "{e}");
    assert!(
        stdout(&out).contains("verified: the controller holds all 1000 records"),
        "{}",
        stdout(&out)
    );
    let out = iai(&[
        "table", "read", "--first", "1", "--count", "1000", "--tcp", &at,
    ]);
    assert_eq!(stdout(&out), csv);
    fresh.stop();
}

/// A new process right after one was killed in the middle of a write: its
/// line knows nothing of the past, so it fences before its first command,
/// and whatever the killed one left in flight answers nothing of it.
#[cfg(unix)]
#[test]
fn a_new_process_after_a_killed_one_fences_first_and_completes() {
    let sim = Sim::tcp(&["--reply-delay-ms", "10"]);
    let at = sim.at.clone();
    let csv = csv_table(1_000, 8, 31);
    let path = temp("killed.csv", csv.as_bytes());
    let p = path.to_str().unwrap().to_string();
    let _ = interrupted_write(&p, &at, 800, libc::SIGKILL);
    let out = iai(&["table", "write", &p, "--tcp", &at, "--resume"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stdout(&out).contains("verified"), "{}", stdout(&out));
    let out = iai(&[
        "table", "read", "--first", "1", "--count", "1000", "--tcp", &at,
    ]);
    assert_eq!(stdout(&out), csv);
    let log = sim.stop();
    // The new connection's first command is a 200H (the fence).
    let second = log
        .split(" opened")
        .nth(2)
        .unwrap_or_else(|| panic!("{log}"));
    let first_command = second
        .lines()
        .find(|l| l.contains(" rx  command"))
        .unwrap_or_else(|| panic!("{second}"));
    assert!(first_command.contains("200H Test Call"), "{first_command}");
}
