//! The bridge on Ethernet: protocol B over TCP, on smoltcp (feature
//! `ethernet`; board binary `lm3s6965-eth`).
//!
//! The bridge itself ([`crate::bridge`]) is unchanged: its upstream is a
//! [`Port`] like a UART's, here backed by a TCP socket ([`host`]), and its
//! downstream is still the controller's UART. What the serial upstream
//! has, the TCP upstream has: checked pass-through, the command policy,
//! the bridge's status query and codes, and the 26DH stream with every
//! chunk read back. TCP's window replaces XON/XOFF: the bridge reads the
//! socket only when it can use the bytes, so a host is held back by TCP
//! instead of being told to stop, and no byte is ever lost on the way in.
//!
//! - [`stellaris`]: the LM3S6965's Ethernet MAC behind smoltcp's
//!   `phy::Device`;
//! - [`host`]: which connection is the host (one at a time; others get
//!   `&` B0B), its end, the upstream [`Port`];
//! - [`config`]: the network block (TCP port, DHCP or a static address);
//! - this module: the interface and its address, and [`run`], the board
//!   loop.
//!
//! Protocol B runs on TCP port [`config::DEFAULT_PORT`] (5020) unless the
//! network block names another. The interface takes its address from DHCP
//! (QEMU's user network: 10.0.2.15), or the block's static one.
//!
//! Memory: everything lives in statics the board hands over: the two
//! frame buffers of the driver ([`stellaris::FRAME_CAP`] bytes each), the
//! socket buffers ([`Buffers`]: [`SOCKET_BUFFER`] bytes per direction
//! and socket; [`modbus::ModbusBuffers`]: [`modbus::CLIENT_BUFFER`]) and
//! the socket slots ([`SocketSlots`]). Nothing is allocated.
//!
//! Modbus TCP ([`modbus`]): [`modbus::CLIENTS`] more sockets on port
//! [`modbus::MODBUS_PORT`] (502), added by [`Net::add_modbus`] and served
//! in [`Net::poll_with`] by the gateway ([`crate::modbus`]) that shares the
//! controller line with the bridge.
//!
//! Sparkplug B ([`sparkplug`]): one client socket to an MQTT broker, added
//! by [`Net::add_sparkplug`] and served in [`Net::poll_with`] from the
//! same gateway's cache and command handshake.

pub mod config;
pub mod host;
pub mod http;
pub mod modbus;
pub mod sparkplug;
pub mod stellaris;
#[cfg(test)]
mod testkit;
#[cfg(test)]
mod tests;

use core::convert::Infallible;

use iai_protocol_b::frame::Station;
use smoltcp::iface::{Config as IfaceConfig, Interface, SocketHandle, SocketSet, SocketStorage};
use smoltcp::phy::Device;
use smoltcp::socket::{dhcpv4, tcp};
use smoltcp::time::Instant;
use smoltcp::wire::{EthernetAddress, IpAddress, IpCidr, Ipv4Address};

use crate::bridge::{Bridge, Error, Poll};
use crate::modbus::Gateway;
use crate::serial::Port;
use crate::status::Stats;
use config::{Addressing, Ipv4Setting, NetConfig, DHCP_FALLBACK_MS};
use host::{HostPort, HostStats, Hosts, Session, SOCKETS};
use http::{Http, HttpBuffers};
use modbus::{ModbusBuffers, ModbusClients, ModbusTcpStats, CLIENTS};
use sparkplug::config::SparkplugConfig;
use sparkplug::{EdgeNode, SparkplugBuffers};

/// Bytes of each socket buffer (receive and transmit, per socket). The
/// receive buffer is the TCP window: the most a host can send ahead of
/// what the bridge has taken.
pub const SOCKET_BUFFER: usize = 1024;

/// Frames taken in per [`Net::poll`], so that a flood of frames cannot
/// keep the loop (and the watchdog's feeding) from going round.
pub const FRAMES_PER_POLL: usize = 8;

