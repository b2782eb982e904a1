//! The request engine (chapter 5: timeouts, resends, reply matching)
//! against scripted controllers and the simulator, in virtual time.

use std::collections::VecDeque;

use host_tests::link::{call, line_to};
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::engine::{feed, Step};
use iai_protocol_b::error::ErrorDetail;
use iai_protocol_b::frame::Station;
use iai_protocol_b::message::{
    AbsoluteMove, AxisStatus, AxisStatusQuery, AxisStatusResponse, ErrorDetailResponse,
    ErrorResponse, Message, RelativeMove, Request, SoftwareReset, SystemStatusQuery, TestCall,
    TestCallResponse,
};
use iai_protocol_b::{
    client::Client, client::Pending, error::Failure, line::Line, line::LineConfig,
};
use iai_simulator::{Faults, Simulator};

const ST: Station = Station(0x99);

/// A line just opened to the controller at `ST`: its first command is
/// fenced.
fn line() -> Line {
    Line::new(LineConfig::new(ST), 7)
}

fn frame<'a>(msg: &impl Message<'a>, station: Station) -> Vec<u8> {
    let mut buf = vec![0u8; msg.emit_len()];
    let n = msg.emit(station, &mut buf).unwrap();
    assert_eq!(n, buf.len(), "emit_len is the frame length");
    buf
}

