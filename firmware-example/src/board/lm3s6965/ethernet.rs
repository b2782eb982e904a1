//! The LM3S6965 with its host side on Ethernet: protocol B over TCP
//! ([`crate::net`]) through the on-chip MAC and smoltcp, the controller on
//! a UART, the Modbus gateway on Modbus TCP sharing the controller line,
//! the status web page, and a Sparkplug B edge node when its block names
//! a broker. Each comes with its block of the configuration page
//! ([`crate::board::config_page`]); the bridge's flow control setting
//! does not apply (TCP's window holds the host back). Once the interface
//! has an address the board prints
//! `firmware-example: protocol-b-tcp listening on A.B.C.D:PORT (SOURCE)`,
//! `firmware-example: modbus-tcp listening on A.B.C.D:502` and
//! `firmware-example: http listening on A.B.C.D:PORT`.

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use cortex_m::peripheral::NVIC;
use lm3s6965::{interrupt, Interrupt};

use super::{feed_watchdog, read, set_bits, start_watchdog, Uart, SYSCTL_RCGC2};
use crate::board::clock::{now_ms, sleep_unless, start_tick};
use crate::board::config_page::{attach_editor, load_config, load_net, load_sparkplug, web_port};
use crate::board::image::boot_seed;
use crate::board::lines::{build_bridge, build_gateway, hand_over};
use crate::board::report::{banner, Out};
use crate::board::run::{finish, stall_if_asked};
use crate::bridge::Bridge;
use crate::modbus::Gateway;
use crate::net::config::NetSource;
use crate::net::http::HttpBuffers;
use crate::net::modbus::{ModbusBuffers, MODBUS_PORT};
use crate::net::sparkplug::{self, SparkplugBuffers};
use crate::net::stellaris::{self, Mmio, Regs, Stellaris, FRAME_CAP};
use crate::net::{self, AddressSource, Buffers, Net, NetEvent, SocketSlots};
use crate::serial::{DownstreamRings, FlowControl, UartRings, DOWNSTREAM_MARKS};

/// The Ethernet board: the controller's UART, the clock.
pub struct Board {
    /// Name printed in the start-up banner.
    pub name: &'static str,
    /// Core clock (the firmware keeps the one it starts on).
    pub core_clock_hz: u32,
    /// The controller's UART.
    pub controller: Uart,
    /// Watchdog period.
    pub watchdog_ms: u32,
}

// System control: the flash user registers (MAC address).
const SYSCTL_USER0: usize = 0x400F_E1E0;
const SYSCTL_USER1: usize = 0x400F_E1E4;
/// RCGC2: the Ethernet MAC (bit 28) and PHY (bit 30).
const RCGC2_ETH: u32 = (1 << 28) | (1 << 30);

static mut DOWN_LINE: DownstreamRings = UartRings::new();
/// The bridge and the network side, written once at start (kept out of
/// `.data`).
static mut BRIDGE: MaybeUninit<Bridge> = MaybeUninit::uninit();
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();
static mut NET: MaybeUninit<Net<'static>> = MaybeUninit::uninit();
static mut ETH: MaybeUninit<Stellaris<Mmio>> = MaybeUninit::uninit();
static mut SLOTS: MaybeUninit<SocketSlots<'static>> = MaybeUninit::uninit();
/// Zeroed: `.bss`.
static mut BUFFERS: Buffers = Buffers::new();
static mut MODBUS_BUFFERS: ModbusBuffers = ModbusBuffers::new();
static mut SPARKPLUG_BUFFERS: SparkplugBuffers = SparkplugBuffers::new();
static mut HTTP_BUFFERS: HttpBuffers = HttpBuffers::new();
static mut RX_FRAME: [u8; FRAME_CAP] = [0; FRAME_CAP];
static mut TX_FRAME: [u8; FRAME_CAP] = [0; FRAME_CAP];

/// The MAC's interrupt only wakes the loop, which reads the frames.
#[interrupt]
fn ETHERNET() {
    let status = Mmio.read(stellaris::reg::RIS);
    Mmio.write(stellaris::reg::RIS, status);
}

/// What [`setup`] builds.
struct Parts {
    bridge: &'static mut Bridge,
    gateway: &'static mut Gateway,
    net: &'static mut Net<'static>,
    eth: &'static mut Stellaris<Mmio>,
    down: crate::serial::ThreadEnd<'static>,
    mac: [u8; 6],
}