/// The socket buffers, in a static of the board.
pub struct Buffers {
    rx: [[u8; SOCKET_BUFFER]; SOCKETS],
    tx: [[u8; SOCKET_BUFFER]; SOCKETS],
}

impl Buffers {
    /// Zeroed buffers (a `static` of them takes no flash).
    pub const fn new() -> Self {
        Buffers {
            rx: [[0; SOCKET_BUFFER]; SOCKETS],
            tx: [[0; SOCKET_BUFFER]; SOCKETS],
        }
    }
}

impl Default for Buffers {
    fn default() -> Self {
        Self::new()
    }
}

/// The slots of the socket set: the protocol-B sockets, DHCP, the Modbus
/// TCP sockets, the web sockets and the Sparkplug node's.
pub type SocketSlots<'a> = [SocketStorage<'a>; SOCKETS + 1 + CLIENTS + http::SOCKETS + 1];

/// Empty socket slots.
pub const EMPTY_SLOTS: SocketSlots<'static> =
    [SocketStorage::EMPTY; SOCKETS + 1 + CLIENTS + http::SOCKETS + 1];

/// What the network side shows the web page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NetView {
    /// The interface's address and where it came from.
    pub address: Option<(Ipv4Setting, AddressSource)>,
    /// Protocol B's TCP port.
    pub port: u16,
    /// The protocol-B hosts' counters.
    pub hosts: HostStats,
    /// Whether a protocol-B host is connected.
    pub host_connected: bool,
    /// The Modbus TCP side's counters, if it is served.
    pub modbus: Option<ModbusTcpStats>,
}

/// Where the interface's address came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AddressSource {
    /// A DHCP lease.
    Dhcp,
    /// The network block's static address.
    Static,
    /// DHCP's fallback (no lease within [`DHCP_FALLBACK_MS`]).
    Fallback,
}

/// What changed on the network side (the board prints it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NetEvent {
    /// The interface has this address; protocol B listens on `port`.
    Listening {
        /// The address and gateway.
        address: Ipv4Setting,
        /// Where it came from.
        source: AddressSource,
        /// The TCP port.
        port: u16,
        /// The Modbus TCP port, if Modbus TCP is served.
        modbus_port: Option<u16>,
        /// The web page's port, if it is served.
        http_port: Option<u16>,
    },
    /// The DHCP lease was lost; no address until the next.
    AddressLost,
    /// News of the Sparkplug edge node.
    Sparkplug(sparkplug::Event),
}

/// A wrapping millisecond tick as smoltcp's clock.
#[derive(Debug, Clone, Copy)]
struct Clock {
    last: u32,
    ms: i64,
}

impl Clock {
    fn at(&mut self, now: u32) -> Instant {
        self.ms = self
            .ms
            .saturating_add(i64::from(now.wrapping_sub(self.last)));
        self.last = now;
        Instant::from_millis(self.ms)
    }
}

/// The network side: the interface, its sockets, its address and the
/// protocol-B hosts.
pub struct Net<'a> {
    iface: Interface,
    sockets: SocketSet<'a>,
    dhcp: Option<SocketHandle>,
    hosts: Hosts,
    modbus: Option<ModbusClients>,
    sparkplug: Option<EdgeNode<'a>>,
    http: Option<Http<'a>>,
    cfg: NetConfig,
    clock: Clock,
    address: Option<(Ipv4Setting, AddressSource)>,
    /// Since when DHCP has been without a lease.
    unaddressed_since: u32,
    station: Station,
}

