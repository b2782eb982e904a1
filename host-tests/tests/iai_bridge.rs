//! `iai` and the bridge firmware end to end: the gateway
//! (`tools/gateway.sh`'s binary: the bridge under QEMU `lm3s6965evb`, the
//! simulator behind it, its host side on a TCP port) and the real `iai`
//! tool as a user runs it.
//!
//! 1. `iai bridge status` decodes the bridge's status reply;
//! 2. `iai probe` finds the bridge and the controller behind it;
//! 3. `iai table write --bridge` sends 600 records x 8 axes as one 26DH
//!    (about 49 KB, the bridge splits it into 2,051-byte commands and
//!    reads each back) and reports the bridge's `#`; `iai table read` gives
//!    the same CSV back; the bridge's counters show the message;
//! 4. `--bridge --replace` leaves exactly the new file's records.
//!
//! The `iai` binary is built here with cargo (a no-op when the test
//! command built it), in this test's profile, as `qemu_gateway.rs` does.
//! Nothing asserts timing. Needs `qemu-system-arm` and the
//! `thumbv7m-none-eabi` rustup target.

mod gateway_proc;

use std::path::PathBuf;

use gateway_proc::{csv_of, err, text, Gateway, SERIAL};
use host_tests::qemu::iai_binary;
use host_tests::qemu::{build_firmware, Board};

/// The value of `name = N` in `iai bridge status`'s listing.
fn counter(listing: &str, name: &str) -> u64 {
    let pat = format!("  {name} = ");
    listing
        .lines()
        .find_map(|l| l.strip_prefix(&pat))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {name} in:\n{listing}"))
}

#[test]
fn iai_sends_whole_tables_through_the_bridge_and_reads_its_status() {
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf, &[] as &[&str], &SERIAL);

    // 1. The status, decoded.
    let status = text(&gw.iai(&iai, &["bridge", "status"]));
    assert!(status.starts_with("bridge at station BB:"), "{status}");
    assert!(
        status.contains("controller_station = 153 -> 99"),
        "{status}"
    );
    assert!(status.contains("flow_control = 1 -> XON/XOFF"), "{status}");
    assert!(status.contains("policy = 0 -> forward all"), "{status}");
    let (ok_before, records_before) = (counter(&status, "streams_ok"), counter(&status, "records"));

    // 2. probe: the bridge, and station 99 behind it.
    let probe = text(&gw.iai(&iai, &["probe", "--timeout", "1000"]));
    assert!(
        probe.contains("bridge BB: a bridge answers its status query: controller station 99"),
        "{probe}"
    );
    assert!(probe.contains("station 99: ANSWERED"), "{probe}");

    // 3. 600 records x 8 axes as one 26DH, far past a controller's 2,051 bytes.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let csv = csv_of(600, 91);
    let path = dir.join(format!("bridge-{}.csv", std::process::id()));
    std::fs::write(&path, &csv).unwrap();
    let file = path.to_str().expect("UTF-8 path");
    let out = gw.iai(&iai, &["table", "write", file, "--bridge"]);
    assert!(
        text(&out).starts_with(
            "verified by the bridge: the controller holds all 600 records (1 26DH message(s) of "
        ),
        "{}\n{}",
        text(&out),
        err(&out)
    );
    assert!(
        err(&out).contains("the bridge answered # with 600"),
        "{}",
        err(&out)
    );
    let back = gw.iai(&iai, &["table", "read", "--first", "1", "--count", "600"]);
    assert!(back.stdout == csv, "read back:\n{}", text(&back));
    let status = text(&gw.iai(&iai, &["bridge", "status"]));
    assert!(counter(&status, "streams_ok") > ok_before, "{status}");
    assert!(
        counter(&status, "records") >= records_before + 600,
        "{status}"
    );
    assert_eq!(counter(&status, "streams_failed"), 0, "{status}");

    // 4. --replace through the bridge: the table becomes the new file's.
    let csv = csv_of(100, 92);
    let small = dir.join(format!("bridge-small-{}.csv", std::process::id()));
    std::fs::write(&small, &csv).unwrap();
    let out = gw.iai(
        &iai,
        &[
            "table",
            "write",
            small.to_str().unwrap(),
            "--bridge",
            "--replace",
        ],
    );
    assert!(
        text(&out).contains(
            "replaced: the controller's table defines exactly these 100 positions (208H: 100)"
        ),
        "{}\n{}",
        text(&out),
        err(&out)
    );
    let back = gw.iai(&iai, &["table", "read", "--all"]);
    assert!(back.stdout == csv, "read back:\n{}", text(&back));
    let _ = std::fs::remove_file(&path);
    let _ = std::fs::remove_file(&small);
}
