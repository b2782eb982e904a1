//! The gateway: the bridge firmware under QEMU with the controller
//! simulator behind it and its host side on a TCP port, so that any
//! protocol-B client (`iai --tcp 127.0.0.1:PORT`) talks to the bridge as
//! through a serial cable. Run by `tools/gateway.sh` (binary `gateway`).
//!
//! QEMU models neither baud rates nor flow control, and a UART fed in
//! bursts overruns the bridge's receive rings (see the README, "Flow
//! control"). So neither side is wired straight to a socket:
//!
//! - **Host side**: the TCP client's bytes go to the bridge's first UART
//!   through a [`HostLink`]: at the line rate, only once QEMU has read the
//!   previous ones, stopped by the bridge's XOFF and restarted by its XON,
//!   as a PC's serial port with IXON does. XON and XOFF from the bridge are
//!   flow control, not data: they never reach the client; the bridge's
//!   other bytes go to the client as they come. One client at a time
//!   ([`run`]).
//! - **Controller side**: the simulator (`iai_simulator`, the controller
//!   `iai simulate` runs) serves the second UART in this process
//!   ([`SimThread`]), its replies paced to the line rate the same way.
//!
//! On a board with the Modbus RTU port (`lm3s6965evb`, its third UART),
//! that port is on a second TCP port, relayed as an RTU line
//! ([`crate::rtu_relay`]). With [`Options::ethernet`] the firmware's own
//! TCP stack is the host side ([`run_ethernet`]).

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use firmware_example::codes;
use firmware_example::config::Config;
use firmware_example::serial::XON;
use iai_protocol_b::frame::Station;
use iai_protocol_b::line;

use crate::bridge::{status_query, status_query_frame, HostLink, SimThread};
use crate::qemu::{
    build_ethernet_firmware, build_firmware, image_loader_arg, page_image, Board, ExitOutcome,
    QemuSession, QUIT_GUARD, QUIT_SEQUENCE, READY_MARKER,
};
use crate::rtu_relay::RtuRelay;
use firmware_example::config::access::DEFAULT_WEB_PORT;
use firmware_example::net::config::{NetConfig, DEFAULT_PORT};
use firmware_example::net::modbus::MODBUS_PORT;
use firmware_example::net::sparkplug::config::SparkplugConfig;
use iai_simulator::{Faults, Simulator};

/// What the gateway runs.
#[derive(Debug, Clone)]
pub struct Options {
    /// The QEMU board.
    pub board: Board,
    /// Line rate of both sides (one of `firmware_example::config::BAUD_RATES`).
    pub baud: u32,
    /// TCP port on 127.0.0.1 for the host side (0: a free one).
    pub port: u16,
    /// TCP port on 127.0.0.1 for the Modbus RTU port, on a board that has
    /// one (0: a free one).
    pub modbus_port: u16,
    /// Line rate of the Modbus RTU port.
    pub modbus_baud: u32,
    /// At the stop, end the firmware with the quit sequence (honoured only
    /// then: `quit_sequence` in the configuration block; with `ethernet`
    /// sent on a new connection to the protocol-B port) and log its stack
    /// peak (`firmware stack peak N bytes`), for the size report.
    pub stack_report: bool,
    /// The simulated controller's time per command, ms.
    pub reply_delay_ms: u32,
    /// Faults the simulated controller injects.
    pub faults: Faults,
    /// Seed of the fault draws.
    pub seed: u64,
    /// The firmware ELF (default: built with the `firmware` profile).
    pub elf: Option<PathBuf>,
    /// Protocol B over TCP: the Ethernet build (`lm3s6965-eth`) with
    /// QEMU's user network forwarding 127.0.0.1:`port` to the bridge's
    /// protocol-B port and 127.0.0.1:`modbus_port` to its Modbus TCP port
    /// (see [`run_ethernet`]).
    pub ethernet: bool,
    /// Ethernet only: the bridge honours the quit sequence (for test runs
    /// that end with [`EthernetGateway::quit`]).
    pub quit_sequence: bool,
    /// Ethernet only: TCP port on 127.0.0.1 forwarded to the web page (0:
    /// a free one).
    pub http_port: u16,
    /// Ethernet only: a network block written into the configuration page
    /// (`None`: blank, so DHCP and port 5020). Its port is the one QEMU
    /// forwards to; a static address must be QEMU's guest address,
    /// 10.0.2.15.
    pub network: Option<NetConfig>,
    /// Ethernet only: a Sparkplug block written into the configuration
    /// page (`None`: blank, the edge node off). Its broker is seen from
    /// the guest: QEMU's user network maps 10.0.2.2 to this machine's
    /// loopback ([`QEMU_HOST`]).
    pub sparkplug: Option<SparkplugConfig>,
    /// Ethernet only: the bridge's configuration block, if not the
    /// gateway's own ([`config`]).
    pub bridge_config: Option<Config>,
    /// The configuration page the firmware boots with.
    pub page: PageSource,
}

/// Where the firmware's configuration page comes from.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum PageSource {
    /// The gateway's own: the bridge block of [`config`] (and
    /// [`Options::network`]).
    #[default]
    Built,
    /// This image of both slots (`iai bridge config block`, or `iai
    /// bridge config get --image` from an earlier run), loaded at
    /// `_bridge_config`.
    Image(PathBuf),
    /// Nothing loaded: a blank page, every default (the quit sequence
    /// off).
    Blank,
}