fn error_frame(code: u16) -> Vec<u8> {
    let mut buf = [0u8; 10];
    let n = ErrorResponse { code }.emit(ST, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// A 212H reply reporting axis 1 at `pos`.
fn status(pos: i32) -> Vec<u8> {
    let mut axes = iai_protocol_b::axis::PerAxis::new();
    axes.push(AxisStatus {
        axis_status: 0x1D,
        current_position: pos,
        ..Default::default()
    })
    .unwrap();
    frame(
        &AxisStatusResponse {
            axis_pattern: iai_protocol_b::axis::AxisPattern::first(1),
            axes,
        },
        ST,
    )
}

/// A controller that answers the n-th command it receives with the n-th
/// entry of its script: frames, each after its delay (ms), in order (a
/// reply never overtakes one scheduled before it). A 200H (a line's
/// fence) is echoed 1 ms after it, in order too, and is neither scripted
/// nor counted in `received`.
struct Scripted {
    script: VecDeque<Vec<(u32, Vec<u8>)>>,
    commands: FrameDecoder,
    outbox: Vec<(u32, Vec<u8>)>,
    received: Vec<(u32, Vec<u8>)>,
    fences: u32,
}

impl Scripted {
    fn new(script: Vec<Vec<(u32, Vec<u8>)>>) -> Self {
        Scripted {
            script: script.into(),
            commands: FrameDecoder::new(),
            outbox: Vec::new(),
            received: Vec::new(),
            fences: 0,
        }
    }
    fn receive(&mut self, bytes: &[u8], now: u32) {
        for &b in bytes {
            if let Status::Complete(Event::Frame(f)) = self.commands.push(b) {
                let last = self.outbox.iter().map(|(t, _)| *t).max().unwrap_or(0);
                if let Ok(q) = TestCall::parse(&f) {
                    self.fences += 1;
                    let echo = frame(
                        &TestCallResponse {
                            test_string: q.test_string,
                        },
                        ST,
                    );
                    self.outbox.push(((now + 1).max(last), echo));
                    continue;
                }
                self.received.push((now, f.as_bytes().to_vec()));
                for (delay, reply) in self.script.pop_front().unwrap_or_default() {
                    let last = self.outbox.iter().map(|(t, _)| *t).max().unwrap_or(0);
                    self.outbox.push(((now + delay).max(last), reply));
                }
            }
        }
    }
    fn next_at(&self) -> Option<u32> {
        self.outbox.iter().map(|(t, _)| *t).min()
    }
    fn take(&mut self, now: u32) -> Vec<u8> {
        self.outbox.sort_by_key(|(t, _)| *t);
        let due = self.outbox.iter().take_while(|(t, _)| *t <= now).count();
        self.outbox.drain(..due).flat_map(|(_, b)| b).collect()
    }
}

/// Runs one request on `line` against a scripted controller;
/// transmissions take `tx_ms` each. Returns the outcome and the tick it
/// ended at.
fn run<'a, R: Request<'a>>(
    client: &mut Client,
    line: &mut Line,
    ctl: &mut Scripted,
    req: &R,
    mut now: u32,
    tx_ms: u32,
) -> (Result<(), Failure>, u32, Pending<R>) {
    let ticket = client.start(line, req, now).unwrap();
    let mut pending = Vec::new();
    loop {
        pending.extend(ctl.take(now));
        feed(client, line, &pending, now);
        pending.clear();
        match client.poll(line, now) {
            Step::Transmit(b) => {
                let b = b.to_vec();
                now += tx_ms;
                ctl.receive(&b, now);
                client.sent(line, now);
            }
            Step::WaitUntil(t) => {
                now = ctl.next_at().map_or(t, |r| r.min(t)).max(now + 1);
            }
            Step::Done(r) => return (r, now, ticket),
            Step::Idle => panic!("idle"),
        }
    }
}

fn client() -> Client {
    Client::new()
}

#[test]
fn no_reply_times_out_after_three_sends_each_timed_from_the_end_of_transmission() {
    let mut c = client();
    let mut l = line();
    let mut ctl = Scripted::new(vec![]);
    // Each send takes 2 s on the wire (a long command at 9,600 baud).
    let (r, end, _) = run(&mut c, &mut l, &mut ctl, &SystemStatusQuery {}, 0, 2_000);
    assert_eq!(r, Err(Failure::Timeout { sends: 3 }));
    assert_eq!(ctl.fences, 1, "a line just opened fences first");
    let sent_at: Vec<u32> = ctl.received.iter().map(|(t, _)| *t).collect();
    // Its first send ends at s; the timeout runs 3 s from that end, the
    // resend ends 2 s later, and so on.
    let s = sent_at[0];
    assert_eq!(sent_at, [s, s + 5_000, s + 10_000]);
    assert_eq!(end, s + 13_000);
    assert_eq!(l.stats().timeouts, 3);
    assert_eq!(l.stats().resends, 2);

    // Four sends when the system allows three re-sends.
    let mut cfg = LineConfig::new(ST);
    cfg.max_sends = 4;
    let mut l = Line::new(cfg, 7);
    let mut ctl = Scripted::new(vec![]);
    let (r, _, _) = run(&mut c, &mut l, &mut ctl, &SystemStatusQuery {}, 0, 1);
    assert_eq!(r, Err(Failure::Timeout { sends: 4 }));
    assert_eq!(ctl.received.len(), 4);
}

#[test]
fn a_late_reply_is_taken_once_and_a_stale_one_never_reads_as_the_next_state() {
    let mut c = client();
    let mut l = line();
    let q = AxisStatusQuery::of(&[1]).unwrap();
    // Before a move the axis is at 0. The reply to the first 212H comes
    // 3.5 s late (after the resend), the reply to the resend 2 s after it.
    // Then a 234H moves the axis; the next 212H is answered with 50,000.
    let mut ctl = Scripted::new(vec![
        vec![(3_500, status(0))],
        vec![(2_000, status(0))],
        vec![(
            5,
            frame(&iai_protocol_b::message::AbsoluteMoveResponse {}, ST),
        )],
        vec![(5, status(50_000))],
    ]);
    let (r, t, ticket) = run(&mut c, &mut l, &mut ctl, &q, 0, 1);
    assert_eq!(r, Ok(()));
    let first = c.response(&ticket).unwrap();
    assert_eq!(first.axes[0].current_position, 0);
    assert_eq!(ctl.received.len(), 2, "sent twice");
    // The move: the reply owed to the resend is settled by a fence (the
    // controller answers in order: it comes before the echo), so it is
    // never taken for the 234H, and the next 212H reads the new state.
    let go = AbsoluteMove::to(&[(1, 50_000)]).unwrap();
    let (r, t, _) = run(&mut c, &mut l, &mut ctl, &go, t, 1);
    assert_eq!(r, Ok(()));
    let (r, _, ticket) = run(&mut c, &mut l, &mut ctl, &q, t, 1);
    assert_eq!(r, Ok(()));
    let after = c.response(&ticket).unwrap();
    assert_eq!(after.axes[0].current_position, 50_000, "not the stale 0");
    assert_eq!(ctl.fences, 2);
    let resend_reply_at = ctl.received[1].0 + 2_000;
    assert!(
        ctl.received[2].0 > resend_reply_at,
        "the 234H went after the owed reply, not 6 s later: {:?}",
        ctl.received[2].0
    );
    assert!(ctl.received[2].0 < resend_reply_at + 10);
    // The owed reply came while the fence's echo was awaited: explained,
    // so stale (not a sign of copies).
    assert_eq!((l.stats().stale, l.stats().unplaced), (1, 0));
}

#[test]
fn replies_from_another_station_or_for_another_id_never_answer() {
    let mut c = client();
    let mut l = line();
    let ctl_frames = vec![vec![
        (
            1,
            frame(
                &iai_protocol_b::message::ServoOnOffResponse {},
                Station(0x01),
            ),
        ),
        (
            2,
            frame(&iai_protocol_b::message::HomeReturnResponse {}, ST),
        ),
        (3, error_frame_for(Station(0x02), 0x123)),
        (4, status(7)),
    ]];
    let mut ctl = Scripted::new(ctl_frames);
    let q = AxisStatusQuery::of(&[1]).unwrap();
    let (r, _, ticket) = run(&mut c, &mut l, &mut ctl, &q, 0, 1);
    assert_eq!(r, Ok(()));
    assert_eq!(c.response(&ticket).unwrap().axes[0].current_position, 7);
    // Two frames of other stations; the 233H reply is this station's, to
    // a command nobody sent on this line: it cannot be placed.
    assert_eq!(l.stats().foreign, 2);
    assert_eq!(l.stats().unplaced, 1);
    assert_eq!(ctl.received.len(), 1);
}

fn error_frame_for(station: Station, code: u16) -> Vec<u8> {
    let mut buf = [0u8; 10];
    let n = ErrorResponse { code }.emit(station, &mut buf).unwrap();
    buf[..n].to_vec()
}

#[test]
fn an_error_reply_is_a_typed_error_not_resent_with_the_216h_detail_when_asked() {
    // Without the detail.
    let mut c = client();
    let mut l = line();
    let mut ctl = Scripted::new(vec![vec![(2, error_frame(0xC74))]]);
    let go = AbsoluteMove::to(&[(1, 1_000)]).unwrap();
    let (r, _, _) = run(&mut c, &mut l, &mut ctl, &go, 0, 1);
    assert_eq!(
        r,
        Err(Failure::Controller {
            code: 0xC74,
            detail: None
        })
    );
    assert_eq!(ctl.received.len(), 1, "not sent again");

    // With it: the client asks 216H for the latest system error.
    let detail = ErrorDetailResponse {
        error_number: 0xC74,
        detail_1: 1,
        detail_2: 5,
        detail_3: 2,
        detail_4: -3,
        ..Default::default()
    };
    let bridge_codes = |code: u16| (0xB00..=0xBFF).contains(&code);
    let mut c: Client = Client::new().with_error_detail_except(bridge_codes);
    let mut l = line();
    let mut ctl = Scripted::new(vec![
        vec![(2, error_frame(0xC74))],
        vec![(2, frame(&detail, ST))],
    ]);
    let (r, _, _) = run(&mut c, &mut l, &mut ctl, &go, 0, 1);
    assert_eq!(
        r,
        Err(Failure::Controller {
            code: 0xC74,
            detail: Some(ErrorDetail {
                error_number: 0xC74,
                detail_1: 1,
                detail_2: 5,
                detail_3: 2,
                detail_4: -3,
                detail_5_to_8: [0; 4],
                matches_code: true,
            })
        })
    );
    assert_eq!(ctl.received.len(), 2);
    assert_eq!(
        &ctl.received[1].1[..9],
        b"!99216001",
        "216H type 0, latest error"
    );

    // A bridge's own code: no 216H is asked for, it would have no detail.
    let mut l = line();
    let mut ctl = Scripted::new(vec![vec![(2, error_frame(0xB02))]]);
    let (r, _, _) = run(&mut c, &mut l, &mut ctl, &go, 0, 1);
    assert_eq!(
        r,
        Err(Failure::Controller {
            code: 0xB02,
            detail: None
        })
    );
    assert_eq!(ctl.received.len(), 1);
}

#[test]
fn software_reset_expects_no_reply_and_holds_the_next_command_10_s() {
    let mut c = client();
    let mut l = line();
    let mut ctl = Scripted::new(vec![vec![], vec![(2, status(1))]]);
    let (r, t, _) = run(&mut c, &mut l, &mut ctl, &SoftwareReset {}, 0, 1);
    assert_eq!(r, Ok(()));
    assert_eq!(c.reply_frame(), None, "no normal response");
    let sent = ctl.received[0].0;
    assert_eq!(t, sent + 3_000, "waited out the timeout for an error reply");
    assert_eq!(ctl.received.len(), 1, "never resent");
    let q = AxisStatusQuery::of(&[1]).unwrap();
    let (r, _, _) = run(&mut c, &mut l, &mut ctl, &q, t, 1);
    assert_eq!(r, Ok(()));
    assert_eq!(
        ctl.received[1].0,
        sent + 10_001,
        "sent 10 s after the reset (+ its 1 ms)"
    );
    // An error reply to the reset is still reported.
    let mut c = client();
    let mut l = line();
    let mut ctl = Scripted::new(vec![vec![(5, error_frame(0x0E1))]]);
    let (r, _, _) = run(&mut c, &mut l, &mut ctl, &SoftwareReset {}, 0, 1);
    assert_eq!(
        r,
        Err(Failure::Controller {
            code: 0x0E1,
            detail: None
        })
    );
}

#[test]
fn a_relative_move_without_reply_is_an_unknown_outcome_sent_once_unless_allowed() {
    let mv = RelativeMove::by(&[(1, 10_000)]).unwrap();
    let mut c = client();
    let mut ctl = Scripted::new(vec![]);
    let (r, _, _) = run(&mut c, &mut line(), &mut ctl, &mv, 0, 1);
    assert_eq!(r, Err(Failure::OutcomeUnknown { sends: 1 }));
    assert_eq!(ctl.received.len(), 1);

    let mut cfg = LineConfig::new(ST);
    cfg.resend_unsafe = true;
    let mut ctl = Scripted::new(vec![]);
    let (r, _, _) = run(&mut c, &mut Line::new(cfg, 7), &mut ctl, &mv, 0, 1);
    assert_eq!(r, Err(Failure::OutcomeUnknown { sends: 3 }));
    assert_eq!(ctl.received.len(), 3);
}

#[test]
fn a_reply_that_arrives_broken_is_resent_after_the_turnaround() {
    let mut broken = status(5);
    let at = broken.len() - 5;
    broken[at] ^= 0x01; // a digit of the position changes: SC fails
    let mut c = client();
    let mut ctl = Scripted::new(vec![vec![(10, broken)], vec![(10, status(5))]]);
    let q = AxisStatusQuery::of(&[1]).unwrap();
    let (r, t, _) = run(&mut c, &mut line(), &mut ctl, &q, 0, 1);
    assert_eq!(r, Ok(()));
    assert_eq!(ctl.received.len(), 2);
    assert!(ctl.received[1].0 < 100, "resent at once, not after 3 s");
    assert!(t < 200);
}

#[test]
fn typed_replies_from_the_simulator_and_a_move_built_from_pairs() {
    let mut sim = Simulator::tta(ST);
    let mut l = line_to(&sim);
    let mut c = client();
    let go = AbsoluteMove::to(&[(2, -25_500), (1, 100_000)])
        .unwrap()
        .with_speed(100);
    // EXAMPLES 4: axes 1 + 2, values in ascending axis order.
    assert_eq!(go.axis_pattern.bits(), 0x03);
    assert_eq!(go.absolute_coordinate.as_slice(), &[100_000, -25_500]);
    let (r, t, _) = call(&mut c, &mut l, &mut sim, &go, 0);
    assert_eq!(r, Ok(()));
    let (r, _, ticket) = call(
        &mut c,
        &mut l,
        &mut sim,
        &AxisStatusQuery::of(&[1, 2, 3]).unwrap(),
        t,
    );
    assert_eq!(r, Ok(()));
    assert_eq!(c.response(&ticket).unwrap().axes.len(), 3);
}

#[test]
fn the_simulator_with_faults_answers_every_request_in_the_end() {
    let faults = Faults {
        flip_bit_in: 1e-3,
        flip_bit_out: 1e-3,
        drop_reply: 0.1,
        garbage_before_reply: 0.2,
        ..Faults::default()
    };
    let mut sim = Simulator::tta(ST).with_faults(faults, 42);
    let mut l = line_to(&sim);
    let mut c = client();
    let mut now = 0;
    let (mut ok, mut timeouts) = (0, 0);
    for _ in 0..500 {
        let (r, t, ticket) = call(
            &mut c,
            &mut l,
            &mut sim,
            &AxisStatusQuery::of(&[1, 2]).unwrap(),
            now,
        );
        now = t;
        match r {
            Ok(()) => {
                ok += 1;
                assert_eq!(c.response(&ticket).unwrap().axes.len(), 2);
            }
            Err(Failure::Timeout { sends: 3 }) => timeouts += 1,
            other => panic!("{other:?}"),
        }
    }
    println!(
        "500 x 212H under faults: {ok} answered, {timeouts} timed out, {:?}",
        l.stats()
    );
    assert!(ok > 480);
}

#[test]
fn the_blocking_flavour_over_a_uart_and_a_closure_clock() {
    use iai_protocol_b::io::Loopback;
    let mut uart = Loopback::default();
    let mut ms = 0u32;
    let mut clock = move || {
        ms += 1;
        ms
    };
    let mut c = client();
    let mut l = line();
    let reply = c
        .call(
            &mut l,
            &mut uart,
            &mut clock,
            &AxisStatusQuery::of(&[1, 4]).unwrap(),
        )
        .unwrap();
    assert_eq!(reply.axes.len(), 2);
    let none = c.call(&mut l, &mut uart, &mut clock, &SoftwareReset {});
    assert!(none.is_ok());
}

/// Every engine's first command (after its line's fence) goes out at once
/// whatever the tick: a bridge idle since boot may send its first command
/// on day 25 (past 2^31 ms) or just before its clock wraps on day 49.7.
#[test]
fn engines_start_at_once_on_any_tick() {
    use iai_protocol_b::{
        profile::Profile, readback::ReadBack, readback::ReadBackConfig, transfer::Transfer,
        transfer::TransferConfig,
    };
    for now in [0u32, 0x8000_0000, 0x8000_0001, u32::MAX - 5_000, u32::MAX] {
        // The echo of a fence, if `bytes` is one.
        let echo = |bytes: &[u8]| -> Option<Vec<u8>> {
            bytes.starts_with(b"!99200").then(|| {
                let mut e = bytes.to_vec();
                e[0] = b'#';
                let sum: u32 = e[..16].iter().map(|&b| u32::from(b)).sum();
                e[16..18].copy_from_slice(format!("{:02X}", sum & 0xFF).as_bytes());
                e
            })
        };
        let mut c = client();
        let mut l = line();
        c.start(&mut l, &AxisStatusQuery::default(), now).unwrap();
        let Step::Transmit(b) = c.poll(&mut l, now) else {
            panic!()
        };
        let e = echo(b).expect("client: the fence");
        c.sent(&mut l, now);
        feed(&mut c, &mut l, &e, now);
        let at = now.wrapping_add(2);
        assert!(
            matches!(c.poll(&mut l, at), Step::Transmit(b) if b.starts_with(b"!99212")),
            "client at {now:#x}"
        );
        let mut t: Transfer<_> = Transfer::new(
            TransferConfig::new(Profile::TTA),
            host_tests::table::table(3, 1, 1),
        );
        let mut l = line();
        let Step::Transmit(b) = t.poll(&mut l, now) else {
            panic!()
        };
        let e = echo(b).expect("transfer: the fence");
        t.sent(&mut l, now);
        feed(&mut t, &mut l, &e, now);
        assert!(
            matches!(t.poll(&mut l, at), Step::Transmit(b) if b.starts_with(b"!9926D")),
            "transfer at {now:#x}"
        );
        let mut r: ReadBack = ReadBack::new(ReadBackConfig::new(Profile::TTA, 1, 100));
        let mut l = line();
        let Step::Transmit(b) = r.poll(&mut l, now) else {
            panic!()
        };
        let e = echo(b).expect("read-back: the fence");
        r.sent(&mut l, now);
        let mut rest = &e[..];
        while !rest.is_empty() {
            rest = &rest[r.received(&mut l, rest, now).consumed..];
        }
        assert!(
            matches!(r.poll(&mut l, at), Step::Transmit(b) if b.starts_with(b"!9921F")),
            "read-back at {now:#x}"
        );
    }
}
