//! The Ethernet build as a Sparkplug B 3.0 edge node on a real broker, end
//! to end: Debian's Mosquitto (user names and passwords, anonymous
//! clients refused), the `lm3s6965-eth` firmware under QEMU with the
//! simulated controller behind it, its Sparkplug block pointing at the
//! broker through QEMU's user network (10.0.2.2), and a Sparkplug host in
//! Python (`host-tests/sparkplug/sparkplug_host.py`: paho-mqtt, the
//! payload decoded with `sparkplug_b.proto` compiled by protoc) that
//! checks every message on its own (types, aliases, seq, DATA by
//! exception) and prints it as JSON for the checks here. Two boots:
//!
//! 1. a primary host configured, commands allowed, the policy forwarding
//!    all: no BIRTH before the host's STATE says online; NBIRTH then
//!    DBIRTH with the metrics and valid types; DCMD servo on, home, a move
//!    of 200 mm, each done only once the controller confirmed, DDATA
//!    while the axis moves, its last position equal to `iai send 212`'s;
//!    a record written through the table window and read back; a rebirth
//!    on NCMD with the same aliases; DDEATH when the controller
//!    stops answering, DBIRTH when it answers again; NDEATH from the
//!    broker, with the last NBIRTH's bdSeq, when QEMU is killed;
//! 2. the read-only policy: NBIRTH without waiting (no primary host), a
//!    DCMD servo refused (`Command/State` refused, code B06, message
//!    232H) and the servo as it was; the broker restarted, the node born
//!    again with bdSeq 1.
//!
//! Mosquitto, protoc and the venv's paho-mqtt and protobuf come from
//! `tools/setup.sh`.

mod sparkplug_kit;

use std::collections::HashMap;
use std::io::Write;
use std::process::Command;
use std::time::{Duration, Instant};

use firmware_example::config::{Config, Policy};
use firmware_example::net::sparkplug::config::{text_of, SparkplugConfig};
use host_tests::gateway::{self, EthernetGateway, Options, QEMU_HOST};
use serde_json::{json, Value};
use sparkplug_kit::{Broker, Host, GROUP, HOST_ID};

/// Protocol-B replies timed while the node publishes: `n` 212H queries
/// of axis 1, one after the other, on one connection to `addr`; the time
/// from each command's last byte to its reply's end.
fn protocol_b_latencies(addr: std::net::SocketAddr, n: usize) -> Vec<Duration> {
    use iai_protocol_b::frame::{emit_frame, Header, Station};
    use std::io::Read;
    let mut buf = [0u8; 64];
    let len = emit_frame(
        &mut buf,
        Header::Command,
        Station(0x99),
        0x212,
        Default::default(),
        |w| w.put(b"01"),
    )
    .unwrap();
    let mut c = std::net::TcpStream::connect(addr).unwrap();
    c.set_nodelay(true).unwrap();
    c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut times = Vec::new();
    let mut byte = [0u8; 1];
    for _ in 0..n {
        c.write_all(&buf[..len]).unwrap();
        let t = Instant::now();
        let mut last = 0u8;
        loop {
            assert_eq!(c.read(&mut byte).unwrap(), 1, "the bridge closed");
            if last == b'\r' && byte[0] == b'\n' {
                break;
            }
            last = byte[0];
        }
        times.push(t.elapsed());
    }
    times
}

fn names(m: &Value) -> Vec<(String, u64, u64)> {
    m["metrics"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| {
            (
                x["name"].as_str().unwrap_or_default().to_owned(),
                x["alias"].as_u64().unwrap_or(u64::MAX),
                x["datatype"].as_u64().unwrap_or(0),
            )
        })
        .collect()
}

fn metric<'a>(m: &'a Value, name: &str) -> &'a Value {
    m["metrics"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["name"] == name)
        .map(|x| &x["value"])
        .unwrap_or_else(|| panic!("no {name} in {m}"))
}

fn node_config(primary: bool) -> SparkplugConfig {
    SparkplugConfig {
        enabled: true,
        commands: true,
        broker: QEMU_HOST,
        port: 0,
        deadband: 0,
        keep_alive_s: 10,
        group: text_of(GROUP),
        username: text_of("gw"),
        password: text_of("gw-secret"),
        primary_host: if primary {
            text_of(HOST_ID)
        } else {
            text_of("")
        },
        ..SparkplugConfig::default()
    }
}

