//! The Ethernet gateway's web page in a real browser, and its
//! configuration through protocol B over TCP, under QEMU (one boot for the
//! page and `iai`, one more for the page carried over):
//!
//! 1. `host-tests/web/browser_check.py` drives headless Chromium through
//!    Selenium on a fresh gateway (`./tools/gateway.sh --ethernet`): axis
//!    1's position on the status page equals `iai send 212`'s, the page
//!    refreshes itself and reads without JavaScript; the form asks for a
//!    password first, then takes Modbus unit 7 with it; a wrong password
//!    and a form from another origin change nothing; the last frames
//!    download; the restart button restarts the gateway, and a Modbus TCP
//!    client gets answers on unit 7 and none on unit 1. Screenshots of
//!    each page go to `target/web-test/PID/`.
//! 2. Over protocol B on TCP, `iai bridge config get` shows what the form
//!    wrote; `config set` with the password and `iai bridge restart`: the
//!    status query reports the new policy.
//! 3. QEMU cannot keep what the firmware wrote (the lm3s6965's slots are
//!    in RAM: its flash is read-only to the CPU), so `config get --image`
//!    carries the page (and, with the password, its verifier) into a new
//!    boot, loaded with `-device loader`: the same settings, the same
//!    password.
//!
//! Skipped, with the reason printed, where Chromium, its driver or
//! Selenium is missing (`tools/setup.sh` installs them).

mod gateway_proc;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use gateway_proc::{err, text, Gateway, ETHERNET};
use host_tests::qemu::{build_ethernet_firmware, iai_binary, target_dir, workspace_root};

/// Why the browser test cannot run here, if it cannot.
fn missing_browser(python: &Path) -> Option<String> {
    for exe in ["/usr/bin/chromium", "/usr/bin/chromedriver"] {
        if !Path::new(exe).exists() {
            return Some(format!("{exe} is missing (tools/setup.sh installs it)"));
        }
    }
    let selenium = Command::new(python)
        .args(["-c", "import selenium, pymodbus"])
        .output();
    match selenium {
        Ok(o) if o.status.success() => None,
        _ => Some(format!(
            "{} has no selenium or pymodbus (tools/setup.sh installs them)",
            python.display()
        )),
    }
}

/// `iai bridge status --json`'s fields.
fn status(gw: &mut Gateway, iai: &Path) -> serde_json::Value {
    let out = gw.iai(iai, &["bridge", "status", "--json"]);
    serde_json::from_str::<serde_json::Value>(&text(&out)).unwrap()["fields"].clone()
}

/// `GET path` on the web page: the answer.
fn get(http: &str, path: &str) -> String {
    let mut c = TcpStream::connect(http).unwrap();
    c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(c, "GET {path} HTTP/1.1\r\nHost: {http}\r\n\r\n").unwrap();
    let mut got = String::new();
    c.read_to_string(&mut got).unwrap();
    got
}

#[test]
fn a_plant_sets_up_and_watches_the_gateway_in_a_browser_and_with_iai() {
    let python = workspace_root().join(".venv/bin/python");
    if let Some(why) = missing_browser(&python) {
        eprintln!("skipped: {why}");
        return;
    }
    let elf = build_ethernet_firmware().expect("build the Ethernet firmware");
    let iai = iai_binary().expect("the iai binary");
    let out = target_dir()
        .join("web-test")
        .join(std::process::id().to_string());
    std::fs::create_dir_all(&out).unwrap();
    let pw = out.join("pw.txt");
    std::fs::write(&pw, "plant-1234\n").unwrap();
    let pw_arg = ["--password-file", pw.to_str().unwrap()];

    // 1. The browser.
    let mut gw = Gateway::start(&elf, &["--ethernet"], &ETHERNET);
    let browser = Command::new(&python)
        .arg(workspace_root().join("host-tests/web/browser_check.py"))
        .args([
            "--http",
            &gw.http,
            "--protocol-b",
            &gw.addr,
            "--modbus",
            &gw.modbus,
        ])
        .arg("--iai")
        .arg(&iai)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("run the browser check");
    eprintln!("screenshots in {}", out.display());
    let said = text(&browser);
    eprint!("{said}");
    assert!(
        browser.status.success(),
        "{said}\n{}\ngateway:\n{}",
        err(&browser),
        gw.log()
    );
    for step in [
        "status",
        "no-javascript",
        "save",
        "wrong-password",
        "cross-origin",
        "frames",
        "restart",
    ] {
        assert!(said.contains(&format!("ok {step} ")), "{step}: {said}");
    }
    for shot in [
        "status",
        "config-fresh",
        "config-saved",
        "wrong-password",
        "cross-origin",
        "restarting",
    ] {
        assert!(out.join(format!("{shot}.png")).is_file(), "{shot}.png");
    }

    // 2. Protocol B over TCP: what the form wrote, then a change and a
    // restart through iai.
    let get_toml = text(&gw.iai(&iai, &["bridge", "config", "get"]));
    assert!(get_toml.contains("[modbus]\nunit = 7"), "{get_toml}");
    assert!(get_toml.contains("# password: set"), "{get_toml}");
    let mut set = vec!["bridge", "config", "set", "bridge.policy=read-only"];
    set.extend(pw_arg);
    let applied = text(&gw.iai(&iai, &set));
    assert!(
        applied.contains("takes effect at the next start"),
        "{applied}"
    );
    assert_eq!(status(&mut gw, &iai)["policy"], 0);
    let mut restart = vec!["bridge", "restart"];
    restart.extend(pw_arg);
    gw.iai(&iai, &restart);
    assert_eq!(status(&mut gw, &iai)["policy"], 1);

    // 3. Carried into the next boot.
    let carried = out.join("carried.bin");
    let mut image = vec![
        "bridge",
        "config",
        "get",
        "--image",
        carried.to_str().unwrap(),
    ];
    image.extend(pw_arg);
    gw.iai(&iai, &image);
    gw.stop();
    drop(gw);
    let mut gw = Gateway::start(
        &elf,
        &["--ethernet", "--config-image", carried.to_str().unwrap()],
        &ETHERNET,
    );
    assert_eq!(status(&mut gw, &iai)["policy"], 1);
    let form = get(&gw.http, "/config");
    assert!(form.contains("name=\"modbus.unit\" value=\"7\""), "{form}");
    assert!(
        !form.contains("id=\"no-password\""),
        "the password came along"
    );
    let mut back = vec!["bridge", "config", "set", "bridge.policy=forward-all"];
    back.extend(pw_arg);
    assert!(text(&gw.iai(&iai, &back)).contains("applied as sequence 2"));
    gw.iai(&iai, &restart);
    assert_eq!(status(&mut gw, &iai)["policy"], 0);
    gw.stop();
}
