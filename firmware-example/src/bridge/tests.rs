//! The bridge's jobs, frame by frame.

extern crate std;
use std::vec::Vec;

use super::*;
use crate::codes;
use crate::config::{AllowList, Policy};
use crate::serial::FlowControl;
use embedded_io::{Read, ReadReady};
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::frame::{emit_frame, Frame, Header};

/// The seed of the bridges under test.
const SEED: u32 = 0;

/// A port over byte vectors: reads `input`, collects what is written. As
/// the controller side it answers the bridge's fences (200H whose ten
/// characters are hex digits; the hosts of these tests send other texts)
/// with their echo, and keeps them out of `output`.
#[derive(Default)]
struct Fake {
    input: Vec<u8>,
    output: Vec<u8>,
    echo_fences: bool,
    fences: u32,
    /// The peer sent XOFF (and no XON since).
    stopped: bool,
}

impl Fake {
    fn controller() -> Self {
        Fake {
            echo_fences: true,
            ..Fake::default()
        }
    }
}

impl embedded_io::ErrorType for Fake {
    type Error = core::convert::Infallible;
}
impl ReadReady for Fake {
    fn read_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(!self.input.is_empty())
    }
}
impl Read for Fake {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        let n = buf.len().min(self.input.len());
        buf[..n].copy_from_slice(&self.input[..n]);
        self.input.drain(..n);
        Ok(n)
    }
}
impl WriteReady for Fake {
    fn write_ready(&mut self) -> Result<bool, Self::Error> {
        Ok(true)
    }
}
impl Write for Fake {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        let fence = buf.len() == 20
            && buf.starts_with(b"!99200")
            && buf[6..16].iter().all(|b| b.is_ascii_hexdigit());
        if self.echo_fences && fence {
            self.fences += 1;
            let f = Frame::new_checked(buf, BypassPolicy::Reject).unwrap();
            let echo = frame(Header::Response, 0x99, 0x200, f.body());
            self.input.extend_from_slice(&echo);
            return Ok(buf.len());
        }
        self.output.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}
impl Port for Fake {
    fn peer_stopped(&mut self) -> bool {
        self.stopped
    }
    fn release_peer_stop(&mut self) {
        self.stopped = false;
    }
}

fn frame(header: Header, station: u8, code: u16, body: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; 64];
    let n = emit_frame(
        &mut buf,
        header,
        Station(station),
        code,
        ChecksumMode::Compute,
        |w| w.put(body),
    )
    .unwrap();
    buf[..n].to_vec()
}

/// Polls until the bridge waits, at tick `now`.
fn settle(b: &mut Bridge, up: &mut Fake, down: &mut Fake, now: u32) {
    for _ in 0..10_000 {
        if let Poll::Wait(_) = b.poll(up, down, now).unwrap() {
            return;
        }
    }
    panic!("the bridge never waits");
}

fn bridge(policy: Policy) -> Bridge {
    Bridge::new(
        Config {
            policy,
            ..Config::DEFAULT
        },
        Source::Default,
        SEED,
    )
}

#[test]
fn own_station_answers_status_and_b09() {
    let mut b = bridge(Policy::ForwardAll);
    let (mut up, mut down) = (Fake::default(), Fake::controller());
    up.input = frame(Header::Command, 0xBB, codes::STATUS_QUERY, b"");
    up.input.extend(frame(Header::Command, 0xBB, 0x212, b"01"));
    settle(&mut b, &mut up, &mut down, 7);
    settle(&mut b, &mut up, &mut down, 8);
    assert!(down.output.is_empty());
    let status = Frame::new_checked(&up.output[..status::REPLY_LEN], BypassPolicy::Reject).unwrap();
    let fields = status::parse(status.body()).unwrap();
    assert_eq!(fields[1], ("uptime_ms", 7));
    assert_eq!(fields[16], ("own_queries", 1));
    assert_eq!(
        &up.output[status::REPLY_LEN..],
        &frame(Header::Error, 0xBB, codes::UNKNOWN_QUERY, b"")[..]
    );
    assert_eq!(b.last_error().map(|e| e.code), Some(codes::UNKNOWN_QUERY));
}

