//! The Ethernet build's host side on arbitrary connection events: the
//! bridge's network side (`net::Net`: smoltcp, the protocol-B sockets and
//! `net::host::Hosts`, the Modbus TCP sockets and `net::modbus`), the
//! bridge and the Modbus gateway as its guest, against a second smoltcp
//! interface with four client sockets, joined by an in-memory wire. The
//! controller never answers (every forwarded command and every poll of
//! the gateway times out).
//!
//! Input: a list of operations, each an op byte and its arguments; client
//! `c` is `op >> 4 & 3`:
//!
//! - `0`: client `c` connects to the protocol-B port (if closed);
//! - `7`: client `c` connects to the Modbus TCP port (if closed);
//! - `1 n bytes..`: client `c` sends up to `n` bytes of the input;
//! - `2 k`: client `c` sends canned frame `k` (a 212H, the bridge's status
//!   query, a 26DH of two records, its first 40 bytes; Modbus TCP: PNOW
//!   read, servo on written, two reads in one segment, a read outside the
//!   map, 43/14 at unit 255, 11H in a 2-byte ADU, a 16 whose byte count
//!   is not its quantity's, half a request), whichever port it is
//!   connected to;
//! - `3`: client `c` closes its sending side (FIN);
//! - `4`: client `c` aborts (RST);
//! - `5`: client `c` stops or starts reading;
//! - `6 t`: `t` x 100 ms pass (the hold, refusal, close and stall limits
//!   are 1 to 10 s);
//! - anything else: one more round.
//!
//! After each operation the wire and both sides run for a few rounds, 1 ms
//! apart. At the end, 25 s pass with every client reading.
//!
//! Checked: no panic; at most one socket has the host's role, and it is
//! the one the session names; a connection that receives `&` B0B receives
//! that frame and nothing else; as many B0B are received as refusals
//! counted, but for connections the client reset or stopped reading;
//! every frame a protocol-B connection receives is well-formed; a Modbus
//! TCP connection receives only whole ADUs (protocol ID 0, a length of
//! 2..=254) whose function is a request's or its exception, but for a
//! connection the client reset or stopped reading, whose last may be cut;
//! every byte the bridge sends downstream belongs to a checked command
//! frame for the controller's station.
#![no_main]

#[path = "common/wire.rs"]
mod wire;

use std::convert::Infallible;

use firmware_example::bridge::{Bridge, Poll};
use firmware_example::codes;
use firmware_example::config::{Config, Source};
use firmware_example::modbus::Gateway;
use firmware_example::net::config::{Addressing, Ipv4Setting, NetConfig};
use firmware_example::net::host::{Role, Session, SOCKETS};
use firmware_example::net::modbus::ModbusBuffers;
use firmware_example::net::{Buffers, Net, EMPTY_SLOTS};
use firmware_example::serial::Port;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::{emit_frame, Header};
use libfuzzer_sys::fuzz_target;
use smoltcp::iface::{Config as IfaceConfig, Interface, SocketHandle, SocketSet, SocketStorage};
use smoltcp::socket::tcp;
use smoltcp::time::Instant;
use smoltcp::wire::{EthernetAddress, IpAddress, IpCidr};
use wire::Wire;

const CLIENTS: usize = 4;
const PORT: u16 = 5020;
const MODBUS_PORT: u16 = 502;

/// The controller's port: takes everything, answers nothing.
#[derive(Default)]
struct Controller {
    output: Vec<u8>,
}

