//! Protocol B over TCP end to end: the Ethernet build (`lm3s6965-eth`,
//! smoltcp on the Stellaris MAC) under QEMU `lm3s6965evb` with QEMU's user
//! network forwarding a port of 127.0.0.1 to the bridge's, and the
//! simulator on the controller UART. Each test's doc says what it checks.
//!
//! Needs `qemu-system-arm` and the `thumbv7m-none-eabi` rustup target.

mod gateway_proc;

use std::io::{Read, Write};
use std::net::{Shutdown, TcpStream};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use gateway_proc::{csv_of, Gateway, ETHERNET};

use host_tests::bridge::{check_table, command_26dh, reply_26dh, status_query_frame, Throughput};
use host_tests::gateway::{tcp_status_query, EthernetGateway, Options};
use host_tests::qemu::build_ethernet_firmware;
use host_tests::table::table;
use iai_protocol_b::frame::{Frame, Header, Station};
use iai_protocol_b::line::LineConfig;
use iai_protocol_b::position::{PositionRecord, PositionStream};

use firmware_example::codes;

/// The bridge's and the controller's stations in the gateway's
/// configuration.
fn stations() -> (Station, Station) {
    let cfg = host_tests::gateway::config(
        115_200,
        firmware_example::config::ModbusConfig::DEFAULT.baud,
    );
    (cfg.bridge_station, cfg.controller_station)
}

/// Frames read from a TCP connection, CR LF ended.
struct Frames {
    conn: TcpStream,
    pending: Vec<u8>,
}

impl Frames {
    fn new(conn: TcpStream) -> Frames {
        Frames {
            conn,
            pending: Vec::new(),
        }
    }

    /// The next frame (from its `#`, `&` or `!` on), `None` at the end of
    /// the connection; panics after `limit`.
    fn next(&mut self, limit: Duration) -> Option<Vec<u8>> {
        self.try_next(limit)
            .unwrap_or_else(|| panic!("no frame within {limit:?}"))
    }

    /// As [`Frames::next`], `None` after `limit` instead of a panic.
    fn try_next(&mut self, limit: Duration) -> Option<Option<Vec<u8>>> {
        let end = Instant::now() + limit;
        loop {
            if let Some(at) = self.pending.windows(2).position(|w| w == b"\r\n") {
                let line: Vec<u8> = self.pending.drain(..at + 2).collect();
                let start = line
                    .iter()
                    .position(|b| matches!(b, b'#' | b'&' | b'!'))
                    .unwrap_or(line.len());
                return Some(Some(line[start..].to_vec()));
            }
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            self.conn.set_read_timeout(Some(left)).unwrap();
            let mut buf = [0u8; 4096];
            match self.conn.read(&mut buf) {
                Ok(0) => return Some(None),
                Ok(n) => self.pending.extend_from_slice(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return Some(None),
                Err(e) => panic!("read: {e}"),
            }
        }
    }

    /// Sends the bridge's status query and returns its fields, skipping
    /// the frames before the reply.
    fn status(&mut self, bridge: Station) -> Vec<(&'static str, u64)> {
        self.conn.write_all(&status_query_frame(bridge)).unwrap();
        loop {
            let frame = self.next(Duration::from_secs(15)).expect("still open");
            let Ok(f) = Frame::new_checked(&frame, Default::default()) else {
                continue;
            };
            if f.header() == Header::Response
                && f.station() == bridge
                && f.code() == codes::STATUS_QUERY
            {
                return firmware_example::status::parse(f.body())
                    .expect("status fields")
                    .to_vec();
            }
        }
    }
}

fn field(fields: &[(&str, u64)], name: &str) -> u64 {
    fields
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, v)| *v)
        .unwrap_or_else(|| panic!("no {name} in {fields:?}"))
}

fn connect(addr: std::net::SocketAddr) -> TcpStream {
    let c = TcpStream::connect(addr).expect("connect");
    c.set_nodelay(true).unwrap();
    c
}

/// The bridge refuses `conn` (a connection made while another host is
/// served): `&` + its station + B0B, then the end of the connection.
fn assert_refused(conn: TcpStream, bridge: Station) {
    let mut frames = Frames::new(conn);
    let frame = frames
        .next(Duration::from_secs(5))
        .expect("a refusal, not a silent close");
    let f = Frame::new_checked(&frame, Default::default()).expect("a valid frame");
    assert_eq!(f.header(), Header::Error);
    assert_eq!(f.station(), bridge);
    assert_eq!(f.code(), codes::HOST_BUSY);
    assert_eq!(frames.next(Duration::from_secs(5)), None, "closed after it");
}