#[test]
fn other_stations_are_ignored_and_refusals_answered_after_the_end() {
    let mut b = bridge(Policy::Allow(AllowList::of(&[0x212])));
    let (mut up, mut down) = (Fake::default(), Fake::controller());
    up.input = frame(Header::Command, 0x42, 0x212, b"01");
    up.input.extend(frame(Header::Command, 0x99, 0x25B, b""));
    settle(&mut b, &mut up, &mut down, 0);
    settle(&mut b, &mut up, &mut down, 1);
    assert!(down.output.is_empty());
    assert_eq!(up.output, frame(Header::Error, 0x99, codes::REFUSED, b""));
    assert_eq!(b.stats().other_station, 1);
    assert_eq!(b.stats().refused, 1);
    // A refused command with a wrong checksum gets no answer.
    let mut bad = frame(Header::Command, 0x99, 0x25B, b"");
    bad[6] ^= 1;
    up.input = bad;
    up.output.clear();
    settle(&mut b, &mut up, &mut down, 2);
    assert!(up.output.is_empty());
    assert_eq!(b.stats().rejected, 1);
    // The allowed one goes through.
    // The allowed one goes through (after the fence of a line just booted
    // and its turnaround).
    up.input = frame(Header::Command, 0x99, 0x212, b"01");
    settle(&mut b, &mut up, &mut down, 3);
    settle(&mut b, &mut up, &mut down, 5);
    assert_eq!(down.fences, 1);
    assert_eq!(down.output, frame(Header::Command, 0x99, 0x212, b"01"));
}

/// Under a restricting policy a 200H whose ten characters hold a frame is
/// refused: a controller that decodes again inside a broken 200H could run
/// the frame although the policy refuses it. Under forward-all it goes.
#[test]
fn no_command_rides_in_a_200h_text_under_a_restricting_policy() {
    // `!9925B` inside the text: a software reset the read-only policy
    // refuses.
    let text = b"!9925B3C\r\n";
    for (policy, refused) in [(Policy::ReadOnly, true), (Policy::ForwardAll, false)] {
        let mut b = bridge(policy);
        let (mut up, mut down) = (Fake::default(), Fake::controller());
        let cmd = frame(Header::Command, 0x99, 0x200, text);
        up.input = cmd.clone();
        settle(&mut b, &mut up, &mut down, 0);
        settle(&mut b, &mut up, &mut down, 2);
        if refused {
            assert!(down.output.is_empty(), "{policy:?}");
            assert_eq!(up.output, frame(Header::Error, 0x99, codes::REFUSED, b""));
            assert_eq!(b.stats().refused, 1);
        } else {
            assert_eq!(down.output, cmd, "{policy:?}");
        }
    }
}

#[test]
fn a_reply_with_xoff_in_its_text_is_not_relayed_under_xon_xoff() {
    for flow in [FlowControl::XonXoff, FlowControl::None] {
        let mut b = Bridge::new(
            Config {
                flow,
                ..Config::DEFAULT
            },
            Source::Default,
            SEED,
        );
        let (mut up, mut down) = (Fake::default(), Fake::controller());
        // 216H: the latest system error, whose reply carries a message.
        let cmd = emitted(&iai_protocol_b::message::ErrorDetailQuery::latest_system_error());
        up.input = cmd.clone();
        settle(&mut b, &mut up, &mut down, 0);
        settle(&mut b, &mut up, &mut down, 2);
        assert_eq!(down.output, cmd);
        let reply = emitted(&iai_protocol_b::message::ErrorDetailResponse {
            error_number: 0x0E1,
            message: b"axis 1 \x13 stopped",
            ..Default::default()
        });
        down.input = reply.clone();
        settle(&mut b, &mut up, &mut down, 5);
        settle(&mut b, &mut up, &mut down, 6);
        let want = match flow {
            FlowControl::XonXoff => frame(Header::Error, 0x99, codes::XON_XOFF_IN_TEXT, b""),
            _ => reply,
        };
        assert_eq!(up.output, want, "{flow:?}");
    }
}

