//! The request engine, frame by frame.

extern crate std;
use std::vec::Vec;

use super::*;
use crate::decoder::Status;
use crate::line::LineConfig;
use crate::message::{AxisStatusQuery, SystemStatusQuery};
use crate::testing::{run, Controller, Fault, ST};

/// `#99212` for axis 1: status 1C, at 2.300 mm (2300 = 0x8FC).
const REPLY_212: &[u8] = b"#9921201 1C 00 00 00 000008FC";

fn reply_212() -> Vec<u8> {
    // The recorded reply without blanks, SC computed.
    let body: Vec<u8> = REPLY_212.iter().copied().filter(|&b| b != b' ').collect();
    let sum = body.iter().fold(0u8, |s, &b| s.wrapping_add(b));
    let mut f = body;
    f.extend_from_slice(std::format!("{sum:02X}\r\n").as_bytes());
    f
}

fn line() -> Line {
    Line::known(LineConfig::new(ST))
}

#[test]
fn a_212h_and_its_typed_reply() {
    let mut c: Client = Client::new();
    let mut l = line();
    let q = AxisStatusQuery::of(&[1]).unwrap();
    let pending = c.start(&mut l, &q, 0).unwrap();
    match c.poll(&mut l, 0) {
        Step::Transmit(b) => assert_eq!(b, b"!992120189\r\n"),
        other => panic!("{other:?}"),
    }
    c.sent(&mut l, 1);
    let reply = reply_212();
    let r = c.received(&mut l, &reply, 5);
    assert_eq!(
        (r.consumed, r.status),
        (reply.len(), Status::Complete(Heard::Answer))
    );
    assert_eq!(c.poll(&mut l, 5), Step::Done(Ok(())));
    let status = c.response(&pending).unwrap();
    assert_eq!(status.axes[0].axis_status, 0x1C);
    assert_eq!(status.axes[0].current_position, 2_300);
}

