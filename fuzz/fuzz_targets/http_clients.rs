//! The web page's request path on arbitrary connection events: the
//! Ethernet build's network side (`net::Net` with the web sockets,
//! `net::http`, the protocol-B and Modbus TCP sockets), the bridge with an
//! editor over a page store in RAM and the Modbus gateway, against a second
//! smoltcp interface with three web clients, joined by an in-memory wire.
//!
//! Input: operations, each an op byte and its arguments; client `c` is
//! `op >> 4 % 3`:
//!
//! - `0`: client `c` connects to the web port (if closed);
//! - `1 n bytes..`: client `c` sends up to `n` bytes of the input;
//! - `2 k`: client `c` sends canned request `k` (the pages, forms with the
//!   password, a wrong one, from another origin, with basic
//!   authentication, a restart, a head of 1,100 bytes);
//! - `3`: client `c` closes its sending side; `4`: aborts; `5`: stops or
//!   starts reading;
//! - `6 t`: `t` x 100 ms pass;
//! - anything else: one more round.
//!
//! After each, a few 1 ms rounds; at the end 12 s with every client
//! reading, then a protocol-B client asks the bridge's status and a
//! Modbus TCP client reads PNOW.
//!
//! Checked: no panic; every web connection receives nothing (reset) or an
//! answer that begins `HTTP/1.1 ` with a status this server sends; the
//! page in force is whole and every block in it checks; the bridge still
//! answers its status query and the gateway a Modbus read.
#![no_main]

#[path = "common/wire.rs"]
mod wire;

use std::mem::MaybeUninit;
use std::ptr::addr_of_mut;

use firmware_example::bridge::{Bridge, NoPort};
use firmware_example::codes;
use firmware_example::config::editor::Editor;
use firmware_example::config::store::{self, MemFlash, PageStore, Store};
use firmware_example::config::{Config, Source, MAGIC};
use firmware_example::modbus::Gateway;
use firmware_example::net::config::{Addressing, Ipv4Setting, NetConfig};
use firmware_example::net::http::HttpBuffers;
use firmware_example::net::modbus::ModbusBuffers;
use firmware_example::net::{Buffers, Net, EMPTY_SLOTS};
use iai_protocol_b::frame::{emit_frame, Header, Station};
use libfuzzer_sys::fuzz_target;
use smoltcp::iface::{Config as IfaceConfig, Interface, SocketHandle, SocketSet, SocketStorage};
use smoltcp::socket::tcp;
use smoltcp::time::Instant;
use smoltcp::wire::{EthernetAddress, IpAddress, IpCidr};
use wire::Wire;

const WEB_CLIENTS: usize = 3;
const PB_PORT: u16 = 5020;
const MODBUS_PORT: u16 = 502;
const WEB_PORT: u16 = 80;

static mut PAGE: [u8; 2048] = [0xFF; 2048];
static mut STORE: MaybeUninit<Store<MemFlash<'static, 1024, 4>>> = MaybeUninit::uninit();
static mut EDITOR: MaybeUninit<Editor<'static>> = MaybeUninit::uninit();

fn no_restart() {}

/// A fresh editor over erased slots (one input at a time; the last run's
/// bridge is gone).
fn editor() -> &'static mut Editor<'static> {
    // SAFETY: see above.
    unsafe {
        let page = &mut *addr_of_mut!(PAGE);
        page.fill(0xFF);
        let store = (*addr_of_mut!(STORE)).write(Store::open(MemFlash::new(page), 0));
        let store: &'static mut dyn PageStore = store;
        (*addr_of_mut!(EDITOR)).write(Editor::new(store, no_restart, 1))
    }
}