/// The address of this machine's loopback as QEMU's user network shows
/// it to the guest.
pub const QEMU_HOST: [u8; 4] = [10, 0, 2, 2];

impl Default for Options {
    fn default() -> Self {
        Options {
            board: Board::Lm3s6965,
            baud: 115_200,
            port: 0,
            modbus_port: 0,
            modbus_baud: firmware_example::config::ModbusConfig::DEFAULT.baud,
            stack_report: false,
            reply_delay_ms: 2,
            faults: Faults::default(),
            seed: 1,
            elf: None,
            ethernet: false,
            quit_sequence: false,
            http_port: 0,
            network: None,
            sparkplug: None,
            bridge_config: None,
            page: PageSource::Built,
        }
    }
}

/// The QEMU arguments that load `opts`' configuration page, and the
/// configuration to load instead ([`QemuSession::start_tied`]'s).
fn page_args(
    opts: &Options,
    elf: &std::path::Path,
    cfg: &Config,
) -> Result<(Vec<String>, Option<Config>), String> {
    match &opts.page {
        PageSource::Built if opts.ethernet => {
            let image = page_image(
                Board::Lm3s6965.config_slot_len(),
                cfg,
                opts.network.as_ref(),
                opts.sparkplug.as_ref(),
            );
            let loader = image_loader_arg(elf, &image).map_err(|e| e.to_string())?;
            Ok((vec!["-device".into(), loader], None))
        }
        PageSource::Built => Ok((Vec::new(), Some(*cfg))),
        PageSource::Image(file) => {
            let image = std::fs::read(file).map_err(|e| format!("{}: {e}", file.display()))?;
            let loader = image_loader_arg(elf, &image).map_err(|e| e.to_string())?;
            Ok((vec!["-device".into(), loader], None))
        }
        PageSource::Blank => Ok((Vec::new(), None)),
    }
}

/// How long QEMU may take to boot the firmware.
const BOOT_TIMEOUT: Duration = Duration::from_secs(30);
/// How long the bridge may take to answer its status query: it first
/// finishes what it was doing (a command it forwarded waits
/// [`line::TIMEOUT_MS`] for the controller, [`line::MAX_SENDS`] times
/// over), with room to spare.
const FENCE_TIMEOUT: Duration =
    Duration::from_millis(line::TIMEOUT_MS as u64 * line::MAX_SENDS as u64 + 6_000);
/// A client that takes nothing for this long is dropped.
const CLIENT_WRITE_TIMEOUT: Duration = Duration::from_secs(10);
/// How often the loops look at their stop flags.
const POLL: Duration = Duration::from_millis(20);

/// The configuration block the gateway boots the bridge with:
/// [`Config::DEFAULT`] at `baud` on both protocol-B sides, the Modbus
/// port's defaults (unit 1, even parity) at `modbus_baud`. The quit
/// sequence stays off, since a client's bytes could hold it.
pub fn config(baud: u32, modbus_baud: u32) -> Config {
    let mut cfg = Config {
        upstream_baud: baud,
        downstream_baud: baud,
        ..Config::DEFAULT
    };
    cfg.modbus.baud = modbus_baud;
    cfg
}

/// Where the gateway listens, once it is ready.
#[derive(Debug, Clone)]
pub struct Ready {
    /// The protocol-B host side: the relay's port, or with `--ethernet`
    /// the port QEMU forwards to the firmware's own TCP stack.
    pub protocol_b: SocketAddr,
    /// Protocol B over TCP straight to the firmware (the Ethernet build),
    /// not through the serial relay.
    pub over_ethernet: bool,
    /// The Modbus RTU port, on a board that has one.
    pub modbus_rtu: Option<SocketAddr>,
    /// Modbus TCP straight to the firmware (the Ethernet build).
    pub modbus_tcp: Option<SocketAddr>,
    /// The NBIRTH topic, once the Sparkplug edge node has published it.
    pub sparkplug: Option<String>,
    /// The web page (the Ethernet build).
    pub http: Option<SocketAddr>,
}

fn log(line: &str) {
    let mut err = io::stderr().lock();
    let _ = writeln!(err, "gateway: {line}");
}