/// The gateway binary with `--ethernet` (what `tools/gateway.sh --ethernet`
/// runs) prints `protocol-b-tcp 127.0.0.1:PORT`; `iai send 212` gets the
/// typed axis status; a second connection while one is served gets `&` BB
/// B0B and is closed, the first goes on; `iai table write` (one command per
/// record) and `iai table write --bridge` (one 26DH, chunks read back by
/// the bridge) of 200 records x 8 axes report `verified`, `iai table read`
/// gives the same CSV back; SIGTERM stops it.
#[test]
fn iai_over_tcp() {
    let elf = build_ethernet_firmware().expect("build lm3s6965-eth");
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf, &["--ethernet"], &ETHERNET);
    let (bridge, _) = stations();
    let addr: std::net::SocketAddr = gw.addr.parse().unwrap();

    // An axis status query, typed.
    let out = gw.iai(&iai, &["send", "212", "query_axis_pattern=1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("212H Axis Status Query"), "{text}");
    assert!(text.contains("axis_pattern = 0x01"), "{text}");

    // One host at a time: the first is served (its status query is
    // answered), a second gets & B0B and is closed, the first goes on.
    let mut first = Frames::new(connect(addr));
    let before = first.status(bridge);
    assert_refused(connect(addr), bridge);
    let after = first.status(bridge);
    assert_eq!(
        field(&after, "own_queries"),
        field(&before, "own_queries") + 1
    );
    drop(first);

    // A table, one command per record, then as one 26DH through the
    // bridge; read back equal each time.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    for (seed, bridge_flag) in [(77, false), (78, true)] {
        let csv = csv_of(200, seed);
        let path = dir.join(format!("eth-{}-{seed}.csv", std::process::id()));
        std::fs::write(&path, &csv).unwrap();
        let file = path.to_str().expect("UTF-8 path");
        let mut args = vec!["table", "write", file];
        if bridge_flag {
            args.push("--bridge");
        }
        let out = gw.iai(&iai, &args);
        let text = String::from_utf8_lossy(&out.stdout);
        let want = if bridge_flag {
            "verified by the bridge: the controller holds all 200 records"
        } else {
            "verified: the controller holds all 200 records"
        };
        assert!(
            text.contains(want),
            "{text}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let back = gw.iai(&iai, &["table", "read", "--first", "1", "--count", "200"]);
        assert!(
            back.stdout == csv,
            "read back:\n{}",
            String::from_utf8_lossy(&back.stdout)
        );
        let _ = std::fs::remove_file(&path);
    }

    let status = gw.stop();
    let log = gw.log();
    assert!(status.success(), "{status}\n{log}");
    assert!(log.contains("stopped;"), "{log}");
}

/// Writes `message` to a new connection from a thread (TCP holds it back
/// while the bridge works) and waits for the bridge's answer; the answer
/// and the seconds from the first byte to it.
fn send_26dh(addr: std::net::SocketAddr, message: Vec<u8>, limit: Duration) -> (Vec<u8>, f64) {
    let conn = connect(addr);
    let mut writer = conn.try_clone().unwrap();
    let started = Instant::now();
    let sender = std::thread::spawn(move || writer.write_all(&message));
    let mut frames = Frames::new(conn);
    let reply = frames.next(limit).expect("an answer");
    let secs = started.elapsed().as_secs_f64();
    sender.join().unwrap().expect("the whole message written");
    (reply, secs)
}

/// After one 26DH of `records` (`host_bytes` sent in `secs`): the
/// bridge's own count says one stream of every record and none failed,
/// the firmware quits cleanly and the simulator holds exactly `records`.
/// The firmware's exit, the chunks sent and the run's throughput.
fn one_stream_held(
    gw: EthernetGateway,
    bridge: Station,
    controller: Station,
    records: &[PositionRecord],
    host_bytes: u64,
    secs: f64,
) -> (host_tests::qemu::ExitOutcome, u64, Throughput) {
    let fields = tcp_status_query(gw.addr, bridge, Duration::from_secs(15)).unwrap();
    assert_eq!(field(&fields, "streams_ok"), 1, "{fields:?}");
    assert_eq!(field(&fields, "streams_failed"), 0, "{fields:?}");
    assert_eq!(
        field(&fields, "records"),
        records.len() as u64,
        "{fields:?}"
    );
    let chunks = field(&fields, "chunks_sent");
    let (exit, sim) = gw
        .quit(Duration::from_secs(20))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(exit.success(), "{}\n{}", exit.stdout, exit.stderr);
    check_table(&sim.table, records).unwrap_or_else(|e| panic!("{e}"));
    let s = sim.stats();
    let throughput = Throughput {
        baud: 115_200,
        host_bytes,
        seconds: secs,
        downstream_bytes: s.bytes_in + s.bytes_out,
        commands: s.commands,
        per_command_ms: Options::default().reply_delay_ms
            + LineConfig::new(controller).turnaround_ms,
    };
    (exit, chunks, throughput)
}

/// One 26DH written whole to the socket (TCP's window holds the host back),
/// answered `#` with the record count; the simulator's table equal to the
/// source; prints the throughput against the downstream line's limit; the
/// run ends with the quit sequence over TCP and the firmware's stack peak
/// is printed (`stack lm3s6965-eth N`, read by `tools/size-report.sh`).
/// `IAI_ETH_RECORDS` sets the record count (default 200; 20000 for the full
/// table).
#[test]
fn a_26dh_over_tcp_is_verified_and_timed() {
    let n: u32 = std::env::var("IAI_ETH_RECORDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(200);
    let elf = build_ethernet_firmware().expect("build lm3s6965-eth");
    let opts = Options {
        elf: Some(elf),
        ethernet: true,
        quit_sequence: true,
        ..Options::default()
    };
    let gw = EthernetGateway::start(&opts).unwrap_or_else(|e| panic!("{e}"));
    let (bridge, controller) = stations();
    let records: Vec<PositionRecord> = table(n, 8, 5).collect();
    let message = command_26dh(controller, &records);
    let host_bytes = message.len() as u64;
    let limit = Duration::from_secs(60 + u64::from(n) / 20);
    let (reply, secs) = send_26dh(gw.addr, message, limit);
    let count = u16::try_from(n).unwrap();
    assert_eq!(
        String::from_utf8_lossy(&reply),
        String::from_utf8_lossy(&reply_26dh(controller, count))
    );
    let (exit, chunks, throughput) =
        one_stream_held(gw, bridge, controller, &records, host_bytes, secs);
    let stack: u64 = exit
        .stdout
        .lines()
        .find_map(|l| l.strip_prefix("firmware-example: stack peak "))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no stack peak in:\n{}", exit.stdout));
    println!("stack lm3s6965-eth {stack}");
    println!("{}", throughput.line("tcp"));
    eprintln!(
        "{n} records x 8 axes over TCP: {host_bytes} bytes in {secs:.1} s, {chunks} chunks; \
         {:.1}% of the line rate against the downstream limit of {:.1}% ({:.0}% of the limit)",
        throughput.percent(),
        throughput.limit_percent(),
        throughput.percent() / throughput.limit_percent() * 100.0
    );
}

/// A connection dropped in the middle of a 26DH, then a new connection
/// works; the bridge counts the failed stream and its last code is B04;
/// what reached the controller is a prefix of that message's records, each
/// equal to its source, and the last record sent was never written; garbage
/// on the port and a connection dropped in the middle of a frame leave a
/// bridge that answers the next host.
#[test]
fn dropped_connections_and_garbage() {
    let elf = build_ethernet_firmware().expect("build lm3s6965-eth");
    let opts = Options {
        elf: Some(elf),
        ethernet: true,
        ..Options::default()
    };
    let gw = EthernetGateway::start(&opts).unwrap_or_else(|e| panic!("{e}"));
    let (bridge, controller) = stations();

    // A 26DH of 150 records numbered 501.., cut after about two thirds
    // of its bytes (several chunks' worth), the connection then dropped.
    let cut: Vec<PositionRecord> = table(150, 8, 9)
        .enumerate()
        .map(|(i, mut r)| {
            r.number = 501 + u16::try_from(i).unwrap();
            r
        })
        .collect();
    let message = command_26dh(controller, &cut);
    let sent = message.len() * 2 / 3;
    let mut host = connect(gw.addr);
    host.write_all(&message[..sent]).unwrap();
    // Let the bridge take what TCP holds, then drop the connection.
    let end = Instant::now() + Duration::from_secs(30);
    while gw.records() == 0 {
        assert!(Instant::now() < end, "no record reached the controller");
        std::thread::sleep(Duration::from_millis(20));
    }
    host.shutdown(Shutdown::Both).unwrap();
    drop(host);

    // A new host is served (after the bridge ended the stream: until
    // then it is refused, and tcp_status_query tries again).
    let fields = tcp_status_query(gw.addr, bridge, Duration::from_secs(30)).unwrap();
    assert_eq!(field(&fields, "streams_failed"), 1, "{fields:?}");
    assert_eq!(field(&fields, "streams_ok"), 0, "{fields:?}");
    assert_eq!(
        field(&fields, "last_error"),
        u64::from(codes::UPSTREAM_STALLED),
        "{fields:?}"
    );

    // Garbage: noise with no frame in it, then a status query on the
    // same connection is answered.
    let mut frames = Frames::new(connect(gw.addr));
    let noise: Vec<u8> = (0..2000u32).map(|i| (i * 37 % 251) as u8).collect();
    frames.conn.write_all(&noise).unwrap();
    frames.conn.write_all(b"\r\n").unwrap();
    let f = frames.status(bridge);
    assert!(field(&f, "rejected") > 0, "{f:?}");
    // Then a partial frame, and the connection dropped in its middle.
    frames.conn.write_all(b"!99212").unwrap();
    drop(frames);
    // Another garbage host: NULs and 0xFF, dropped without a CR LF.
    let mut noisy = connect(gw.addr);
    noisy.write_all(&[0u8; 700]).unwrap();
    noisy.write_all(&[0xFF; 700]).unwrap();
    drop(noisy);

    // The next host works: a whole 26DH, verified.
    let records: Vec<PositionRecord> = table(50, 8, 10).collect();
    let (reply, _) = send_26dh(
        gw.addr,
        command_26dh(controller, &records),
        Duration::from_secs(60),
    );
    assert_eq!(
        String::from_utf8_lossy(&reply),
        String::from_utf8_lossy(&reply_26dh(controller, 50))
    );

    let sim = gw.stop().expect("simulator");
    // Positions 1..=50: the last message, equal to its source. 501..:
    // what was written of the cut message, a prefix of its records each
    // equal to its source, and not all of them.
    let mut whole = sim.table.clone();
    let written: Vec<PositionRecord> = whole.split_off(&501).into_values().collect();
    check_table(&whole, &records).unwrap_or_else(|e| panic!("{e}"));
    assert!(!written.is_empty());
    assert!(written.len() < cut.len(), "{} written", written.len());
    assert_eq!(written[..], cut[..written.len()]);
}

/// A network block in the configuration page gives a static address and
/// port 6020; the firmware says so and answers there.
#[test]
fn static_address_and_port_from_the_network_block() {
    use firmware_example::net::config::{Addressing, Ipv4Setting, NetConfig};
    let elf = build_ethernet_firmware().expect("build lm3s6965-eth");
    let net = NetConfig {
        addressing: Addressing::Static,
        port: 6020,
        address: Ipv4Setting {
            // QEMU's user network forwards to its guest address.
            address: [10, 0, 2, 15],
            prefix: 24,
            gateway: Some([10, 0, 2, 2]),
        },
    };
    let opts = Options {
        elf: Some(elf),
        ethernet: true,
        network: Some(net),
        ..Options::default()
    };
    let gw = EthernetGateway::start(&opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        gw.listening
            .ends_with("protocol-b-tcp listening on 10.0.2.15:6020 (static)"),
        "{}",
        gw.listening
    );
    assert!(
        gw.qemu.stdout_so_far().contains("network block Block"),
        "{}",
        gw.qemu.stdout_so_far()
    );
    let (bridge, _) = stations();
    let fields = tcp_status_query(gw.addr, bridge, Duration::from_secs(15)).unwrap();
    assert_eq!(field(&fields, "own_queries"), 2, "{fields:?}");
    gw.stop().expect("simulator");
}

/// The firmware's TCP counters from its last words (`tcp hosts N refused
/// N cut short N stalled N`): hosts, refused, cut short, stalled.
fn tcp_counters(stdout: &str) -> [u64; 4] {
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("firmware-example: tcp hosts "))
        .unwrap_or_else(|| panic!("no tcp counters in:\n{stdout}"));
    let words: Vec<&str> = line.split([' ', ';']).collect();
    let at = |i: usize| -> u64 {
        words
            .get(i)
            .and_then(|w| w.parse().ok())
            .unwrap_or_else(|| panic!("tcp counters {line:?}"))
    };
    // "N refused N cut short N stalled N; frames ..."
    [at(0), at(2), at(5), at(7)]
}

/// The 212H axis status query of axis 1 to `controller`.
fn axis_status_query(controller: Station) -> Vec<u8> {
    use iai_protocol_b::axis::AxisPattern;
    use iai_protocol_b::message::{AxisStatusQuery, Message};
    let mut buf = [0u8; 64];
    let n = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(1),
    }
    .emit(controller, &mut buf)
    .expect("212H");
    buf[..n].to_vec()
}

