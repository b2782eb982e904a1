//! The edge node in the host model: a broker played by a client socket
//! of the rig (`testkit`), the packets read with [`super::mqtt`] and the
//! payloads with [`super::payload`], in simulated milliseconds.

extern crate std;
use std::string::String;
use std::vec::Vec;

use super::config::{text_of, SparkplugConfig};
use super::mqtt::{self, Packet, Writer};
use super::payload::{self, MetricIn, Received};
use super::{metrics, BACKOFF_MIN_MS, OUT_BUFFER};
use crate::net::config::Addressing;
use crate::net::testkit::{net_config, Rig, CLIENT_IP};

const BROKER_PORT: u16 = 1883;

fn config() -> SparkplugConfig {
    SparkplugConfig {
        enabled: true,
        broker: CLIENT_IP,
        port: BROKER_PORT,
        group: text_of("Plant"),
        node: text_of("gw1"),
        primary_host: text_of("scada"),
        deadband: 100,
        ..SparkplugConfig::default()
    }
}

/// A received packet, owned.
#[derive(Debug, Clone, PartialEq)]
enum Got {
    Connect(Vec<u8>),
    Subscribe(Vec<String>),
    Publish(String, Vec<u8>),
    PubAck(u16),
    Ping,
    Disconnect,
}

/// The broker's side: bytes from the node, cut into packets.
struct Broker {
    pending: Vec<u8>,
    /// Packets taken and not yet looked at.
    ready: Vec<Got>,
}

impl Broker {
    fn take(&mut self, rig: &mut Rig<'static>) -> Vec<Got> {
        self.pending.extend(rig.received(0));
        let mut out = Vec::new();
        while let Ok(Some(n)) = mqtt::frame_len(&self.pending) {
            if n > self.pending.len() {
                break;
            }
            let p: Vec<u8> = self.pending.drain(..n).collect();
            let body_at = 2 + p[1..].iter().position(|b| b & 0x80 == 0).unwrap();
            let body = &p[body_at..];
            out.push(match p[0] >> 4 {
                1 => Got::Connect(body.to_vec()),
                8 => {
                    let mut topics = Vec::new();
                    let mut rest = &body[2..];
                    while rest.len() > 2 {
                        let n = usize::from(u16::from_be_bytes([rest[0], rest[1]]));
                        topics.push(String::from_utf8(rest[2..2 + n].to_vec()).unwrap());
                        rest = &rest[3 + n..];
                    }
                    Got::Subscribe(topics)
                }
                3 => match mqtt::parse(&p).unwrap() {
                    Packet::Publish { topic, payload, .. } => {
                        Got::Publish(topic.into(), payload.to_vec())
                    }
                    other => panic!("{other:?}"),
                },
                4 => Got::PubAck(u16::from_be_bytes([body[0], body[1]])),
                12 => Got::Ping,
                14 => Got::Disconnect,
                t => panic!("packet type {t}"),
            });
        }
        out
    }

    fn send(rig: &mut Rig<'static>, f: impl FnOnce(&mut Writer<'_>)) {
        let mut buf = [0u8; 600];
        let mut w = Writer::new(&mut buf);
        f(&mut w);
        assert!(!w.overflowed());
        rig.client(0).send_slice(w.written()).unwrap();
    }

    /// Runs until the node has sent a packet, at most `ms`.
    fn next(&mut self, rig: &mut Rig<'static>, ms: u32) -> Got {
        if self.ready.is_empty() {
            let mut got = Vec::new();
            rig.run_until(ms, 1, |r| {
                got = self.take(r);
                !got.is_empty()
            });
            self.ready = got;
        }
        assert!(
            !self.ready.is_empty(),
            "nothing from the node within {ms} ms"
        );
        self.ready.remove(0)
    }
}

fn metrics_of(payload: &[u8]) -> Vec<MetricIn<'_>> {
    let all: Vec<_> = payload::metrics(payload).collect();
    if let Some(bad) = all.iter().position(Result::is_err) {
        panic!(
            "metric {bad} broken after {:?}\n{payload:02X?}",
            all.get(bad.wrapping_sub(1))
        );
    }
    all.into_iter().map(Result::unwrap).collect()
}