/// Boots the bridge, puts the simulator behind it, listens on
/// 127.0.0.1:`port` (and `modbus_port` on a board with the Modbus port),
/// calls `on_ready` with those addresses once the bridge has answered
/// through the relay, and relays clients until `stop` is set, one at a
/// time (`serve`).
/// An error if anything fails to start or QEMU exits on its own; QEMU is
/// stopped in every case.
///
/// The simulator runs in this process rather than as an `iai simulate
/// --connect` process: pacing needs to know how much QEMU has not read
/// yet, which a Unix socket to QEMU tells (`SIOCOUTQ`) and a TCP socket
/// does not (loopback TCP counts bytes as delivered once the kernel holds
/// them); and one process is one thing to stop: QEMU is this process's
/// child, killed through its own handle (and by the kernel should this
/// process die without stopping it, [`QemuSession::start_tied`]), and the
/// simulator is a thread.
pub fn run(opts: &Options, stop: &AtomicBool, on_ready: impl FnOnce(Ready)) -> Result<(), String> {
    for b in [opts.baud, opts.modbus_baud] {
        if !firmware_example::config::BAUD_RATES.contains(&b) {
            return Err(format!(
                "baud rate {b} is not one the bridge runs at ({:?})",
                firmware_example::config::BAUD_RATES
            ));
        }
    }
    if opts.ethernet {
        return run_ethernet(opts, stop, on_ready);
    }
    let listener = TcpListener::bind(("127.0.0.1", opts.port))
        .map_err(|e| format!("cannot listen on 127.0.0.1:{}: {e}", opts.port))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    listener
        .set_nonblocking(true)
        .map_err(|e| format!("listener: {e}"))?;
    let modbus_listener = if opts.board.has_modbus() {
        let l = TcpListener::bind(("127.0.0.1", opts.modbus_port))
            .map_err(|e| format!("cannot listen on 127.0.0.1:{}: {e}", opts.modbus_port))?;
        Some(l)
    } else {
        None
    };
    let modbus_addr = match &modbus_listener {
        Some(l) => Some(l.local_addr().map_err(|e| e.to_string())?),
        None => None,
    };
    let elf = match &opts.elf {
        Some(p) => p.clone(),
        None => build_firmware(opts.board)
            .map_err(|e| format!("building the firmware for {}: {e}", opts.board))?,
    };
    let mut cfg = config(opts.baud, opts.modbus_baud);
    cfg.quit_sequence = opts.stack_report;
    let (args, loaded) = page_args(opts, &elf, &cfg)?;
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    // Tied: QEMU goes with this thread even if the process is killed.
    let mut qemu = QemuSession::start_tied(
        opts.board,
        &elf,
        BOOT_TIMEOUT,
        Some(READY_MARKER),
        &args,
        loaded.as_ref(),
        modbus_listener.is_some(),
    )
    .map_err(|e| format!("starting QEMU: {e}"))?;

    let mut sim = Simulator::tta(cfg.controller_station);
    sim.response_delay_ms = opts.reply_delay_ms;
    sim.refuse = true;
    let sim = sim.with_faults(opts.faults.clone(), opts.seed);
    let downstream = qemu
        .downstream
        .try_clone()
        .map_err(|e| format!("controller side: {e}"))?;
    let sim = SimThread::spawn(sim, downstream, Some(opts.baud));
    let link = HostLink::new(&qemu.upstream, Some(opts.baud), true)
        .map_err(|e| format!("host side: {e}"))?;
    let link = Arc::new(link);
    // The relay's own flag: set when the gateway stops, whatever stopped it.
    let relay_stop = Arc::new(AtomicBool::new(false));
    let relay = match (modbus_listener, &qemu.modbus) {
        (Some(l), Some(uart)) => {
            let r = RtuRelay::spawn(l, uart, opts.modbus_baud, Arc::clone(&relay_stop))
                .map_err(|e| format!("Modbus side: {e}"))?;
            Some(r)
        }
        _ => None,
    };

    let (client, result): Served = match status_query(&link, cfg.bridge_station, FENCE_TIMEOUT) {
        Err(e) => (
            None,
            Err(format!("the bridge did not answer through the relay: {e}")),
        ),
        Ok(_) => {
            link.discard_received();
            log(&format!(
                "{} (QEMU pid {}) up; host side relayed at {} baud with XON/XOFF, \
                 simulated controller (station {:02X}) behind it; Ctrl-C stops",
                opts.board,
                qemu.pid(),
                opts.baud,
                cfg.controller_station.0
            ));
            if let Some(at) = modbus_addr {
                log(&format!(
                    "Modbus RTU port (unit {}, {} baud) relayed on {at}",
                    cfg.modbus.unit, cfg.modbus.baud
                ));
            }
            on_ready(Ready {
                protocol_b: addr,
                over_ethernet: false,
                modbus_tcp: None,
                modbus_rtu: modbus_addr,
                sparkplug: None,
                http: None,
            });
            serve(&listener, &link, &mut qemu, stop, cfg.bridge_station)
        }
    };

    // QEMU first: its end closes the lines, which ends the threads.
    if opts.stack_report && result.is_ok() {
        report_stack(qemu);
    } else {
        drop(qemu);
    }
    relay_stop.store(true, Ordering::Relaxed);
    if let Some(client) = client {
        client.join_within(Duration::from_secs(5));
    }
    if let Some(r) = relay {
        let s = r.join();
        log(&format!(
            "Modbus RTU port: {} client(s), {} frame(s) in ({} bytes), {} byte(s) of replies",
            s.clients, s.frames, s.bytes_in, s.bytes_out
        ));
    }
    match sim.join() {
        Ok(sim) => {
            let s = sim.stats();
            log(&format!(
                "stopped; the simulator answered {} command(s) and holds {} position(s)",
                s.commands,
                sim.table.len()
            ));
        }
        Err(e) => log(&format!("stopped; {e}")),
    }
    result
}

/// Ends the firmware with the quit sequence and logs the stack peak it
/// reports; QEMU is killed if it does not end within 10 s.
fn report_stack(mut qemu: QemuSession) {
    if let Err(e) = qemu.quit() {
        log(&format!("no stack peak: sending the quit sequence: {e}"));
        return;
    }
    match qemu.wait(Duration::from_secs(10)) {
        Ok(out) => log_stack_peak(&out.stdout),
        Err(e) => log(&format!("no stack peak: {e}")),
    }
}

/// Logs the stack peak the firmware printed as it ended
/// (`firmware stack peak N bytes`), or that it printed none.
fn log_stack_peak(stdout: &str) {
    match stdout
        .lines()
        .find_map(|l| l.strip_prefix("firmware-example: stack peak "))
        .and_then(|l| l.split_whitespace().next())
    {
        Some(peak) => log(&format!("firmware stack peak {peak} bytes")),
        None => log(&format!(
            "no stack peak in the firmware's output:\n{stdout}"
        )),
    }
}