#[test]
fn no_reply_within_3_s_gives_no_answer_and_the_deadline_says_when() {
    let mut b = bridge(Policy::ForwardAll);
    let (mut up, mut down) = (Fake::default(), Fake::controller());
    up.input = frame(Header::Command, 0x99, 0x212, b"01");
    // Just booted: the line's fence goes first, answered at once; the
    // command follows after the turnaround (two ticks).
    settle(&mut b, &mut up, &mut down, 100);
    assert_eq!(down.fences, 1);
    assert!(down.output.is_empty());
    settle(&mut b, &mut up, &mut down, 102);
    assert_eq!(down.output, frame(Header::Command, 0x99, 0x212, b"01"));
    let Poll::Wait(w) = b.poll(&mut up, &mut down, 102).unwrap() else {
        panic!("waits for the reply");
    };
    assert_eq!(w.reason, Reason::Controller);
    assert_eq!(w.deadline, Some(102 + 3_000));
    settle(&mut b, &mut up, &mut down, 3_101);
    assert!(!b.is_idle());
    settle(&mut b, &mut up, &mut down, 3_102);
    assert!(b.is_idle());
    assert!(up.output.is_empty());
    assert_eq!(b.stats().reply_timeouts, 1);
}

// ---------------------------------------------------------------------
// What may still arrive belongs to the line, not to one 26DH.
// ---------------------------------------------------------------------

use iai_protocol_b::message::{
    ChangePositionData2, ChangePositionData2Response, EffectivePositionQuery2,
    EffectivePositionResponse2, Message, Repeated,
};
use iai_protocol_b::position::PositionRecord;

/// Position 1, coordinate 1 at `x`.
fn rec(x: i32) -> PositionRecord {
    PositionRecord::new(1, 30, 30, 100, &[(1, x)]).unwrap()
}

fn emitted<'a>(m: &impl Message<'a>) -> Vec<u8> {
    let mut buf = [0u8; 256];
    let n = m.emit(Station(0x99), &mut buf).unwrap();
    buf[..n].to_vec()
}

/// The host's 26DH of position 1 at `x`.
fn host_26dh(x: i32) -> Vec<u8> {
    emitted(&ChangePositionData2 {
        records: Repeated::from_slice(&[rec(x)]),
    })
}

fn chunk_reply() -> Vec<u8> {
    emitted(&ChangePositionData2Response {
        number_of_changed_positions: 1,
    })
}

/// A 21FH reply showing position 1 at `x`.
fn read_back(x: i32) -> Vec<u8> {
    emitted(&EffectivePositionResponse2 {
        records: Repeated::from_slice(&[rec(x)]),
    })
}

/// The commands the bridge wrote downstream since the last call, by ID.
fn commands(down: &mut Fake) -> Vec<u16> {
    let mut dec: iai_protocol_b::decoder::FrameDecoder<4096> = Default::default();
    let mut ids = Vec::new();
    for &b in &down.output {
        if let iai_protocol_b::decoder::Status::Complete(iai_protocol_b::decoder::Event::Frame(f)) =
            dec.push(b)
        {
            ids.push(f.code());
        }
    }
    down.output.clear();
    ids
}