/// Builds the bridge, the driver and the network side in their statics and
/// hands the controller UART's interrupt end over. Not inlined: its frame
/// (the pieces are built on the way into their statics) is gone before the
/// loop runs.
#[inline(never)]
fn setup(board: &Board, now: u32) -> Parts {
    let (cfg, source) = load_config();
    let (net_cfg, net_source) = load_net();
    let web = web_port();
    board
        .controller
        .init(board.core_clock_hz, cfg.downstream_baud);
    set_bits(SYSCTL_RCGC2, RCGC2_ETH);
    let mac = stellaris::mac_from_user(read(SYSCTL_USER0), read(SYSCTL_USER1));
    let seed = boot_seed();
    // SAFETY: `setup` runs once; these are the only references to these
    // statics, and the UART's interrupt is unmasked only after its end was
    // handed over.
    let parts = unsafe {
        let bridge = build_bridge(&mut *addr_of_mut!(BRIDGE), cfg, source);
        let gateway = build_gateway(&mut *addr_of_mut!(GATEWAY), &cfg);
        let eth = (*addr_of_mut!(ETH)).write(Stellaris::new(
            Mmio,
            &mut *addr_of_mut!(RX_FRAME),
            &mut *addr_of_mut!(TX_FRAME),
        ));
        eth.init(mac);
        let slots = (*addr_of_mut!(SLOTS)).write(net::EMPTY_SLOTS);
        let net = (*addr_of_mut!(NET)).write(Net::new(
            net_cfg,
            mac,
            u64::from(seed) << 32 | u64::from(boot_seed()),
            cfg.bridge_station,
            eth,
            slots,
            &mut *addr_of_mut!(BUFFERS),
            now,
        ));
        net.add_modbus(&mut *addr_of_mut!(MODBUS_BUFFERS), MODBUS_PORT);
        net.add_http(&mut *addr_of_mut!(HTTP_BUFFERS), web);
        let down = hand_over(
            &mut *addr_of_mut!(DOWN_LINE),
            FlowControl::None,
            DOWNSTREAM_MARKS,
            board.controller.pend(),
            board.controller.end(),
        );
        Parts {
            bridge,
            gateway,
            net,
            eth,
            down,
            mac,
        }
    };
    banner(board.name, source, FlowControl::None);
    let mut out = Out::new();
    out.str("firmware-example: network block ")
        .str(match net_source {
            NetSource::Block => "Block",
            NetSource::Blank => "Blank",
            NetSource::Invalid(_) => "Invalid",
        })
        .str(", MAC ");
    for (i, b) in mac.iter().enumerate() {
        if i > 0 {
            out.str(":");
        }
        out.hex_byte(*b);
    }
    out.str("\n");
    parts
}

/// Adds the Sparkplug B node its block asks for (none without a broker)
/// and says where it reports. Not inlined, as [`setup`]: the block and its
/// parse are on this frame, gone before the loop runs and not nested in
/// setup's.
#[inline(never)]
fn setup_sparkplug(net: &mut Net<'static>, mac: [u8; 6], now: u32) {
    // SAFETY: called once, at start; the only reference to these buffers.
    let buffers = unsafe { &mut *addr_of_mut!(SPARKPLUG_BUFFERS) };
    net.add_sparkplug(load_sparkplug(), mac, buffers, now);
    if let Some(node) = net.sparkplug() {
        let cfg = node.config();
        let mut out = Out::new();
        out.str("firmware-example: sparkplug ")
            .str(sparkplug::NAMESPACE)
            .str("/")
            .str(&cfg.group)
            .str("/NBIRTH/")
            .str(node.node_id())
            .str(" via broker ");
        dotted(&mut out, cfg.broker);
        out.str(":").dec(u64::from(cfg.port)).str("\n");
    }
}