/// The client served when the relay ended, and how it ended.
type Served = (Option<Client>, Result<(), String>);

/// Relays one client at a time until `stop`; returns the client being
/// served at that moment.
///
/// A connection made while a client is connected is closed at once,
/// unanswered. What a client wrote before it closed its connection is
/// still sent (a serial driver drains its output on close), and one
/// connection made meanwhile waits for that instead of being refused.
/// Between clients the line is made clean ([`settle`]); only then is the
/// next client served (its bytes wait meanwhile).
fn serve(
    listener: &TcpListener,
    link: &Arc<HostLink>,
    qemu: &mut QemuSession,
    stop: &AtomicBool,
    bridge: Station,
) -> Served {
    let mut client: Option<Client> = None;
    // A connection made while the client before it was leaving.
    let mut next: Option<(TcpStream, SocketAddr)> = None;
    loop {
        if stop.load(Ordering::Relaxed) {
            return (client, Ok(()));
        }
        match qemu.try_wait() {
            Ok(None) => {}
            Ok(Some(status)) => {
                // A Ctrl-C on the terminal reaches QEMU as well as us.
                let end = Instant::now() + Duration::from_millis(500);
                while !stop.load(Ordering::Relaxed) && Instant::now() < end {
                    thread::sleep(POLL);
                }
                if stop.load(Ordering::Relaxed) {
                    return (client, Ok(()));
                }
                let why = format!(
                    "QEMU exited on its own ({status})\n{}",
                    qemu.stderr_so_far()
                );
                return (client, Err(why));
            }
            Err(e) => return (client, Err(format!("QEMU: {e}"))),
        }
        retire_finished(&mut client, link, bridge);
        if client.is_none() {
            if let Some((conn, peer)) = next.take() {
                client = admit(conn, peer, link);
            }
        }
        match listener.accept() {
            Ok((conn, peer)) => match &client {
                None if next.is_none() => client = admit(conn, peer, link),
                // The client before closed its connection and its last
                // bytes are still going out: this one waits for them.
                Some(c) if c.leaving() && next.is_none() => next = Some((conn, peer)),
                _ => {
                    log(&format!(
                        "refused {peer}: one client at a time, and one is connected"
                    ));
                    let _ = conn.shutdown(Shutdown::Both);
                }
            },
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => thread::sleep(POLL),
            Err(e) => {
                log(&format!("accept: {e}"));
                thread::sleep(POLL);
            }
        }
    }
}

/// Starts serving `conn`.
fn admit(conn: TcpStream, peer: SocketAddr, link: &Arc<HostLink>) -> Option<Client> {
    // What the bridge sent while nobody listened is not this client's.
    link.discard_received();
    match Client::start(conn, peer, Arc::clone(link)) {
        Ok(c) => {
            log(&format!("{peer} connected"));
            Some(c)
        }
        Err(e) => {
            log(&format!("{peer}: {e}"));
            None
        }
    }
}

/// Takes the client out once its threads ended, and cleans the line.
fn retire_finished(client: &mut Option<Client>, link: &HostLink, bridge: Station) {
    if !client.as_ref().is_some_and(Client::finished) {
        return;
    }
    if let Some(c) = client.take() {
        let end = c.join();
        log(&format!(
            "{} left ({} byte(s) in, {} out{})",
            end.peer,
            end.bytes_in,
            end.bytes_out,
            end.why.map(|w| format!("; {w}")).unwrap_or_default()
        ));
        settle(link, bridge, end.mid_frame);
    }
}

/// Makes the line clean after a client: an XON (in case the client sent
/// an XOFF, which stops the bridge's transmitter), CR LF if it stopped in
/// the middle of a frame (the bridge drops a partial frame, and ends a
/// partial 26DH with `&` B01), then the bridge's own status query, whose
/// reply comes after anything the bridge still owed: what came before it
/// is dropped.
fn settle(link: &HostLink, bridge: Station, mid_frame: bool) {
    let _ = link.write_raw(&[XON]);
    if mid_frame {
        if let Err(e) = link.send(b"\r\n", |_| {}) {
            log(&format!("ending the client's partial frame: {e}"));
        }
    }
    if let Err(e) = status_query(link, bridge, FENCE_TIMEOUT) {
        log(&format!(
            "the bridge did not answer its status query after the client left ({e}); going on"
        ));
    }
    link.discard_received();
}

/// Bytes read from a client and not yet sent to the bridge.
#[derive(Default)]
struct Inbox {
    data: VecDeque<u8>,
    /// The client closed its side (or its connection failed).
    closed: bool,
}

type Shared<T> = Arc<(Mutex<T>, Condvar)>;

fn lock<T>(shared: &Shared<T>) -> MutexGuard<'_, T> {
    shared.0.lock().unwrap_or_else(PoisonError::into_inner)
}

/// One client: a thread reads it, one sends what it wrote to the bridge,
/// one sends the bridge's bytes to it.
struct Client {
    peer: SocketAddr,
    done: Arc<AtomicBool>,
    inbox: Shared<Inbox>,
    threads: [JoinHandle<()>; 3],
    upward: Arc<Mutex<Upward>>,
    bytes_out: Arc<AtomicU64>,
}

/// What went up from a client.
#[derive(Default)]
struct Upward {
    bytes: u64,
    last: Option<u8>,
    why: Option<String>,
}

