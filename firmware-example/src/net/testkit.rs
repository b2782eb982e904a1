//! The host model of the network side, shared by the tests of [`super`]
//! (hosts, addresses) and [`super::modbus`]: a [`Net`] and its bridge on
//! one end of an in-memory wire, a second smoltcp interface with client
//! sockets on the other, stepped together in simulated milliseconds.
//!
//! The wire can lose a connection's frames both ways from a chosen moment
//! ([`Rig::vanish`]: a peer unplugged, no FIN, no RST), and a test may
//! answer the frames the bridge's side sends itself ([`Rig::server`]: a
//! DHCP server, for instance).

extern crate std;
use std::boxed::Box;
use std::collections::{BTreeMap, VecDeque};
use std::vec;
use std::vec::Vec;

use smoltcp::iface::{Config as IfaceConfig, Interface, SocketHandle, SocketSet, SocketStorage};
use smoltcp::phy::{Device, DeviceCapabilities, Medium, RxToken, TxToken};
use smoltcp::socket::tcp;
use smoltcp::time::Instant;
use smoltcp::wire::{
    EthernetAddress, EthernetFrame, EthernetProtocol, IpAddress, IpCidr, IpProtocol, Ipv4Packet,
    TcpPacket,
};

use super::config::{Addressing, Ipv4Setting, NetConfig};
use super::modbus::{ModbusBuffers, MODBUS_PORT};
use super::{Buffers, Net, NetEvent, SocketSlots, EMPTY_SLOTS};
use crate::bridge::{Bridge, NoPort, Poll};
use crate::config::{Config, Policy, Source};
use crate::modbus::Gateway;

/// The bridge's MAC address.
pub const NET_MAC: [u8; 6] = [0x02, 0, 0, 0, 0, 1];
/// The bridge's static address (and DHCP fallback) in [`net_config`].
pub const NET_IP: [u8; 4] = [10, 0, 0, 1];
/// The clients' address.
pub const CLIENT_IP: [u8; 4] = [10, 0, 0, 2];
/// The protocol-B port in [`net_config`].
pub const PB_PORT: u16 = 5020;

/// One end of the wire: frames in, frames out.
#[derive(Default)]
pub struct Wire {
    rx: VecDeque<Vec<u8>>,
    tx: VecDeque<Vec<u8>>,
}

pub struct Rx(Vec<u8>);
pub struct Tx<'a>(&'a mut VecDeque<Vec<u8>>);

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

/// The TCP ports (source, destination) of an Ethernet frame carrying
/// IPv4 and TCP.
pub fn tcp_ports(frame: &[u8]) -> Option<(u16, u16)> {
    let eth = EthernetFrame::new_checked(frame).ok()?;
    if eth.ethertype() != EthernetProtocol::Ipv4 {
        return None;
    }
    let ip = Ipv4Packet::new_checked(eth.payload()).ok()?;
    if ip.next_header() != IpProtocol::Tcp {
        return None;
    }
    let tcp = TcpPacket::new_checked(ip.payload()).ok()?;
    Some((tcp.src_port(), tcp.dst_port()))
}

/// Client sockets: one more than the firmware serves Modbus TCP clients
/// at once (and more than its protocol-B sockets).
pub const CLIENT_SOCKETS: usize = crate::net::modbus::CLIENTS + 1;

/// The clients' side: an interface at [`CLIENT_IP`] and
/// [`CLIENT_SOCKETS`] sockets.
pub struct Clients<'a> {
    wire: Wire,
    iface: Interface,
    sockets: SocketSet<'a>,
    handles: Vec<SocketHandle>,
}

/// Answers a frame the bridge's side sent (at tick `now`) with frames of
/// its own, put on the bridge's wire.
pub type Server = Box<dyn FnMut(u32, &[u8]) -> Vec<Vec<u8>>>;

