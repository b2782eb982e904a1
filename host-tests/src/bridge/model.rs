//! The bridge library on a deterministic virtual-time model of its two
//! serial lines, the host and the controller.
//!
//! What is modelled (times in nanoseconds of virtual time):
//! * **Line rate.** Each line carries one byte per 10 bit times (8N1) in
//!   each direction, at its own baud rate.
//! * **The receive rings of the boards**: the bridge's
//!   [`UpstreamRings`] and [`DownstreamRings`] with their real capacities and
//!   marks, driven through their interrupt ends exactly as the boards' UART
//!   interrupt handlers drive them (receive a byte, then service and
//!   transmit). A byte that finds the upstream ring full is an overrun,
//!   counted by the line, as on hardware.
//! * **The host** sends its bytes back to back at line rate. With
//!   XON/XOFF it stops `host_latency` bytes after an XOFF reaches it and
//!   goes on when XON reaches it; with RTS/CTS it stops `host_latency`
//!   bytes after the bridge drops RTS. Without flow control it never
//!   stops.
//! * **The controller** is the simulator ([`Simulator`]): it answers after
//!   its `response_delay_ms` (the per-command processing time), its reply
//!   goes back at line rate.
//! * **The bridge's loop** runs after every event, and at the deadline its
//!   last [`Poll::Wait`] named; it takes no virtual time (its speed on a
//!   real MCU is measured separately: instructions per byte, `icount`).
//!
//! Nothing here reads a wall clock: the same inputs give the same run.

use std::collections::VecDeque;

use firmware_example::bridge::{Bridge, Poll};
use firmware_example::config::{Config, Source};
use firmware_example::serial::{
    DownstreamRings, FlowControl, UpstreamRings, DOWNSTREAM_MARKS, HOST_LATENCY, UPSTREAM_MARKS,
    XOFF, XON,
};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};

use iai_simulator::Simulator;

/// Settings of a model run.
#[derive(Debug, Clone, Copy)]
pub struct ModelConfig {
    /// The bridge's configuration (flow control, stations, policy, rates).
    pub bridge: Config,
    /// Bytes the host still sends after it was told to stop.
    pub host_latency: usize,
    /// Give up on a command after this much virtual time without its
    /// reply, ms.
    pub reply_limit_ms: u64,
    /// A host that gives up on a command this long after its last byte
    /// (protocol B's 3 s, 2003 p. 62) and goes on with the next, whatever
    /// the bridge is still doing; after the last command the run goes on
    /// until the bridge is idle and the lines are quiet. `None`: the host
    /// waits as long as something moves.
    pub host_timeout_ms: Option<u64>,
}

impl ModelConfig {
    /// Both lines at `baud`, `flow` upstream, a host with
    /// [`HOST_LATENCY`] (the boards' assumption), everything else default.
    pub fn new(baud: u32, flow: FlowControl) -> Self {
        ModelConfig {
            bridge: Config {
                upstream_baud: baud,
                downstream_baud: baud,
                flow,
                ..Config::DEFAULT
            },
            host_latency: HOST_LATENCY,
            reply_limit_ms: 30_000,
            host_timeout_ms: None,
        }
    }
}

/// What a model run measured.
#[derive(Debug, Clone, Default)]
pub struct ModelReport {
    /// The reply to each command (`None`: none within the limit), in order:
    /// the first frame the host got while that command was its current one.
    pub replies: Vec<Option<Vec<u8>>>,
    /// Every frame the host got, in order (with a host that gives up, a
    /// late answer to one command comes while the next is current).
    pub answers: Vec<Vec<u8>>,
    /// Upstream bytes that found the receive ring full (overruns).
    pub overruns: u32,
    /// Times the bridge stopped the host (XOFF sent, or RTS dropped).
    pub pauses: u32,
    /// Bytes the host sent.
    pub host_bytes: u64,
    /// Virtual time from the first byte to the last reply, ns.
    pub elapsed_ns: u64,
    /// The virtual clock when the run ended, ns: where the next run on the
    /// same bridge and simulator starts (their lines remember times).
    pub end_ns: u64,
    /// For each command that got a reply: from the host's last byte to the
    /// reply's last byte, ns (what the host's 3 s reply timeout measures).
    pub reply_after_ns: Vec<Option<u64>>,
    /// Highest upstream ring level seen.
    pub max_ring: usize,
    /// Times the bridge's loop ran.
    pub polls: u64,
    /// Waits that named an event already there (bytes to read): a broken
    /// [`Poll::Wait`] contract; a board's loop hides it by polling again.
    pub stale_waits: u64,
}

impl ModelReport {
    /// Host bytes per second of virtual time.
    pub fn rate(&self) -> f64 {
        self.host_bytes as f64 * 1e9 / self.elapsed_ns.max(1) as f64
    }
}