fn boot(broker: &Broker, primary: bool, policy: Policy, quit: bool) -> EthernetGateway {
    let mut sp = node_config(primary);
    sp.port = broker.port;
    let opts = Options {
        ethernet: true,
        quit_sequence: quit,
        sparkplug: Some(sp),
        bridge_config: Some(Config {
            policy,
            ..gateway::config(115_200, 115_200)
        }),
        ..Options::default()
    };
    EthernetGateway::start(&opts).expect("the Ethernet gateway")
}

#[test]
fn the_gateway_is_a_sparkplug_edge_node_on_mosquitto() {
    let mut broker = Broker::start();
    let mut host = Host::start(broker.port);
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");

    // Boot 1: a primary host is configured; nothing is born before its
    // STATE says online.
    let gw = boot(&broker, true, Policy::ForwardAll, false);
    let t0 = Instant::now();
    assert!(
        gw.qemu.wait_for_stdout(
            "sparkplug connected",
            Instant::now() + Duration::from_secs(30)
        ),
        "the node did not connect:\n{}",
        gw.qemu.stdout_so_far()
    );
    std::thread::sleep(Duration::from_secs(3));
    while let Ok(m) = host.lines.try_recv() {
        assert!(
            m.get("kind").is_none() || m["kind"] == "STATE",
            "before STATE: {m}"
        );
    }
    host.send(json!({ "state": true }));
    let nbirth = host.wait_for("NBIRTH", 20, |m| m["kind"] == "NBIRTH");
    let node = nbirth["node"].as_str().unwrap().to_owned();
    assert!(
        node.starts_with("gw-"),
        "a node ID from the MAC address: {node}"
    );
    let bd_seq = metric(&nbirth, "bdSeq").clone();
    let n = names(&nbirth);
    assert_eq!(n[0], ("bdSeq".into(), u64::MAX, 4), "bdSeq first, Int64");
    for (name, ty) in [
        ("Node Control/Rebirth", 11),
        ("Node Info/Firmware", 12),
        ("Node Info/Uptime ms", 8),
        ("Controller Line/Up", 11),
        ("Host Line/Host Connected", 11),
        ("Bridge/Forwarded", 7),
        ("Config/Policy", 5),
    ] {
        assert!(
            n.iter().any(|(m, _, t)| m == name && *t == ty),
            "{name} ({ty}) in NBIRTH"
        );
    }
    assert_eq!(metric(&nbirth, "Node Control/Rebirth"), false);
    let dbirth = host.wait_for("DBIRTH", 20, |m| m["kind"] == "DBIRTH");
    println!(
        "NBIRTH after STATE, DBIRTH {:.1} s after boot: {} node and {} device metrics",
        t0.elapsed().as_secs_f64(),
        n.len(),
        names(&dbirth).len()
    );
    let d = names(&dbirth);
    for axis in 1..=8 {
        for (what, ty) in [
            ("Position", 3),
            ("Status", 5),
            ("Status Bits", 6),
            ("Alarm", 6),
            ("Servo", 11),
        ] {
            let name = format!("Axis {axis}/{what}");
            assert!(
                d.iter().any(|(m, _, t)| *m == name && *t == ty),
                "{name} ({ty}) in DBIRTH"
            );
        }
    }
    for (name, ty) in [
        ("Error/Number", 6),
        ("Error/Detail 1", 7),
        ("Program/Status", 6),
        ("System/Mode", 6),
        ("Table/Window", 17),
        ("Table/Records Written", 7),
        ("Command/State", 12),
    ] {
        assert!(
            d.iter().any(|(m, _, t)| m == name && *t == ty),
            "{name} ({ty}) in DBIRTH"
        );
    }
    assert_eq!(host.device["Command/State"], "idle");

    // Commands: each done only once the controller confirmed it.
    let done = |seq: u64| {
        move |d: &HashMap<String, Value>| d["Command/Seq"] == seq && d["Command/State"] == "done"
    };
    host.dcmd(&node, "Axis 1/Servo", "Boolean", json!(true));
    host.wait_device("servo on done", 10, done(1));
    host.wait_device("servo on seen", 10, |d| d["Axis 1/Servo"] == true);
    host.dcmd(&node, "Axis 1/Home", "Boolean", json!(true));
    host.wait_device("home done", 10, done(2));
    // Homed and at rest (212H status: homing done, operation completed),
    // as a DDATA after the command says.
    let at_rest = |m: &Value| {
        m["kind"] == "DDATA"
            && m["metrics"].as_array().unwrap().iter().any(|x| {
                let s = x["value"].as_u64().unwrap_or(0);
                x["name"] == "Axis 1/Status" && (s >> 1) & 3 == 2 && s & 0x10 != 0
            })
    };
    host.wait_for("homed and at rest", 20, at_rest);
    assert_eq!(host.device["Axis 1/Home"], true);
    let before = host.seen("DDATA");
    // Protocol B while the node publishes the move (and a rebirth).
    let addr = gw.addr;
    let timing = std::thread::spawn(move || protocol_b_latencies(addr, 150));
    host.dcmd(&node, "Axis 1/Move To", "Int32", json!(200_000));
    host.send(json!({ "rebirth": node }));
    host.wait_device("move done", 10, done(3));
    host.wait_device("at 200 mm", 30, |d| d["Axis 1/Position"] == 200_000);
    let moving: Vec<i64> = host.log[before..]
        .iter()
        .filter(|m| m["kind"] == "DDATA")
        .filter_map(|m| m["metrics"].as_array())
        .flatten()
        .filter(|x| x["name"] == "Axis 1/Position")
        .filter_map(|x| x["value"].as_i64())
        .collect();
    assert!(
        moving.iter().filter(|p| (1..200_000).contains(*p)).count() >= 2,
        "DDATA while the axis moves: {moving:?}"
    );
    let mut times = timing.join().unwrap();
    times.sort();
    println!(
        "protocol-B 212H replies during the move with MQTT on: {} replies, median {:.1} ms, \
         99th {:.1} ms, worst {:.1} ms",
        times.len(),
        times[times.len() / 2].as_secs_f64() * 1e3,
        times[times.len() * 99 / 100].as_secs_f64() * 1e3,
        times[times.len() - 1].as_secs_f64() * 1e3
    );
    let out = Command::new(&iai)
        .args([
            "send",
            "212",
            "query_axis_pattern=1",
            "--tcp",
            &gw.addr.to_string(),
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    let pos: i64 = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("axes[0].current_position = "))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("iai send 212: {text}"));
    assert_eq!(
        json!(pos),
        host.device["Axis 1/Position"],
        "the last DDATA position is 212H's"
    );
    println!(
        "DDATA positions while moving: {} ({:?} ...)",
        moving.len(),
        &moving[..moving.len().min(4)]
    );

    // The table window as in the Modbus map: one record written (26DH,
    // read back), then the window read from its position (21FH).
    let mut record = [0u16; 21];
    record[..5].copy_from_slice(&[5, 0b1, 30, 30, 100]);
    record[5..7].copy_from_slice(&[0, 12_345]);
    let hex: String = record.iter().map(|w| format!("{w:04x}")).collect();
    host.dcmd(&node, "Table/Window", "Bytes", json!(hex));
    host.wait_device("the window written", 10, done(4));
    host.dcmd(&node, "Table/Window Head", "UInt16", json!(5));
    host.wait_device("the window read", 10, done(5));
    let window = host.device["Table/Window"]
        .as_str()
        .unwrap_or_default()
        .to_owned();
    assert_eq!(&window[..hex.len()], hex, "position 5 read back as written");

    // Rebirth on NCMD: the same aliases.
    let aliases = |m: &Value| {
        names(m)
            .into_iter()
            .map(|(n, a, _)| (n, a))
            .collect::<Vec<_>>()
    };
    let births = host.seen("NBIRTH");
    host.send(json!({ "rebirth": node }));
    let again = host.wait_for("NBIRTH after NCMD", 10, |m| m["kind"] == "NBIRTH");
    assert_eq!(host.seen("NBIRTH"), births + 1);
    assert_eq!(metric(&again, "bdSeq"), &bd_seq, "same session, same bdSeq");
    assert_eq!(aliases(&again), aliases(&nbirth));
    let dbirth2 = host.wait_for("DBIRTH after NCMD", 10, |m| m["kind"] == "DBIRTH");
    assert_eq!(aliases(&dbirth2), aliases(&dbirth));

    // The controller stops answering: DDEATH; answers again: DBIRTH.
    gw.set_controller_silent(true);
    let t = Instant::now();
    host.wait_for("DDEATH", 30, |m| m["kind"] == "DDEATH");
    println!(
        "DDEATH {:.1} s after the controller went silent",
        t.elapsed().as_secs_f64()
    );
    gw.set_controller_silent(false);
    let t = Instant::now();
    host.wait_for("DBIRTH again", 30, |m| m["kind"] == "DBIRTH");
    println!(
        "DBIRTH {:.1} s after it answered again",
        t.elapsed().as_secs_f64()
    );

    // QEMU killed: the broker delivers the Will, the last NBIRTH's bdSeq.
    let pid = gw.qemu.pid();
    let _ = Command::new("kill")
        .args(["-KILL", &pid.to_string()])
        .status();
    let ndeath = host.wait_for("NDEATH", 30, |m| m["kind"] == "NDEATH");
    assert_eq!(metric(&ndeath, "bdSeq"), &bd_seq);
    drop(gw);

    // Boot 2: the read-only policy; no primary host, so no STATE awaited.
    host.send(json!({ "state": false }));
    let gw = boot(&broker, false, Policy::ReadOnly, true);
    host.wait_for("NBIRTH, boot 2", 30, |m| m["kind"] == "NBIRTH");
    host.wait_for("DBIRTH, boot 2", 30, |m| m["kind"] == "DBIRTH");
    let servo = host.device["Axis 1/Servo"].clone();
    let flip = !servo.as_bool().unwrap();
    host.dcmd(&node, "Axis 1/Servo", "Boolean", json!(flip));
    host.wait_device("refused", 10, |d| d["Command/State"] == "refused");
    assert_eq!(host.device["Command/Code"], 0xB06);
    assert_eq!(host.device["Command/Message"], 0x232);
    // A second later the servo is as it was.
    let end = Instant::now() + Duration::from_secs(1);
    while let Ok(m) = host
        .lines
        .recv_timeout(end.saturating_duration_since(Instant::now()))
    {
        host.log.push(m);
    }
    let servo_now = host
        .log
        .iter()
        .rev()
        .filter(|m| m["kind"] == "DBIRTH" || m["kind"] == "DDATA")
        .filter_map(|m| m["metrics"].as_array())
        .flatten()
        .find(|x| x["name"] == "Axis 1/Servo")
        .map(|x| x["value"].clone());
    assert_eq!(
        servo_now,
        Some(servo),
        "nothing reached the controller:\n{}",
        host.tail()
    );
    // The broker restarts: the node connects again with bdSeq 1 and is
    // born again (the host, back later than the node, asks a rebirth).
    let t = Instant::now();
    broker.restart();
    let nbirth = host.wait_for("NBIRTH after the broker restarted", 60, |m| {
        m["kind"] == "NBIRTH"
    });
    assert_eq!(metric(&nbirth, "bdSeq"), 1);
    host.wait_for("DBIRTH after the broker restarted", 30, |m| {
        m["kind"] == "DBIRTH"
    });
    println!(
        "born again {:.1} s after the broker restarted",
        t.elapsed().as_secs_f64()
    );

    // The firmware's own end (the quit sequence): its stack peak after
    // a session of the edge node, for the size report.
    // The controller falls silent first: a reply on its way when QEMU
    // exits would end the simulator with a broken pipe.
    gw.set_controller_silent(true);
    std::thread::sleep(Duration::from_millis(100));
    let (out, _) = gw.quit(Duration::from_secs(10)).expect("the quit sequence");
    let peak = out
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("firmware-example: stack peak "))
        .and_then(|l| l.split_whitespace().next())
        .unwrap_or_else(|| panic!("no stack peak in:\n{}", out.stdout));
    println!("stack lm3s6965-eth {peak} (a Sparkplug session)");
}
