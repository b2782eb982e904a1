//! The interface's address in simulated time ([`testkit`]): DHCP without
//! a server gives the network block's fallback after [`DHCP_FALLBACK_MS`]
//! and not before, DHCP goes on asking, and a lease that comes later
//! replaces the fallback (a host connected on the fallback address is let
//! go at once; the next is served on the leased address). The DHCP server
//! is the test's own: OFFER and ACK frames built with smoltcp's wire types.

extern crate std;
use std::cell::RefCell;
use std::rc::Rc;
use std::vec;
use std::vec::Vec;

use iai_protocol_b::checksum::ChecksumMode;
use iai_protocol_b::frame::{emit_frame, Frame, Header};
use smoltcp::phy::ChecksumCapabilities;
use smoltcp::wire::{
    DhcpMessageType, DhcpPacket, DhcpRepr, EthernetFrame, EthernetProtocol, EthernetRepr,
    IpProtocol, Ipv4Packet, Ipv4Repr, UdpPacket, UdpRepr, DHCP_CLIENT_PORT, DHCP_SERVER_PORT,
};

use super::host::Session;
use super::modbus::MODBUS_PORT;
use super::testkit::{net_config, Rig, Server, NET_IP, PB_PORT};
use super::*;
use crate::codes;
use crate::config::Config;

/// The test's DHCP server.
const SERVER_IP: Ipv4Address = Ipv4Address::new(10, 0, 0, 254);
const SERVER_MAC: EthernetAddress = EthernetAddress([0x02, 0, 0, 0, 0, 0xFE]);
/// The address it leases.
const LEASE: [u8; 4] = [10, 0, 0, 50];

/// A DHCP message the bridge's side sent: its type, transaction and
/// hardware address.
fn dhcp_request(frame: &[u8]) -> Option<(DhcpMessageType, u32, EthernetAddress)> {
    let eth = EthernetFrame::new_checked(frame).ok()?;
    if eth.ethertype() != EthernetProtocol::Ipv4 {
        return None;
    }
    let ip = Ipv4Packet::new_checked(eth.payload()).ok()?;
    if ip.next_header() != IpProtocol::Udp {
        return None;
    }
    let udp = UdpPacket::new_checked(ip.payload()).ok()?;
    if udp.dst_port() != DHCP_SERVER_PORT {
        return None;
    }
    let packet = DhcpPacket::new_checked(udp.payload()).ok()?;
    let repr = DhcpRepr::parse(&packet).ok()?;
    Some((
        repr.message_type,
        repr.transaction_id,
        repr.client_hardware_address,
    ))
}

/// The server's `kind` (OFFER or ACK) of [`LEASE`]/24 for transaction
/// `xid` of `client`, broadcast.
fn dhcp_answer(kind: DhcpMessageType, xid: u32, client: EthernetAddress) -> Vec<u8> {
    let repr = DhcpRepr {
        message_type: kind,
        transaction_id: xid,
        secs: 0,
        client_hardware_address: client,
        client_ip: Ipv4Address::UNSPECIFIED,
        your_ip: Ipv4Address::from(LEASE),
        server_ip: SERVER_IP,
        router: None,
        subnet_mask: Some(Ipv4Address::new(255, 255, 255, 0)),
        relay_agent_ip: Ipv4Address::UNSPECIFIED,
        broadcast: false,
        requested_ip: None,
        client_identifier: None,
        server_identifier: Some(SERVER_IP),
        parameter_request_list: None,
        dns_servers: None,
        max_size: None,
        lease_duration: Some(3_600),
        renew_duration: None,
        rebind_duration: None,
        additional_options: &[],
    };
    let udp_len = 8 + repr.buffer_len();
    let ip = Ipv4Repr {
        src_addr: SERVER_IP,
        dst_addr: Ipv4Address::BROADCAST,
        next_header: IpProtocol::Udp,
        payload_len: udp_len,
        hop_limit: 64,
    };
    let eth = EthernetRepr {
        src_addr: SERVER_MAC,
        dst_addr: EthernetAddress::BROADCAST,
        ethertype: EthernetProtocol::Ipv4,
    };
    let mut frame = vec![0u8; eth.buffer_len() + ip.buffer_len() + udp_len];
    let caps = ChecksumCapabilities::default();
    let mut f = EthernetFrame::new_unchecked(&mut frame[..]);
    eth.emit(&mut f);
    let mut p = Ipv4Packet::new_unchecked(f.payload_mut());
    ip.emit(&mut p, &caps);
    let udp = UdpRepr {
        src_port: DHCP_SERVER_PORT,
        dst_port: DHCP_CLIENT_PORT,
    };
    udp.emit(
        &mut UdpPacket::new_unchecked(p.payload_mut()),
        &SERVER_IP.into(),
        &Ipv4Address::BROADCAST.into(),
        repr.buffer_len(),
        |payload| repr.emit(&mut DhcpPacket::new_unchecked(payload)).unwrap(),
        &caps,
    );
    frame
}

/// What the server saw: each DHCP message's tick and type.
type Seen = Rc<RefCell<Vec<(u32, DhcpMessageType)>>>;

/// A DHCP server that answers from tick `up_from` on (a DISCOVER with an
/// OFFER, a REQUEST with an ACK) and notes every message it sees.
fn dhcp_server(up_from: u32, seen: Seen) -> Server {
    std::boxed::Box::new(move |now, frame| {
        let Some((kind, xid, client)) = dhcp_request(frame) else {
            return Vec::new();
        };
        seen.borrow_mut().push((now, kind));
        let answer = match kind {
            DhcpMessageType::Discover => DhcpMessageType::Offer,
            DhcpMessageType::Request => DhcpMessageType::Ack,
            _ => return Vec::new(),
        };
        if now < up_from {
            return Vec::new();
        }
        vec![dhcp_answer(answer, xid, client)]
    })
}

