//! The gateway as a Sparkplug B 3.0 edge node (Eclipse Sparkplug 3.0) on
//! an MQTT 3.1.1 broker: one TCP socket in the network side's set, served
//! from [`crate::net::Net::poll_with`] with bounded work per round.
//!
//! - The node: NBIRTH (`bdSeq`, [`metrics::NODE`]), NDATA of what changed
//!   every [`NDATA_PERIOD_MS`], `Node Control/Rebirth` on NCMD; NDEATH is
//!   the Will (QoS 1) of each CONNECT and is published before a clean
//!   disconnect. `bdSeq` counts sessions (0..=255), `seq` every message
//!   after NBIRTH (0), wrapping.
//! - One device, [`DEVICE`], the controller: DBIRTH once the gateway's
//!   polls answer, DDATA by exception (aliases only, positions past the
//!   deadband) once a poll period, DDEATH when its polls have failed for
//!   [`DEVICE_DEAD_MS`], DBIRTH when they answer again.
//! - With a primary host configured, no BIRTH before its STATE
//!   (`spBv1.0/STATE/HOST`) says online; offline ends the session cleanly
//!   (NDEATH, DISCONNECT) and the node connects again.
//! - DCMD metrics ([`metrics::command`]) go, when the block allows
//!   commands, through the gateway's command policy and handshake
//!   ([`crate::modbus::registers::Registers::command`]); the handshake's
//!   state is published as `Command/*` metrics: done only once the
//!   controller confirmed.
//! - A broker that refuses, vanishes or restarts: the socket is dropped
//!   and the node connects again after a backoff ([`BACKOFF_MIN_MS`]
//!   doubling to [`BACKOFF_MAX_MS`]).
//!
//! Timestamps are milliseconds since start, or since the epoch once a
//! primary host's STATE has given its time (the board has no clock).
//! Memory: the socket buffers and the packet buffers are in
//! [`SparkplugBuffers`], a static of the board; nothing is allocated.

pub mod config;
pub mod metrics;
pub mod mqtt;
pub mod payload;
#[cfg(test)]
mod tests;

use heapless::Deque;
use iai_protocol_b::clock::reached;
use smoltcp::iface::{Interface, SocketHandle, SocketSet};
use smoltcp::socket::tcp;
use smoltcp::wire::{IpAddress, IpEndpoint};

use crate::bridge::Bridge;
use crate::modbus::registers::WINDOW_WORDS;
use crate::modbus::Gateway;
use config::{SparkplugConfig, Text};
use metrics::{DeviceMetric, Refusal, View, DEVICE_ALIAS, MAX_DEVICE, NODE};
use mqtt::{Packet, Writer};
use payload::{DataType, Received, Value};

/// The Sparkplug topic namespace.
pub const NAMESPACE: &str = "spBv1.0";
/// The controller's device ID.
pub const DEVICE: &str = "controller";
/// Bytes of the socket's receive buffer.
pub const RX_BUFFER: usize = 512;
/// Bytes of the socket's transmit buffer.
pub const TX_BUFFER: usize = 1024;
/// Longest packet the node sends (a DBIRTH of eight axes).
pub const OUT_BUFFER: usize = 3072;
/// Longest packet the node takes (a DCMD with a whole table window);
/// longer ones are skipped.
pub const IN_BUFFER: usize = 512;
/// NDATA at most this often.
pub const NDATA_PERIOD_MS: u32 = 10_000;
/// The controller is dead once its polls have failed and its axes have
/// not answered for this long.
pub const DEVICE_DEAD_MS: u16 = 5_000;
/// First wait before connecting again.
pub const BACKOFF_MIN_MS: u32 = 1_000;
/// Longest wait before connecting again.
pub const BACKOFF_MAX_MS: u32 = 30_000;
/// Longest wait for the TCP connection or the CONNACK.
pub const CONNECT_TIMEOUT_MS: u32 = 10_000;
/// Packets taken per round.
const PACKETS_PER_POLL: usize = 4;

/// The node's buffers, in a static of the board.
pub struct SparkplugBuffers {
    rx: [u8; RX_BUFFER],
    tx: [u8; TX_BUFFER],
    out: [u8; OUT_BUFFER],
    inbox: [u8; IN_BUFFER],
    window: [u16; WINDOW_WORDS],
    published: Published,
}

/// What the node last published: fingerprints of the values
/// ([`metrics::fingerprint`]) and the positions (the deadband's
/// reference). Kept with the buffers, in the board's static.
pub struct Published {
    node: [u32; NODE.len()],
    device: [u32; MAX_DEVICE],
    positions: [i32; 8],
}

impl SparkplugBuffers {
    /// Zeroed buffers (a `static` of them takes no flash).
    pub const fn new() -> Self {
        SparkplugBuffers {
            rx: [0; RX_BUFFER],
            tx: [0; TX_BUFFER],
            out: [0; OUT_BUFFER],
            inbox: [0; IN_BUFFER],
            window: [0; WINDOW_WORDS],
            published: Published {
                node: [0; NODE.len()],
                device: [0; MAX_DEVICE],
                positions: [0; 8],
            },
        }
    }
}

