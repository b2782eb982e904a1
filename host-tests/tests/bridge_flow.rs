//! The bridge library in the virtual-time host model: line-rate arrival
//! into the boards' real receive ring, a controller that takes time per
//! chunk, a host that honours XON/XOFF or RTS/CTS a few bytes late.
//!
//! Figures (printed, not asserted against time): overruns, pauses, the
//! effective rate against the line rate, virtual time, real time.

use std::time::Instant;

use firmware_example::codes;
use firmware_example::serial::FlowControl;
use host_tests::bridge::model::{self, ModelConfig, ModelReport};
use host_tests::bridge::{check_table, command_26dh, error_reply, reply_26dh, Throughput};
use host_tests::table::table;
use iai_protocol_b::line::LineConfig;
use iai_protocol_b::position::PositionRecord;
use iai_simulator::Simulator;

/// Processing time the controller takes per command (writing 24 records).
const PROCESSING_MS: u32 = 50;

/// One 26DH of `n` 8-axis records through the bridge in the model, to a
/// controller that takes [`PROCESSING_MS`] per command: the run, the
/// controller (its table) and the records sent.
fn send_table(
    cfg: &ModelConfig,
    n: u32,
    seed: u32,
) -> (ModelReport, Simulator, Vec<PositionRecord>) {
    let station = cfg.bridge.controller_station;
    let records: Vec<_> = table(n, 8, seed).collect();
    let cmd = command_26dh(station, &records);
    let mut sim = Simulator::tta(station);
    sim.response_delay_ms = PROCESSING_MS;
    let mut bridge = model::bridge(&cfg.bridge);
    let r = model::run(cfg, &mut bridge, &mut sim, &[&cmd], 0);
    assert_eq!(r.host_bytes, cmd.len() as u64);
    (r, sim, records)
}

fn full_table(baud: u32, flow: FlowControl) {
    let started = Instant::now();
    let cfg = ModelConfig::new(baud, flow);
    let station = cfg.bridge.controller_station;
    let (r, sim, records) = send_table(&cfg, 20_000, 7);
    let line_rate = f64::from(baud) / 10.0;
    let reply_after_ms = r.reply_after_ns[0].map_or(f64::NAN, |ns| ns as f64 / 1e6);
    eprintln!(
        "{baud} baud {flow:?}: {} bytes, {} overruns, {} pauses, ring peak {} of 255, \
         virtual {:.1} s, {:.0} B/s = {:.0}% of the line rate ({line_rate:.0} B/s), \
         reply {reply_after_ms:.0} ms after the host's last byte, {} polls, real {:?}",
        r.host_bytes,
        r.overruns,
        r.pauses,
        r.max_ring,
        r.elapsed_ns as f64 / 1e9,
        r.rate(),
        r.rate() * 100.0 / line_rate,
        r.polls,
        started.elapsed()
    );
    let s = sim.stats();
    let throughput = Throughput {
        baud,
        host_bytes: r.host_bytes,
        seconds: r.elapsed_ns as f64 / 1e9,
        downstream_bytes: s.bytes_in + s.bytes_out,
        commands: s.commands,
        per_command_ms: PROCESSING_MS + LineConfig::new(station).turnaround_ms,
    };
    let flow_name = match flow {
        FlowControl::XonXoff => "xon-xoff",
        FlowControl::RtsCts => "rts-cts",
        FlowControl::None => "none",
    };
    println!("{}", throughput.line(flow_name));
    let of_limit = throughput.percent() / throughput.limit_percent() * 100.0;
    eprintln!(
        "{:.1}% of the line rate against a limit of {:.1}%: {of_limit:.1}% of the limit",
        throughput.percent(),
        throughput.limit_percent()
    );
    assert_eq!(r.overruns, 0);
    assert_eq!(r.stale_waits, 0);
    assert_eq!(r.replies, vec![Some(reply_26dh(station, 20_000))]);
    check_table(&sim.table, &records).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        r.pauses > 0,
        "the controller is slower than the line: the host must be paused"
    );
    // The host times out 3 s after its last byte (2003 p. 62): the
    // bridge's last chunks, their read-back and the reply must fit. Virtual
    // time, so this is the protocol's deadline, not a machine's speed.
    // Virtual time again: the bridge keeps the downstream line busy. The
    // host's bytes hide under the controller's, so the rate comes within
    // 10 % of what the downstream bytes and the controller's time allow.
    assert!(
        of_limit >= 90.0,
        "{of_limit:.1}% of the downstream line's limit"
    );
    assert!(
        reply_after_ms <= 3_000.0,
        "the reply came {reply_after_ms:.0} ms after the host's last byte"
    );
}

#[test]
fn table_20000x8_at_9600_xon_xoff_no_overrun() {
    full_table(9_600, FlowControl::XonXoff);
}

#[test]
fn table_20000x8_at_9600_rts_cts_no_overrun() {
    full_table(9_600, FlowControl::RtsCts);
}

#[test]
fn table_20000x8_at_115200_xon_xoff_no_overrun() {
    full_table(115_200, FlowControl::XonXoff);
}

#[test]
fn table_20000x8_at_115200_rts_cts_no_overrun() {
    full_table(115_200, FlowControl::RtsCts);
}

#[test]
fn without_flow_control_the_loss_shows_and_the_bridge_answers_b07() {
    for baud in [9_600, 115_200] {
        let cfg = ModelConfig::new(baud, FlowControl::None);
        let station = cfg.bridge.controller_station;
        let (r, sim, _) = send_table(&cfg, 2_000, 7);
        eprintln!(
            "{baud} baud, no flow control: {} overruns, reply {:?}, {} of 2000 records written",
            r.overruns,
            r.replies[0].as_deref().map(String::from_utf8_lossy),
            sim.table.len()
        );
        assert!(r.overruns > 0);
        assert_eq!(
            r.replies,
            vec![Some(error_reply(station, codes::UPSTREAM_OVERRUN))]
        );
        assert!(sim.table.len() < 2_000);
    }
}

/// The marks leave room for the host's latency: a host that stops within
/// [`HOST_LATENCY`](firmware_example::serial::HOST_LATENCY) bytes (and a
/// good deal more) never overruns; one that sends 120 bytes after XOFF
/// does, and the bridge says so with B07 instead of a false `#`.
#[test]
fn host_latency_within_the_margin_never_overruns() {
    for (latency, overruns_expected) in [
        (0, false),
        (4, false),
        (17, false),
        (60, false),
        (120, true),
    ] {
        let mut cfg = ModelConfig::new(115_200, FlowControl::XonXoff);
        cfg.host_latency = latency;
        let station = cfg.bridge.controller_station;
        let (r, _, _) = send_table(&cfg, 300, 3);
        eprintln!(
            "host latency {latency} bytes: {} overruns, ring peak {}",
            r.overruns, r.max_ring
        );
        if overruns_expected {
            assert!(r.overruns > 0);
            assert_eq!(
                r.replies,
                vec![Some(error_reply(station, codes::UPSTREAM_OVERRUN))]
            );
        } else {
            assert_eq!(r.overruns, 0);
            assert_eq!(r.replies, vec![Some(reply_26dh(station, 300))]);
        }
    }
}
