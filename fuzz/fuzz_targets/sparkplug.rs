//! The Sparkplug edge node's receive path on arbitrary broker behaviour:
//! the network side (`net::Net` with `net::sparkplug::EdgeNode` on its
//! socket, the Modbus gateway whose cache and handshake it reads and
//! commands) against a broker played by a second smoltcp interface, its
//! socket listening on 1883, joined by an in-memory wire.
//!
//! Input: a list of operations, each an op byte and its arguments:
//!
//! - `0`: the broker sends CONNACK (accepted); `1 c`: CONNACK with code `c`;
//! - `2`: SUBACK; `3`: STATE online (QoS 1); `4`: STATE offline;
//! - `5`: NCMD `Node Control/Rebirth` = true;
//! - `6 k`: DCMD with canned metric `k` (servo, home, a move, alarm reset,
//!   the window head, two window records, a metric by alias, an unknown
//!   name), in a payload of one metric;
//! - `7 n bytes..`: the broker sends up to `n` bytes of the input (broken
//!   packets, any of the above cut or joined);
//! - `8`: the broker resets the connection and listens again;
//! - `9 t`: `t` x 100 ms pass (keep-alive, backoff, DATA periods);
//! - `10`: the controller answers the gateway's polls (its cache fresh);
//! - anything else: one more round.
//!
//! After each operation the wire and both sides run for a few rounds, 1 ms
//! apart. Checked: no panic; what the node sends splits into whole MQTT
//! packets (a length the standard allows), each CONNECT, PUBLISH, PUBACK,
//! SUBSCRIBE, PINGREQ or DISCONNECT, CONNECT first on each connection,
//! every PUBLISH on a topic of `spBv1.0/`.
#![no_main]

#[path = "common/wire.rs"]
mod wire;

use firmware_example::bridge::Bridge;
use firmware_example::config::{Config, Policy, Source};
use firmware_example::modbus::Gateway;
use firmware_example::net::config::{Addressing, Ipv4Setting, NetConfig};
use firmware_example::net::modbus::ModbusBuffers;
use firmware_example::net::sparkplug::config::{text_of, SparkplugConfig};
use firmware_example::net::sparkplug::mqtt::{self, Writer};
use firmware_example::net::sparkplug::payload::{self, DataType, Value};
use firmware_example::net::sparkplug::SparkplugBuffers;
use firmware_example::net::{Buffers, Net, EMPTY_SLOTS};
use libfuzzer_sys::fuzz_target;
use smoltcp::iface::{Config as IfaceConfig, Interface, SocketSet, SocketStorage};
use smoltcp::socket::tcp;
use smoltcp::time::Instant;
use smoltcp::wire::{EthernetAddress, IpAddress, IpCidr};
use wire::Wire;

const BROKER_PORT: u16 = 1883;