impl embedded_io::ErrorType for Controller {
    type Error = Infallible;
}
impl embedded_io::ReadReady for Controller {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(false)
    }
}
impl embedded_io::Read for Controller {
    fn read(&mut self, _: &mut [u8]) -> Result<usize, Infallible> {
        Ok(0)
    }
}
impl embedded_io::WriteReady for Controller {
    fn write_ready(&mut self) -> Result<bool, Infallible> {
        Ok(true)
    }
}
impl embedded_io::Write for Controller {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.output.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
impl Port for Controller {}

/// What a client connection received, one buffer per connection.
struct Client {
    handle: SocketHandle,
    reading: bool,
    /// Bytes of each connection this socket made (the last is current).
    received: Vec<Vec<u8>>,
    /// The port each of those connections was made to.
    ports: Vec<u16>,
    /// For each, whether the client reset it or stopped reading it.
    cut: Vec<bool>,
    /// Connections of this socket that were reset by it, or not read
    /// for a while: a refusal sent to them may be lost.
    unclean: u32,
    /// The current connection is among them.
    current_unclean: bool,
}

fn frame(header: Header, station: u8, code: u16, body: &[u8]) -> Vec<u8> {
    let mut buf = vec![0u8; 64 + body.len()];
    let n = emit_frame(
        &mut buf,
        header,
        iai_protocol_b::frame::Station(station),
        code,
        Default::default(),
        |w| w.put(body),
    )
    .unwrap_or(0);
    buf.truncate(n);
    buf
}

/// One round: the clients' interface, the bridge's network side, the
/// bridge, the network side and the clients again; the clients that read
/// take what they received. Checks the host's role.
#[allow(clippy::too_many_arguments)]
fn round(
    now: &mut u32,
    net: &mut Net<'_>,
    bridge: &mut Bridge,
    gateway: &mut Gateway,
    bridge_wire: &mut Wire,
    client_wire: &mut Wire,
    iface: &mut Interface,
    sockets: &mut SocketSet<'_>,
    clients: &mut [Client],
    down: &mut Controller,
) {
    *now = now.wrapping_add(1);
    let t = Instant::from_millis(i64::from(*now));
    iface.poll(t, client_wire, sockets);
    bridge_wire.rx.extend(client_wire.tx.drain(..));
    let _ = net.poll_with(bridge_wire, bridge, Some(&mut *gateway), *now);
    client_wire.rx.extend(bridge_wire.tx.drain(..));
    for _ in 0..16 {
        let mut up = net.host_port();
        match bridge.poll_with(&mut up, down, &mut *gateway, *now) {
            Ok(Poll::Busy) => {}
            Ok(Poll::Wait(w)) if w.deadline == Some(*now) => {}
            _ => break,
        }
    }
    let _ = net.poll_with(bridge_wire, bridge, Some(&mut *gateway), *now);
    client_wire.rx.extend(bridge_wire.tx.drain(..));
    iface.poll(t, client_wire, sockets);
    bridge_wire.rx.extend(client_wire.tx.drain(..));
    for c in clients.iter_mut() {
        let s = sockets.get_mut::<tcp::Socket>(c.handle);
        if c.reading {
            while s.can_recv() {
                let Some(last) = c.received.last_mut() else {
                    break;
                };
                if s.recv(|b| (b.len(), last.extend_from_slice(b))).is_err() {
                    break;
                }
            }
        }
    }
    // One host at most, and the one the session names.
    let hosts: Vec<usize> = (0..SOCKETS)
        .filter(|&n| net.hosts().role(n) == Some(Role::Host))
        .collect();
    assert!(hosts.len() <= 1, "two hosts: {hosts:?}");
    match net.hosts().session() {
        Session::Host(n) => assert_eq!(hosts, [n]),
        Session::Vacant | Session::Draining => assert!(hosts.is_empty()),
    }
}

fuzz_target!(|data: &[u8]| {
    let cfg = Config::DEFAULT;
    let station = cfg.bridge_station;
    let controller_station = cfg.controller_station;
    let canned: [Vec<u8>; 12] = {
        let q212 = frame(Header::Command, controller_station.0, 0x212, b"01");
        let status = frame(Header::Command, station.0, codes::STATUS_QUERY, b"");
        let mut body = Vec::new();
        body.extend_from_slice(b"0000010002");
        for _ in 0..2 {
            body.extend_from_slice(&[b'0'; 60]);
        }
        let d26 = frame(Header::Command, controller_station.0, 0x26D, &body);
        let cut = d26.get(..40).unwrap_or(&d26).to_vec();
        // Modbus TCP ADUs (unit 1): PNOW of axis 1; DRG1 := servo on;
        // two reads in one segment; a read outside the map.
        let pnow = vec![0, 1, 0, 0, 0, 6, 1, 0x03, 0x90, 0x00, 0, 2];
        let servo = vec![0, 2, 0, 0, 0, 6, 1, 0x06, 0x0D, 0x00, 0x10, 0x00];
        let mut two = vec![0, 3, 0, 0, 0, 6, 1, 0x03, 0x90, 0x05, 0, 1];
        two.extend_from_slice(&[0, 4, 0, 0, 0, 6, 1, 0x04, 0x90, 0x00, 0, 2]);
        let outside = vec![0, 5, 0, 0, 0, 6, 1, 0x03, 0xFF, 0xF0, 0, 1];
        // Read Device Identification (43/14) at unit 255; 11H Report
        // Server ID, a 2-byte ADU; 16 whose byte count is not its
        // quantity's; half of a request (the rest never comes).
        let ident = vec![0, 6, 0, 0, 0, 5, 0xFF, 0x2B, 0x0E, 0x01, 0x00];
        let report = vec![0, 7, 0, 0, 0, 2, 1, 0x11];
        let bulk = vec![0, 8, 0, 0, 0, 11, 1, 0x10, 0x0D, 0x03, 0, 1, 4, 0, 9, 0, 9];
        let half = vec![0, 9, 0, 0, 0, 6, 1, 0x03];
        [
            q212, status, d26, cut, pnow, servo, two, outside, ident, report, bulk, half,
        ]
    };

    // The bridge's side: 10.0.0.1, port 5020.
    let net_cfg = NetConfig {
        addressing: Addressing::Static,
        port: PORT,
        address: Ipv4Setting {
            address: [10, 0, 0, 1],
            prefix: 24,
            gateway: None,
        },
    };
    let mut now: u32 = 0;
    let mut bridge_wire = Wire::default();
    let mut slots = EMPTY_SLOTS;
    let mut buffers = Buffers::new();
    let mut net = Net::new(
        net_cfg,
        [0x02, 0, 0, 0, 0, 1],
        1,
        station,
        &mut bridge_wire,
        &mut slots,
        &mut buffers,
        now,
    );
    let mut modbus_buffers = ModbusBuffers::new();
    net.add_modbus(&mut modbus_buffers, MODBUS_PORT);
    let mut bridge = Bridge::new(cfg, Source::Default, 0x5EED);
    let mut gateway = Box::new(Gateway::new(cfg.modbus, cfg.policy));
    let mut down = Controller::default();

    // The clients' side: 10.0.0.2.
    let mut client_wire = Wire::default();
    let mut iface = Interface::new(
        IfaceConfig::new(EthernetAddress([0x02, 0, 0, 0, 0, 2]).into()),
        &mut client_wire,
        Instant::from_millis(0),
    );
    iface.update_ip_addrs(|a| {
        let _ = a.push(IpCidr::new(IpAddress::v4(10, 0, 0, 2), 24));
    });
    let mut storage: [SocketStorage<'_>; CLIENTS] = Default::default();
    let mut sockets = SocketSet::new(&mut storage[..]);
    let mut clients: Vec<Client> = (0..CLIENTS)
        .map(|_| {
            let s = tcp::Socket::new(
                tcp::SocketBuffer::new(vec![0u8; 1024]),
                tcp::SocketBuffer::new(vec![0u8; 2048]),
            );
            Client {
                handle: sockets.add(s),
                reading: true,
                received: Vec::new(),
                ports: Vec::new(),
                cut: Vec::new(),
                unclean: 0,
                current_unclean: false,
            }
        })
        .collect();
    let mut local_port: u16 = 40_000;

    let mut rest = data;
    while let Some((&op, tail)) = rest.split_first() {
        rest = tail;
        let c = usize::from(op >> 4) % CLIENTS;
        let handle = clients[c].handle;
        match op & 0x0F {
            op @ (0 | 7) => {
                let port = if op == 0 { PORT } else { MODBUS_PORT };
                let s = sockets.get_mut::<tcp::Socket>(handle);
                if !s.is_open() {
                    local_port = local_port.wrapping_add(1).max(40_000);
                    if s.connect(
                        iface.context(),
                        (IpAddress::v4(10, 0, 0, 1), port),
                        local_port,
                    )
                    .is_ok()
                    {
                        clients[c].received.push(Vec::new());
                        clients[c].ports.push(port);
                        clients[c].cut.push(false);
                        clients[c].reading = true;
                        clients[c].current_unclean = false;
                    }
                }
            }
            1 => {
                let Some((&n, tail)) = rest.split_first() else {
                    break;
                };
                let n = usize::from(n).min(tail.len());
                let (bytes, tail) = tail.split_at(n);
                rest = tail;
                let _ = sockets.get_mut::<tcp::Socket>(handle).send_slice(bytes);
            }
            2 => {
                let Some((&k, tail)) = rest.split_first() else {
                    break;
                };
                rest = tail;
                let bytes = &canned[usize::from(k) % canned.len()];
                let _ = sockets.get_mut::<tcp::Socket>(handle).send_slice(bytes);
            }
            3 => sockets.get_mut::<tcp::Socket>(handle).close(),
            4 => {
                sockets.get_mut::<tcp::Socket>(handle).abort();
                let cl = &mut clients[c];
                if !cl.current_unclean && !cl.received.is_empty() {
                    cl.current_unclean = true;
                    cl.unclean += 1;
                }
                if let Some(cut) = cl.cut.last_mut() {
                    *cut = true;
                }
            }
            5 => {
                let cl = &mut clients[c];
                cl.reading = !cl.reading;
                if !cl.reading && !cl.current_unclean && !cl.received.is_empty() {
                    cl.current_unclean = true;
                    cl.unclean += 1;
                }
                if !cl.reading {
                    if let Some(cut) = cl.cut.last_mut() {
                        *cut = true;
                    }
                }
            }
            6 => {
                let Some((&t, tail)) = rest.split_first() else {
                    break;
                };
                rest = tail;
                // Time passes in 100 ms steps, each a round.
                for _ in 0..t {
                    now = now.wrapping_add(99);
                    round(
                        &mut now,
                        &mut net,
                        &mut bridge,
                        &mut gateway,
                        &mut bridge_wire,
                        &mut client_wire,
                        &mut iface,
                        &mut sockets,
                        &mut clients,
                        &mut down,
                    );
                }
            }
            _ => {}
        }
        for _ in 0..4 {
            round(
                &mut now,
                &mut net,
                &mut bridge,
                &mut gateway,
                &mut bridge_wire,
                &mut client_wire,
                &mut iface,
                &mut sockets,
                &mut clients,
                &mut down,
            );
        }
    }
    // Everyone reads; 25 s pass.
    for c in clients.iter_mut() {
        c.reading = true;
    }
    for _ in 0..250 {
        now = now.wrapping_add(99);
        round(
            &mut now,
            &mut net,
            &mut bridge,
            &mut gateway,
            &mut bridge_wire,
            &mut client_wire,
            &mut iface,
            &mut sockets,
            &mut clients,
            &mut down,
        );
    }

    // What the clients received: well-formed frames; a refusal alone.
    let refusal = frame(Header::Error, station.0, codes::HOST_BUSY, b"");
    let mut refusals = 0u32;
    for c in &clients {
        for ((conn, &port), &cut) in c.received.iter().zip(&c.ports).zip(&c.cut) {
            if port == MODBUS_PORT {
                check_adus(conn, cut);
                continue;
            }
            if conn.windows(refusal.len()).any(|w| w == refusal.as_slice()) {
                assert_eq!(conn, &refusal, "a refused connection got more");
                refusals += 1;
                continue;
            }
            let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Reject);
            for &b in conn {
                if let Status::Complete(Event::Error(e)) = dec.push(b) {
                    panic!("a broken frame went to a client: {e}");
                }
            }
        }
    }
    // Every refusal reached its connection, unless that client reset it
    // or stopped reading (the bridge resets a refused connection that
    // lingers, and what it had not read is lost with it).
    let refused = net.hosts().stats().refused;
    let unclean: u32 = clients.iter().map(|c| c.unclean).sum();
    assert!(refusals <= refused, "{refusals} B0B for {refused} refusals");
    assert!(
        refusals + unclean >= refused,
        "{refused} refused, {refusals} B0B received, {unclean} connections reset or unread"
    );

    // Downstream: only whole, checked commands for the controller.
    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Reject);
    let mut in_frame = 0usize;
    for &b in &down.output {
        in_frame += 1;
        match dec.push(b) {
            Status::Complete(Event::Frame(f)) => {
                assert_eq!(f.header(), Header::Command);
                assert_eq!(f.station(), controller_station);
                in_frame = 0;
            }
            Status::Complete(Event::Error(e)) => panic!("a broken frame went downstream: {e}"),
            Status::Partial => {}
        }
    }
    assert_eq!(in_frame, 0, "a partial frame went downstream");
});

/// A Modbus TCP connection's bytes: whole ADUs with protocol ID 0 and a
/// length of 2..=254, each a response (a read or write function's, or its
/// exception); the last may be cut if the client reset the connection or
/// stopped reading it (`cut`).
fn check_adus(mut conn: &[u8], cut: bool) {
    while !conn.is_empty() {
        if conn.len() < 8 {
            assert!(
                cut,
                "a cut ADU on a connection read to the end: {conn:02X?}"
            );
            return;
        }
        assert_eq!(&conn[2..4], &[0, 0], "protocol ID: {conn:02X?}");
        let len = usize::from(u16::from_be_bytes([conn[4], conn[5]]));
        assert!((2..=254).contains(&len), "ADU length {len}: {conn:02X?}");
        if conn.len() < 6 + len {
            assert!(
                cut,
                "a cut ADU on a connection read to the end: {conn:02X?}"
            );
            return;
        }
        let function = conn[7] & 0x7F;
        assert!(
            matches!(function, 0x01..=0x06 | 0x0F | 0x10 | 0x2B) || conn[7] & 0x80 != 0,
            "function {:02X} in {conn:02X?}",
            conn[7]
        );
        conn = &conn[6 + len..];
    }
}