/// How a client's connection ended.
struct End {
    peer: SocketAddr,
    bytes_in: u64,
    bytes_out: u64,
    mid_frame: bool,
    why: Option<String>,
}

impl Client {
    fn start(conn: TcpStream, peer: SocketAddr, link: Arc<HostLink>) -> io::Result<Client> {
        conn.set_nonblocking(false)?;
        conn.set_nodelay(true)?;
        conn.set_read_timeout(Some(POLL))?;
        conn.set_write_timeout(Some(CLIENT_WRITE_TIMEOUT))?;
        let reader = conn.try_clone()?;
        let done = Arc::new(AtomicBool::new(false));
        let inbox: Shared<Inbox> = Arc::default();
        let upward = Arc::new(Mutex::new(Upward::default()));
        let bytes_out = Arc::new(AtomicU64::new(0));
        let threads = [
            {
                let (done, inbox) = (Arc::clone(&done), Arc::clone(&inbox));
                thread::spawn(move || read_client(reader, &inbox, &done))
            },
            {
                let (done, inbox, link) =
                    (Arc::clone(&done), Arc::clone(&inbox), Arc::clone(&link));
                let up = Arc::clone(&upward);
                thread::spawn(move || forward_up(&inbox, &link, &done, &up))
            },
            {
                let (done, sent) = (Arc::clone(&done), Arc::clone(&bytes_out));
                thread::spawn(move || forward_down(conn, &link, &done, &sent))
            },
        ];
        Ok(Client {
            peer,
            done,
            inbox,
            threads,
            upward,
            bytes_out,
        })
    }

    /// Whether the client closed its side (or the connection failed): it
    /// is leaving, though what it wrote may still be going out.
    fn leaving(&self) -> bool {
        self.done.load(Ordering::Relaxed) || lock(&self.inbox).closed
    }

    fn finished(&self) -> bool {
        self.threads.iter().all(JoinHandle::is_finished)
    }

    fn join(self) -> End {
        let mut why = None;
        for t in self.threads {
            if t.join().is_err() {
                why = Some("a relay thread failed".to_owned());
            }
        }
        let up = std::mem::take(&mut *self.upward.lock().unwrap_or_else(PoisonError::into_inner));
        End {
            peer: self.peer,
            bytes_in: up.bytes,
            bytes_out: self.bytes_out.load(Ordering::Relaxed),
            mid_frame: up.last.is_some_and(|b| b != b'\n'),
            why: up.why.or(why),
        }
    }

    /// Ends the client's threads (they end within [`POLL`] or so, or once
    /// QEMU is gone) and waits up to `limit` for them.
    fn join_within(self, limit: Duration) {
        self.done.store(true, Ordering::Relaxed);
        self.inbox.1.notify_all();
        let end = Instant::now() + limit;
        while !self.finished() && Instant::now() < end {
            thread::sleep(POLL);
        }
        if self.finished() {
            self.join();
        }
    }
}

/// Reads everything the client writes into `inbox` until it closes.
fn read_client(mut conn: TcpStream, inbox: &Shared<Inbox>, done: &AtomicBool) {
    let mut buf = [0u8; 4096];
    while !done.load(Ordering::Relaxed) {
        match conn.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                lock(inbox)
                    .data
                    .extend(buf.get(..n).unwrap_or_default().iter().copied());
                inbox.1.notify_all();
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock
                        | io::ErrorKind::TimedOut
                        | io::ErrorKind::Interrupted
                ) => {}
            Err(_) => break,
        }
    }
    lock(inbox).closed = true;
    inbox.1.notify_all();
}

/// Client → bridge: what the client wrote, at the line rate, until it
/// closed and all is sent (or the other direction failed).
fn forward_up(inbox: &Shared<Inbox>, link: &HostLink, done: &AtomicBool, up: &Mutex<Upward>) {
    // Small pieces: the bridge's XOFF stops the link between them.
    const PIECE: usize = 256;
    loop {
        let piece: Vec<u8> = {
            let mut st = lock(inbox);
            loop {
                if done.load(Ordering::Relaxed) {
                    return;
                }
                if !st.data.is_empty() {
                    let n = st.data.len().min(PIECE);
                    break st.data.drain(..n).collect();
                }
                if st.closed {
                    done.store(true, Ordering::Relaxed);
                    return;
                }
                st = inbox
                    .1
                    .wait_timeout(st, POLL)
                    .unwrap_or_else(PoisonError::into_inner)
                    .0;
            }
        };
        let sent = link.send(&piece, |_| {});
        let mut u = up.lock().unwrap_or_else(PoisonError::into_inner);
        if let Err(e) = sent {
            u.why = Some(format!("the bridge took no more: {e}"));
            done.store(true, Ordering::Relaxed);
            return;
        }
        u.bytes += piece.len() as u64;
        u.last = piece.last().copied().or(u.last);
    }
}

/// Bridge → client: the bridge's bytes (XON/XOFF taken out by the link)
/// as they come, until the client is gone.
fn forward_down(mut conn: TcpStream, link: &HostLink, done: &AtomicBool, sent: &AtomicU64) {
    while !done.load(Ordering::Relaxed) {
        match link.read_some(POLL) {
            Ok(bytes) if bytes.is_empty() => {}
            Ok(bytes) => {
                if conn.write_all(&bytes).is_err() {
                    break;
                }
                sent.fetch_add(bytes.len() as u64, Ordering::Relaxed);
            }
            Err(_) => break,
        }
    }
    done.store(true, Ordering::Relaxed);
    let _ = conn.shutdown(Shutdown::Both);
}