/// One metric as a payload.
fn one_metric(name: Option<&str>, alias: Option<u16>, t: DataType, v: Value<'_>) -> Vec<u8> {
    let mut buf = vec![0u8; 512];
    let mut w = Writer::new(&mut buf);
    payload::header(&mut w, 1, None);
    match name {
        Some(n) => payload::metric(
            &mut w,
            Some(&|w: &mut Writer<'_>| w.put(n.as_bytes())),
            alias,
            t,
            v,
        ),
        None => payload::metric(&mut w, None, alias, t, v),
    }
    let n = w.len();
    buf.truncate(n);
    buf
}

/// A PUBLISH from the broker.
fn publication(topic: &str, qos: u8, body: &[u8]) -> Vec<u8> {
    let mut buf = vec![0u8; 1024];
    let mut w = Writer::new(&mut buf);
    mqtt::packet(&mut w, 0x30 | qos << 1, |w| {
        w.field(topic.as_bytes());
        if qos > 0 {
            w.u16(9);
        }
        w.put(body);
    });
    let n = w.len();
    buf.truncate(n);
    buf
}

/// Checks what the node sent on one connection, packet by packet.
fn check_stream(bytes: &[u8]) {
    let mut rest = bytes;
    let mut first = true;
    while !rest.is_empty() {
        let n = match mqtt::frame_len(rest) {
            Ok(Some(n)) => n,
            Ok(None) => return,
            Err(_) => panic!("a malformed length from the node: {rest:02X?}"),
        };
        let Some(p) = rest.get(..n) else { return };
        let kind = p[0] >> 4;
        assert!(
            matches!(kind, 1 | 3 | 4 | 8 | 12 | 14),
            "packet type {kind} from the node"
        );
        assert_eq!(first, kind == 1, "CONNECT first, and only first");
        if kind == 3 {
            match mqtt::parse(p) {
                Ok(mqtt::Packet::Publish { topic, .. }) => {
                    assert!(topic.starts_with("spBv1.0/"), "{topic}")
                }
                other => panic!("a PUBLISH that does not read back: {other:?}"),
            }
        }
        first = false;
        rest = &rest[n..];
    }
}

fuzz_target!(|data: &[u8]| {
    let group = "G";
    let node = "n1";
    let dcmd_topic = format!("spBv1.0/{group}/DCMD/{node}/controller");
    let window = {
        let mut words = Vec::new();
        for k in 0..2u16 {
            let mut rec = [0u16; 21];
            rec[0] = 10 + k;
            rec[1] = 1;
            rec[4] = 100;
            rec[6] = 500 * (k + 1);
            for w in rec {
                words.extend_from_slice(&w.to_be_bytes());
            }
        }
        words
    };
    let canned: Vec<Vec<u8>> = vec![
        one_metric(
            Some("Axis 1/Servo"),
            None,
            DataType::Boolean,
            Value::Bool(true),
        ),
        one_metric(
            Some("Axis 1/Home"),
            None,
            DataType::Boolean,
            Value::Bool(true),
        ),
        one_metric(
            Some("Axis 1/Move To"),
            None,
            DataType::Int32,
            Value::Int(25_500),
        ),
        one_metric(
            Some("Alarm Reset"),
            None,
            DataType::Boolean,
            Value::Bool(true),
        ),
        one_metric(
            Some("Table/Window Head"),
            None,
            DataType::UInt16,
            Value::Int(10),
        ),
        {
            let ws: Vec<u16> = window
                .chunks(2)
                .map(|c| u16::from_be_bytes([c[0], c[1]]))
                .collect();
            one_metric(
                Some("Table/Window"),
                None,
                DataType::Bytes,
                Value::Words(&ws),
            )
        },
        one_metric(None, Some(104), DataType::Boolean, Value::Bool(false)),
        one_metric(
            Some("Axis 9/Servo"),
            None,
            DataType::Boolean,
            Value::Bool(true),
        ),
    ];

    let net_cfg = NetConfig {
        addressing: Addressing::Static,
        port: 5020,
        address: Ipv4Setting {
            address: [10, 0, 0, 1],
            prefix: 24,
            gateway: None,
        },
    };
    let cfg = Config::DEFAULT;
    let mut now: u32 = 0;
    let mut node_wire = Wire::default();
    let mut slots = Box::new(EMPTY_SLOTS);
    let mut buffers = Box::new(Buffers::new());
    let mut modbus = Box::new(ModbusBuffers::new());
    let mut sp_buffers = Box::new(SparkplugBuffers::new());
    let mut net = Net::new(
        net_cfg,
        [0x02, 0, 0, 0, 0, 1],
        1,
        cfg.bridge_station,
        &mut node_wire,
        &mut slots,
        &mut buffers,
        now,
    );
    net.add_modbus(&mut modbus, 502);
    let sp = SparkplugConfig {
        enabled: true,
        commands: data.first().is_some_and(|b| b & 1 == 1),
        broker: [10, 0, 0, 2],
        port: BROKER_PORT,
        keep_alive_s: 5,
        group: text_of(group),
        node: text_of(node),
        primary_host: text_of("host"),
        ..SparkplugConfig::default()
    };
    net.add_sparkplug(sp, [0x02, 0, 0, 0, 0, 1], &mut sp_buffers, now);
    let mut bridge = Bridge::new(cfg, Source::Default, 1);
    let mut gateway = Box::new(Gateway::new(cfg.modbus, Policy::ForwardAll));

    let mut broker_wire = Wire::default();
    let mut iface = Interface::new(
        IfaceConfig::new(EthernetAddress([0x02, 0, 0, 0, 0, 2]).into()),
        &mut broker_wire,
        Instant::from_millis(0),
    );
    iface.update_ip_addrs(|a| {
        let _ = a.push(IpCidr::new(IpAddress::v4(10, 0, 0, 2), 24));
    });
    let mut storage: [SocketStorage<'_>; 1] = Default::default();
    let mut sockets = SocketSet::new(&mut storage[..]);
    let handle = sockets.add(tcp::Socket::new(
        tcp::SocketBuffer::new(vec![0u8; 2048]),
        tcp::SocketBuffer::new(vec![0u8; 2048]),
    ));
    sockets
        .get_mut::<tcp::Socket>(handle)
        .listen(BROKER_PORT)
        .unwrap();
    // What the node sent on each connection.
    let mut streams: Vec<Vec<u8>> = vec![Vec::new()];

    let mut round = |now: &mut u32,
                     net: &mut Net<'_>,
                     gateway: &mut Gateway,
                     iface: &mut Interface,
                     sockets: &mut SocketSet<'_>,
                     node_wire: &mut Wire,
                     broker_wire: &mut Wire,
                     streams: &mut Vec<Vec<u8>>| {
        *now = now.wrapping_add(1);
        let t = Instant::from_millis(i64::from(*now));
        iface.poll(t, broker_wire, sockets);
        node_wire.rx.extend(broker_wire.tx.drain(..));
        let _ = net.poll_with(node_wire, &mut bridge, Some(gateway), *now);
        broker_wire.rx.extend(node_wire.tx.drain(..));
        iface.poll(t, broker_wire, sockets);
        node_wire.rx.extend(broker_wire.tx.drain(..));
        let s = sockets.get_mut::<tcp::Socket>(handle);
        while s.can_recv() {
            let _ = s.recv(|b| {
                if let Some(cur) = streams.last_mut() {
                    cur.extend_from_slice(b);
                }
                (b.len(), ())
            });
        }
    };

    let mut ops = data.get(1..).unwrap_or(&[]).iter().copied();
    let mut input_at = 0usize;
    while let Some(op) = ops.next() {
        input_at += 1;
        let send = |sockets: &mut SocketSet<'_>, bytes: &[u8]| {
            let _ = sockets.get_mut::<tcp::Socket>(handle).send_slice(bytes);
        };
        match op {
            0 => send(&mut sockets, &[0x20, 2, 0, 0]),
            1 => {
                let c = ops.next().unwrap_or(5);
                send(&mut sockets, &[0x20, 2, 0, c]);
            }
            2 => send(&mut sockets, &[0x90, 5, 0, 1, 1, 1, 1]),
            3 => send(
                &mut sockets,
                &publication("spBv1.0/STATE/host", 1, br#"{"online":true,"timestamp":1}"#),
            ),
            4 => send(
                &mut sockets,
                &publication(
                    "spBv1.0/STATE/host",
                    1,
                    br#"{"online":false,"timestamp":2}"#,
                ),
            ),
            5 => {
                let m = one_metric(
                    Some("Node Control/Rebirth"),
                    None,
                    DataType::Boolean,
                    Value::Bool(true),
                );
                send(
                    &mut sockets,
                    &publication(&format!("spBv1.0/{group}/NCMD/{node}"), 0, &m),
                );
            }
            6 => {
                let k = usize::from(ops.next().unwrap_or(0)) % canned.len();
                send(&mut sockets, &publication(&dcmd_topic, 0, &canned[k]));
            }
            7 => {
                let n = usize::from(ops.next().unwrap_or(0));
                let bytes: Vec<u8> = ops.by_ref().take(n).collect();
                send(&mut sockets, &bytes);
            }
            8 => {
                let s = sockets.get_mut::<tcp::Socket>(handle);
                s.abort();
                let _ = s.listen(BROKER_PORT);
                streams.push(Vec::new());
            }
            9 => {
                let t = u32::from(ops.next().unwrap_or(1)) * 100;
                for _ in 0..t / 10 {
                    now = now.wrapping_add(9);
                    round(
                        &mut now,
                        &mut net,
                        &mut gateway,
                        &mut iface,
                        &mut sockets,
                        &mut node_wire,
                        &mut broker_wire,
                        &mut streams,
                    );
                }
            }
            10 => {
                let c = &mut gateway.regs.cache;
                c.link_up = true;
                c.axes[0].current_position = input_at as i32 * 1_000;
                c.axes_at.set(now);
            }
            _ => {}
        }
        for _ in 0..4 {
            round(
                &mut now,
                &mut net,
                &mut gateway,
                &mut iface,
                &mut sockets,
                &mut node_wire,
                &mut broker_wire,
                &mut streams,
            );
        }
        // A new connection of the node after the broker's socket closed.
        let s = sockets.get_mut::<tcp::Socket>(handle);
        if !s.is_open() {
            let _ = s.listen(BROKER_PORT);
            streams.push(Vec::new());
        }
    }
    for s in &streams {
        check_stream(s);
    }
});