/// Nanoseconds per byte (10 bits) at `baud`.
fn byte_ns(baud: u32) -> u64 {
    10_000_000_000 / u64::from(baud.max(1))
}

/// The host's side of the upstream line.
struct Host {
    /// Bytes of the current command not yet sent.
    out: VecDeque<u8>,
    /// Bytes it may still send before it stops (`None`: not stopping).
    stop_after: Option<usize>,
    stopped: bool,
    /// The bridge's RTS as the host last saw it.
    cts: bool,
    replies: FrameDecoder<4096>,
}

impl Host {
    /// XOFF arrived (or CTS dropped): `latency` more bytes go out. A second
    /// XOFF while stopping or stopped changes nothing.
    fn told_to_stop(&mut self, latency: usize) {
        if self.stopped || self.stop_after.is_some() {
            return;
        }
        if latency == 0 {
            self.stopped = true;
            self.stop_after = None;
        } else {
            self.stop_after = Some(latency);
        }
    }

    /// XON arrived (or CTS rose).
    fn go_on(&mut self) {
        self.stopped = false;
        self.stop_after = None;
    }

    /// The host's UART looks at CTS (the bridge's RTS) before each byte;
    /// bytes already in its FIFO still go.
    fn sample_cts(&mut self, rts: bool, latency: usize) {
        if self.cts && !rts {
            self.told_to_stop(latency);
        } else if !self.cts && rts {
            self.go_on();
        }
        self.cts = rts;
    }

    /// One byte went out.
    fn sent_one(&mut self) {
        if let Some(n) = self.stop_after {
            if n <= 1 {
                self.stopped = true;
                self.stop_after = None;
            } else {
                self.stop_after = Some(n - 1);
            }
        }
    }
}

