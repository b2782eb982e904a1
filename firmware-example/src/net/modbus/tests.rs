//! The Modbus TCP sockets against a second smoltcp interface over an
//! in-memory wire, in simulated time: four clients answered in order, the
//! fifth connection reset, the idle close, a bad length.

extern crate std;
use std::collections::VecDeque;
use std::vec;
use std::vec::Vec;

use smoltcp::iface::{Config as IfaceConfig, Interface, SocketHandle, SocketSet, SocketStorage};
use smoltcp::phy::{Device, DeviceCapabilities, Medium, RxToken, TxToken};
use smoltcp::socket::tcp;
use smoltcp::time::Instant;
use smoltcp::wire::{EthernetAddress, IpAddress, IpCidr};

use super::*;
use crate::bridge::Bridge;
use crate::config::{Config, Policy, Source};
use crate::net::config::{Addressing, Ipv4Setting, NetConfig};
use crate::net::{Buffers, Net, EMPTY_SLOTS};

/// One end of the wire: frames in, frames out.
#[derive(Default)]
struct Wire {
    rx: VecDeque<Vec<u8>>,
    tx: VecDeque<Vec<u8>>,
}

struct Rx(Vec<u8>);
struct Tx<'a>(&'a mut VecDeque<Vec<u8>>);

impl RxToken for Rx {
    fn consume<R, F: FnOnce(&[u8]) -> R>(self, f: F) -> R {
        f(&self.0)
    }
}

impl TxToken for Tx<'_> {
    fn consume<R, F: FnOnce(&mut [u8]) -> R>(self, len: usize, f: F) -> R {
        let mut frame = vec![0u8; len];
        let r = f(&mut frame);
        self.0.push_back(frame);
        r
    }
}

impl Device for Wire {
    type RxToken<'a> = Rx;
    type TxToken<'a> = Tx<'a>;

    fn receive(&mut self, _: Instant) -> Option<(Rx, Tx<'_>)> {
        let frame = self.rx.pop_front()?;
        Some((Rx(frame), Tx(&mut self.tx)))
    }

    fn transmit(&mut self, _: Instant) -> Option<Tx<'_>> {
        Some(Tx(&mut self.tx))
    }

    fn capabilities(&self) -> DeviceCapabilities {
        let mut caps = DeviceCapabilities::default();
        caps.medium = Medium::Ethernet;
        caps.max_transmission_unit = 1514;
        caps
    }
}

/// Client sockets: one more than the firmware serves at once.
const CLIENT_SOCKETS: usize = CLIENTS + 1;

/// The clients' side: an interface at 10.0.0.2 and [`CLIENT_SOCKETS`]
/// sockets.
struct Clients<'a> {
    wire: Wire,
    iface: Interface,
    sockets: SocketSet<'a>,
    handles: Vec<SocketHandle>,
}

/// `(bridge, gateway, net, its wire)` and the clients, stepped together.
struct Rig<'a> {
    now: u32,
    bridge: Bridge,
    gateway: Gateway,
    net: Net<'a>,
    wire: Wire,
    clients: Clients<'a>,
}

impl<'a> Rig<'a> {
    /// `ms` milliseconds, a round per `step` ms.
    fn run(&mut self, ms: u32, step: u32) {
        let end = self.now + ms;
        while self.now < end {
            self.now += step;
            let t = Instant::from_millis(i64::from(self.now));
            let c = &mut self.clients;
            c.iface.poll(t, &mut c.wire, &mut c.sockets);
            self.wire.rx.extend(c.wire.tx.drain(..));
            let gw = Some(&mut self.gateway);
            let _ = self
                .net
                .poll_with(&mut self.wire, &mut self.bridge, gw, self.now);
            c.wire.rx.extend(self.wire.tx.drain(..));
            c.iface.poll(t, &mut c.wire, &mut c.sockets);
            self.wire.rx.extend(c.wire.tx.drain(..));
        }
    }

