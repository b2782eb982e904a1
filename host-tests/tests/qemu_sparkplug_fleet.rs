//! A plant's fleet on one broker: three Ethernet gateways under QEMU, each
//! with its own simulated controller, edge nodes `robot-1` to `robot-3` of
//! one group on one Mosquitto, watched by the Python Sparkplug host
//! (`sparkplug_kit`). Each is born, its axis 1 is put in service and
//! moved 200 mm by DCMD; the messages and payload bytes each node
//! published are counted over a window of motion and one of rest, and
//! printed per node and second (figures, not assertions on time).

mod sparkplug_kit;

use std::time::{Duration, Instant};

use firmware_example::net::sparkplug::config::{text_of, SparkplugConfig};
use host_tests::gateway::{EthernetGateway, Options, QEMU_HOST};
use serde_json::{json, Value};
use sparkplug_kit::{Broker, Host, GROUP};

const NODES: [&str; 3] = ["robot-1", "robot-2", "robot-3"];

/// Messages and payload bytes per node in `log` (from `from` on), per
/// second of `secs`.
fn rates(log: &[Value], secs: f64) -> Vec<(f64, f64)> {
    NODES
        .iter()
        .map(|n| {
            let mine: Vec<&Value> = log.iter().filter(|m| m["node"] == *n).collect();
            let bytes: u64 = mine.iter().filter_map(|m| m["bytes"].as_u64()).sum();
            (mine.len() as f64 / secs, bytes as f64 / secs)
        })
        .collect()
}

#[test]
fn three_gateways_on_one_broker() {
    let broker = Broker::start();
    let mut host = Host::start(broker.port);
    let t = Instant::now();
    let gateways: Vec<EthernetGateway> = NODES
        .iter()
        .map(|node| {
            let opts = Options {
                ethernet: true,
                sparkplug: Some(SparkplugConfig {
                    enabled: true,
                    commands: true,
                    broker: QEMU_HOST,
                    port: broker.port,
                    group: text_of(GROUP),
                    node: text_of(node),
                    username: text_of("gw"),
                    password: text_of("gw-secret"),
                    ..SparkplugConfig::default()
                }),
                ..Options::default()
            };
            EthernetGateway::start(&opts).expect("a gateway")
        })
        .collect();
    for _ in 0..NODES.len() {
        host.wait_for("the births", 60, |m| m["kind"] == "DBIRTH");
    }
    for n in NODES {
        assert!(
            host.log
                .iter()
                .any(|m| m["kind"] == "NBIRTH" && m["node"] == n),
            "{n} born"
        );
        assert!(
            host.log
                .iter()
                .any(|m| m["kind"] == "DBIRTH" && m["node"] == n),
            "{n}'s controller"
        );
    }
    println!(
        "three gateways up and born in {:.1} s",
        t.elapsed().as_secs_f64()
    );

    for n in NODES {
        host.dcmd(n, "Axis 1/Servo", "Boolean", json!(true));
    }
    host.collect(Duration::from_secs(1));
    for n in NODES {
        host.dcmd(n, "Axis 1/Home", "Boolean", json!(true));
    }
    host.collect(Duration::from_secs(3));
    let from = host.log.len();
    for n in NODES {
        host.dcmd(n, "Axis 1/Move To", "Int32", json!(200_000));
    }
    host.collect(Duration::from_secs(5));
    let moving = rates(&host.log[from..], 5.0);
    for n in NODES {
        let last = host
            .log
            .iter()
            .rev()
            .filter(|m| m["node"] == n && (m["kind"] == "DDATA" || m["kind"] == "DBIRTH"))
            .filter_map(|m| m["metrics"].as_array())
            .flatten()
            .find(|x| x["name"] == "Axis 1/Position")
            .map(|x| x["value"].clone());
        // Within the default deadband (0.010 mm) of the target.
        let last = last.and_then(|v| v.as_i64());
        assert!(
            last.is_some_and(|p| (p - 200_000).abs() < 10),
            "{n}'s axis 1 at 200 mm: {last:?}"
        );
    }
    let from = host.log.len();
    host.collect(Duration::from_secs(20));
    let resting = rates(&host.log[from..], 20.0);
    for (i, n) in NODES.iter().enumerate() {
        println!(
            "fleet {n}: a 5 s window with a 200 mm move (2 s at 100 mm/s) {:.1} messages/s {:.0} payload bytes/s; \
             at rest (20 s) {:.2} messages/s {:.0} payload bytes/s",
            moving[i].0, moving[i].1, resting[i].0, resting[i].1
        );
    }
    drop(gateways);
}