impl<'a> Net<'a> {
    /// The interface on `device` with MAC address `mac` (unicast: see
    /// [`stellaris::mac_from_user`]) and the protocol-B sockets listening
    /// on `cfg`'s port; `seed` seeds TCP's sequence numbers and DHCP's
    /// transaction IDs (give each boot its own); `station` is the bridge's
    /// own (for B0B).
    #[allow(clippy::too_many_arguments)]
    pub fn new<D: Device>(
        cfg: NetConfig,
        mac: [u8; 6],
        seed: u64,
        station: Station,
        device: &mut D,
        slots: &'a mut SocketSlots<'a>,
        buffers: &'a mut Buffers,
        now: u32,
    ) -> Self {
        let mut clock = Clock { last: now, ms: 0 };
        let mut iface_cfg = IfaceConfig::new(EthernetAddress(mac).into());
        iface_cfg.random_seed = seed;
        let iface = Interface::new(iface_cfg, device, clock.at(now));
        let mut sockets = SocketSet::new(slots.as_mut_slice());
        let Buffers { rx, tx } = buffers;
        let mut handles = [SocketHandle::default(); SOCKETS];
        for ((handle, rx), tx) in handles.iter_mut().zip(rx.iter_mut()).zip(tx.iter_mut()) {
            let mut socket = tcp::Socket::new(
                tcp::SocketBuffer::new(rx.as_mut_slice()),
                tcp::SocketBuffer::new(tx.as_mut_slice()),
            );
            host::configure(&mut socket);
            *handle = sockets.add(socket);
        }
        let dhcp = (cfg.addressing == Addressing::Dhcp).then(|| sockets.add(dhcpv4::Socket::new()));
        let mut net = Net {
            iface,
            sockets,
            dhcp,
            hosts: Hosts::new(handles, cfg.port),
            modbus: None,
            sparkplug: None,
            http: None,
            cfg,
            clock,
            address: None,
            unaddressed_since: now,
            station,
        };
        if cfg.addressing == Addressing::Static {
            net.set_address(Some(cfg.address), AddressSource::Static);
        }
        net
    }

    /// The interface's address and where it came from.
    pub fn address(&self) -> Option<(Ipv4Setting, AddressSource)> {
        self.address
    }

    /// The protocol-B hosts.
    pub fn hosts(&self) -> &Hosts {
        &self.hosts
    }

    /// Serves Modbus TCP on `port` (see [`modbus`]) on sockets over
    /// `buffers`; they listen from the next [`Net::poll_with`] with a
    /// gateway. Once only: a second call changes nothing.
    pub fn add_modbus(&mut self, buffers: &'a mut ModbusBuffers, port: u16) {
        if self.modbus.is_some() {
            return;
        }
        let handles = buffers.add_sockets(&mut self.sockets);
        self.modbus = Some(ModbusClients::new(handles, port));
    }

    /// The Modbus TCP clients, if Modbus TCP is served.
    pub fn modbus(&self) -> Option<&ModbusClients> {
        self.modbus.as_ref()
    }

    /// Runs the Sparkplug edge node with `cfg` (if it is enabled) on a
    /// socket over `buffers`; `mac` names it when `cfg` gives no node ID.
    /// Once only: a second call changes nothing.
    pub fn add_sparkplug(
        &mut self,
        cfg: SparkplugConfig,
        mac: [u8; 6],
        buffers: &'a mut SparkplugBuffers,
        now: u32,
    ) {
        if self.sparkplug.is_none() && cfg.enabled {
            let node = EdgeNode::new(cfg, mac, buffers, &mut self.sockets, now);
            self.sparkplug = Some(node);
        }
    }