/// What the Ethernet firmware prints once protocol B listens on TCP
/// (followed by `A.B.C.D:PORT (dhcp|static|fallback)`).
pub const TCP_LISTENING: &str = "protocol-b-tcp listening on ";
/// What the Ethernet firmware prints once Modbus TCP listens (followed by
/// `A.B.C.D:502`), right after [`TCP_LISTENING`]'s line.
pub const MODBUS_TCP_LISTENING: &str = "modbus-tcp listening on ";
/// What the Ethernet firmware prints at start when its Sparkplug edge
/// node runs (followed by `spBv1.0/GROUP/NBIRTH/NODE via broker A:P`).
pub const SPARKPLUG_NODE: &str = "firmware-example: sparkplug spBv1.0/";
/// What it prints once NBIRTH is out (followed by `bdSeq N`).
pub const SPARKPLUG_BORN: &str = "sparkplug NBIRTH out, ";
/// What the Ethernet firmware prints once the web page listens (followed
/// by `A.B.C.D:80`), right after [`MODBUS_TCP_LISTENING`]'s line.
pub const HTTP_LISTENING: &str = "http listening on ";
/// How long the Ethernet firmware may take to get an address (DHCP, or
/// its fallback address after `DHCP_FALLBACK_MS`).
const ADDRESS_TIMEOUT: Duration = Duration::from_secs(30);

/// The Ethernet build under QEMU with the simulator on its controller
/// UART: `lm3s6965-eth` with QEMU's user network
/// (`-nic user,model=stellaris,restrict=on`) forwarding [`Self::addr`]
/// to the bridge's protocol-B port and [`Self::modbus_addr`] to its
/// Modbus TCP port (502). Nothing relays the host's bytes: a client talks
/// to the firmware's TCP stack. Dropping it stops QEMU.
pub struct EthernetGateway {
    /// The QEMU session (its upstream UART is not used).
    pub qemu: QemuSession,
    /// Where protocol B is reached (127.0.0.1, forwarded by QEMU).
    pub addr: SocketAddr,
    /// Where Modbus TCP is reached (127.0.0.1, forwarded by QEMU to the
    /// firmware's port 502).
    pub modbus_addr: SocketAddr,
    /// Where the web page is reached (127.0.0.1, forwarded by QEMU to the
    /// firmware's port 80, the web block's default).
    pub http_addr: SocketAddr,
    /// The firmware's [`TCP_LISTENING`] line.
    pub listening: String,
    sim: SimThread,
}

impl EthernetGateway {
    /// Boots the firmware (built unless `opts.elf` names one), puts the
    /// simulator behind it, waits for [`TCP_LISTENING`] and for the bridge
    /// to answer its status query over TCP. `opts.port` and
    /// `opts.modbus_port` 0: a free port.
    pub fn start(opts: &Options) -> Result<EthernetGateway, String> {
        if opts.board != Board::Lm3s6965 {
            return Err(format!(
                "--ethernet runs on lm3s6965 (QEMU models the Stellaris Ethernet MAC there), not {}",
                opts.board
            ));
        }
        let port = match opts.port {
            0 => free_port()?,
            p => p,
        };
        let addr = SocketAddr::from(([127, 0, 0, 1], port));
        let modbus_port = match opts.modbus_port {
            0 => free_port()?,
            p => p,
        };
        let modbus_addr = SocketAddr::from(([127, 0, 0, 1], modbus_port));
        let http_port = match opts.http_port {
            0 => free_port()?,
            p => p,
        };
        let http_addr = SocketAddr::from(([127, 0, 0, 1], http_port));
        let elf = match &opts.elf {
            Some(p) => p.clone(),
            None => build_ethernet_firmware()
                .map_err(|e| format!("building the Ethernet firmware: {e}"))?,
        };
        let cfg = Config {
            quit_sequence: opts.quit_sequence || opts.stack_report,
            ..opts
                .bridge_config
                .unwrap_or_else(|| config(opts.baud, opts.modbus_baud))
        };
        let guest_port = opts.network.map_or(DEFAULT_PORT, |n| n.port);
        // With a broker the guest must reach this machine's loopback
        // (10.0.2.2); otherwise it reaches nothing (`restrict=on`).
        let restrict = if opts.sparkplug.is_some() {
            "off"
        } else {
            "on"
        };
        let nic = format!(
            "user,model=stellaris,restrict={restrict},hostfwd=tcp:127.0.0.1:{port}-:{guest_port},\
             hostfwd=tcp:127.0.0.1:{modbus_port}-:{MODBUS_PORT},\
             hostfwd=tcp:127.0.0.1:{http_port}-:{DEFAULT_WEB_PORT}"
        );
        // The bridge's block, the Sparkplug block and the network block
        // in one page.
        let (page, _) = page_args(opts, &elf, &cfg)?;
        let mut args = vec!["-nic", nic.as_str()];
        args.extend(page.iter().map(String::as_str));
        let qemu = QemuSession::start_tied(
            Board::Lm3s6965,
            &elf,
            BOOT_TIMEOUT,
            Some(READY_MARKER),
            &args,
            None,
            false,
        )
        .map_err(|e| format!("starting QEMU: {e}"))?;
        let mut sim = Simulator::tta(cfg.controller_station);
        sim.response_delay_ms = opts.reply_delay_ms;
        sim.refuse = true;
        let sim = sim.with_faults(opts.faults.clone(), opts.seed);
        let downstream = qemu
            .downstream
            .try_clone()
            .map_err(|e| format!("controller side: {e}"))?;
        let sim = SimThread::spawn(sim, downstream, Some(opts.baud));
        let mut gw = EthernetGateway {
            qemu,
            addr,
            modbus_addr,
            http_addr,
            listening: String::new(),
            sim,
        };
        if !gw
            .qemu
            .wait_for_stdout(TCP_LISTENING, Instant::now() + ADDRESS_TIMEOUT)
        {
            return Err(format!(
                "the firmware did not print {TCP_LISTENING:?} within {ADDRESS_TIMEOUT:?}\n{}",
                gw.qemu.stdout_so_far()
            ));
        }
        // The whole line: semihosting output may come in pieces.
        let end = Instant::now() + Duration::from_secs(2);
        gw.listening = loop {
            let out = gw.qemu.stdout_so_far();
            let line = out
                .split_inclusive('\n')
                .find(|l| l.contains(TCP_LISTENING))
                .unwrap_or_default();
            if line.ends_with('\n') || Instant::now() >= end {
                break line.trim().to_owned();
            }
            thread::sleep(Duration::from_millis(10));
        };
        if !gw
            .qemu
            .wait_for_stdout(MODBUS_TCP_LISTENING, Instant::now() + BOOT_TIMEOUT)
        {
            return Err(format!(
                "the firmware did not print {MODBUS_TCP_LISTENING:?}\n{}",
                gw.qemu.stdout_so_far()
            ));
        }
        if !gw
            .qemu
            .wait_for_stdout(HTTP_LISTENING, Instant::now() + BOOT_TIMEOUT)
        {
            return Err(format!(
                "the firmware did not print {HTTP_LISTENING:?}\n{}",
                gw.qemu.stdout_so_far()
            ));
        }
        tcp_status_query(addr, cfg.bridge_station, FENCE_TIMEOUT)
            .map_err(|e| format!("the bridge did not answer over TCP: {e}"))?;
        Ok(gw)
    }