/// Issue "one memory of the line", case 2: a 26DH's read-back reply comes
/// late, the bridge answers after the host gave up, the host sends the
/// 26DH again. The reply still owed to the first message's read-back
/// arrives while the second message starts: it must not verify the
/// second message's chunk, which the controller stored with two digits
/// swapped. The second message's first command is fenced, the owed reply
/// comes before the echo, and the swap is found and rewritten.
#[test]
fn a_reply_owed_to_the_first_26dh_never_verifies_the_resent_one() {
    let mut b = bridge(Policy::ForwardAll);
    let (mut up, mut down) = (Fake::default(), Fake::controller());
    // Message 1: fence (echoed by the fake), chunk, read-back.
    up.input = host_26dh(111_111);
    settle(&mut b, &mut up, &mut down, 0);
    settle(&mut b, &mut up, &mut down, 2);
    assert_eq!(commands(&mut down), [0x26D]);
    down.input = chunk_reply();
    settle(&mut b, &mut up, &mut down, 10);
    settle(&mut b, &mut up, &mut down, 12);
    assert_eq!(commands(&mut down), [0x21F]);
    // No read-back reply within 3 s: the query is sent again; then the
    // late reply to the first query comes and verifies message 1.
    settle(&mut b, &mut up, &mut down, 3_012);
    assert_eq!(commands(&mut down), [0x21F]);
    down.input = read_back(111_111);
    settle(&mut b, &mut up, &mut down, 3_050);
    assert_eq!(up.output, reply_26dh_of(1));
    up.output.clear();
    // The host had given up after its 3 s and sends message 1 again; the
    // reply owed to the second read-back query comes meanwhile.
    up.input = host_26dh(111_111);
    down.echo_fences = false;
    settle(&mut b, &mut up, &mut down, 3_100);
    let fence = down.output.clone();
    assert!(fence.starts_with(b"!99200"), "the resent message is fenced");
    down.output.clear();
    // In order: the owed reply (the first message's content), the echo.
    let f = Frame::new_checked(&fence, BypassPolicy::Reject).unwrap();
    down.input = read_back(111_111);
    down.input
        .extend(frame(Header::Response, 0x99, 0x200, f.body()));
    down.echo_fences = true;
    settle(&mut b, &mut up, &mut down, 3_110);
    settle(&mut b, &mut up, &mut down, 3_112);
    assert_eq!(commands(&mut down), [0x26D]);
    // The controller stores position 1 swapped (1,094,151): the chunk's
    // read-back shows it, and the chunk is rewritten before any `#`.
    down.input = chunk_reply();
    settle(&mut b, &mut up, &mut down, 3_120);
    settle(&mut b, &mut up, &mut down, 3_122);
    assert_eq!(commands(&mut down), [0x21F]);
    down.input = read_back(1_094_151);
    settle(&mut b, &mut up, &mut down, 3_130);
    settle(&mut b, &mut up, &mut down, 3_132);
    assert!(
        up.output.is_empty(),
        "no answer before the rewrite is read back"
    );
    assert_eq!(commands(&mut down), [0x26D]);
    down.input = chunk_reply();
    settle(&mut b, &mut up, &mut down, 3_140);
    settle(&mut b, &mut up, &mut down, 3_142);
    assert_eq!(commands(&mut down), [0x21F]);
    down.input = read_back(111_111);
    settle(&mut b, &mut up, &mut down, 3_150);
    settle(&mut b, &mut up, &mut down, 3_152);
    assert_eq!(up.output, reply_26dh_of(1));
}

/// Issue "one memory of the line", case 4: the 26DH path gives up on a
/// read-back (its three queries unanswered: `&` B02 to the host), and the
/// reply to one of them comes late, while the host's next command, a
/// 21FH of its own, waits to go down. The pass-through is fenced: the late
/// reply comes before the echo and is not relayed; the host gets the reply
/// to its own query.
#[test]
fn the_pass_through_never_relays_a_reply_to_the_bridges_own_query() {
    let mut b = bridge(Policy::ForwardAll);
    let (mut up, mut down) = (Fake::default(), Fake::controller());
    up.input = host_26dh(111_111);
    settle(&mut b, &mut up, &mut down, 0);
    settle(&mut b, &mut up, &mut down, 2);
    down.input = chunk_reply();
    settle(&mut b, &mut up, &mut down, 10);
    settle(&mut b, &mut up, &mut down, 12);
    for t in [3_012, 6_012, 9_012] {
        settle(&mut b, &mut up, &mut down, t);
    }
    assert_eq!(commands(&mut down), [0x26D, 0x21F, 0x21F, 0x21F]);
    assert_eq!(
        up.output,
        frame(Header::Error, 0x99, codes::CONTROLLER_TIMEOUT, b"")
    );
    up.output.clear();
    // The host asks 21FH for positions 1..2 itself.
    let mine = emitted(&EffectivePositionQuery2 {
        query_head_position_number: 1,
        number_of_query_records: 2,
    });
    up.input = mine.clone();
    down.echo_fences = false;
    settle(&mut b, &mut up, &mut down, 9_020);
    // Fenced: the bridge's queries are owed. The controller answers in
    // order: the late reply to the bridge's last query first (5,998 ms
    // after it was sent: within its timeout and late window), then the
    // fence's echo.
    let fence = down.output.clone();
    assert!(fence.starts_with(b"!99200"), "a fence, not the host's 21FH");
    down.output.clear();
    let f = Frame::new_checked(&fence, BypassPolicy::Reject).unwrap();
    down.input = read_back(999);
    down.input
        .extend(frame(Header::Response, 0x99, 0x200, f.body()));
    settle(&mut b, &mut up, &mut down, 12_010);
    settle(&mut b, &mut up, &mut down, 12_012);
    assert_eq!(commands(&mut down), [0x21F]);
    assert!(up.output.is_empty(), "the late reply was not relayed");
    down.input = read_back(111_111);
    settle(&mut b, &mut up, &mut down, 12_030);
    settle(&mut b, &mut up, &mut down, 12_031);
    assert_eq!(
        up.output,
        read_back(111_111),
        "the reply to the host's query"
    );
}