/// `(bridge, gateway, net, its wire)` and the clients, stepped together.
pub struct Rig<'a> {
    /// The tick of the last round.
    pub now: u32,
    pub bridge: Bridge,
    pub gateway: Gateway,
    pub net: Net<'a>,
    wire: Wire,
    clients: Clients<'a>,
    /// Whether each round also polls the bridge, with the host's socket
    /// as its upstream and no controller (the protocol-B tests); the
    /// Modbus tests leave the bridge alone.
    pub serve_bridge: bool,
    /// Answers the bridge side's frames (see [`Server`]).
    pub server: Option<Server>,
    /// What [`Net::poll_with`] reported, and when.
    pub events: Vec<(u32, NetEvent)>,
    /// Client ports whose frames are lost both ways.
    vanished: Vec<u16>,
    /// When a frame of each client port last reached the bridge's side.
    last_in: BTreeMap<u16, u32>,
}

/// The network block of the tests: static (or DHCP with this fallback)
/// [`NET_IP`]/24, protocol B on [`PB_PORT`].
pub fn net_config(addressing: Addressing) -> NetConfig {
    NetConfig {
        addressing,
        port: PB_PORT,
        address: Ipv4Setting {
            address: NET_IP,
            prefix: 24,
            gateway: None,
        },
    }
}

fn leak(n: usize) -> &'static mut [u8] {
    Box::leak(vec![0u8; n].into_boxed_slice())
}

impl Rig<'static> {
    /// The bridge's side on `cfg` with Modbus TCP on [`MODBUS_PORT`], the
    /// clients at [`CLIENT_IP`]/24; tick 0.
    pub fn new(cfg: NetConfig) -> Self {
        let slots: &'static mut SocketSlots<'static> = Box::leak(Box::new(EMPTY_SLOTS));
        let buffers = Box::leak(Box::new(Buffers::new()));
        let modbus = Box::leak(Box::new(ModbusBuffers::new()));
        let mut wire = Wire::default();
        let bridge_cfg = Config::DEFAULT;
        let mut net = Net::new(
            cfg,
            NET_MAC,
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
            let [a0, a1, a2, a3] = CLIENT_IP;
            let _ = a.push(IpCidr::new(IpAddress::v4(a0, a1, a2, a3), 24));
        });
        let storage = Box::leak(Box::new(
            <[SocketStorage<'static>; CLIENT_SOCKETS]>::default(),
        ));
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
            serve_bridge: false,
            server: None,
            events: Vec::new(),
            vanished: Vec::new(),
            last_in: BTreeMap::new(),
        }
    }
}

impl Rig<'static> {
    /// Runs the Sparkplug edge node with `cfg` (its broker: a client
    /// socket of this rig listening at [`CLIENT_IP`]).
    pub fn add_sparkplug(&mut self, cfg: super::sparkplug::config::SparkplugConfig) {
        let buffers = Box::leak(Box::new(super::sparkplug::SparkplugBuffers::new()));
        self.net.add_sparkplug(cfg, NET_MAC, buffers, self.now);
    }
}

impl<'a> Rig<'a> {
    /// `ms` milliseconds, a round per `step` ms.
    pub fn run(&mut self, ms: u32, step: u32) {
        self.run_until(ms, step, |_| false);
    }

    /// As [`Rig::run`], stopping early after the first round at whose end
    /// `done` holds; whether it did.
    pub fn run_until(
        &mut self,
        ms: u32,
        step: u32,
        mut done: impl FnMut(&mut Self) -> bool,
    ) -> bool {
        let end = self.now + ms;
        while self.now < end {
            self.round(step);
            if done(self) {
                return true;
            }
        }
        false
    }