    fn client(&mut self, n: usize) -> &mut tcp::Socket<'a> {
        let h = self.clients.handles[n];
        self.clients.sockets.get_mut::<tcp::Socket<'a>>(h)
    }

    fn connect(&mut self, n: usize, local_port: u16) {
        let c = &mut self.clients;
        let h = c.handles[n];
        let s = c.sockets.get_mut::<tcp::Socket>(h);
        s.connect(
            c.iface.context(),
            (IpAddress::v4(10, 0, 0, 1), MODBUS_PORT),
            local_port,
        )
        .unwrap();
    }

    fn received(&mut self, n: usize) -> Vec<u8> {
        let s = self.client(n);
        let mut out = Vec::new();
        while s.can_recv() {
            s.recv(|b| (b.len(), out.extend_from_slice(b))).unwrap();
        }
        out
    }
}

fn leak(n: usize) -> &'static mut [u8] {
    std::boxed::Box::leak(vec![0u8; n].into_boxed_slice())
}

fn rig(slots: &'static mut crate::net::SocketSlots<'static>) -> Rig<'static> {
    let buffers = std::boxed::Box::leak(std::boxed::Box::new(Buffers::new()));
    let modbus = std::boxed::Box::leak(std::boxed::Box::new(ModbusBuffers::new()));
    let cfg = NetConfig {
        addressing: Addressing::Static,
        port: 5020,
        address: Ipv4Setting {
            address: [10, 0, 0, 1],
            prefix: 24,
            gateway: None,
        },
    };
    let mut wire = Wire::default();
    let bridge_cfg = Config::DEFAULT;
    let mut net = Net::new(
        cfg,
        [0x02, 0, 0, 0, 0, 1],
        1,
        bridge_cfg.bridge_station,
        &mut wire,
        slots,
        buffers,
        0,
    );
    net.add_modbus(modbus, MODBUS_PORT);
    let mut cwire = Wire::default();
    let mut iface = Interface::new(
        IfaceConfig::new(EthernetAddress([0x02, 0, 0, 0, 0, 2]).into()),
        &mut cwire,
        Instant::from_millis(0),
    );
    iface.update_ip_addrs(|a| {
        let _ = a.push(IpCidr::new(IpAddress::v4(10, 0, 0, 2), 24));
    });
    let storage =
        std::boxed::Box::leak(std::boxed::Box::new(<[SocketStorage<'static>;
            CLIENT_SOCKETS]>::default(
        )));
    let mut sockets = SocketSet::new(&mut storage[..]);
    let handles = (0..CLIENT_SOCKETS)
        .map(|_| {
            sockets.add(tcp::Socket::new(
                tcp::SocketBuffer::new(leak(1024)),
                tcp::SocketBuffer::new(leak(1024)),
            ))
        })
        .collect();
    Rig {
        now: 0,
        bridge: Bridge::new(bridge_cfg, Source::Default, 1),
        gateway: Gateway::new(bridge_cfg.modbus, Policy::ForwardAll),
        net,
        wire,
        clients: Clients {
            wire: cwire,
            iface,
            sockets,
            handles,
        },
    }
}

/// Read input registers 9000H..9001H (PNOW of axis 1), transaction `tid`.
fn read_pnow(tid: u16) -> Vec<u8> {
    let mut v = tid.to_be_bytes().to_vec();
    v.extend_from_slice(&[0, 0, 0, 6, 1, 4, 0x90, 0, 0, 2]);
    v
}

/// The answer to [`read_pnow`] with PNOW 12,000.
fn pnow_answer(tid: u16) -> Vec<u8> {
    let mut v = tid.to_be_bytes().to_vec();
    v.extend_from_slice(&[0, 0, 0, 7, 1, 4, 4, 0, 0, 0x2E, 0xE0]);
    v
}