fn post(path: &str, origin: &str, body: &str) -> Vec<u8> {
    format!(
        "POST {path} HTTP/1.1\r\nHost: 10.0.0.1\r\nOrigin: {origin}\r\n\
         Content-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

fn canned() -> Vec<Vec<u8>> {
    let get = |path: &str| format!("GET {path} HTTP/1.1\r\nHost: 10.0.0.1\r\n\r\n").into_bytes();
    vec![
        get("/"),
        get("/live"),
        get("/config"),
        get("/frames.txt"),
        post(
            "/config",
            "http://10.0.0.1",
            "modbus.unit=7&new_password=plant-1234&new_password2=plant-1234",
        ),
        post(
            "/config",
            "http://10.0.0.1",
            "modbus.unit=9&web.reads=password&password=plant-1234",
        ),
        post("/config", "http://10.0.0.1", "modbus.unit=9&password=plant-0000"),
        post("/config", "http://evil.example", "modbus.unit=3&password=plant-1234"),
        post("/restart", "http://10.0.0.1", "password=plant-1234"),
        b"GET /live HTTP/1.1\r\nHost: 10.0.0.1\r\nAuthorization: Basic Z2F0ZXdheTpwbGFudC0xMjM0\r\n\r\n"
            .to_vec(),
        format!(
            "GET / HTTP/1.1\r\nHost: 10.0.0.1\r\nX-Pad: {}\r\n\r\n",
            "a".repeat(1_100)
        )
        .into_bytes(),
    ]
}

/// The statuses this server answers with.
const STATUSES: [&str; 15] = [
    "200", "400", "401", "403", "404", "405", "408", "409", "411", "413", "415", "429", "431",
    "500", "503",
];

struct Side<'a> {
    now: u32,
    net: Net<'a>,
    bridge: Bridge,
    gateway: Box<Gateway>,
    wire: Wire,
    cwire: Wire,
    iface: Interface,
    sockets: SocketSet<'a>,
}

impl Side<'_> {
    fn round(&mut self) {
        self.now = self.now.wrapping_add(1);
        let t = Instant::from_millis(i64::from(self.now));
        self.iface.poll(t, &mut self.cwire, &mut self.sockets);
        self.wire.rx.extend(self.cwire.tx.drain(..));
        let _ = self.net.poll_with(
            &mut self.wire,
            &mut self.bridge,
            Some(&mut *self.gateway),
            self.now,
        );
        for _ in 0..16 {
            let mut up = self.net.host_port();
            if !matches!(
                self.bridge.poll(&mut up, &mut NoPort, self.now),
                Ok(firmware_example::bridge::Poll::Busy)
            ) {
                break;
            }
        }
        self.cwire.rx.extend(self.wire.tx.drain(..));
        self.iface.poll(t, &mut self.cwire, &mut self.sockets);
        self.wire.rx.extend(self.cwire.tx.drain(..));
    }

    fn take(&mut self, h: SocketHandle, into: &mut Vec<u8>) {
        let s = self.sockets.get_mut::<tcp::Socket>(h);
        while s.can_recv() {
            if s.recv(|b| (b.len(), into.extend_from_slice(b))).is_err() {
                break;
            }
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let canned = canned();
    let net_cfg = NetConfig {
        addressing: Addressing::Static,
        port: PB_PORT,
        address: Ipv4Setting {
            address: [10, 0, 0, 1],
            prefix: 24,
            gateway: None,
        },
    };
    let mut wire = Wire::default();
    let mut slots = EMPTY_SLOTS;
    let mut buffers = Buffers::new();
    let mut modbus_buffers = ModbusBuffers::new();
    let mut http_buffers = Box::new(HttpBuffers::new());
    let cfg = Config::DEFAULT;
    let mut net = Net::new(
        net_cfg,
        [0x02, 0, 0, 0, 0, 1],
        1,
        cfg.bridge_station,
        &mut wire,
        &mut slots,
        &mut buffers,
        0,
    );
    net.add_modbus(&mut modbus_buffers, MODBUS_PORT);
    net.add_http(&mut http_buffers, WEB_PORT);
    let mut bridge = Bridge::new(cfg, Source::Default, 0x5EED);
    bridge.attach_editor(editor());
    let mut gateway = Box::new(Gateway::new(cfg.modbus, cfg.policy));
    gateway.regs.cache.axes[0].current_position = 12_000;

    let mut cwire = Wire::default();
    let mut iface = Interface::new(
        IfaceConfig::new(EthernetAddress([0x02, 0, 0, 0, 0, 2]).into()),
        &mut cwire,
        Instant::from_millis(0),
    );
    iface.update_ip_addrs(|a| {
        let _ = a.push(IpCidr::new(IpAddress::v4(10, 0, 0, 2), 24));
    });
    let mut storage: [SocketStorage<'_>; WEB_CLIENTS + 2] = Default::default();
    let mut sockets = SocketSet::new(&mut storage[..]);
    let handles: Vec<SocketHandle> = (0..WEB_CLIENTS + 2)
        .map(|_| {
            sockets.add(tcp::Socket::new(
                tcp::SocketBuffer::new(vec![0u8; 2048]),
                tcp::SocketBuffer::new(vec![0u8; 2048]),
            ))
        })
        .collect();
    let mut side = Side {
        now: 0,
        net,
        bridge,
        gateway,
        wire,
        cwire,
        iface,
        sockets,
    };
    // What each web connection received (the last is current).
    let mut got: Vec<Vec<Vec<u8>>> = vec![Vec::new(); WEB_CLIENTS];
    let mut reading = [true; WEB_CLIENTS];
    let mut local_port: u16 = 40_000;

    let mut rest = data;
    while let Some((&op, tail)) = rest.split_first() {
        rest = tail;
        let c = usize::from(op >> 4) % WEB_CLIENTS;
        let h = handles[c];
        match op & 0x0F {
            0 => {
                let s = side.sockets.get_mut::<tcp::Socket>(h);
                if !s.is_open() {
                    local_port = local_port.wrapping_add(1).max(40_000);
                    if s.connect(
                        side.iface.context(),
                        (IpAddress::v4(10, 0, 0, 1), WEB_PORT),
                        local_port,
                    )
                    .is_ok()
                    {
                        got[c].push(Vec::new());
                        reading[c] = true;
                    }
                }
            }
            1 => {
                let Some((&n, tail)) = rest.split_first() else {
                    break;
                };
                let n = usize::from(n).min(tail.len());
                let _ = side
                    .sockets
                    .get_mut::<tcp::Socket>(h)
                    .send_slice(&tail[..n]);
                rest = &tail[n..];
            }
            2 => {
                let Some((&k, tail)) = rest.split_first() else {
                    break;
                };
                rest = tail;
                let bytes = &canned[usize::from(k) % canned.len()];
                let _ = side.sockets.get_mut::<tcp::Socket>(h).send_slice(bytes);
            }
            3 => side.sockets.get_mut::<tcp::Socket>(h).close(),
            4 => side.sockets.get_mut::<tcp::Socket>(h).abort(),
            5 => reading[c] = !reading[c],
            6 => {
                let Some((&t, tail)) = rest.split_first() else {
                    break;
                };
                rest = tail;
                for _ in 0..t {
                    side.now = side.now.wrapping_add(99);
                    side.round();
                }
            }
            _ => {}
        }
        for _ in 0..4 {
            side.round();
            for n in 0..WEB_CLIENTS {
                if reading[n] {
                    if let Some(last) = got[n].last_mut() {
                        side.take(handles[n], last);
                    }
                }
            }
        }
    }
    for _ in 0..120 {
        side.now = side.now.wrapping_add(99);
        side.round();
        for n in 0..WEB_CLIENTS {
            if let Some(last) = got[n].last_mut() {
                side.take(handles[n], last);
            }
        }
    }

    // Every web answer begins with a status line this server sends.
    for conn in got.iter().flatten() {
        if conn.is_empty() {
            continue;
        }
        let head = String::from_utf8_lossy(&conn[..conn.len().min(12)]).into_owned();
        if conn.len() >= 12 {
            assert!(head.starts_with("HTTP/1.1 "), "{head:?}");
            assert!(STATUSES.contains(&&head[9..12]), "{head:?}");
        } else {
            assert!(
                "HTTP/1.1 200".starts_with(&head[..head.len().min(9)]),
                "{head:?}"
            );
        }
    }

    // The page in force: whole, its bridge block checks.
    {
        let e = side.bridge.editor().expect("attached");
        if e.sequence().is_some() {
            let mut p = vec![0u8; 1024];
            e.store().read(0, &mut p).expect("readable");
            // SAFETY: the editor is done with the slots for now.
            let slots = unsafe { &*addr_of_mut!(PAGE) };
            let (in_force, _) = store::page_in(slots, 1024).expect("whole");
            assert_eq!(in_force, &p[..]);
            if p[..4] == MAGIC {
                assert!(Config::parse(&p).is_ok());
            }
        }
    }

    // Protocol B and Modbus TCP still answer.
    let pb = handles[WEB_CLIENTS];
    let mb = handles[WEB_CLIENTS + 1];
    let ctx = side.iface.context();
    let _ = side.sockets.get_mut::<tcp::Socket>(pb).connect(
        ctx,
        (IpAddress::v4(10, 0, 0, 1), PB_PORT),
        50_000,
    );
    let ctx = side.iface.context();
    let _ = side.sockets.get_mut::<tcp::Socket>(mb).connect(
        ctx,
        (IpAddress::v4(10, 0, 0, 1), MODBUS_PORT),
        50_001,
    );
    for _ in 0..50 {
        side.round();
    }
    let mut status = [0u8; 16];
    let n = emit_frame(
        &mut status,
        Header::Command,
        Station(0xBB),
        codes::STATUS_QUERY,
        Default::default(),
        |_| Ok(()),
    )
    .unwrap_or(0);
    let _ = side
        .sockets
        .get_mut::<tcp::Socket>(pb)
        .send_slice(&status[..n]);
    let _ = side
        .sockets
        .get_mut::<tcp::Socket>(mb)
        .send_slice(&[0, 7, 0, 0, 0, 6, 1, 4, 0x90, 0, 0, 2]);
    let (mut pb_got, mut mb_got) = (Vec::new(), Vec::new());
    for _ in 0..200 {
        side.round();
        side.take(pb, &mut pb_got);
        side.take(mb, &mut mb_got);
    }
    assert!(
        pb_got.starts_with(b"#BBB00"),
        "{:?}",
        String::from_utf8_lossy(&pb_got)
    );
    assert_eq!(mb_got, [0, 7, 0, 0, 0, 7, 1, 4, 4, 0, 0, 0x2E, 0xE0]);
});