/// Sends `command` on a new connection and returns the first frame from
/// `from`; a connection answered `&` B0B (a host still being let go) or
/// closed unanswered is tried again until `limit`.
fn exchange_when_served(
    addr: std::net::SocketAddr,
    bridge: Station,
    from: Station,
    command: &[u8],
    limit: Duration,
) -> Vec<u8> {
    let end = Instant::now() + limit;
    loop {
        assert!(Instant::now() < end, "not served within {limit:?}");
        let Ok(conn) = TcpStream::connect(addr) else {
            std::thread::sleep(Duration::from_millis(100));
            continue;
        };
        conn.set_nodelay(true).unwrap();
        let mut frames = Frames::new(conn);
        if frames.conn.write_all(command).is_err() {
            continue;
        }
        // A connection that waits for the bridge to finish a departed
        // host's work is served once it is idle, a held one is refused
        // within 1 s: 10 s without a frame is a fault, not a wait.
        let left = end.saturating_duration_since(Instant::now());
        let limit = left.min(Duration::from_secs(10));
        while let Some(frame) = frames
            .try_next(limit)
            .unwrap_or_else(|| panic!("no frame within {limit:?}"))
        {
            let Ok(f) = Frame::new_checked(&frame, Default::default()) else {
                continue;
            };
            if f.header() == Header::Error && f.station() == bridge && f.code() == codes::HOST_BUSY
            {
                break;
            }
            if f.station() == from {
                return frame;
            }
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// 1,000 connections made one after another, 20 ms apart (QEMU's user
/// network accepts one at a time), and dropped: at once, after part of a
/// 212H, after part of a 26DH's first record (positions 901..), after a
/// whole 212H or status query whose reply is never read; then a new client
/// gets the 212H reply the controller gives, byte for byte, and a 26DH of
/// 20 records is answered `#`; the simulator holds exactly those 20
/// records; the firmware's counters (after the quit sequence) show every
/// connection that sent bytes served or refused (all of them on an idle
/// machine) and none reset for not reading. About 21 s;
/// `IAI_ETH_CONNECTIONS` sets the count.
#[test]
fn a_thousand_connects_and_disconnects() {
    use iai_simulator::Simulator;
    let started = Instant::now();
    let elf = build_ethernet_firmware().expect("build lm3s6965-eth");
    let opts = Options {
        elf: Some(elf),
        ethernet: true,
        quit_sequence: true,
        ..Options::default()
    };
    let gw = EthernetGateway::start(&opts).unwrap_or_else(|e| panic!("{e}"));
    let (bridge, controller) = stations();
    let q212 = axis_status_query(controller);
    let status = status_query_frame(bridge);
    // A 26DH for positions 901.. cut inside its first record: no record of
    // it is whole, so none may reach the controller.
    let cut_26dh: Vec<PositionRecord> = table(5, 8, 21)
        .enumerate()
        .map(|(i, mut r)| {
            r.number = 901 + u16::try_from(i).unwrap();
            r
        })
        .collect();
    let cut_26dh = command_26dh(controller, &cut_26dh);
    // Envelope and prefix, one record; four more records and the trailer
    // (SC, CR, LF: 4 bytes) after it.
    let record_len = (cut_26dh.len() - PositionStream::CHANGE_2.overhead()) / 5;
    let first_record_ends = cut_26dh.len() - 4 * record_len - 4;

    // IAI_ETH_CONNECTIONS sets the count (default 1000).
    let connections: u32 = std::env::var("IAI_ETH_CONNECTIONS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1000);
    let churn_started = Instant::now();
    let (mut at_once, mut partial, mut unread, mut failed) = (0u32, 0u32, 0u32, 0u32);
    for i in 0..connections {
        let Ok(mut conn) = TcpStream::connect(gw.addr) else {
            failed += 1;
            continue;
        };
        let _ = conn.set_nodelay(true);
        // Write errors are expected: a connection the bridge could not take
        // (all its sockets busy) is reset.
        let sent = match i % 5 {
            0 => {
                at_once += 1;
                Ok(())
            }
            1 => {
                partial += 1;
                let cut = 1 + (i as usize * 7) % (q212.len() - 2);
                conn.write_all(&q212[..cut])
            }
            2 => {
                partial += 1;
                let cut = 1 + (i as usize * 13) % (first_record_ends - 1);
                conn.write_all(&cut_26dh[..cut])
            }
            3 => {
                unread += 1;
                conn.write_all(&q212)
            }
            _ => {
                unread += 1;
                conn.write_all(&status)
            }
        };
        if sent.is_err() {
            failed += 1;
        }
        drop(conn);
        // QEMU's user network takes one connection at a time from its
        // listening socket (backlog 1): without a pause the kernel drops
        // the next SYN and the client sends it again a second later.
        std::thread::sleep(Duration::from_millis(20));
    }
    let churn = churn_started.elapsed();
    eprintln!(
        "{connections} connections in {:.1} s: {at_once} closed at once, {partial} after part of a \
         frame, {unread} after a whole command unread; {failed} refused or reset by the stack",
        churn.as_secs_f64()
    );

    // A normal client: the 212H reply the controller gives, byte for byte.
    let mut oracle = Simulator::tta(controller);
    oracle.receive(&q212, 0);
    let want = oracle.take_output(1_000);
    let got = exchange_when_served(gw.addr, bridge, controller, &q212, Duration::from_secs(30));
    assert_eq!(
        String::from_utf8_lossy(&got),
        String::from_utf8_lossy(&want)
    );
    let fields = tcp_status_query(gw.addr, bridge, Duration::from_secs(15)).unwrap();
    assert_eq!(field(&fields, "streams_ok"), 0, "{fields:?}");
    assert_eq!(field(&fields, "records"), 0, "{fields:?}");
    assert!(field(&fields, "forwarded") >= 1, "{fields:?}");

    // A small table, verified by the bridge.
    let records: Vec<PositionRecord> = table(20, 8, 22).collect();
    let (reply, _) = send_26dh(
        gw.addr,
        command_26dh(controller, &records),
        Duration::from_secs(30),
    );
    assert_eq!(
        String::from_utf8_lossy(&reply),
        String::from_utf8_lossy(&reply_26dh(controller, 20))
    );
    let (exit, sim) = gw
        .quit(Duration::from_secs(20))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(exit.success(), "{}\n{}", exit.stdout, exit.stderr);
    // Exactly the verified records: nothing of the cut messages.
    check_table(&sim.table, &records).unwrap_or_else(|e| panic!("{e}"));
    // Every connection that sent something reached the bridge: served as
    // the host or refused (besides the churn: the start-up query, the
    // 212H, the status query, the 26DH and the quit sequence). One closed
    // at once may not: QEMU's user network drops a client that left
    // before its own connection to the bridge was up (seen on a loaded
    // machine; on an idle one all 1,005 were served). None had to be
    // reset for not reading.
    let [hosts, refused, cut_short, stalled] = tcp_counters(&exit.stdout);
    eprintln!("bridge: {hosts} hosts, {refused} refused, {cut_short} cut short, {stalled} stalled");
    let with_bytes = u64::from(connections - at_once - failed) + 5;
    assert!(
        hosts + refused >= with_bytes && hosts + refused <= u64::from(connections) + 5,
        "{hosts} hosts and {refused} refused for {connections} connections, \
         {with_bytes} with bytes"
    );
    assert_eq!(stalled, 0);
    eprintln!(
        "a_thousand_connects_and_disconnects: {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// A connection to `addr` whose receive buffer is set to `rcvbuf` bytes
/// before it connects (so that the window it offers stays that small).
fn connect_small_window(addr: std::net::SocketAddrV4, rcvbuf: i32) -> TcpStream {
    use std::os::fd::FromRawFd;
    #[repr(C)]
    struct SockaddrIn {
        family: u16,
        port: u16,
        addr: u32,
        zero: [u8; 8],
    }
    extern "C" {
        fn socket(domain: i32, kind: i32, protocol: i32) -> i32;
        fn setsockopt(fd: i32, level: i32, name: i32, value: *const i32, len: u32) -> i32;
        fn connect(fd: i32, addr: *const SockaddrIn, len: u32) -> i32;
        fn close(fd: i32) -> i32;
    }
    const AF_INET: i32 = 2;
    const SOCK_STREAM: i32 = 1;
    const SOL_SOCKET: i32 = 1;
    const SO_RCVBUF: i32 = 8;
    let sa = SockaddrIn {
        family: AF_INET as u16,
        port: addr.port().to_be(),
        addr: u32::from(*addr.ip()).to_be(),
        zero: [0; 8],
    };
    // SAFETY: plain socket calls on a descriptor this function owns; the
    // pointers are to live locals of the sizes given.
    unsafe {
        let fd = socket(AF_INET, SOCK_STREAM, 0);
        assert!(fd >= 0, "socket: {}", std::io::Error::last_os_error());
        let rc = setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, 4);
        assert_eq!(rc, 0, "SO_RCVBUF: {}", std::io::Error::last_os_error());
        let len = std::mem::size_of::<SockaddrIn>() as u32;
        if connect(fd, &sa, len) != 0 {
            let e = std::io::Error::last_os_error();
            close(fd);
            panic!("connect: {e}");
        }
        TcpStream::from_raw_fd(fd)
    }
}

/// A host whose socket offers the smallest window the kernel allows sends
/// 20,000 status queries and reads nothing; QEMU's user network buffers
/// what it can (about 1.6 MB), then the bridge's transmit buffer stays
/// full, it stops answering, and 10 s later resets the host: a client
/// refused meanwhile is served no sooner than 10 s after the slow host
/// began, fewer queries were answered than sent, the slow host's connection
/// ends, and the firmware counts one host reset for it. About 12 s.
#[test]
fn a_host_that_stops_reading_is_reset() {
    let started = Instant::now();
    let elf = build_ethernet_firmware().expect("build lm3s6965-eth");
    let opts = Options {
        elf: Some(elf),
        ethernet: true,
        quit_sequence: true,
        ..Options::default()
    };
    let gw = EthernetGateway::start(&opts).unwrap_or_else(|e| panic!("{e}"));
    let (bridge, _) = stations();
    let std::net::SocketAddr::V4(addr) = gw.addr else {
        panic!("{} is not IPv4", gw.addr)
    };
    // A host that sends status queries and reads nothing, its window as
    // small as the kernel allows: what QEMU's user network takes for it
    // (its own buffer and its socket's) fills up, then the bridge's
    // transmit buffer, and the bridge stops taking its queries.
    let mut slow = connect_small_window(addr, 1);
    slow.set_nodelay(true).unwrap();
    let query = status_query_frame(bridge);
    let queries = 20_000;
    let mut writer = slow.try_clone().unwrap();
    let sender = std::thread::spawn(move || {
        let mut sent = 0u32;
        for _ in 0..queries {
            if writer.write_all(&query).is_err() {
                break;
            }
            sent += 1;
        }
        sent
    });
    let stopped_reading = Instant::now();
    // Meanwhile others are refused; once the bridge reset the slow host
    // (10 s after it last took a byte) the next one is served.
    let fields = tcp_status_query(gw.addr, bridge, Duration::from_secs(90))
        .unwrap_or_else(|e| panic!("{e}"));
    let served_after = stopped_reading.elapsed();
    let own = field(&fields, "own_queries");
    // The slow host's connection is gone: what was buffered for it, then
    // its end.
    slow.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let mut got = 0usize;
    let mut buf = vec![0u8; 65536];
    let ended = loop {
        match slow.read(&mut buf) {
            Ok(0) => break "closed",
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break "reset",
            Err(e) => panic!("the slow host's connection is still open: {e} after {got} bytes"),
        }
    };
    let sent = sender.join().unwrap();
    eprintln!(
        "slow host: {sent} status queries sent, {own} answered by the bridge in all, \
         {got} bytes of answers read afterwards, connection {ended}; the next host served \
         {:.1} s after the slow one began",
        served_after.as_secs_f64()
    );
    assert!(
        served_after >= Duration::from_secs(10),
        "served after {served_after:?}: the slow host was not holding the bridge"
    );
    assert!(
        u64::from(sent) > own,
        "every query was answered: the slow host never stalled the bridge"
    );
    let (exit, _) = gw
        .quit(Duration::from_secs(20))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(exit.success(), "{}\n{}", exit.stdout, exit.stderr);
    // The bridge's own count: one host reset for taking nothing.
    let [hosts, refused, cut_short, stalled] = tcp_counters(&exit.stdout);
    eprintln!("bridge: {hosts} hosts, {refused} refused, {cut_short} cut short, {stalled} stalled");
    assert_eq!(stalled, 1);
    eprintln!(
        "a_host_that_stops_reading_is_reset: {:.1} s",
        started.elapsed().as_secs_f64()
    );
}

/// `iai table write --bridge --tcp` of 20,000 records x 8 axes (1,640,014
/// bytes, one 26DH): iai reports it verified by the bridge, the bridge
/// counts one stream of 20,000 records, and the simulator's table equals
/// the source; prints the time and the throughput (about 170 s on an idle
/// machine; no bound on speed, only a 20-minute limit on the run).
#[test]
fn iai_writes_the_full_table_through_the_bridge() {
    const RECORDS: u32 = 20_000;
    const LIMIT: Duration = Duration::from_secs(20 * 60);
    let started = Instant::now();
    let elf = build_ethernet_firmware().expect("build lm3s6965-eth");
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");
    let opts = Options {
        elf: Some(elf),
        ethernet: true,
        quit_sequence: true,
        ..Options::default()
    };
    let gw = EthernetGateway::start(&opts).unwrap_or_else(|e| panic!("{e}"));
    let (bridge, controller) = stations();
    let records: Vec<PositionRecord> = table(RECORDS, 8, 31).collect();
    let csv = csv_of(RECORDS, 31);
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("eth-full-{}.csv", std::process::id()));
    std::fs::write(&path, &csv).unwrap();
    let host_bytes = command_26dh(controller, &records).len() as u64;

    // iai on its own: its output to files, killed if it outlives LIMIT.
    let out_path = path.with_extension("out");
    let err_path = path.with_extension("err");
    let t0 = Instant::now();
    let mut child = Command::new(&iai)
        .args(["table", "write"])
        .arg(&path)
        .args(["--bridge", "--tcp", &gw.addr.to_string()])
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .expect("run iai");
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for iai") {
            break status;
        }
        if t0.elapsed() > LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("iai table write --bridge still running after {LIMIT:?}");
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let secs = t0.elapsed().as_secs_f64();
    let stdout = std::fs::read_to_string(&out_path).unwrap_or_default();
    let stderr = std::fs::read_to_string(&err_path).unwrap_or_default();
    for p in [&path, &out_path, &err_path] {
        let _ = std::fs::remove_file(p);
    }
    assert!(status.success(), "iai: {status}\n{stdout}\n{stderr}");
    assert!(
        stdout.contains(&format!(
            "verified by the bridge: the controller holds all {RECORDS} records (1 26DH message(s)"
        )),
        "{stdout}\n{stderr}"
    );

    let (_, chunks, throughput) =
        one_stream_held(gw, bridge, controller, &records, host_bytes, secs);
    println!("{}", throughput.line("iai-tcp"));
    eprintln!(
        "iai table write --bridge over TCP: {RECORDS} records x 8 axes, {host_bytes} bytes in \
         {secs:.1} s ({:.0} bytes/s, {:.1} records/s), {chunks} chunks; {:.1}% of the line rate \
         against the downstream limit of {:.1}%; the whole test {:.1} s",
        host_bytes as f64 / secs,
        f64::from(RECORDS) / secs,
        throughput.percent(),
        throughput.limit_percent(),
        started.elapsed().as_secs_f64()
    );
}