    /// One round, `step` ms after the last: the clients, the bridge's
    /// side, the clients again, frames carried between them.
    fn round(&mut self, step: u32) {
        self.now += step;
        let t = Instant::from_millis(i64::from(self.now));
        let c = &mut self.clients;
        c.iface.poll(t, &mut c.wire, &mut c.sockets);
        self.carry_in();
        let gw = Some(&mut self.gateway);
        if let Some(event) = self
            .net
            .poll_with(&mut self.wire, &mut self.bridge, gw, self.now)
        {
            self.events.push((self.now, event));
        }
        if self.serve_bridge {
            for _ in 0..100 {
                let mut up = self.net.host_port();
                match self.bridge.poll(&mut up, &mut NoPort, self.now) {
                    Ok(Poll::Busy) => {}
                    _ => break,
                }
            }
        }
        self.carry_out();
        let c = &mut self.clients;
        c.iface.poll(t, &mut c.wire, &mut c.sockets);
        self.carry_in();
    }

    fn is_lost(&self, ports: Option<(u16, u16)>) -> bool {
        ports.is_some_and(|(s, d)| self.vanished.contains(&s) || self.vanished.contains(&d))
    }

    /// The clients' frames to the bridge's side (less the lost ones).
    fn carry_in(&mut self) {
        while let Some(frame) = self.clients.wire.tx.pop_front() {
            let ports = tcp_ports(&frame);
            if self.is_lost(ports) {
                continue;
            }
            if let Some((src, _)) = ports {
                self.last_in.insert(src, self.now);
            }
            self.wire.rx.push_back(frame);
        }
    }

    /// The bridge side's frames to the clients (less the lost ones), each
    /// shown to the server first.
    fn carry_out(&mut self) {
        while let Some(frame) = self.wire.tx.pop_front() {
            if let Some(server) = self.server.as_mut() {
                let answers = server(self.now, &frame);
                self.wire.rx.extend(answers);
            }
            if !self.is_lost(tcp_ports(&frame)) {
                self.clients.wire.rx.push_back(frame);
            }
        }
    }

    /// From now on the frames of client socket `n`'s connection are lost
    /// both ways, as if its host were unplugged. Returns when a frame of
    /// it last reached the bridge's side.
    pub fn vanish(&mut self, n: usize) -> Option<u32> {
        let port = self.client(n).local_endpoint()?.port;
        self.vanished.push(port);
        self.last_in.get(&port).copied()
    }

    /// Client socket `n`.
    pub fn client(&mut self, n: usize) -> &mut tcp::Socket<'a> {
        let h = self.clients.handles[n];
        self.clients.sockets.get_mut::<tcp::Socket<'a>>(h)
    }

    /// Client socket `n` connects from `local_port` to `port` of the
    /// bridge's [`NET_IP`].
    pub fn connect(&mut self, n: usize, port: u16, local_port: u16) {
        self.connect_to(n, NET_IP, port, local_port);
    }

    /// Client socket `n` connects from `local_port` to `address:port`.
    pub fn connect_to(&mut self, n: usize, address: [u8; 4], port: u16, local_port: u16) {
        let c = &mut self.clients;
        let h = c.handles[n];
        let s = c.sockets.get_mut::<tcp::Socket>(h);
        let [a, b, cc, d] = address;
        s.connect(
            c.iface.context(),
            (IpAddress::v4(a, b, cc, d), port),
            local_port,
        )
        .unwrap();
    }

    /// Runs until client socket `n` is connected (at most `ms` ms), then
    /// queues `bytes` on it.
    pub fn send_when_connected(&mut self, n: usize, bytes: &[u8], ms: u32) {
        let up = self.run_until(ms, 1, |r| r.client(n).may_send());
        assert!(up, "client {n} not connected: {}", self.client(n).state());
        self.client(n).send_slice(bytes).unwrap();
    }

    /// What client socket `n` has received since the last call.
    pub fn received(&mut self, n: usize) -> Vec<u8> {
        let s = self.client(n);
        let mut out = Vec::new();
        while s.can_recv() {
            s.recv(|b| (b.len(), out.extend_from_slice(b))).unwrap();
        }
        out
    }
}