/// Issue "one memory of the line", case 7: more bytes of the same burst
/// after the reply (a copy from an echoing converter) must not cost the
/// reply: the client takes no bytes once it holds it.
#[test]
fn a_copy_in_the_same_burst_never_costs_the_reply_taken() {
    let mut c: Client = Client::new();
    let mut l = line();
    let q = AxisStatusQuery::of(&[1]).unwrap();
    let pending = c.start(&mut l, &q, 0).unwrap();
    let _ = c.poll(&mut l, 0);
    c.sent(&mut l, 1);
    let reply = reply_212();
    let mut burst = reply.clone();
    burst.extend_from_slice(&reply);
    crate::engine::feed(&mut c, &mut l, &burst, 5);
    // The copy is read (by the line, while the client keeps its reply).
    assert_eq!(l.stats().stale + l.stats().unplaced, 1);
    assert_eq!(c.poll(&mut l, 5), Step::Done(Ok(())));
    assert_eq!(
        c.response(&pending).unwrap().axes[0].current_position,
        2_300
    );
    // The same through the blocking loop, over a UART that hands out the
    // reply and its copy in one read.
    struct Burst(Vec<u8>, Vec<u8>);
    impl embedded_io::ErrorType for Burst {
        type Error = core::convert::Infallible;
    }
    impl embedded_io::ReadReady for Burst {
        fn read_ready(&mut self) -> Result<bool, Self::Error> {
            Ok(!self.0.is_empty())
        }
    }
    impl embedded_io::Read for Burst {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
            let n = buf.len().min(self.0.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0.drain(..n);
            Ok(n)
        }
    }
    impl embedded_io::Write for Burst {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            if buf.starts_with(b"!99212") {
                let r = core::mem::take(&mut self.1);
                self.0.extend_from_slice(&r);
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }
    let short: Vec<u8> = {
        // 24 bytes of reply + its copy: one 32-byte read takes the reply
        // and the start of the copy.
        let mut b = reply.clone();
        b.extend_from_slice(&reply);
        b
    };
    let mut uart = Burst(Vec::new(), short);
    let mut t = 10u32;
    let mut clock = move || {
        t += 1;
        t
    };
    let mut l = line();
    let got = c.call(&mut l, &mut uart, &mut clock, &q).unwrap();
    assert_eq!(got.axes[0].current_position, 2_300);
}

/// A new call on a line where an earlier one gave up: the reply the
/// earlier command still owes is settled by a fence, so the new call gets
/// its own reply, not the old one (issue case 6, through the client).
#[test]
fn a_new_call_never_takes_the_reply_an_earlier_one_still_owes() {
    let mut ctl = Controller::new();
    // The first 215H's reply comes 9.1 s late, after all three sends gave
    // up; the replies to the resends follow it (in order).
    ctl.faults.insert(
        0,
        Fault {
            late_ms: 9_100,
            ..Fault::default()
        },
    );
    let mut c: Client<64, 128> = Client::new();
    let mut l = line();
    c.start(&mut l, &SystemStatusQuery {}, 0).unwrap();
    let first = run(&mut c, &mut l, &mut ctl, 0);
    assert_eq!(first.result, Err(Failure::Timeout { sends: 3 }));
    // 216H next: fenced; the 215H replies come before the echo, stale.
    let pending = c
        .start(&mut l, &ErrorDetailQuery::latest_system_error(), first.now)
        .unwrap();
    let second = run(&mut c, &mut l, &mut ctl, first.now);
    let kinds: Vec<&[u8]> = ctl.received.iter().map(|(_, c)| &c[..6]).collect();
    assert_eq!(
        kinds,
        [b"!99215", b"!99215", b"!99215", b"!99200", b"!99216"]
    );
    assert_eq!(second.result, Ok(()));
    assert_eq!(c.reply_frame().map(|f| f.code()), Some(0x216));
    assert!(c.response(&pending).is_ok());
}

/// The echo of a fence arriving in pieces (as bytes come off a serial
/// line), with polls in between, is still the echo: the command goes out
/// at once rather than after the fallback wait.
#[test]
fn a_fence_echo_in_pieces_is_still_its_echo() {
    for split in 1..20 {
        let mut c: Client = Client::new();
        // A line just opened: it fences before its first command.
        let mut l = Line::new(LineConfig::new(ST), 0x1234_5678);
        let q = AxisStatusQuery::of(&[1]).unwrap();
        c.start(&mut l, &q, 0).unwrap();
        let fence = match c.poll(&mut l, 0) {
            Step::Transmit(b) => b.to_vec(),
            other => panic!("{other:?}"),
        };
        assert!(fence.starts_with(b"!99200"), "{fence:?}");
        c.sent(&mut l, 1);
        // The echo: '#' for '!', SC two more.
        let body = &fence[1..fence.len() - 4];
        let mut echo = std::vec![b'#'];
        echo.extend_from_slice(body);
        let sum = echo.iter().fold(0u8, |s, &b| s.wrapping_add(b));
        echo.extend_from_slice(std::format!("{sum:02X}\r\n").as_bytes());
        let (first, rest) = echo.split_at(split);
        let r = c.received(&mut l, first, 3);
        assert_eq!((r.consumed, r.status), (first.len(), Status::Partial));
        assert!(matches!(c.poll(&mut l, 4), Step::WaitUntil(_)));
        let r = c.received(&mut l, rest, 5);
        assert_eq!(
            (r.consumed, r.status),
            (rest.len(), Status::Complete(Heard::Fence)),
            "split {split}"
        );
        // The command follows after the turnaround, long before the
        // 3 s the line would wait for owed replies without the echo.
        let mut now = 6;
        loop {
            match c.poll(&mut l, now) {
                Step::Transmit(b) => {
                    assert_eq!(b, b"!992120189\r\n", "split {split}");
                    break;
                }
                Step::WaitUntil(t) if t > now && t < 100 => now = t,
                other => panic!("split {split} at {now}: {other:?}"),
            }
        }
        assert_eq!(l.stats().fences_failed, 0);
    }
}

/// The echo of a 200H command `cmd` (`#` for `!`, SC again).
fn echo_of(cmd: &[u8]) -> Vec<u8> {
    let body = &cmd[1..cmd.len() - 4];
    let mut e = std::vec![b'#'];
    e.extend_from_slice(body);
    let sum = e.iter().fold(0u8, |s, &b| s.wrapping_add(b));
    e.extend_from_slice(std::format!("{sum:02X}\r\n").as_bytes());
    e
}

/// Issue "never wrong when the line breaks its rules": a program
/// restarted with the same seed while its first fence's echo is still on
/// the way. The new run's first fence has the same text: the old echo
/// settles it (by order, everything before it has arrived), and the new
/// fence's own echo then comes while a test call waits. A 200H reply is
/// taken only if it carries the call's own text: the fence's echo is not
/// the answer to `HELLO-0042`.
#[test]
fn a_restart_with_the_same_seed_never_answers_a_test_call_with_a_fence_echo() {
    let seed = 0x4A_7C15;
    let first_run_fence = {
        let mut l = Line::new(LineConfig::new(ST), seed);
        let mut c: Client<64, 128> = Client::new();
        c.start(&mut l, &AxisStatusQuery::of(&[1]).unwrap(), 0)
            .unwrap();
        let Step::Transmit(f) = c.poll(&mut l, 0) else {
            panic!("a fence first")
        };
        f.to_vec()
        // The program stops here; the controller echoes the fence later.
    };
    let mut l = Line::new(LineConfig::new(ST), seed);
    let mut c: Client<64, 128> = Client::new();
    let call = crate::message::TestCall {
        test_string: *b"HELLO-0042",
    };
    let pending = c.start(&mut l, &call, 100).unwrap();
    let Step::Transmit(f) = c.poll(&mut l, 100) else {
        panic!("a fence first")
    };
    assert_eq!(f, &first_run_fence[..], "the same seed gives the same text");
    c.sent(&mut l, 101);
    // The first run's echo: it settles this fence (same text, and by order).
    crate::engine::feed(&mut c, &mut l, &echo_of(&first_run_fence), 110);
    let Step::Transmit(cmd) = c.poll(&mut l, 112) else {
        panic!("the test call")
    };
    assert!(cmd.starts_with(b"!99200HELLO-0042"));
    let cmd = cmd.to_vec();
    c.sent(&mut l, 113);
    // This run's own fence echo arrives while the call waits: not its reply.
    crate::engine::feed(&mut c, &mut l, &echo_of(&first_run_fence), 120);
    assert!(matches!(c.poll(&mut l, 121), Step::WaitUntil(_)));
    // Then the call's own echo.
    crate::engine::feed(&mut c, &mut l, &echo_of(&cmd), 130);
    assert_eq!(c.poll(&mut l, 131), Step::Done(Ok(())));
    let r = c.response(&pending).unwrap();
    assert_eq!(&r.test_string, b"HELLO-0042");
    assert_eq!(l.stats().mismatches, 1);
}

/// The reply's type follows from the request: a ticket of an earlier
/// request reads nothing of a later one's reply, and a request without a
/// reply says so.
#[test]
fn a_ticket_reads_its_own_request_s_reply_only() {
    let mut ctl = Controller::new();
    let mut c: Client<64, 128> = Client::new();
    let mut l = line();
    let status = c.start(&mut l, &SystemStatusQuery {}, 0).unwrap();
    assert_eq!(
        c.response(&status),
        Err(Error::NoReply { id: 0x215 }),
        "not over yet"
    );
    let first = run(&mut c, &mut l, &mut ctl, 0);
    assert_eq!(first.result, Ok(()));
    assert!(c.response(&status).is_ok());
    let axes = c
        .start(&mut l, &AxisStatusQuery::of(&[1]).unwrap(), first.now)
        .unwrap();
    assert_eq!(
        c.response(&status).map(|_| ()),
        Err(Error::UnexpectedMessageId {
            expected: 0x215,
            found: 0x212
        })
    );
    run(&mut c, &mut l, &mut ctl, first.now);
    assert!(c.response(&axes).is_ok());
}
