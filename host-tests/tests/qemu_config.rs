//! `iai bridge config` and `iai bridge restart` end to end on the serial
//! gateway (`lm3s6965evb` under QEMU, protocol B through the relay), and
//! the page they write is the one the firmware reads after its restart:
//!
//! 1. `iai bridge config block gateway.toml -o config.bin` (an allow-list
//!    policy and a password), loaded by QEMU at `_bridge_config`: the
//!    status query reports that policy, `config get` that page;
//! 2. a change without the password is refused before anything is sent;
//!    with it, `config set` applies a new page (sequence 2, "at the next
//!    start") and the running bridge still has the old policy;
//! 3. `iai bridge restart`: the firmware resets (a system reset, which
//!    keeps the lm3s6965's slots: QEMU maps its flash read-only, so the
//!    firmware keeps them in RAM a reset leaves as it was) and reads the
//!    new page: the status reports the new policy;
//! 4. QEMU itself cannot keep what the firmware wrote (the RAM is gone
//!    with the process), so the test carries the page into the next
//!    boot: `config get --image` reads it back over protocol B (with the
//!    password, its verifier too), and the next QEMU loads it with
//!    `-device loader`: the same policy, and the same password works.
//!
//! And on mps2-an386, whose "flash" is RAM the CPU writes, the slots are
//! written in place and a system reset keeps them (nothing loaded there:
//! QEMU copies a loaded image back at a reset).

mod gateway_proc;

use std::path::{Path, PathBuf};

use gateway_proc::{err, text, Gateway, SERIAL};
use host_tests::qemu::{build_firmware, iai_binary, target_dir, Board};

/// A folder of this test's own in the target directory.
fn workdir(name: &str) -> PathBuf {
    let d = target_dir()
        .join("qemu-config-test")
        .join(format!("{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `iai bridge status --json` on the gateway: its fields.
fn status(gw: &mut Gateway, iai: &Path) -> serde_json::Value {
    let out = gw.iai(iai, &["bridge", "status", "--json"]);
    serde_json::from_str::<serde_json::Value>(&text(&out)).unwrap()["fields"].clone()
}

#[test]
fn iai_configures_the_serial_gateway_and_the_firmware_reads_it_after_a_restart() {
    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = iai_binary().expect("the iai binary");
    let dir = workdir("serial");
    let pw = dir.join("pw.txt");
    std::fs::write(&pw, "plant-1234\n").unwrap();
    let pw_arg = ["--password-file", pw.to_str().unwrap()];
    std::fs::write(
        dir.join("gateway.toml"),
        "[bridge]\npolicy = \"allow-list\"\nallow = \"200-2FF\"\n\n[access]\npassword = \"plant-1234\"\n",
    )
    .unwrap();
    let block = std::process::Command::new(&iai)
        .args([
            "bridge",
            "config",
            "block",
            "gateway.toml",
            "-o",
            "config.bin",
        ])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(block.status.success(), "{}", err(&block));
    assert!(
        err(&block).contains("lm3s6965's two 1024-byte slots at 0x3f800"),
        "{}",
        err(&block)
    );
    assert_eq!(std::fs::read(dir.join("config.bin")).unwrap().len(), 2048);

    // 1. Booted with the block.
    let image = dir.join("config.bin");
    let mut gw = Gateway::start(&elf, &["--config-image", image.to_str().unwrap()], &SERIAL);
    let s = status(&mut gw, &iai);
    assert_eq!(
        (s["config_source"].as_u64(), s["policy"].as_u64()),
        (Some(1), Some(2))
    );
    assert_eq!(s["allow_list_len"], 256);
    let get = text(&gw.iai(&iai, &["bridge", "config", "get"]));
    assert!(
        get.contains("# the gateway's configuration page, sequence 1"),
        "{get}"
    );
    assert!(get.contains("policy = \"allow-list\""), "{get}");
    assert!(get.contains("allow = \"200-2FF\""), "{get}");
    assert!(get.contains("# password: set"), "{get}");

    // 2. No password, nothing sent; with it, the page written.
    let addr = gw.addr.clone();
    let refused = std::process::Command::new(&iai)
        .args([
            "bridge",
            "config",
            "set",
            "bridge.policy=read-only",
            "--tcp",
            &addr,
        ])
        .env_remove("IAI_BRIDGE_PASSWORD")
        .output()
        .unwrap();
    assert!(!refused.status.success());
    assert!(
        err(&refused).contains("needs the gateway's password"),
        "{}",
        err(&refused)
    );
    let mut set = vec!["bridge", "config", "set", "bridge.policy=read-only"];
    set.extend(pw_arg);
    let applied = text(&gw.iai(&iai, &set));
    assert_eq!(
        applied.trim(),
        "applied as sequence 2; takes effect at the next start (iai bridge restart)"
    );
    assert_eq!(
        status(&mut gw, &iai)["policy"],
        2,
        "the running bridge, until it restarts"
    );

    // 3. Restarted, it reads the new page.
    let mut restart = vec!["bridge", "restart"];
    restart.extend(pw_arg);
    let out = text(&gw.iai(&iai, &restart));
    assert!(
        out.starts_with("restarted: the gateway answers again"),
        "{out}"
    );
    let s = status(&mut gw, &iai);
    assert_eq!(
        (s["config_source"].as_u64(), s["policy"].as_u64()),
        (Some(1), Some(1))
    );
    assert!(s["uptime_ms"].as_u64().unwrap() < 60_000);

    // 4. Carried into the next boot by the test.
    let carried = dir.join("carried.bin");
    let mut get_image = vec![
        "bridge",
        "config",
        "get",
        "--image",
        carried.to_str().unwrap(),
    ];
    get_image.extend(pw_arg);
    let got = text(&gw.iai(&iai, &get_image));
    assert!(got.contains("sequence 2"), "{got}");
    gw.stop();
    drop(gw);
    let mut gw = Gateway::start(
        &elf,
        &["--config-image", carried.to_str().unwrap()],
        &SERIAL,
    );
    assert_eq!(status(&mut gw, &iai)["policy"], 1);
    let mut back = vec!["bridge", "config", "set", "bridge.policy=forward-all"];
    back.extend(pw_arg);
    // The carried image is the page as sequence 1 (as a programmer writes
    // it), so this one is 2.
    let applied = text(&gw.iai(&iai, &back));
    assert!(applied.contains("applied as sequence 2"), "{applied}");
    gw.iai(&iai, &restart);
    assert_eq!(status(&mut gw, &iai)["policy"], 0);
    gw.stop();
}

#[test]
fn mps2_an386_writes_its_slots_in_place_and_a_reset_keeps_them() {
    let elf = build_firmware(Board::Mps2An386).expect("build mps2-an386 firmware");
    let iai = iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(
        &elf,
        &["--board", "mps2-an386", "--blank-config"],
        &SERIAL[..1],
    );
    let s = status(&mut gw, &iai);
    assert_eq!(
        (s["config_source"].as_u64(), s["policy"].as_u64()),
        (Some(2), Some(0))
    );
    // A fresh gateway: the password first, in the same command.
    let set = [
        "bridge",
        "config",
        "set",
        "access.password=plant-1234",
        "bridge.policy=read-only",
    ];
    assert!(text(&gw.iai(&iai, &set)).contains("sequence 2"));
    gw.iai(&iai, &["bridge", "restart", "--password", "plant-1234"]);
    let s = status(&mut gw, &iai);
    assert_eq!(
        (s["config_source"].as_u64(), s["policy"].as_u64()),
        (Some(1), Some(1))
    );
    gw.stop();
}