fn publish_to(rig: &mut Rig<'static>, topic: &str, qos: u8, body: impl FnOnce(&mut Writer<'_>)) {
    Broker::send(rig, |w| {
        mqtt::packet(w, 0x30 | qos << 1, |w| {
            w.field(topic.as_bytes());
            if qos > 0 {
                w.u16(7);
            }
            body(w);
        })
    });
}

#[test]
fn no_birth_before_the_primary_host_is_online_then_births_data_commands_ndeath_when_it_leaves_and_new_sessions(
) {
    let mut rig = Rig::new(net_config(Addressing::Static));
    rig.add_sparkplug(config());
    rig.client(0).listen(BROKER_PORT).unwrap();
    let mut broker = Broker {
        pending: Vec::new(),
        ready: Vec::new(),
    };
    // CONNECT: clean session, Will QoS 1 on NDEATH with bdSeq 0.
    let Got::Connect(c) = broker.next(&mut rig, 3_000) else {
        panic!()
    };
    assert_eq!(c[7], 0b0000_1110, "clean session, Will, Will QoS 1");
    let will_topic = b"spBv1.0/Plant/NDEATH/gw1";
    let at = 10 + 2 + 3 + 2;
    assert_eq!(&c[at..at + will_topic.len()], will_topic);
    let will = &c[at + will_topic.len() + 2..];
    let bd = metrics_of(will);
    assert_eq!(bd[0].name, Some("bdSeq"));
    assert_eq!(bd[0].value, Received::Int(0));

    Broker::send(&mut rig, |w| w.put(&[0x20, 2, 0, 0]));
    let Got::Subscribe(topics) = broker.next(&mut rig, 1_000) else {
        panic!()
    };
    assert_eq!(
        topics,
        [
            "spBv1.0/Plant/NCMD/gw1",
            "spBv1.0/Plant/DCMD/gw1/controller",
            "spBv1.0/STATE/scada"
        ]
    );
    // No BIRTH while the primary host is not online.
    rig.run(2_000, 5);
    assert_eq!(broker.take(&mut rig), []);
    publish_to(&mut rig, "spBv1.0/STATE/scada", 1, |w| {
        w.put(br#"{"online" : true, "timestamp": 1700000000000}"#)
    });
    assert_eq!(broker.next(&mut rig, 500), Got::PubAck(7));
    let Got::Publish(topic, nbirth) = broker.next(&mut rig, 500) else {
        panic!()
    };
    assert_eq!(topic, "spBv1.0/Plant/NBIRTH/gw1");
    let m = metrics_of(&nbirth);
    assert_eq!((m[0].name, m[0].value), (Some("bdSeq"), Received::Int(0)));
    assert_eq!(m[1].name, Some("Node Control/Rebirth"));
    assert_eq!(m[1].alias, Some(1));
    assert_eq!(m.len(), 1 + metrics::NODE.len());
    // seq 0, and a timestamp from the host's clock.
    assert_eq!(&nbirth[..1], [0x08]);
    assert!(nbirth.windows(2).any(|w| w == [0x18, 0]));

    // The controller answers the gateway's polls: DBIRTH.
    let now = rig.now;
    let cache = &mut rig.gateway.regs.cache;
    cache.link_up = true;
    cache.axes[0].current_position = 25_500;
    cache.axes_at.set(now);
    let Got::Publish(topic, dbirth) = broker.next(&mut rig, 500) else {
        panic!()
    };
    assert_eq!(topic, "spBv1.0/Plant/DBIRTH/gw1/controller");
    let d = metrics_of(&dbirth);
    assert_eq!(d.len(), metrics::device_count(8));
    assert_eq!(d[0].name, Some("Axis 1/Position"));
    assert_eq!((d[0].alias, d[0].value), (Some(100), Received::Int(25_500)));
    std::println!(
        "DBIRTH of 8 axes: {} bytes of payload ({} metrics), out buffer {OUT_BUFFER}",
        dbirth.len(),
        d.len()
    );

    // A move within the deadband (100) is not news; past it, DDATA with
    // that one metric, by alias only.
    let keep_fresh = |r: &mut Rig<'static>| {
        let now = r.now;
        r.gateway.regs.cache.axes_at.set(now);
    };
    rig.gateway.regs.cache.axes[0].current_position = 25_550;
    keep_fresh(&mut rig);
    rig.run(300, 5);
    assert_eq!(broker.take(&mut rig), []);
    rig.gateway.regs.cache.axes[0].current_position = 25_700;
    keep_fresh(&mut rig);
    let Got::Publish(topic, ddata) = broker.next(&mut rig, 500) else {
        panic!()
    };
    assert_eq!(topic, "spBv1.0/Plant/DDATA/gw1/controller");
    let m = metrics_of(&ddata);
    assert_eq!(m.len(), 1);
    assert_eq!((m[0].name, m[0].alias), (None, Some(100)));
    assert_eq!(m[0].value, Received::Int(25_700));

    // DCMD servo on with commands off in the block: refused, published.
    publish_to(&mut rig, "spBv1.0/Plant/DCMD/gw1/controller", 0, |w| {
        payload::metric(
            w,
            Some(&|w: &mut Writer<'_>| w.put(b"Axis 1/Servo")),
            None,
            payload::DataType::Boolean,
            payload::Value::Bool(true),
        )
    });
    keep_fresh(&mut rig);
    let Got::Publish(_, ddata) = broker.next(&mut rig, 500) else {
        panic!()
    };
    let m = metrics_of(&ddata);
    assert!(
        m.iter().any(|m| m.value == Received::Str("refused")),
        "{m:?}"
    );
    assert!(!rig.gateway.regs.hs.busy(), "nothing queued");

    // NCMD rebirth: NBIRTH again with bdSeq 0 and the same aliases.
    publish_to(&mut rig, "spBv1.0/Plant/NCMD/gw1", 0, |w| {
        payload::metric(
            w,
            Some(&|w: &mut Writer<'_>| w.put(b"Node Control/Rebirth")),
            None,
            payload::DataType::Boolean,
            payload::Value::Bool(true),
        )
    });
    let Got::Publish(topic, again) = broker.next(&mut rig, 500) else {
        panic!()
    };
    assert_eq!(topic, "spBv1.0/Plant/NBIRTH/gw1");
    assert_eq!(metrics_of(&again).len(), metrics_of(&nbirth).len());
    keep_fresh(&mut rig);
    let Got::Publish(topic, dbirth2) = broker.next(&mut rig, 500) else {
        panic!()
    };
    assert_eq!(topic, "spBv1.0/Plant/DBIRTH/gw1/controller");
    let aliases = |p: &[u8]| -> Vec<_> { metrics_of(p).iter().map(|m| m.alias).collect() };
    assert_eq!(aliases(&dbirth2), aliases(&dbirth));

    // The primary host goes offline: NDEATH (bdSeq 0) and DISCONNECT,
    // then a new session whose Will has bdSeq 1.
    publish_to(&mut rig, "spBv1.0/STATE/scada", 1, |w| {
        w.put(br#"{"online":false,"timestamp":1700000001000}"#)
    });
    assert_eq!(broker.next(&mut rig, 500), Got::PubAck(7));
    let Got::Publish(topic, ndeath) = broker.next(&mut rig, 500) else {
        panic!()
    };
    assert_eq!(topic, "spBv1.0/Plant/NDEATH/gw1");
    assert_eq!(metrics_of(&ndeath)[0].value, Received::Int(0));
    assert_eq!(broker.next(&mut rig, 500), Got::Disconnect);
    rig.client(0).close();
    assert!(
        rig.run_until(1_000, 1, |r| !r.client(0).is_open()),
        "the node closes"
    );
    rig.client(0).listen(BROKER_PORT).unwrap();
    broker.pending.clear();
    let Got::Connect(c) = broker.next(&mut rig, BACKOFF_MIN_MS + 3_000) else {
        panic!()
    };
    let will = &c[at + will_topic.len() + 2..];
    assert_eq!(metrics_of(will)[0].value, Received::Int(1));
    Broker::send(&mut rig, |w| w.put(&[0x20, 2, 0, 0]));
    assert!(matches!(broker.next(&mut rig, 500), Got::Subscribe(_)));

    // The broker vanishes (a reset): a new session after the backoff,
    // its Will with bdSeq 2.
    rig.client(0).abort();
    rig.run(5, 1);
    rig.client(0).listen(BROKER_PORT).unwrap();
    broker.pending.clear();
    let Got::Connect(c) = broker.next(&mut rig, BACKOFF_MIN_MS + 3_000) else {
        panic!()
    };
    let will = &c[at + will_topic.len() + 2..];
    assert_eq!(metrics_of(will)[0].value, Received::Int(2));
    let s = rig.net.sparkplug().unwrap().stats();
    assert_eq!((s.sessions, s.births, s.refusals), (2, 2, 1));
}

/// The broker's side of the model: answers CONNECT, SUBSCRIBE and
/// PINGREQ, counts the PUBLISH packets and every byte the node sent.
#[derive(Default)]
struct BrokerModel {
    pending: Vec<u8>,
    publishes: u64,
    bytes: u64,
}

impl BrokerModel {
    fn serve(&mut self, rig: &mut Rig<'static>) {
        let got = rig.received(0);
        self.bytes += got.len() as u64;
        self.pending.extend(got);
        while let Ok(Some(n)) = mqtt::frame_len(&self.pending) {
            if n > self.pending.len() {
                break;
            }
            let p: Vec<u8> = self.pending.drain(..n).collect();
            let body_at = 2 + p[1..].iter().position(|b| b & 0x80 == 0).unwrap();
            let answer: &[u8] = match p[0] >> 4 {
                1 => &[0x20, 2, 0, 0],
                8 => &[0x90, 4, p[body_at], p[body_at + 1], 1, 1],
                12 => &[0xD0, 0],
                3 => {
                    self.publishes += 1;
                    &[]
                }
                _ => &[],
            };
            if !answer.is_empty() {
                rig.client(0).send_slice(answer).unwrap();
            }
        }
    }
}

/// Axis 1 of a controller in the model: 200 mm out at 100 mm/s, 2 s at
/// rest, back, 2 s at rest (an 8 s cycle), from `phase` ms on.
fn profile(t: u32, phase: u32) -> i32 {
    let c = (t + phase) % 8_000;
    match c {
        0..2_000 => (c * 100) as i32,
        2_000..4_000 => 200_000,
        4_000..6_000 => 200_000 - ((c - 4_000) * 100) as i32,
        _ => 0,
    }
}

#[test]
fn a_fleet_of_200_nodes_in_the_host_model_prints_its_load() {
    // `IAI_FLEET_NODES` and `IAI_FLEET_SECONDS` change the run's size.
    let env = |k: &str, d: u32| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let nodes = env("IAI_FLEET_NODES", 200);
    let secs = env("IAI_FLEET_SECONDS", 24);
    let step = 5;
    let poll = crate::config::ModbusConfig::DEFAULT.poll_period_ms as u32;
    let wall = std::time::Instant::now();
    let mut per_node = Vec::new();
    for n in 0..nodes {
        let mut rig = Rig::new(net_config(Addressing::Static));
        let mut cfg = config();
        cfg.primary_host = text_of("");
        cfg.deadband = SparkplugConfig::default().deadband;
        rig.add_sparkplug(cfg);
        rig.client(0).listen(BROKER_PORT).unwrap();
        let mut broker = BrokerModel::default();
        let phase = n * 8_000 / nodes.max(1);
        let mut next_poll = 0;
        while rig.now < secs * 1_000 {
            if rig.now >= next_poll {
                // The gateway's poll round: the controller answers.
                let now = rig.now;
                let c = &mut rig.gateway.regs.cache;
                c.link_up = true;
                c.polls_ok = c.polls_ok.wrapping_add(8);
                c.axes[0].current_position = profile(now, phase);
                c.axes_at.set(now);
                next_poll += poll;
            }
            rig.run(step, step);
            broker.serve(&mut rig);
            if !rig.client(0).is_open() {
                rig.client(0).listen(BROKER_PORT).unwrap();
            }
        }
        let s = rig.net.sparkplug().unwrap().stats();
        assert_eq!(s.sessions, 1, "node {n}: one session throughout");
        per_node.push((
            broker.publishes as f64 / secs as f64,
            broker.bytes as f64 / secs as f64,
        ));
    }
    let mean =
        |f: fn(&(f64, f64)) -> f64| per_node.iter().map(f).sum::<f64>() / per_node.len() as f64;
    let max = |f: fn(&(f64, f64)) -> f64| per_node.iter().map(f).fold(0.0, f64::max);
    let (m, b) = (mean(|p| p.0), mean(|p| p.1));
    std::println!(
        "fleet model: {nodes} nodes, {secs} s, polling every {poll} ms, axis 1 of each moving half \
         the time at 100 mm/s: per node {m:.2} messages/s ({:.2} at most) and {b:.0} bytes/s \
         ({:.0} at most) of MQTT; the fleet {:.0} messages/s, {:.1} kB/s into the broker \
         (run took {:.1} s)",
        max(|p| p.0),
        max(|p| p.1),
        m * nodes as f64,
        b * nodes as f64 / 1e3,
        wall.elapsed().as_secs_f64()
    );
}

#[test]
fn a_refused_connect_is_tried_again_after_a_backoff_with_the_same_bd_seq() {
    let mut rig = Rig::new(net_config(Addressing::Static));
    let mut cfg = config();
    cfg.username = text_of("gw");
    cfg.password = text_of("wrong");
    rig.add_sparkplug(cfg);
    rig.client(0).listen(BROKER_PORT).unwrap();
    let mut broker = Broker {
        pending: Vec::new(),
        ready: Vec::new(),
    };
    let mut attempts = Vec::new();
    for _ in 0..3 {
        let Got::Connect(c) = broker.next(&mut rig, 40_000) else {
            panic!()
        };
        attempts.push(rig.now);
        // Return code 4: bad user name or password.
        Broker::send(&mut rig, |w| w.put(&[0x20, 2, 0, 4]));
        let will_at = 10 + 2 + 3 + 2 + "spBv1.0/Plant/NDEATH/gw1".len() + 2;
        let will_len = usize::from(u16::from_be_bytes([c[will_at - 2], c[will_at - 1]]));
        let will = &c[will_at..will_at + will_len];
        assert_eq!(
            metrics_of(will)[0].value,
            Received::Int(0),
            "no session, no new bdSeq"
        );
        assert!(rig.run_until(2_000, 1, |r| !r.client(0).is_open()));
        rig.client(0).listen(BROKER_PORT).unwrap();
        broker.pending.clear();
    }
    let gaps: Vec<u32> = attempts.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(
        gaps[0] >= BACKOFF_MIN_MS && gaps[1] >= 2 * BACKOFF_MIN_MS,
        "{gaps:?}"
    );
    let s = rig.net.sparkplug().unwrap().stats();
    assert_eq!((s.sessions, s.refused, s.births), (0, 3, 0));
}

#[test]
fn a_broker_that_closes_ends_the_session_and_the_next_one_counts_seq_from_nbirth() {
    let mut rig = Rig::new(net_config(Addressing::Static));
    let mut cfg = config();
    cfg.primary_host = text_of("");
    rig.add_sparkplug(cfg);
    rig.client(0).listen(BROKER_PORT).unwrap();
    let mut broker = Broker {
        pending: Vec::new(),
        ready: Vec::new(),
    };
    for session in 0..2u8 {
        let Got::Connect(_) = broker.next(&mut rig, 40_000) else {
            panic!()
        };
        Broker::send(&mut rig, |w| w.put(&[0x20, 2, 0, 0]));
        // 4 s of a controller whose axis 1 moves: every message's seq is
        // the one before's plus one, from NBIRTH's 0.
        let mut seqs = Vec::new();
        let mut kinds = Vec::new();
        for _ in 0..80 {
            let now = rig.now;
            let c = &mut rig.gateway.regs.cache;
            c.link_up = true;
            c.axes_at.set(now);
            c.axes[0].current_position = 10 * now as i32;
            rig.run(50, 5);
            for g in broker.take(&mut rig) {
                if let Got::Publish(t, p) = g {
                    assert_eq!(&p[..1], [0x08], "timestamp first");
                    let (_, rest) =
                        p[1..].split_at(p[1..].iter().position(|b| b & 0x80 == 0).unwrap() + 1);
                    assert_eq!(rest[0], 0x18, "then seq");
                    seqs.push(rest[1]);
                    kinds.push(String::from(t.split('/').nth(2).unwrap()));
                }
            }
        }
        assert_eq!(&kinds[..2], ["NBIRTH", "DBIRTH"], "session {session}");
        assert!(kinds.iter().filter(|k| *k == "DDATA").count() >= 30);
        let expected: Vec<u8> = (0..seqs.len() as u8).collect();
        assert_eq!(seqs, expected, "session {session}");
        // The broker closes its side (a FIN): the session is over.
        rig.client(0).close();
        assert!(rig.run_until(3_000, 5, |r| !r.client(0).is_open()));
        rig.client(0).listen(BROKER_PORT).unwrap();
        broker.pending.clear();
        broker.ready.clear();
    }
    let s = rig.net.sparkplug().unwrap().stats();
    assert_eq!((s.sessions, s.births), (2, 2));
}