    /// The Sparkplug edge node, if it runs.
    pub fn sparkplug(&self) -> Option<&EdgeNode<'a>> {
        self.sparkplug.as_ref()
    }

    /// The Sparkplug edge node, to end its session ([`EdgeNode::leave`]).
    pub fn sparkplug_mut(&mut self) -> Option<&mut EdgeNode<'a>> {
        self.sparkplug.as_mut()
    }

    /// Serves the web page ([`http`]) on `port` on sockets over `buffers`;
    /// they listen from the next [`Net::poll_with`]. Once only.
    pub fn add_http(&mut self, buffers: &'a mut HttpBuffers, port: u16) {
        if self.http.is_some() {
            return;
        }
        let (handles, form) = buffers.add_sockets(&mut self.sockets);
        self.http = Some(Http::new(handles, form, port));
    }

    /// The web side, if the web page is served.
    pub fn http(&self) -> Option<&Http<'a>> {
        self.http.as_ref()
    }

    /// The settings in force.
    pub fn config(&self) -> &NetConfig {
        &self.cfg
    }

    /// The bridge's upstream for this round (see [`host`]).
    pub fn host_port(&mut self) -> HostPort<'_, 'a> {
        self.hosts.port(&mut self.sockets)
    }

    /// One round of the network side at tick `now`: frames in (at most
    /// [`FRAMES_PER_POLL`]) and out, timers, DHCP, then the hosts (see
    /// [`Hosts::service`]). What changed about the address, if anything.
    pub fn poll<D: Device>(
        &mut self,
        device: &mut D,
        bridge: &mut Bridge,
        now: u32,
    ) -> Option<NetEvent> {
        self.poll_with(device, bridge, None, now)
    }

    /// [`Net::poll`], and then the Modbus TCP clients, answered by
    /// `gateway` (if Modbus TCP was added and a gateway is given), and the
    /// web page's connections (if it was added).
    pub fn poll_with<D: Device>(
        &mut self,
        device: &mut D,
        bridge: &mut Bridge,
        gateway: Option<&mut Gateway>,
        now: u32,
    ) -> Option<NetEvent> {
        let t = self.clock.at(now);
        let sockets = &mut self.sockets;
        self.iface.poll_maintenance(t);
        for _ in 0..FRAMES_PER_POLL {
            if self.iface.poll_ingress_single(t, device, sockets)
                == smoltcp::iface::PollIngressSingleResult::None
            {
                break;
            }
        }
        for _ in 0..FRAMES_PER_POLL {
            if self.iface.poll_egress(t, device, sockets) == smoltcp::iface::PollResult::None {
                break;
            }
        }
        let event = self.poll_address(now);
        self.hosts
            .service(&mut self.sockets, bridge, self.station, now);
        let mut gateway = gateway;
        if let (Some(clients), Some(gateway)) = (self.modbus.as_mut(), gateway.as_deref_mut()) {
            clients.service(&mut self.sockets, gateway, now);
        }
        if let Some(web) = self.http.as_mut() {
            let view = NetView {
                address: self.address,
                port: self.cfg.port,
                hosts: self.hosts.stats(),
                host_connected: matches!(self.hosts.session(), Session::Host(_)),
                modbus: self.modbus.as_ref().map(ModbusClients::stats),
            };
            web.service(&mut self.sockets, bridge, gateway.as_deref_mut(), view, now);
        }
        if let (Some(node), Some(gateway)) = (self.sparkplug.as_mut(), gateway) {
            let hosts = (self.hosts.host_handle().is_some(), self.hosts.stats().hosts);
            let news = node.service(
                &mut self.iface,
                &mut self.sockets,
                bridge,
                gateway,
                hosts,
                now,
            );
            if let Some(news) = news {
                // One event a round: the address's first, the node's kept.
                if event.is_some() {
                    node.defer(news);
                } else {
                    return Some(NetEvent::Sparkplug(news));
                }
            }
        }
        event
    }

    /// DHCP's news, or the fallback address when it has none for too long.
    fn poll_address(&mut self, now: u32) -> Option<NetEvent> {
        let handle = self.dhcp?;
        let news = match self.sockets.get_mut::<dhcpv4::Socket>(handle).poll() {
            None => None,
            Some(dhcpv4::Event::Configured(c)) => Some(Some(Ipv4Setting {
                address: c.address.address().octets(),
                prefix: c.address.prefix_len(),
                gateway: c.router.map(|r| r.octets()),
            })),
            Some(dhcpv4::Event::Deconfigured) => Some(None),
        };
        match news {
            Some(Some(setting)) => Some(self.set_address(Some(setting), AddressSource::Dhcp)),
            // DHCP (re)starting without a lease: news only if one was lost.
            Some(None) if self.address.is_none() => None,
            Some(None) => {
                self.unaddressed_since = now;
                Some(self.set_address(None, AddressSource::Dhcp))
            }
            None if self.address.is_none()
                && now.wrapping_sub(self.unaddressed_since) >= DHCP_FALLBACK_MS =>
            {
                Some(self.set_address(Some(self.cfg.address), AddressSource::Fallback))
            }
            None => None,
        }
    }

    /// Puts `setting` (or no address) on the interface.
    fn set_address(&mut self, setting: Option<Ipv4Setting>, source: AddressSource) -> NetEvent {
        // The block's address and prefix are checked, and DHCP's come from
        // a valid CIDR and a unicast address; a setting that is neither
        // counts as no address all the same, which keeps smoltcp's two
        // assertions (a prefix of at most 32, a unicast address) out of
        // the image.
        let setting = setting.filter(|s| s.prefix <= 32 && config::is_host_address(s.address));
        self.address = setting.map(|s| (s, source));
        self.iface.update_ip_addrs(|addrs| {
            addrs.clear();
            if let Some(s) = setting {
                let [a, b, c, d] = s.address;
                let _ = addrs.push(IpCidr::new(IpAddress::v4(a, b, c, d), s.prefix));
            }
        });
        let routes = self.iface.routes_mut();
        routes.remove_default_ipv4_route();
        if let Some([a, b, c, d]) = setting.and_then(|s| s.gateway) {
            let _ = routes.add_default_ipv4_route(Ipv4Address::new(a, b, c, d));
        }
        match setting {
            Some(address) => NetEvent::Listening {
                address,
                source,
                port: self.cfg.port,
                modbus_port: self.modbus.as_ref().map(ModbusClients::port),
                http_port: self.http.as_ref().map(Http::port),
            },
            None => NetEvent::AddressLost,
        }
    }
}