impl Default for SparkplugBuffers {
    fn default() -> Self {
        Self::new()
    }
}

/// What the board hears about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// The broker accepted the connection.
    Connected,
    /// NBIRTH is out, with this `bdSeq`.
    Born {
        /// The session's `bdSeq`.
        bd_seq: u8,
    },
    /// The broker refused the connection (CONNACK return code).
    Refused(u8),
    /// The connection ended (the broker vanished, or the node left).
    Lost,
}

/// Counters of the edge node.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SparkplugStats {
    /// TCP connections attempted.
    pub attempts: u32,
    /// Sessions the broker accepted.
    pub sessions: u32,
    /// Connections the broker refused.
    pub refused: u32,
    /// Sessions and attempts that ended other than by the node leaving
    /// (a refusal, a timeout, a reset, a close).
    pub lost: u32,
    /// NBIRTHs published.
    pub births: u32,
    /// PUBLISH packets sent.
    pub published: u32,
    /// Bytes written to the broker.
    pub bytes_out: u64,
    /// Bytes read from the broker.
    pub bytes_in: u64,
    /// Packets that were malformed or too long for [`IN_BUFFER`].
    pub malformed: u32,
    /// DCMD metrics taken as commands.
    pub commands: u32,
    /// DCMD metrics refused.
    pub refusals: u32,
}

/// Where the connection is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Link {
    /// Waiting to connect until then.
    Waiting(u32),
    /// TCP connecting since then.
    Connecting(u32),
    /// CONNECT sent then, CONNACK awaited.
    Handshake(u32),
    /// The broker accepted.
    Session,
    /// NDEATH and DISCONNECT queued; the socket closes once they are out.
    Leaving,
}

/// What the session still owes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Owed {
    subscribe: bool,
    /// A primary host's STATE online is awaited before any BIRTH.
    await_state: bool,
    nbirth: bool,
    /// NBIRTH is out (DBIRTH, DDATA, NDATA may follow).
    born: bool,
    /// The device's DBIRTH is out (and no DDEATH since).
    device_born: bool,
    /// Leave cleanly once what is queued is out.
    leave: bool,
}

/// The edge node.
pub struct EdgeNode<'a> {
    handle: SocketHandle,
    cfg: SparkplugConfig,
    node_id: Text,
    link: Link,
    owed: Owed,
    backoff: u32,
    /// The `bdSeq` of the next CONNECT's Will.
    bd_seq: u8,
    seq: u8,
    packet_id: u16,
    /// The packet being sent (taken out while one is written).
    out: Option<&'a mut [u8; OUT_BUFFER]>,
    out_len: usize,
    out_sent: usize,
    /// Bytes received (taken out while a packet is handled).
    inbox: Option<&'a mut [u8; IN_BUFFER]>,
    in_len: usize,
    /// Bytes of an over-long packet still to skip.
    skip: usize,
    pubacks: Deque<u16, 4>,
    last_rx: u32,
    last_tx: u32,
    next_ndata: u32,
    next_ddata: u32,
    /// What was last published.
    published: &'a mut Published,
    /// The table window as published (taken out while it is read).
    window: Option<&'a mut [u16; WINDOW_WORDS]>,
    motion: (u16, u16),
    targets: [i32; 8],
    refusal: Option<Refusal>,
    /// Uptime: the last tick and the milliseconds counted.
    clock: (u32, u64),
    /// Epoch milliseconds at uptime 0, from a STATE.
    epoch_at_zero: Option<u64>,
    local_port: u16,
    stats: SparkplugStats,
    /// A birth not reported yet (the board heard another event).
    pending_event: Option<Event>,
}

impl<'a> EdgeNode<'a> {
    /// The node with `cfg`, its socket added to `sockets` over `buffers`;
    /// `mac` names it when the block gives no node ID.
    pub fn new(
        cfg: SparkplugConfig,
        mac: [u8; 6],
        buffers: &'a mut SparkplugBuffers,
        sockets: &mut SocketSet<'a>,
        now: u32,
    ) -> Self {
        let SparkplugBuffers {
            rx,
            tx,
            out,
            inbox,
            window,
            published,
        } = buffers;
        let mut socket = tcp::Socket::new(
            tcp::SocketBuffer::new(rx.as_mut_slice()),
            tcp::SocketBuffer::new(tx.as_mut_slice()),
        );
        socket.set_nagle_enabled(false);
        let handle = sockets.add(socket);
        let node_id = if cfg.node.is_empty() {
            default_node_id(mac)
        } else {
            cfg.node.clone()
        };
        let [.., m4, m5] = mac;
        EdgeNode {
            handle,
            cfg,
            node_id,
            link: Link::Waiting(now),
            owed: Owed::default(),
            backoff: BACKOFF_MIN_MS,
            bd_seq: 0,
            seq: 0,
            packet_id: 0,
            out: Some(out),
            out_len: 0,
            out_sent: 0,
            inbox: Some(inbox),
            in_len: 0,
            skip: 0,
            pubacks: Deque::new(),
            last_rx: now,
            last_tx: now,
            next_ndata: now,
            next_ddata: now,
            published,
            window: Some(window),
            motion: (0, 0),
            targets: [0; 8],
            refusal: None,
            clock: (now, 0),
            epoch_at_zero: None,
            local_port: 49_152 + (u16::from_be_bytes([m4, m5]) % 8_192),
            stats: SparkplugStats::default(),
            pending_event: None,
        }
    }