    /// Records the simulator has stored so far.
    pub fn records(&self) -> u64 {
        self.sim.records()
    }

    /// Switches the simulated controller off (`true`) or on again.
    pub fn set_controller_silent(&self, silent: bool) {
        self.sim.set_silent(silent);
    }

    /// The Sparkplug NBIRTH topic the firmware announced at start, once
    /// it says NBIRTH is out ([`SPARKPLUG_BORN`]; waits until `deadline`).
    pub fn sparkplug_birth(&self, deadline: Instant) -> Option<String> {
        if !self.qemu.wait_for_stdout(SPARKPLUG_BORN, deadline) {
            return None;
        }
        let out = self.qemu.stdout_so_far();
        out.lines()
            .find_map(|l| l.strip_prefix(SPARKPLUG_NODE))
            .and_then(|l| l.split_whitespace().next())
            .map(str::to_owned)
    }

    /// Ends the run the firmware's way (it must have been started with
    /// `quit_sequence`): the quit sequence on a new connection after
    /// [`QUIT_GUARD`] of silence; QEMU's exit (with the firmware's last
    /// words: its counters and stack peak) within `timeout`, and the
    /// simulator as it ended.
    pub fn quit(self, timeout: Duration) -> Result<(ExitOutcome, Simulator), String> {
        let EthernetGateway {
            qemu, sim, addr, ..
        } = self;
        let sent = TcpStream::connect(addr).and_then(|mut c| {
            thread::sleep(QUIT_GUARD);
            c.write_all(&QUIT_SEQUENCE)?;
            c.flush()?;
            Ok(c)
        });
        let outcome = match sent {
            Ok(_conn) => qemu.wait(timeout).map_err(|e| e.to_string()),
            Err(e) => Err(format!("sending the quit sequence: {e}")),
        };
        let sim = sim.join().map_err(|e| e.to_string());
        Ok((outcome?, sim?))
    }

    /// Stops QEMU; the simulator as it ended.
    pub fn stop(self) -> io::Result<Simulator> {
        let EthernetGateway { qemu, sim, .. } = self;
        // QEMU first: its end closes the controller line, which ends the
        // simulator's thread.
        drop(qemu);
        sim.join()
    }
}