/// `#99` 26DH with the count: the bridge's answer to a whole 26DH.
fn reply_26dh_of(count: u16) -> Vec<u8> {
    emitted(&ChangePositionData2Response {
        number_of_changed_positions: count,
    })
}

/// Issue "never wrong when the line breaks its rules": the bridge restarts
/// (same seed, and the host's first byte at the same tick: its first fence
/// has the same text) while its first fence's echo is on the way. The old
/// echo settles the new fence; the new fence's own echo then arrives while
/// the host's 200H waits for its reply. The pass-through never relays a
/// frame the bridge itself caused: the host gets the echo of its own text.
#[test]
fn a_restarted_bridge_never_relays_its_own_fence_echo() {
    let query = frame(Header::Command, 0x99, 0x212, b"01");
    let first_fence = {
        let mut b = bridge(Policy::ForwardAll);
        let (mut up, mut down) = (Fake::default(), Fake::default());
        up.input = query.clone();
        settle(&mut b, &mut up, &mut down, 0);
        let fence = down.output.clone();
        assert!(
            fence.starts_with(b"!99200"),
            "a line just booted fences first"
        );
        fence
        // Power cut: the echo is still on its way.
    };
    let mut b = bridge(Policy::ForwardAll);
    let (mut up, mut down) = (Fake::default(), Fake::default());
    let call = frame(Header::Command, 0x99, 0x200, b"HELLO-0042");
    // The host's first bytes as after the first boot: as many, at the same
    // tick (the fences would differ otherwise).
    up.input = call[..query.len()].to_vec();
    settle(&mut b, &mut up, &mut down, 0);
    up.input = call[query.len()..].to_vec();
    settle(&mut b, &mut up, &mut down, 0);
    assert_eq!(down.output, first_fence, "the same seed, the same text");
    down.output.clear();
    let echo = |cmd: &[u8]| {
        let f = Frame::new_checked(cmd, BypassPolicy::Reject).unwrap();
        frame(Header::Response, 0x99, 0x200, f.body())
    };
    // The first boot's echo settles the fence; the host's 200H goes down.
    down.input = echo(&first_fence);
    settle(&mut b, &mut up, &mut down, 10);
    settle(&mut b, &mut up, &mut down, 12);
    assert_eq!(down.output, call);
    // This boot's own fence echo, then the controller's echo of the call.
    down.input = echo(&first_fence);
    settle(&mut b, &mut up, &mut down, 20);
    assert!(
        up.output.is_empty(),
        "the bridge's own fence echo is not relayed"
    );
    down.input = echo(&call);
    settle(&mut b, &mut up, &mut down, 30);
    settle(&mut b, &mut up, &mut down, 31);
    assert_eq!(up.output, echo(&call));
}

/// Issue "never wrong when the line breaks its rules": an XOFF in noise
/// (and no XON) holds the bridge's transmitter at most
/// `Config::xoff_hold_ms`; the bridge wakes for it, lets go, counts it.
#[test]
fn an_xoff_holds_the_transmitter_at_most_the_configured_time() {
    let mut b = bridge(Policy::ForwardAll);
    let (mut up, mut down) = (Fake::default(), Fake::controller());
    up.stopped = true;
    let hold = Config::DEFAULT.xoff_hold_ms;
    match b.poll(&mut up, &mut down, 100).unwrap() {
        Poll::Wait(w) => assert_eq!(w.deadline, Some(100 + hold)),
        other => panic!("{other:?}"),
    }
    settle(&mut b, &mut up, &mut down, 100 + hold - 1);
    assert!(up.stopped, "held until the limit");
    settle(&mut b, &mut up, &mut down, 100 + hold);
    assert!(!up.stopped, "let go at the limit");
    assert_eq!(b.stats().xoff_released, 1);
    // An XOFF the host lifts itself is not counted.
    up.stopped = true;
    settle(&mut b, &mut up, &mut down, 200 + hold);
    up.stopped = false;
    settle(&mut b, &mut up, &mut down, 300 + 2 * hold);
    assert_eq!(b.stats().xoff_released, 1);
}