/// Bridges between the TCP host and the controller's port `down` until the
/// quit sequence (`Ok` with the counters) or a downstream error, as
/// [`crate::bridge::run`] does for a serial host; `gateway` answers the
/// Modbus TCP clients (if [`Net::add_modbus`] was called) and shares the
/// controller line with the bridge as its guest, as on the serial board.
///
/// Each pass: [`Net::poll_with`] (frames in and out, the hosts, the Modbus
/// clients), then [`Bridge::poll_with`] with the host's socket as its
/// upstream and the gateway as its guest. When neither can move, `sleep`
/// is called with a readiness check (a new tick, a frame waiting according
/// to `rx_pending`, the controller's port); the tick wakes it at least
/// once a millisecond, which also serves smoltcp's timers and the
/// gateway's polls. `report` hears about address changes; `feed` runs
/// once a pass.
#[allow(clippy::too_many_arguments)]
pub fn run<D: Device, P: Port>(
    bridge: &mut Bridge,
    gateway: &mut Gateway,
    net: &mut Net<'_>,
    device: &mut D,
    down: &mut P,
    now_ms: impl Fn() -> u32,
    rx_pending: impl Fn(&D) -> bool,
    mut sleep: impl FnMut(&mut dyn FnMut() -> bool),
    mut feed: impl FnMut(),
    mut report: impl FnMut(NetEvent),
) -> Result<Stats, Error<Infallible, P::Error>> {
    loop {
        feed();
        let now = now_ms();
        if let Some(event) = net.poll_with(device, bridge, Some(&mut *gateway), now) {
            report(event);
        }
        let mut up = net.host_port();
        match bridge.poll_with(&mut up, down, &mut *gateway, now)? {
            Poll::Quit => return Ok(bridge.stats()),
            Poll::Busy => {}
            Poll::Wait(w) => {
                let i = w.interest;
                let start = now_ms();
                let device = &*device;
                sleep(&mut || {
                    now_ms() != start
                        || rx_pending(device)
                        || (i.down_read && down.read_ready().unwrap_or(true))
                        || (i.down_write && down.write_ready().unwrap_or(true))
                });
            }
        }
    }
}
