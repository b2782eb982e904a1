//! The core from `std` (`hosted::StdLink`) against the controller
//! simulator over TCP: a typed call and a verified table write on a line
//! that drops, delays and repeats replies, with no glue but the stream.

use std::net::{TcpListener, TcpStream};
use std::time::Instant;

use host_tests::table::table;
use iai_protocol_b::hosted::StdLink;
use iai_protocol_b::message::{AxisStatusQuery, Homing, ServoOnOff};
use iai_protocol_b::transfer::Guarantee;
use iai_protocol_b::{
    client::Client, frame::Station, line::LineConfig, profile::Profile, transfer::Transfer,
    transfer::TransferConfig,
};
use iai_simulator::server::{serve_tcp, ServeOptions, Shared};
use iai_simulator::{Controller, Faults};

/// A simulated TTA on a free port, with `faults`.
fn simulator(faults: Faults) -> (String, Shared) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let at = listener.local_addr().unwrap().to_string();
    let shared = Shared::new(Controller::tta(Station(0x99)));
    let opts = ServeOptions {
        faults,
        seed: 17,
        log_frames: false,
    };
    let s = shared.clone();
    std::thread::spawn(move || serve_tcp(listener, s, opts));
    (at, shared)
}

#[test]
fn a_typed_call_over_a_tcp_stream() {
    let (at, _shared) = simulator(Faults::default());
    let mut link = StdLink::new(
        TcpStream::connect(&at).unwrap(),
        LineConfig::new(Station(0x99)),
    );
    let mut client: Client = Client::new();
    link.call(&mut client, &ServoOnOff::new(&[1], true).unwrap())
        .unwrap();
    let status = link
        .call(&mut client, &AxisStatusQuery::of(&[1]).unwrap())
        .unwrap();
    let axis = status.axes.first().unwrap();
    assert!(axis.servo_on());
    assert_eq!(axis.homing(), Homing::NotDone);
    // The new line fenced before its first command, and only then.
    assert_eq!(link.line().stats().fences, 1);
}

#[test]
fn a_verified_table_write_on_a_faulty_line() {
    let faults =
        iai_simulator::server::parse_faults("drop=0.05,late=0.05:3500,dup=0.05:200").unwrap();
    let (at, shared) = simulator(faults);
    let mut link = StdLink::new(
        TcpStream::connect(&at).unwrap(),
        LineConfig::new(Station(0x99)),
    );
    let records = table(150, 8, 5);
    let mut t: Transfer<_> = Transfer::new(TransferConfig::new(Profile::TTA), records.clone());
    let (wall, cpu) = (Instant::now(), cpu_time());
    let guarantee = link.run(&mut t).unwrap();
    assert_eq!(guarantee, Guarantee::Verified);
    let ctl = shared.ctl.lock().unwrap();
    for r in records {
        assert_eq!(ctl.table.get(&r.number), Some(&r), "position {}", r.number);
    }
    println!(
        "150 x 8 verified over TCP with faults: {:.1} s wall, {:.2} s CPU, {} retries",
        wall.elapsed().as_secs_f64(),
        cpu_time() - cpu,
        t.stats().retries
    );
}

/// CPU seconds this process has used (user + system), from /proc.
fn cpu_time() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    let ticks: f64 = after
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|v| v.parse::<f64>().ok())
        .sum();
    ticks / 100.0
}