    /// The settings in force.
    pub fn config(&self) -> &SparkplugConfig {
        &self.cfg
    }

    /// The edge node ID.
    pub fn node_id(&self) -> &str {
        &self.node_id
    }

    /// Counters.
    pub fn stats(&self) -> SparkplugStats {
        self.stats
    }

    /// Whether NBIRTH is out in the current session.
    pub fn born(&self) -> bool {
        self.link == Link::Session && self.owed.born
    }

    /// The `bdSeq` of the current session's NBIRTH (the next CONNECT's,
    /// between sessions).
    pub fn bd_seq(&self) -> u8 {
        match self.link {
            Link::Session | Link::Leaving => self.bd_seq.wrapping_sub(1),
            _ => self.bd_seq,
        }
    }

    /// Keeps `event` for the next round (the board hears one a round).
    pub fn defer(&mut self, event: Event) {
        self.pending_event = Some(event);
    }

    /// Ends the session cleanly: NDEATH, then DISCONNECT; the node
    /// connects again after the shortest backoff.
    pub fn leave(&mut self) {
        if self.link == Link::Session {
            self.owed.leave = true;
        }
    }

    /// One round at `now`: the connection, what came in, what is owed.
    pub fn service(
        &mut self,
        iface: &mut Interface,
        sockets: &mut SocketSet<'_>,
        bridge: &Bridge,
        gateway: &mut Gateway,
        hosts: (bool, u32),
        now: u32,
    ) -> Option<Event> {
        if !self.cfg.enabled {
            return None;
        }
        let (last, ms) = self.clock;
        self.clock = (now, ms.wrapping_add(u64::from(now.wrapping_sub(last))));
        // The controller is polled for the node even with no Modbus
        // master about.
        gateway.regs.active = true;
        let socket = sockets.get_mut::<tcp::Socket>(self.handle);
        let mut event = None;
        match self.link {
            Link::Waiting(until) => {
                if reached(now, until) && iface.ipv4_addr().is_some() {
                    event = self.connect(iface, socket, now);
                }
            }
            Link::Connecting(since) => {
                if socket.state() == tcp::State::Established {
                    self.send_connect(now);
                    self.link = Link::Handshake(now);
                } else if !socket.is_active() || timed_out(now, since) {
                    event = self.drop_link(socket, now);
                }
            }
            Link::Handshake(since) if timed_out(now, since) => {
                event = self.drop_link(socket, now);
            }
            Link::Handshake(_) | Link::Session | Link::Leaving => {
                event = self.converse(socket, bridge, gateway, hosts, now);
            }
        }
        match (event, self.pending_event.take()) {
            (Some(e), pending) => {
                self.pending_event = pending;
                Some(e)
            }
            (None, pending) => pending,
        }
    }

    /// Starts a TCP connection to the broker.
    fn connect(
        &mut self,
        iface: &mut Interface,
        socket: &mut tcp::Socket<'_>,
        now: u32,
    ) -> Option<Event> {
        socket.abort();
        self.stats.attempts = self.stats.attempts.wrapping_add(1);
        self.local_port = if self.local_port >= 65_000 {
            49_152
        } else {
            self.local_port + 1
        };
        let [a, b, c, d] = self.cfg.broker;
        let remote = IpEndpoint::new(IpAddress::v4(a, b, c, d), self.cfg.port);
        match socket.connect(iface.context(), remote, self.local_port) {
            Ok(()) => {
                self.link = Link::Connecting(now);
                None
            }
            Err(_) => self.drop_link(socket, now),
        }
    }

    /// The connection failed or ended: abort it, wait, connect again.
    fn drop_link(&mut self, socket: &mut tcp::Socket<'_>, now: u32) -> Option<Event> {
        let was_session = matches!(self.link, Link::Session | Link::Leaving);
        let clean = self.link == Link::Leaving;
        if clean {
            socket.close();
        } else {
            socket.abort();
            self.stats.lost = self.stats.lost.wrapping_add(1);
        }
        let wait = if clean { BACKOFF_MIN_MS } else { self.backoff };
        self.link = Link::Waiting(now.wrapping_add(wait));
        self.backoff = self.backoff.saturating_mul(2).min(BACKOFF_MAX_MS);
        self.owed = Owed::default();
        self.out_len = 0;
        self.out_sent = 0;
        self.in_len = 0;
        self.skip = 0;
        self.pubacks.clear();
        was_session.then_some(Event::Lost)
    }

    /// Milliseconds for a payload's timestamp.
    fn timestamp(&self) -> u64 {
        self.epoch_at_zero.unwrap_or(0).wrapping_add(self.clock.1)
    }