/// Runs `commands` through `bridge` one after the other (each waits for its
/// reply or [`ModelConfig::reply_limit_ms`]) against `sim`, in virtual
/// time from `start_ns` (a run on a bridge and simulator used before
/// starts where the last one ended: [`ModelReport::end_ns`]). The bridge
/// keeps its state across calls.
pub fn run(
    cfg: &ModelConfig,
    bridge: &mut Bridge,
    sim: &mut Simulator,
    commands: &[&[u8]],
    start_ns: u64,
) -> ModelReport {
    let mut up_line: Box<UpstreamRings> = Box::default();
    let mut down_line: Box<DownstreamRings> = Box::default();
    let pend = || {};
    let flow = cfg.bridge.flow;
    let (mut up_isr, mut up) = up_line.split(flow, UPSTREAM_MARKS, &pend);
    let (mut down_isr, mut down) = down_line.split(FlowControl::None, DOWNSTREAM_MARKS, &pend);
    let up_byte = byte_ns(cfg.bridge.upstream_baud);
    let down_byte = byte_ns(cfg.bridge.downstream_baud);

    let mut host = Host {
        out: VecDeque::new(),
        stop_after: None,
        stopped: false,
        cts: true,
        replies: FrameDecoder::with_policy(BypassPolicy::Reject),
    };
    let mut report = ModelReport::default();
    let mut t: u64 = start_ns;
    let ms = |t: u64| (t / 1_000_000) as u32;
    // When each line direction is free for its next byte.
    let mut host_tx_free = t;
    let mut bridge_up_tx_free = t;
    let mut bridge_down_tx_free = t;
    let mut ctrl_tx_free = t;
    let mut ctrl_out: VecDeque<u8> = VecDeque::new();
    let mut deadline: Option<u64> = None;
    let mut run_bridge = true;

    let drain = cfg.host_timeout_ms.is_some();
    for cmd in commands.iter().map(Some).chain(drain.then_some(None)) {
        let draining = cmd.is_none();
        host.out
            .extend(cmd.into_iter().flat_map(|c| c.iter().copied()));
        let mut reply = None;
        let mut last_host_byte = t;
        let mut reply_after = None;
        let mut last_progress = t;
        loop {
            // The bridge's loop, until it waits.
            if run_bridge {
                run_bridge = false;
                deadline = None;
                loop {
                    report.polls += 1;
                    match bridge.poll(&mut up, &mut down, ms(t)) {
                        Ok(Poll::Busy) => {}
                        Ok(Poll::Wait(w)) => {
                            // The contract: nothing the bridge waits for is
                            // there already (a board's loop would poll
                            // again at once; the model counts it).
                            let i = w.interest;
                            if (i.up_read && up.rx_level() > 0)
                                || (i.down_read && down.rx_level() > 0)
                            {
                                report.stale_waits += 1;
                            }
                            deadline = w.deadline.map(|d| {
                                let now = ms(t);
                                let ahead = d.wrapping_sub(now);
                                let ahead = if ahead >= 0x8000_0000 { 0 } else { ahead };
                                (u64::from(now) + u64::from(ahead)) * 1_000_000
                            });
                            break;
                        }
                        Ok(Poll::Quit) => break,
                        Err(e) => match e {},
                    }
                }
                // What a pended interrupt would do: XON once drained.
                up_isr.service();
                down_isr.service();
                if flow == FlowControl::RtsCts {
                    host.sample_cts(up_isr.rts(), cfg.host_latency);
                }
            }
            if reply.is_some() && host.out.is_empty() && !draining {
                break;
            }
            let quiet = bridge.is_idle()
                && ctrl_out.is_empty()
                && sim.next_output_at().is_none()
                && !down_isr.wants_tx()
                && !up_isr.wants_tx();
            if draining && quiet {
                break;
            }

            // The next event.
            let host_can = !host.out.is_empty() && !host.stopped;
            let mut next = u64::MAX;
            let mut pick = |when: u64, what: u8, next_what: &mut u8| {
                if when < next {
                    next = when;
                    *next_what = what;
                }
            };
            let mut what = 0u8;
            if host_can {
                pick(host_tx_free.max(t), 1, &mut what);
            }
            if up_isr.wants_tx() {
                pick(bridge_up_tx_free.max(t), 2, &mut what);
            }
            if down_isr.wants_tx() {
                pick(bridge_down_tx_free.max(t), 3, &mut what);
            }
            if !ctrl_out.is_empty() {
                pick(ctrl_tx_free.max(t), 4, &mut what);
            } else if let Some(at) = sim.next_output_at() {
                pick((u64::from(at) * 1_000_000).max(t), 5, &mut what);
            }
            if let Some(d) = deadline {
                pick(d.max(t), 6, &mut what);
            }
            if next == u64::MAX {
                // Nothing will ever happen again: the command got no reply.
                break;
            }
            if ms(next).saturating_sub(ms(last_progress)) as u64 > cfg.reply_limit_ms {
                break;
            }
            let gave_up = !draining
                && cfg.host_timeout_ms.is_some_and(|limit| {
                    reply.is_none()
                        && host.out.is_empty()
                        && next.saturating_sub(last_host_byte) > limit * 1_000_000
                });
            if gave_up {
                t = last_host_byte + cfg.host_timeout_ms.unwrap_or(0) * 1_000_000;
                break;
            }
            t = next;
            match what {
                1 => {
                    // Host → bridge: one byte arrives.
                    if let Some(b) = host.out.pop_front() {
                        report.host_bytes += 1;
                        host_tx_free = t + up_byte;
                        // The byte has arrived when its last bit has.
                        last_host_byte = t + up_byte;
                        up_isr.on_receive(b);
                        report.max_ring = report.max_ring.max(up_isr.rx_level());
                        host.sent_one();
                    }
                }
                2 => {
                    // Bridge → host: one byte leaves.
                    up_isr.service();
                    if let Some(b) = up_isr.next_tx(true) {
                        bridge_up_tx_free = t + up_byte;
                        match b {
                            XOFF if flow == FlowControl::XonXoff => {
                                report.pauses += 1;
                                host.told_to_stop(cfg.host_latency);
                            }
                            XON if flow == FlowControl::XonXoff => host.go_on(),
                            _ => {
                                if let Status::Complete(Event::Frame(f)) = host.replies.push(b) {
                                    report.answers.push(f.as_bytes().to_vec());
                                    reply = Some(f.as_bytes().to_vec());
                                    report.elapsed_ns = t + up_byte - start_ns;
                                    reply_after =
                                        Some((t + up_byte).saturating_sub(last_host_byte));
                                }
                            }
                        }
                    }
                }
                3 => {
                    // Bridge → controller.
                    down_isr.service();
                    if let Some(b) = down_isr.next_tx(true) {
                        bridge_down_tx_free = t + down_byte;
                        sim.receive(&[b], ms(t));
                    }
                }
                4 => {
                    // Controller → bridge.
                    if let Some(b) = ctrl_out.pop_front() {
                        ctrl_tx_free = t + down_byte;
                        down_isr.on_receive(b);
                    }
                }
                5 => ctrl_out.extend(sim.take_output(ms(t))),
                _ => {}
            }
            if flow == FlowControl::RtsCts {
                host.sample_cts(up_isr.rts(), cfg.host_latency);
            }
            if what != 6 {
                last_progress = t;
            }
            run_bridge = true;
        }
        if !draining {
            report.replies.push(reply);
            report.reply_after_ns.push(reply_after);
        }
    }
    report.end_ns = t;
    report.overruns = up.overruns();
    if flow == FlowControl::RtsCts {
        report.pauses = up.pauses();
    }
    report
}

/// A fresh bridge with `cfg` (boxed: it is a few kilobytes).
pub fn bridge(cfg: &Config) -> Box<Bridge> {
    Box::new(Bridge::new(*cfg, Source::Default, 0x5EED))
}