/// Prints an address change: the line the gateway and the tests wait for.
fn report(event: NetEvent) {
    let mut out = Out::new();
    match event {
        NetEvent::Listening {
            address,
            source,
            port,
            modbus_port,
            http_port,
        } => {
            out.str("firmware-example: protocol-b-tcp listening on ");
            dotted(&mut out, address.address);
            out.str(":").dec(u64::from(port)).str(" (");
            out.str(match source {
                AddressSource::Dhcp => "dhcp",
                AddressSource::Static => "static",
                AddressSource::Fallback => "fallback",
            });
            out.str(")\n");
            if let Some(mb) = modbus_port {
                out.str("firmware-example: modbus-tcp listening on ");
                dotted(&mut out, address.address);
                out.str(":").dec(u64::from(mb)).str("\n");
            }
            if let Some(web) = http_port {
                out.str("firmware-example: http listening on ");
                dotted(&mut out, address.address);
                out.str(":").dec(u64::from(web)).str("\n");
            }
        }
        NetEvent::AddressLost => {
            out.str("firmware-example: DHCP lease lost\n");
        }
        NetEvent::Sparkplug(e) => {
            out.str("firmware-example: sparkplug ");
            match e {
                sparkplug::Event::Connected => out.str("connected"),
                sparkplug::Event::Born { bd_seq } => {
                    out.str("NBIRTH out, bdSeq ").dec(u64::from(bd_seq))
                }
                sparkplug::Event::Refused(code) => {
                    out.str("refused, CONNACK ").dec(u64::from(code))
                }
                sparkplug::Event::Lost => out.str("connection lost"),
            };
            out.str("\n");
        }
    }
}

/// An IPv4 address, dotted.
fn dotted(out: &mut Out, address: [u8; 4]) {
    for (i, b) in address.iter().enumerate() {
        if i > 0 {
            out.str(".");
        }
        out.dec(u64::from(*b));
    }
}

/// The board's counters at the end of a run: the TCP hosts, the Modbus
/// TCP clients and the gateway, the MAC's frames.
fn print_counters(net: &Net<'_>, gateway: &Gateway, eth: &Stellaris<Mmio>) {
    let h = net.hosts().stats();
    let d = eth.stats();
    Out::new()
        .str("firmware-example: tcp hosts ")
        .dec(u64::from(h.hosts))
        .str(" refused ")
        .dec(u64::from(h.refused))
        .str(" cut short ")
        .dec(u64::from(h.cut_short))
        .str(" stalled ")
        .dec(u64::from(h.stalled));
    if let Some(m) = net.modbus() {
        let m = m.stats();
        let g = gateway.stats();
        Out::new()
            .str("; modbus-tcp connections ")
            .dec(u64::from(m.connections))
            .str(" requests ")
            .dec(u64::from(m.requests))
            .str(" answered ")
            .dec(u64::from(g.answered))
            .str(" dropped ")
            .dec(u64::from(g.dropped))
            .str(" idle closed ")
            .dec(u64::from(m.idle_closed));
    }
    Out::new()
        .str("; frames in ")
        .dec(u64::from(d.rx_frames))
        .str(" out ")
        .dec(u64::from(d.tx_frames))
        .str(" dropped ")
        .dec(u64::from(d.rx_dropped))
        .str(" fifo resets ")
        .dec(u64::from(d.rx_resets))
        .str("\n");
}

/// The Ethernet board: the bridge and the gateway behind the network side
/// ([`net::run`]) until the host's quit sequence.
#[inline]
pub fn run(board: &Board) -> ! {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, board.core_clock_hz);
    let Parts {
        bridge,
        gateway,
        net,
        eth,
        mut down,
        mac,
    } = setup(board, now_ms());
    setup_sparkplug(net, mac, now_ms());
    // The page's last block is read: the editor takes the store.
    attach_editor(bridge);
    if let Some((address, source)) = net.address() {
        report(NetEvent::Listening {
            address,
            source,
            port: net.config().port,
            modbus_port: net.modbus().map(|m| m.port()),
            http_port: net.http().map(|h| h.port()),
        });
    }
    // SAFETY: the handlers only touch their own state, handed over above.
    unsafe {
        NVIC::unmask(board.controller.interrupt());
        NVIC::unmask(Interrupt::ETHERNET);
    }
    start_watchdog(board.core_clock_hz, board.watchdog_ms);
    stall_if_asked();
    let result = net::run(
        bridge,
        gateway,
        net,
        eth,
        &mut down,
        now_ms,
        Stellaris::rx_pending,
        sleep_unless,
        feed_watchdog,
        report,
    );
    print_counters(net, gateway, eth);
    finish(result, 0)
}