    /// The topic `spBv1.0/GROUP/KIND/NODE[/controller]` into `buf`.
    fn topic<'b>(&self, buf: &'b mut [u8; TOPIC_LEN], kind: &str, device: bool) -> &'b [u8] {
        let mut w = Writer::new(buf);
        for part in [
            NAMESPACE,
            "/",
            &self.cfg.group,
            "/",
            kind,
            "/",
            &self.node_id,
        ] {
            w.put(part.as_bytes());
        }
        if device {
            w.put(b"/");
            w.put(DEVICE.as_bytes());
        }
        let n = w.len();
        buf.get(..n).unwrap_or(&[])
    }

    /// Writes a packet with `f` into the out buffer (empty: nothing to
    /// send).
    fn build(&mut self, now: u32, f: impl FnOnce(&mut Self, &mut Writer<'_>)) {
        let Some(out) = self.out.take() else {
            return;
        };
        let mut w = Writer::new(out.as_mut_slice());
        f(self, &mut w);
        let (len, overflowed) = (w.len(), w.overflowed());
        self.out = Some(out);
        // An overflow cannot happen with the tables as they are (the
        // largest DBIRTH fits OUT_BUFFER, see the tests); nothing is sent.
        self.out_len = if overflowed { 0 } else { len };
        self.out_sent = 0;
        if self.out_len > 0 {
            self.last_tx = now;
        }
    }

    /// CONNECT with NDEATH as the Will.
    fn send_connect(&mut self, now: u32) {
        let mut topic = [0u8; TOPIC_LEN];
        let mut will = [0u8; 48];
        let mut wp = Writer::new(&mut will);
        self.ndeath_payload(&mut wp);
        let will_len = wp.len();
        let topic = self.topic(&mut topic, "NDEATH", false);
        let payload = will.get(..will_len).unwrap_or(&[]);
        self.build(now, |me, w| {
            let will = mqtt::Will {
                topic,
                payload,
                qos: 1,
            };
            let cfg = &me.cfg;
            mqtt::connect(
                w,
                &me.node_id,
                cfg.keep_alive_s,
                will,
                &cfg.username,
                &cfg.password,
            );
        });
    }

    /// NDEATH's payload: the timestamp and `bdSeq`.
    fn ndeath_payload(&self, w: &mut Writer<'_>) {
        payload::header(w, self.timestamp(), None);
        payload::metric(
            w,
            Some(&|w: &mut Writer<'_>| w.put(b"bdSeq")),
            None,
            DataType::Int64,
            Value::Long(u64::from(self.bd_seq())),
        );
    }

    /// A session's round: out, in, what is owed.
    fn converse(
        &mut self,
        socket: &mut tcp::Socket<'_>,
        bridge: &Bridge,
        gateway: &mut Gateway,
        hosts: (bool, u32),
        now: u32,
    ) -> Option<Event> {
        // A broker that closed its side (FIN) has ended the session too.
        if !socket.is_active() || !socket.may_send() || !socket.may_recv() {
            return self.drop_link(socket, now);
        }
        self.flush(socket);
        let mut event = None;
        for _ in 0..PACKETS_PER_POLL {
            match self.take_packet(socket, gateway, now) {
                Ok(None) => break,
                Ok(Some(e)) => event = event.or(e),
                Err(()) => {
                    self.stats.malformed = self.stats.malformed.wrapping_add(1);
                    return self.drop_link(socket, now);
                }
            }
        }
        if let Some(Event::Refused(_)) = event {
            self.stats.refused = self.stats.refused.wrapping_add(1);
            self.drop_link(socket, now);
            return event;
        }
        let keep_alive = u32::from(self.cfg.keep_alive_s) * 1_000;
        if now.wrapping_sub(self.last_rx) > keep_alive + keep_alive / 2 {
            return self.drop_link(socket, now).or(event);
        }
        if self.out_len > 0 {
            return event;
        }
        if self.link == Link::Leaving {
            return self.drop_link(socket, now).or(event);
        }
        if self.link == Link::Session {
            event = event.or(self.next_message(bridge, gateway, hosts, now));
            if self.out_len == 0 && now.wrapping_sub(self.last_tx) >= keep_alive / 2 {
                self.build(now, |_, w| mqtt::pingreq(w));
            }
        }
        self.flush(socket);
        event
    }

    /// Sends what the out buffer holds, as far as the socket takes it.
    fn flush(&mut self, socket: &mut tcp::Socket<'_>) {
        if let Some(out) = self.out.as_deref() {
            let pending = out.get(self.out_sent..self.out_len).unwrap_or(&[]);
            if !pending.is_empty() {
                if let Ok(n) = socket.send_slice(pending) {
                    self.out_sent += n;
                    self.stats.bytes_out = self.stats.bytes_out.wrapping_add(n as u64);
                }
            }
        }
        if self.out_sent >= self.out_len {
            self.out_sent = 0;
            self.out_len = 0;
        }
    }

    /// Reads from the socket and handles one whole packet if one is in:
    /// `Ok(None)` when none is, `Err` for a malformed one.
    fn take_packet(
        &mut self,
        socket: &mut tcp::Socket<'_>,
        gateway: &mut Gateway,
        now: u32,
    ) -> Result<Option<Option<Event>>, ()> {
        // A PUBACK owed must find room before more is read.
        if self.pubacks.is_full() {
            return Ok(None);
        }
        if self.skip > 0 {
            let mut sink = [0u8; 64];
            let want = self.skip.min(sink.len());
            let n = match sink.get_mut(..want) {
                Some(s) => socket.recv_slice(s).unwrap_or(0),
                None => 0,
            };
            self.skip -= n.min(self.skip);
            self.count_in(n, now);
            return Ok((n > 0).then_some(None));
        }
        let Some(inbox) = self.inbox.take() else {
            return Ok(None);
        };
        let result = self.take_from(inbox, socket, gateway, now);
        self.inbox = Some(inbox);
        result
    }

    fn take_from(
        &mut self,
        inbox: &mut [u8; IN_BUFFER],
        socket: &mut tcp::Socket<'_>,
        gateway: &mut Gateway,
        now: u32,
    ) -> Result<Option<Option<Event>>, ()> {
        if let Some(free) = inbox.get_mut(self.in_len..) {
            if !free.is_empty() {
                let n = socket.recv_slice(free).unwrap_or(0);
                self.in_len += n;
                self.count_in(n, now);
            }
        }
        let have = inbox.get(..self.in_len).unwrap_or(&[]);
        let total = match mqtt::frame_len(have) {
            Ok(Some(t)) => t,
            Ok(None) => return Ok(None),
            Err(_) => return Err(()),
        };
        if total > IN_BUFFER {
            // Too long to take: skipped, counted.
            self.stats.malformed = self.stats.malformed.wrapping_add(1);
            self.skip = total - self.in_len;
            self.in_len = 0;
            return Ok(Some(None));
        }
        if total > self.in_len {
            return Ok(None);
        }
        let event = match mqtt::parse(inbox.get(..total).unwrap_or(&[])) {
            Ok(p) => self.handle(p, gateway, now),
            Err(_) => return Err(()),
        };
        // What follows the packet moves to the front.
        mqtt::shift_down(inbox, total..self.in_len, total);
        self.in_len = self.in_len.saturating_sub(total);
        Ok(Some(event))
    }

    fn count_in(&mut self, n: usize, now: u32) {
        if n > 0 {
            self.last_rx = now;
            self.stats.bytes_in = self.stats.bytes_in.wrapping_add(n as u64);
        }
    }

    /// One packet from the broker.
    fn handle(&mut self, p: Packet<'_>, gateway: &mut Gateway, now: u32) -> Option<Event> {
        match p {
            Packet::ConnAck { code: 0 } if matches!(self.link, Link::Handshake(_)) => {
                self.link = Link::Session;
                self.bd_seq = self.bd_seq.wrapping_add(1);
                self.backoff = BACKOFF_MIN_MS;
                self.stats.sessions = self.stats.sessions.wrapping_add(1);
                let awaits = !self.cfg.primary_host.is_empty();
                self.owed = Owed {
                    subscribe: true,
                    await_state: awaits,
                    nbirth: !awaits,
                    ..Owed::default()
                };
                Some(Event::Connected)
            }
            Packet::ConnAck { code } => Some(Event::Refused(code.max(1))),
            Packet::Publish {
                topic,
                qos,
                id,
                payload,
            } => {
                if let (1, Some(id)) = (qos, id) {
                    let _ = self.pubacks.push_back(id);
                }
                self.publication(topic, payload, gateway, now);
                None
            }
            _ => None,
        }
    }

    /// A message on one of the node's subscriptions.
    fn publication(&mut self, topic: &str, payload: &[u8], gateway: &mut Gateway, now: u32) {
        let Some(rest) = topic
            .strip_prefix(NAMESPACE)
            .and_then(|t| t.strip_prefix('/'))
        else {
            return;
        };
        if let Some(host) = rest.strip_prefix("STATE/") {
            if host == self.cfg.primary_host.as_str() && !host.is_empty() {
                self.state(payload);
            }
            return;
        }
        let Some(rest) = rest
            .strip_prefix(self.cfg.group.as_str())
            .and_then(|t| t.strip_prefix('/'))
        else {
            return;
        };
        let node = self.node_id.clone();
        if rest
            .strip_prefix("NCMD/")
            .is_some_and(|n| n == node.as_str())
        {
            let rebirth = payload::metrics(payload).flatten().any(|m| {
                (m.name == Some(metrics::NODE[metrics::REBIRTH].name)
                    || m.alias == Some(1 + metrics::REBIRTH as u64))
                    && m.value == Received::Bool(true)
            });
            if rebirth && self.owed.born {
                self.owed.nbirth = true;
            }
            return;
        }
        let device = rest
            .strip_prefix("DCMD/")
            .and_then(|r| r.strip_prefix(node.as_str()))
            .and_then(|r| r.strip_prefix('/'));
        if device == Some(DEVICE) {
            for m in payload::metrics(payload).flatten() {
                self.dcmd(m, gateway);
            }
            self.next_ddata = now;
        }
    }

    /// A primary host's STATE (Sparkplug 3.0: `{"online":B,"timestamp":T}`).
    fn state(&mut self, payload: &[u8]) {
        let Some(online) = json_field(payload, b"online") else {
            return;
        };
        if let Some(t) = json_field(payload, b"timestamp").and_then(json_number) {
            self.epoch_at_zero = Some(t.wrapping_sub(self.clock.1));
        }
        if online.starts_with(b"true") {
            if self.owed.await_state {
                self.owed.await_state = false;
                self.owed.nbirth = true;
            }
        } else if online.starts_with(b"false") && self.owed.born {
            self.owed.leave = true;
        }
    }

    /// One DCMD metric.
    fn dcmd(&mut self, m: payload::MetricIn<'_>, gateway: &mut Gateway) {
        let axes = gateway.regs.cfg.axes;
        let by_alias = m
            .alias
            .and_then(|a| a.checked_sub(u64::from(DEVICE_ALIAS)))
            .and_then(|i| usize::try_from(i).ok())
            .and_then(|i| DeviceMetric::at(i, axes));
        let by_name = m.name.and_then(|n| {
            (0..metrics::device_count(axes))
                .filter_map(|i| DeviceMetric::at(i, axes))
                .find(|d| d.is_named(n))
        });
        let Some(target) = by_name.or(by_alias) else {
            return;
        };
        let bytes = match m.value {
            Received::Bytes(b) => b,
            _ => &[],
        };
        let [flags, ..] = gateway.regs.hs.words();
        let seq = (flags & 0xFF) as u8;
        let refuse = |me: &mut Self, code: u16, message: u16| {
            me.stats.refusals = me.stats.refusals.wrapping_add(1);
            me.refusal = Some(Refusal { code, message, seq });
        };
        let cmd = match metrics::command(target, m.value, self.motion) {
            None | Some(Err(())) => return refuse(self, crate::codes::UPSTREAM_FRAME, 0),
            Some(Ok(cmd)) => cmd,
        };
        match metrics::submit(&mut gateway.regs, cmd, bytes, self.cfg.commands) {
            Err((code, message)) => refuse(self, code, message),
            Ok(()) => {
                self.stats.commands = self.stats.commands.wrapping_add(1);
                self.refusal = None;
                match cmd {
                    metrics::Command::Speed(v) => self.motion.0 = v,
                    metrics::Command::Acceleration(v) => self.motion.1 = v,
                    metrics::Command::Job(crate::modbus::command::Job::Move {
                        axis,
                        position,
                        ..
                    }) => {
                        if let Some(t) = self.targets.get_mut(usize::from(axis.wrapping_sub(1))) {
                            *t = position;
                        }
                    }
                    _ => {}
                }
            }
        }
    }

    /// Puts the next message owed into the out buffer, if any.
    fn next_message(
        &mut self,
        bridge: &Bridge,
        gateway: &Gateway,
        hosts: (bool, u32),
        now: u32,
    ) -> Option<Event> {
        if let Some(id) = self.pubacks.pop_front() {
            self.build(now, |_, w| mqtt::puback(w, id));
            return None;
        }
        if self.owed.subscribe {
            self.owed.subscribe = false;
            self.subscribe(now);
            return None;
        }
        let regs = &gateway.regs;
        let view = View {
            bridge,
            regs,
            modbus_answered: gateway.stats().answered,
            host_connected: hosts.0,
            hosts: hosts.1,
            uptime_ms: self.clock.1,
            deadband: self.cfg.deadband,
            motion: self.motion,
            refusal: self.refusal,
            targets: self.targets,
        };
        if self.owed.leave {
            self.leave_now(now);
            return None;
        }
        if self.owed.await_state {
            return None;
        }
        if self.owed.nbirth {
            self.nbirth(&view, now);
            return Some(Event::Born {
                bd_seq: self.bd_seq(),
            });
        }
        if !self.owed.born {
            return None;
        }
        let c = &regs.cache;
        let age = c.axes_at.age(now);
        let alive = c.link_up && age < DEVICE_DEAD_MS;
        let dead = !c.link_up && age >= DEVICE_DEAD_MS;
        if !self.owed.device_born && alive {
            self.dbirth(&view, now);
        } else if self.owed.device_born && dead {
            self.owed.device_born = false;
            self.build(now, |me, w| {
                let mut topic = [0u8; TOPIC_LEN];
                let seq = me.next_seq();
                let ts = me.timestamp();
                mqtt::publish(w, me.topic(&mut topic, "DDEATH", true), 0, 0, |w| {
                    payload::header(w, ts, Some(seq));
                });
            });
            self.stats.published = self.stats.published.wrapping_add(1);
        } else if self.owed.device_born && reached(now, self.next_ddata) {
            self.next_ddata = now.wrapping_add(regs.schedule.period_ms());
            self.data(&view, now, true);
        } else if reached(now, self.next_ndata) {
            self.next_ndata = now.wrapping_add(NDATA_PERIOD_MS);
            self.data(&view, now, false);
        }
        None
    }

    fn next_seq(&mut self) -> u8 {
        let s = self.seq;
        self.seq = s.wrapping_add(1);
        s
    }

    /// SUBSCRIBE to NCMD, DCMD and, if configured, the primary host's
    /// STATE.
    fn subscribe(&mut self, now: u32) {
        let mut ncmd = [0u8; TOPIC_LEN];
        let mut dcmd = [0u8; TOPIC_LEN];
        let mut state = [0u8; TOPIC_LEN];
        let ncmd = self.topic(&mut ncmd, "NCMD", false);
        // DCMD to the controller: `spBv1.0/G/DCMD/N/controller`.
        let dcmd = self.topic(&mut dcmd, "DCMD", true);
        let state = {
            let mut w = Writer::new(&mut state);
            w.put(NAMESPACE.as_bytes());
            w.put(b"/STATE/");
            w.put(self.cfg.primary_host.as_bytes());
            let n = w.len();
            state.get(..n).unwrap_or(&[])
        };
        let with_state = !self.cfg.primary_host.is_empty();
        self.packet_id = self.packet_id.wrapping_add(1).max(1);
        let id = self.packet_id;
        self.build(now, |_, w| {
            let all = [(ncmd, 1), (dcmd, 1), (state, 1)];
            let n = if with_state { 3 } else { 2 };
            mqtt::subscribe(w, id, all.get(..n).unwrap_or(&[]));
        });
    }

    /// NDEATH, then DISCONNECT, and the socket closes once they are out.
    fn leave_now(&mut self, now: u32) {
        self.build(now, |me, w| {
            let mut topic = [0u8; TOPIC_LEN];
            let topic = me.topic(&mut topic, "NDEATH", false);
            mqtt::publish(w, topic, 0, 0, |w| me.ndeath_payload(w));
            mqtt::disconnect(w);
        });
        self.stats.published = self.stats.published.wrapping_add(1);
        self.link = Link::Leaving;
        self.owed.leave = false;
    }

    /// NBIRTH: `bdSeq`, then every node metric with its name, alias and
    /// type; `seq` starts again at 0. The device is born again after it.
    fn nbirth(&mut self, view: &View<'_>, now: u32) {
        self.seq = 0;
        self.build(now, |me, w| {
            let mut topic = [0u8; TOPIC_LEN];
            let seq = me.next_seq();
            let ts = me.timestamp();
            let bd = me.bd_seq();
            let topic = me.topic(&mut topic, "NBIRTH", false);
            mqtt::publish(w, topic, 0, 0, |w| {
                payload::header(w, ts, Some(seq));
                payload::metric(
                    w,
                    Some(&|w: &mut Writer<'_>| w.put(b"bdSeq")),
                    None,
                    DataType::Int64,
                    Value::Long(u64::from(bd)),
                );
                for (i, d) in NODE.iter().enumerate() {
                    let v = view.node(i);
                    if let Some(slot) = me.published.node.get_mut(i) {
                        *slot = metrics::fingerprint(v);
                    }
                    let name = |w: &mut Writer<'_>| w.put(d.name.as_bytes());
                    payload::metric(w, Some(&name), Some(1 + i as u16), d.datatype, v);
                }
            });
        });
        self.owed.nbirth = false;
        self.owed.born = true;
        self.owed.device_born = false;
        self.next_ndata = now.wrapping_add(NDATA_PERIOD_MS);
        self.stats.births = self.stats.births.wrapping_add(1);
        self.stats.published = self.stats.published.wrapping_add(1);
    }

    /// DBIRTH: every device metric with its name, alias and type.
    fn dbirth(&mut self, view: &View<'_>, now: u32) {
        let axes = view.regs.cfg.axes;
        self.build(now, |me, w| {
            let mut topic = [0u8; TOPIC_LEN];
            let seq = me.next_seq();
            let ts = me.timestamp();
            let topic = me.topic(&mut topic, "DBIRTH", true);
            let Some(words) = me.window.take() else {
                return w.fail();
            };
            mqtt::publish(w, topic, 0, 0, |w| {
                payload::header(w, ts, Some(seq));
                for i in 0..metrics::device_count(axes) {
                    let Some(m) = DeviceMetric::at(i, axes) else {
                        continue;
                    };
                    let v = view.device(m, words);
                    me.remember(m, i, v);
                    let name = |w: &mut Writer<'_>| m.name(w);
                    let alias = DEVICE_ALIAS + i as u16;
                    payload::metric(w, Some(&name), Some(alias), m.def().datatype, v);
                }
            });
            me.window = Some(words);
        });
        self.owed.device_born = true;
        self.next_ddata = now.wrapping_add(view.regs.schedule.period_ms());
        self.stats.published = self.stats.published.wrapping_add(1);
    }

    /// Notes `v` as the value of device metric `m` (index `i`) published.
    fn remember(&mut self, m: DeviceMetric, i: usize, v: Value<'_>) {
        if let Some(slot) = self.published.device.get_mut(i) {
            *slot = metrics::fingerprint(v);
        }
        if let (DeviceMetric::Axis(axis, metrics::POSITION), Value::Int(p)) = (m, v) {
            if let Some(slot) = self
                .published
                .positions
                .get_mut(usize::from(axis.wrapping_sub(1)))
            {
                *slot = p as i32;
            }
        }
    }

    /// Whether device metric `m` (index `i`) now at `v` differs from what
    /// was published (positions: by the deadband at least).
    fn changed(&self, m: DeviceMetric, i: usize, v: Value<'_>) -> bool {
        if let (DeviceMetric::Axis(axis, metrics::POSITION), Value::Int(p)) = (m, v) {
            let last = self
                .published
                .positions
                .get(usize::from(axis.wrapping_sub(1)))
                .copied()
                .unwrap_or(0);
            let moved = (p as i32).abs_diff(last);
            return moved > 0 && moved >= self.cfg.deadband;
        }
        self.published.device.get(i).copied() != Some(metrics::fingerprint(v))
    }

    /// DDATA (`device`) or NDATA of the metrics that changed, by alias;
    /// nothing if none did.
    fn data(&mut self, view: &View<'_>, now: u32, device: bool) {
        let axes = view.regs.cfg.axes;
        let seq = self.seq;
        let mut count = 0u32;
        self.build(now, |me, w| {
            let mut topic = [0u8; TOPIC_LEN];
            let ts = me.timestamp();
            let topic = me.topic(&mut topic, if device { "DDATA" } else { "NDATA" }, device);
            let Some(words) = me.window.take() else {
                return w.fail();
            };
            mqtt::publish(w, topic, 0, 0, |w| {
                payload::header(w, ts, Some(seq));
                if device {
                    for i in 0..metrics::device_count(axes) {
                        let Some(m) = DeviceMetric::at(i, axes) else {
                            continue;
                        };
                        let v = view.device(m, words);
                        if me.changed(m, i, v) {
                            me.remember(m, i, v);
                            let alias = DEVICE_ALIAS + i as u16;
                            payload::metric(w, None, Some(alias), m.def().datatype, v);
                            count += 1;
                        }
                    }
                } else {
                    // Not the rebirth request: it only ever reads false.
                    for (i, d) in NODE.iter().enumerate().skip(1) {
                        let v = view.node(i);
                        let f = metrics::fingerprint(v);
                        if me.published.node.get(i) != Some(&f) {
                            if let Some(slot) = me.published.node.get_mut(i) {
                                *slot = f;
                            }
                            payload::metric(w, None, Some(1 + i as u16), d.datatype, v);
                            count += 1;
                        }
                    }
                }
            });
            me.window = Some(words);
        });
        if count == 0 {
            self.out_len = 0;
        } else {
            self.seq = seq.wrapping_add(1);
            self.stats.published = self.stats.published.wrapping_add(1);
        }
    }
}

/// Longest topic: `spBv1.0/` and three IDs of [`config::TEXT_LEN`] bytes,
/// the kind and [`DEVICE`].
const TOPIC_LEN: usize = 8 + 3 * config::TEXT_LEN + 8 + 16;

/// The default edge node ID: `gw-` and the MAC address in hex.
pub fn default_node_id(mac: [u8; 6]) -> Text {
    let mut t = Text::new();
    let _ = t.push_str("gw-");
    for b in mac {
        for nibble in [b >> 4, b & 0xF] {
            let c = char::from_digit(u32::from(nibble), 16).unwrap_or('0');
            let _ = t.push(c);
        }
    }
    t
}

fn timed_out(now: u32, since: u32) -> bool {
    now.wrapping_sub(since) >= CONNECT_TIMEOUT_MS
}

/// The text after `"key"` and its colon in a flat JSON object (spaces
/// skipped), or `None`.
fn json_field<'p>(json: &'p [u8], key: &[u8]) -> Option<&'p [u8]> {
    let at = json.windows(key.len() + 2).position(|w| {
        w.first() == Some(&b'"') && w.get(1..=key.len()) == Some(key) && w.last() == Some(&b'"')
    })?;
    let rest = json.get(at + key.len() + 2..)?;
    let rest = trim_start(rest);
    let rest = trim_start(rest.strip_prefix(b":")?);
    Some(rest)
}

fn trim_start(s: &[u8]) -> &[u8] {
    let n = s.iter().take_while(|b| b.is_ascii_whitespace()).count();
    s.get(n..).unwrap_or(&[])
}

/// The decimal number at the head of `s`.
fn json_number(s: &[u8]) -> Option<u64> {
    let digits = s.iter().take_while(|b| b.is_ascii_digit());
    let mut n = 0u64;
    let mut any = false;
    for d in digits {
        n = n.checked_mul(10)?.checked_add(u64::from(d - b'0'))?;
        any = true;
    }
    any.then_some(n)
}