#[test]
fn four_clients_are_answered_in_order_a_fifth_is_reset_a_silent_one_closed() {
    assert_eq!(CLIENTS, 4);
    let slots = std::boxed::Box::leak(std::boxed::Box::new(EMPTY_SLOTS));
    let mut rig = rig(slots);
    rig.gateway.regs.cache.axes[0].current_position = 12_000;
    rig.run(10, 1);
    for n in 0..CLIENTS {
        rig.connect(n, 40_000 + n as u16);
    }
    rig.run(20, 1);
    for n in 0..CLIENTS {
        assert!(
            rig.client(n).may_send(),
            "client {n}: {}",
            rig.client(n).state()
        );
    }
    // All four at once, each with three requests back to back: every
    // client gets its own answers, in its order, their IDs echoed.
    let tid = |n: usize, k: u16| (n as u16 + 1) << 8 | k;
    for n in 0..CLIENTS {
        let three: Vec<u8> = (1..=3).flat_map(|k| read_pnow(tid(n, k))).collect();
        rig.client(n).send_slice(&three).unwrap();
    }
    rig.run(20, 1);
    for n in 0..CLIENTS {
        let want: Vec<u8> = (1..=3).flat_map(|k| pnow_answer(tid(n, k))).collect();
        assert_eq!(rig.received(n), want, "client {n}");
    }
    // A fifth connection while all four are taken is reset by the stack;
    // the four are still served.
    rig.connect(CLIENTS, 40_010);
    rig.run(20, 1);
    assert!(
        !rig.client(CLIENTS).is_open(),
        "{}",
        rig.client(CLIENTS).state()
    );
    for n in 0..CLIENTS {
        rig.client(n).send_slice(&read_pnow(tid(n, 4))).unwrap();
    }
    rig.run(20, 1);
    for n in 0..CLIENTS {
        assert_eq!(rig.received(n), pnow_answer(tid(n, 4)), "client {n}");
    }
    // Client 1 keeps asking every 10 s; the others say nothing more.
    for k in 0..6u16 {
        rig.run(10_000, 5);
        rig.client(1).send_slice(&read_pnow(100 + k)).unwrap();
        rig.run(20, 1);
        assert_eq!(rig.received(1), pnow_answer(100 + k));
    }
    // 60 s after their last request, the silent ones were closed: they
    // read our FIN.
    for n in [0, 2, 3] {
        assert!(
            !rig.client(n).may_recv(),
            "client {n}: {}",
            rig.client(n).state()
        );
    }
    assert!(rig.client(1).may_recv(), "{}", rig.client(1).state());
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.connections, 4);
    assert_eq!(stats.requests, 4 * 4 + 6);
    assert_eq!(stats.idle_closed, 3);
    // Their sockets listen again: the client reset before is served now,
    // and so is a new one.
    for n in [0, 2, 3] {
        rig.client(n).close();
    }
    rig.run(3_000, 5);
    for n in [0, 2, 3] {
        rig.client(n).abort();
    }
    rig.client(CLIENTS).abort();
    rig.run(10, 1);
    rig.connect(CLIENTS, 40_011);
    rig.connect(0, 40_012);
    rig.run(20, 1);
    rig.client(CLIENTS).send_slice(&read_pnow(77)).unwrap();
    rig.client(0).send_slice(&read_pnow(78)).unwrap();
    rig.run(20, 1);
    assert_eq!(rig.received(CLIENTS), pnow_answer(77));
    assert_eq!(rig.received(0), pnow_answer(78));
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.connections, 6);
}

#[test]
fn a_length_field_out_of_range_resets_the_connection() {
    let slots = std::boxed::Box::leak(std::boxed::Box::new(EMPTY_SLOTS));
    let mut rig = rig(slots);
    rig.run(10, 1);
    rig.connect(0, 40_000);
    rig.run(20, 1);
    // Protocol ID 1: dropped, the next request answered.
    let mut bad = read_pnow(1);
    bad[3] = 1;
    bad.extend(read_pnow(2));
    rig.client(0).send_slice(&bad).unwrap();
    rig.run(20, 1);
    let got = rig.received(0);
    assert_eq!(got[..2], [0, 2]);
    assert_eq!(got.len(), 13);
    // Length 255: the stream cannot be followed.
    rig.client(0)
        .send_slice(&[0, 3, 0, 0, 0, 255, 1, 4])
        .unwrap();
    rig.run(20, 1);
    assert!(!rig.client(0).is_open(), "{}", rig.client(0).state());
    let stats = rig.net.modbus().map(ModbusClients::stats).unwrap();
    assert_eq!(stats.framing_reset, 1);
}
