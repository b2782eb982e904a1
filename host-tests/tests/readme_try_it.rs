//! The README's "Try it" commands, run as written: the commands are read
//! from README.md's `sh` block under "## Try it" (so the README and this
//! test cannot drift apart), and `table.csv` is the example table of the
//! README's "CSV position tables".
//!
//! `./tools/gateway.sh` builds the firmware, the gateway and `iai` in
//! release and then starts the gateway on the `lm3s6965` firmware with its
//! arguments; here the same gateway runs on the firmware and binaries of
//! this test's profile (the script's last line is checked to be that
//! start). Each `iai` command then runs in a directory holding
//! `table.csv`, with `127.0.0.1:PORT` the gateway's address, and its
//! output is checked: the 212H reply decoded, each table write verified,
//! the bridge's status decoded, probe finding the bridge and the
//! controller. The table read back at the end is the README's table. A
//! command this test has no expectation for fails it.
//!
//! Needs `qemu-system-arm` and the `thumbv7m-none-eabi` rustup target.

mod gateway_proc;

use std::path::Path;
use std::process::Output;

use gateway_proc::{err, text, Gateway, SERIAL};
use host_tests::qemu::iai_binary;
use host_tests::qemu::{build_firmware, workspace_root, Board};

/// The lines of the fenced block of kind `lang` that follows the line
/// `heading` in `doc`.
fn block_after<'a>(doc: &'a str, heading: &str, lang: &str) -> Vec<&'a str> {
    let mut lines = doc.lines().skip_while(|l| l.trim_end() != heading);
    assert!(lines.next().is_some(), "no {heading:?} in README.md");
    let fence = format!("```{lang}");
    let mut lines = lines.skip_while(|l| l.trim_end() != fence);
    assert!(
        lines.next().is_some(),
        "no {fence} block after {heading:?} in README.md"
    );
    lines.take_while(|l| l.trim_end() != "```").collect()
}

/// A command line without its trailing comment, as words.
fn words(line: &str) -> Vec<&str> {
    let command = line.split(" #").next().unwrap_or(line);
    command.split_whitespace().collect()
}

/// Checks what the README command `cmd` (its words after `iai`) printed.
fn check(cmd: &[&str], out: &Output, records: usize) {
    let (o, e) = (text(out), err(out));
    let has = |s: &str, what: &str| assert!(s.contains(what), "iai {cmd:?}: no {what:?} in:\n{s}");
    let starts =
        |s: &str, what: &str| assert!(s.starts_with(what), "iai {cmd:?}: {what:?} first in:\n{s}");
    match cmd {
        ["send", "212", ..] => {
            // Axis 1's status, decoded, from station 99 behind the bridge.
            has(&o, "response st 99  212H Axis Status Query");
            has(&o, "axis_pattern = 0x01 (1)");
            has(&o, "axes[0].axis_status = ");
            has(&o, "axes[0].current_position = ");
        }
        ["table", "write", "table.csv", rest @ ..] if rest.contains(&"--bridge") => {
            starts(
                &o,
                &format!(
                    "verified by the bridge: the controller holds all {records} records (1 26DH message(s) of "
                ),
            );
            has(&e, &format!("the bridge answered # with {records}"));
        }
        ["table", "write", "table.csv", ..] => starts(
            &o,
            &format!("verified: the controller holds all {records} records written now"),
        ),
        ["bridge", "status", ..] => {
            starts(&o, "bridge at station BB:");
            has(&o, "controller_station = 153 -> 99");
            has(&o, "flow_control = 1 -> XON/XOFF");
        }
        ["probe", ..] => {
            has(
                &o,
                "bridge BB: a bridge answers its status query: controller station 99",
            );
            has(&o, "station 99: ANSWERED");
        }
        _ => panic!(
            "README's Try it runs `iai {cmd:?}`, which this test has no expectation for: add one"
        ),
    }
}

#[test]
fn the_readme_try_it_commands_work_as_written() {
    let root = workspace_root();
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let commands: Vec<Vec<&str>> = block_after(&readme, "## Try it", "sh")
        .into_iter()
        .map(words)
        .filter(|w| !w.is_empty())
        .collect();
    let table = block_after(&readme, "### CSV position tables", "text");
    let records = table.len() - 1;
    assert!(records > 0, "README's example table has no rows");

    // The first command starts the gateway; gateway.sh ends by starting the
    // gateway binary on the lm3s6965 firmware with the script's arguments.
    let (start, rest) = commands.split_first().expect("Try it has commands");
    assert_eq!(start.first(), Some(&"./tools/gateway.sh"), "{start:?}");
    let script = std::fs::read_to_string(root.join("tools/gateway.sh")).expect("gateway.sh");
    assert!(
        script.contains("\nboard=lm3s6965\n"),
        "gateway.sh's default board"
    );
    assert!(
        script
            .trim_end()
            .ends_with(r#"exec "$tdir/release/gateway" --elf "$tdir/$target/firmware/$bin" "$@""#),
        "gateway.sh no longer ends by starting the gateway"
    );
    let args: Vec<String> = start.iter().skip(1).map(|a| a.to_string()).collect();
    assert!(
        !args.iter().any(|a| a.starts_with("--board")),
        "this test runs the lm3s6965 board only: {args:?}"
    );
    assert!(rest.len() >= 3, "Try it has {} iai commands", rest.len());

    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf, &args, &SERIAL);
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("try-it-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = table.join("\n") + "\n";
    std::fs::write(dir.join("table.csv"), &csv).unwrap();

    for cmd in rest {
        let (first, words) = cmd.split_first().expect("a command");
        assert_eq!(*first, "iai", "{cmd:?}");
        let args: Vec<String> = words
            .iter()
            .map(|w| w.replace("127.0.0.1:PORT", &gw.addr))
            .collect();
        let out = gw.run(&iai, &args, &dir);
        check(words, &out, records);
    }

    // What the writes left: the README's table, read back whole.
    let addr = gw.addr.clone();
    let back = gw.run(&iai, &["table", "read", "--all", "--tcp", &addr], &dir);
    assert_eq!(text(&back), csv, "the table read back");
    let _ = std::fs::remove_dir_all(&dir);
}