/// The bridge's status query.
fn status_query() -> Vec<u8> {
    let mut buf = [0u8; 32];
    let n = emit_frame(
        &mut buf,
        Header::Command,
        Config::DEFAULT.bridge_station,
        codes::STATUS_QUERY,
        ChecksumMode::Compute,
        |_| Ok(()),
    )
    .unwrap();
    buf[..n].to_vec()
}

/// Whether `bytes` is the status query's answer, whole.
fn is_status_answer(bytes: &[u8]) -> bool {
    Frame::new_checked(bytes, Default::default()).is_ok_and(|f| {
        f.header() == Header::Response
            && f.station() == Config::DEFAULT.bridge_station
            && f.code() == codes::STATUS_QUERY
    })
}

#[test]
fn without_dhcp_the_fallback_after_its_delay_then_a_late_lease_replaces_it() {
    // The server answers from 15 s on, after the fallback.
    let server_up = DHCP_FALLBACK_MS + 5_000;
    let cfg = net_config(Addressing::Dhcp);
    let mut rig = Rig::new(cfg);
    rig.serve_bridge = true;
    let seen: Seen = Rc::default();
    rig.server = Some(dhcp_server(server_up, seen.clone()));

    // A host tries the fallback address from 5 s on: nobody answers it
    // before the fallback.
    rig.run(5_000, 1);
    rig.connect(0, PB_PORT, 42_000);
    rig.run(DHCP_FALLBACK_MS - 1 - rig.now, 1);
    assert_eq!(rig.events, []);
    assert_eq!(rig.net.address(), None);
    assert!(!rig.client(0).may_send(), "{}", rig.client(0).state());
    let asked: Vec<_> = seen.borrow().clone();
    assert!(
        !asked.is_empty() && asked.iter().all(|&(_, k)| k == DhcpMessageType::Discover),
        "{asked:?}"
    );

    // The fallback, on time: the block's address, then the host is served.
    rig.run(2, 1);
    let fallback = NetEvent::Listening {
        address: cfg.address,
        source: AddressSource::Fallback,
        port: PB_PORT,
        modbus_port: Some(MODBUS_PORT),
        http_port: None,
    };
    assert_eq!(rig.events, [(DHCP_FALLBACK_MS, fallback)]);
    assert_eq!(
        rig.net.address(),
        Some((cfg.address, AddressSource::Fallback))
    );
    assert!(rig.run_until(5_000, 1, |r| r.client(0).may_send()));
    rig.client(0).send_slice(&status_query()).unwrap();
    rig.run(50, 1);
    assert!(is_status_answer(&rig.received(0)));
    let Session::Host(on_fallback) = rig.net.hosts().session() else {
        panic!("{:?}", rig.net.hosts().session())
    };

    // DHCP goes on asking; the server, up at 15 s, answers the next
    // DISCOVER: the lease replaces the fallback.
    let leased = rig.run_until(30_000, 1, |r| r.events.len() > 1);
    assert!(leased, "no lease; DHCP seen: {:?}", seen.borrow());
    let (at, event) = rig.events[1];
    let lease = Ipv4Setting {
        address: LEASE,
        prefix: 24,
        gateway: None,
    };
    assert_eq!(
        event,
        NetEvent::Listening {
            address: lease,
            source: AddressSource::Dhcp,
            port: PB_PORT,
            modbus_port: Some(MODBUS_PORT),
            http_port: None,
        }
    );
    assert_eq!(rig.net.address(), Some((lease, AddressSource::Dhcp)));
    let asked: Vec<_> = seen.borrow().clone();
    let discover = asked
        .iter()
        .find(|&&(t, k)| t >= server_up && k == DhcpMessageType::Discover)
        .map(|&(t, _)| t)
        .unwrap_or_else(|| panic!("no DISCOVER after the server came up: {asked:?}"));
    assert!(
        asked
            .iter()
            .any(|&(t, k)| t > DHCP_FALLBACK_MS && t < server_up && k == DhcpMessageType::Discover),
        "DHCP stopped asking after the fallback: {asked:?}"
    );
    assert!(
        at >= discover && at < discover + 10,
        "lease at {at}, DISCOVER at {discover}"
    );
    std::eprintln!("fallback at {DHCP_FALLBACK_MS} ms; DHCP seen {asked:?}; lease at {at} ms");

    // The host on the fallback address is let go at once (its socket's
    // address is gone); the next host is served on the lease.
    let let_go = rig.run_until(100, 1, |r| {
        r.net.hosts().session() != Session::Host(on_fallback)
    });
    assert!(let_go, "the fallback's host still holds the bridge");
    assert!(
        rig.now - at < 5,
        "let go {} ms after the lease",
        rig.now - at
    );
    rig.connect_to(1, LEASE, PB_PORT, 42_001);
    rig.send_when_connected(1, &status_query(), 100);
    let mut got = Vec::new();
    let served = rig.run_until(3_000, 1, |r| {
        got.extend(r.received(1));
        got.ends_with(b"\r\n")
    });
    assert!(served && is_status_answer(&got), "{got:?}");
    // Nothing answers on the fallback address any more.
    rig.connect_to(2, NET_IP, PB_PORT, 42_002);
    rig.run(3_000, 1);
    assert!(!rig.client(2).may_send(), "{}", rig.client(2).state());
    assert_eq!(rig.events.len(), 2, "{:?}", rig.events);
}