/// The Ethernet gateway ([`EthernetGateway`]) for `tools/gateway.sh
/// --ethernet`: calls `on_ready` with the forwarded address once the
/// bridge answered over TCP, and runs until `stop` (or fails when QEMU
/// exits on its own). One protocol-B client at a time: the firmware
/// answers others `&` B0B and closes them; Modbus TCP clients (four at
/// once) on the forwarded Modbus address. With `stack_report`, the stop
/// ends the firmware with the quit sequence on the protocol-B port
/// ([`EthernetGateway::quit`]) and logs its stack peak, as on serial.
pub fn run_ethernet(
    opts: &Options,
    stop: &AtomicBool,
    on_ready: impl FnOnce(Ready),
) -> Result<(), String> {
    let mut gw = EthernetGateway::start(opts)?;
    log(&format!(
        "lm3s6965evb-eth (QEMU pid {}) up; {} forwarded from {}, Modbus TCP (port \
         {MODBUS_PORT}) from {}; simulated controller (station {:02X}) behind it at {} \
         baud; Ctrl-C stops",
        gw.qemu.pid(),
        gw.listening,
        gw.addr,
        gw.modbus_addr,
        config(opts.baud, opts.modbus_baud).controller_station.0,
        opts.baud
    ));
    let sparkplug = match &opts.sparkplug {
        None => None,
        Some(_) => {
            let topic = gw.sparkplug_birth(Instant::now() + Duration::from_secs(60));
            let topic = topic.ok_or_else(|| {
                format!(
                    "the edge node published no NBIRTH within 60 s (is the broker up?)\n{}",
                    gw.qemu.stdout_so_far()
                )
            })?;
            Some(format!("spBv1.0/{topic}"))
        }
    };
    on_ready(Ready {
        protocol_b: gw.addr,
        over_ethernet: true,
        modbus_rtu: None,
        modbus_tcp: Some(gw.modbus_addr),
        sparkplug,
        http: Some(gw.http_addr),
    });
    let result = watch(&mut gw.qemu, stop);
    let ended = if opts.stack_report && result.is_ok() {
        gw.quit(Duration::from_secs(10)).map(|(out, sim)| {
            log_stack_peak(&out.stdout);
            sim
        })
    } else {
        gw.stop().map_err(|e| e.to_string())
    };
    match ended {
        Ok(sim) => {
            let s = sim.stats();
            log(&format!(
                "stopped; the simulator answered {} command(s) and holds {} position(s)",
                s.commands,
                sim.table.len()
            ));
        }
        Err(e) => log(&format!("stopped; {e}")),
    }
    result
}

/// A port on 127.0.0.1 free a moment ago.
fn free_port() -> Result<u16, String> {
    TcpListener::bind(("127.0.0.1", 0))
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| format!("finding a free port: {e}"))
}

/// Waits until `stop` (`Ok`) or QEMU exits on its own (an error).
fn watch(qemu: &mut QemuSession, stop: &AtomicBool) -> Result<(), String> {
    loop {
        if stop.load(Ordering::Relaxed) {
            return Ok(());
        }
        match qemu.try_wait() {
            Ok(None) => thread::sleep(POLL),
            Ok(Some(status)) => {
                // A Ctrl-C on the terminal reaches QEMU as well as us.
                let end = Instant::now() + Duration::from_millis(500);
                while !stop.load(Ordering::Relaxed) && Instant::now() < end {
                    thread::sleep(POLL);
                }
                if stop.load(Ordering::Relaxed) {
                    return Ok(());
                }
                return Err(format!(
                    "QEMU exited on its own ({status})\n{}",
                    qemu.stderr_so_far()
                ));
            }
            Err(e) => return Err(format!("QEMU: {e}")),
        }
    }
}

/// The bridge's status query over a TCP connection to `addr` (retried
/// while the connection is refused or closed unanswered, as while the
/// firmware is still getting its address, until `timeout`): the named
/// fields of its reply. Frames before the reply are skipped; the
/// connection is closed after it.
pub fn tcp_status_query(
    addr: SocketAddr,
    bridge: Station,
    timeout: Duration,
) -> Result<Vec<(&'static str, u64)>, String> {
    let deadline = Instant::now() + timeout;
    let mut last = String::from("no attempt");
    while Instant::now() < deadline {
        match status_over(addr, bridge, deadline) {
            Ok(fields) => return Ok(fields),
            Err(e) => last = e,
        }
        thread::sleep(Duration::from_millis(200));
    }
    Err(format!(
        "no status reply from {addr} within {timeout:?} ({last})"
    ))
}

fn status_over(
    addr: SocketAddr,
    bridge: Station,
    deadline: Instant,
) -> Result<Vec<(&'static str, u64)>, String> {
    use iai_protocol_b::frame::{Frame, Header};
    let left = deadline.saturating_duration_since(Instant::now());
    let mut conn = TcpStream::connect_timeout(&addr, left.max(Duration::from_millis(1)))
        .map_err(|e| format!("connect: {e}"))?;
    conn.set_nodelay(true).map_err(|e| e.to_string())?;
    conn.write_all(&status_query_frame(bridge))
        .map_err(|e| format!("send: {e}"))?;
    let mut pending = Vec::new();
    let mut buf = [0u8; 512];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err("timed out".into());
        }
        conn.set_read_timeout(Some(left.min(Duration::from_secs(1))))
            .map_err(|e| e.to_string())?;
        let n = match conn.read(&mut buf) {
            Ok(0) => return Err("closed without the reply".into()),
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                continue
            }
            Err(e) => return Err(format!("read: {e}")),
        };
        pending.extend_from_slice(buf.get(..n).unwrap_or_default());
        while let Some(end) = pending.windows(2).position(|w| w == b"\r\n") {
            let line: Vec<u8> = pending.drain(..end + 2).collect();
            let start = line
                .iter()
                .position(|&b| b == b'#' || b == b'&')
                .unwrap_or(line.len());
            let Some(frame) = line.get(start..) else {
                continue;
            };
            let Ok(f) = Frame::new_checked(frame, Default::default()) else {
                continue;
            };
            if f.header() == Header::Error && f.station() == bridge {
                return Err(format!(
                    "the bridge answered {:?}",
                    String::from_utf8_lossy(frame)
                ));
            }
            if f.header() != Header::Response
                || f.station() != bridge
                || f.code() != codes::STATUS_QUERY
            {
                continue;
            }
            return firmware_example::status::parse(f.body())
                .map(|f| f.to_vec())
                .ok_or_else(|| format!("bad status reply {:?}", String::from_utf8_lossy(frame)));
        }
    }
}
