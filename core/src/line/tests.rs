//! The line's rules, frame by frame.

use super::*;
use crate::checksum::BypassPolicy;

const S: Station = Station(0x99);

fn frame(bytes: &[u8]) -> Frame<'_> {
    Frame::new_checked(bytes, BypassPolicy::Reject).unwrap()
}

/// A line whose past is known (its opening fence already answered).
fn line(cfg: LineConfig) -> Line {
    Line::known(cfg)
}

fn spec() -> Line {
    line(LineConfig::new(S))
}

/// Offers `f` at `now`, its content fitting the command or not.
fn offer(l: &mut Line, f: &Frame<'_>, fits: bool, now: u32) -> Heard {
    let verdict = Verdict {
        fits,
        values: Span::UNKNOWN,
        keep: false,
    };
    l.offer(f, verdict, now)
}

/// [`Line::hear`] of a frame known by its envelope.
fn hear(l: &mut Line, id: u16, values: Span, now: u32) -> Heard {
    let verdict = Verdict {
        fits: true,
        values,
        keep: false,
    };
    l.hear(Header::Response, S, id, None, verdict, 0, now)
}

/// Runs `l` to its first send of the command started, from `now`.
fn first_send(l: &mut Line, now: u32) {
    assert_eq!(l.poll(now), Due::Send { fresh: true });
}

// 212H for axis 1, its reply (axis 1: status 1C, position 2.300 mm).
const REPLY_212: &[u8] = b"#992122A\r\n";

#[test]
fn a_reply_counts_only_after_the_command_was_sent() {
    let mut l = spec();
    l.start(&catalogue::SYSTEM_STATUS_QUERY, 0);
    assert_eq!(l.poll(0), Due::Send { fresh: true });
    assert_eq!(l.poll(0), Due::Send { fresh: false });
    let f = frame(b"#99215000000000000000FD\r\n");
    // Before `sent`: not the reply, and nothing explains it.
    assert_eq!(offer(&mut l, &f, true, 0), Heard::Unplaced);
    l.sent(10);
    assert_eq!(l.poll(11), Due::WaitUntil(3_010));
    assert_eq!(offer(&mut l, &f, true, 12), Heard::Answer);
    assert_eq!(l.poll(12), Due::Done(Ok(())));
}

#[test]
fn timeout_runs_from_the_end_of_transmission_and_resends_up_to_the_limit() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    // A slow line: each send takes 2 s to transmit.
    let mut end = 2_000;
    for send in 1..=3u8 {
        assert_eq!(l.sends(), send);
        l.sent(end);
        assert_eq!(l.poll(end + 2_999), Due::WaitUntil(end + 3_000));
        let due = l.poll(end + 3_000);
        if send < 3 {
            assert_eq!(due, Due::Send { fresh: true });
            end += 5_000;
        } else {
            assert_eq!(due, Due::Done(Err(Failure::Timeout { sends: 3 })));
        }
    }
    assert!(l.faulted());
}

#[test]
fn an_unsafe_command_is_sent_once_and_its_timeout_is_an_unknown_outcome() {
    let mut l = spec();
    l.start(&catalogue::RELATIVE_MOVE, 0);
    first_send(&mut l, 0);
    l.sent(5);
    assert_eq!(
        l.poll(3_005),
        Due::Done(Err(Failure::OutcomeUnknown { sends: 1 }))
    );
    // Opting in allows the resends.
    let mut cfg = LineConfig::new(S);
    cfg.resend_unsafe = true;
    let mut l = line(cfg);
    l.start(&catalogue::RELATIVE_MOVE, 0);
    first_send(&mut l, 0);
    l.sent(5);
    assert_eq!(l.poll(3_005), Due::Send { fresh: true });
}

#[test]
fn an_error_reply_finishes_without_a_resend() {
    let mut l = spec();
    l.start(&catalogue::ABSOLUTE_MOVE, 0);
    first_send(&mut l, 0);
    l.sent(1);
    assert_eq!(
        offer(&mut l, &frame(b"&99C7446\r\n"), true, 2),
        Heard::Rejected(0xC74)
    );
    assert_eq!(
        l.poll(3),
        Due::Done(Err(Failure::Controller {
            code: 0xC74,
            detail: None
        }))
    );
    assert_eq!(l.sends(), 1);
}

#[test]
fn the_turnaround_is_two_ticks() {
    let mut l = spec();
    l.start(&catalogue::SERVO_ON_OFF, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(
        offer(&mut l, &frame(b"#992322C\r\n"), true, 7),
        Heard::Answer
    );
    l.start(&catalogue::SERVO_ON_OFF, 7);
    assert_eq!(l.poll(8), Due::WaitUntil(9));
    assert_eq!(l.poll(9), Due::Send { fresh: true });
}

#[test]
fn a_broken_reply_is_resent_after_the_turnaround_not_the_timeout() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(100);
    l.broken(Some((Header::Response, S, 0x212)), 150);
    assert_eq!(l.poll(151), Due::WaitUntil(152));
    assert_eq!(l.poll(152), Due::Send { fresh: true });
    assert_eq!(l.sends(), 2);
}

#[test]
fn software_reset_waits_for_an_error_reply_then_holds_the_line_10_s() {
    let mut l = spec();
    l.start(&catalogue::SOFTWARE_RESET, 0);
    first_send(&mut l, 0);
    l.sent(100);
    assert_eq!(l.poll(3_100), Due::Done(Ok(())));
    assert_eq!(l.sends(), 1);
    l.start(&catalogue::SYSTEM_STATUS_QUERY, 3_100);
    assert_eq!(l.poll(3_100), Due::WaitUntil(10_100));
}

#[test]
fn a_broken_error_reply_to_a_reset_is_not_a_sent_reset() {
    let mut l = spec();
    l.start(&catalogue::SOFTWARE_RESET, 0);
    first_send(&mut l, 0);
    l.sent(10);
    l.broken(Some((Header::Error, S, 0x027)), 11);
    assert_eq!(
        l.poll(13),
        Due::Done(Err(Failure::OutcomeUnknown { sends: 1 }))
    );
}

#[test]
fn another_station_is_foreign_another_id_unplaced_and_wrong_content_a_mismatch() {
    let mut l = spec();
    l.start(&catalogue::SERVO_ON_OFF, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(
        offer(&mut l, &frame(b"#012321B\r\n"), true, 1),
        Heard::Foreign
    );
    // A reply to 233H, which nothing on this line is owed.
    assert_eq!(
        offer(&mut l, &frame(b"#992332D\r\n"), true, 1),
        Heard::Unplaced
    );
    assert_eq!(
        offer(&mut l, &frame(b"#992322C\r\n"), false, 1),
        Heard::Mismatch
    );
    assert!(l.awaiting());
    assert!(l.faulted());
}

#[test]
fn a_first_command_after_tick_2_31_goes_out_at_once() {
    // A bridge idle since boot sends its first command on day 25.
    for now in [0x8000_0000u32, 0x8000_0001, u32::MAX - 5_000, u32::MAX] {
        let mut l = spec();
        l.start(&catalogue::AXIS_STATUS_QUERY, now);
        assert_eq!(l.poll(now), Due::Send { fresh: true }, "{now:#x}");
    }
}

#[test]
fn holds_set_long_ago_are_over() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 10), Heard::Answer);
    // Idle for 30 days: the turnaround hold at 12 now seems to lie 19
    // days ahead on the wrapping clock.
    let later = 12u32.wrapping_add(30 * 86_400_000);
    l.start(&catalogue::AXIS_STATUS_QUERY, later);
    assert_eq!(l.poll(later), Due::Send { fresh: true });
}

// ---------------------------------------------------------------------
// What may still arrive: owed replies and fences.
// ---------------------------------------------------------------------

/// The fence after a seed of 123456: `!99200` + text + SC.
const FENCE_1: &[u8] = b"!9920012345600011B\r\n";
const ECHO_1: &[u8] = b"#9920012345600011D\r\n";

#[test]
fn a_line_just_opened_fences_before_its_first_command() {
    let mut l = Line::new(LineConfig::new(S), 0x12_3456);
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    assert_eq!(l.poll(0), Due::Fence);
    assert_eq!(l.fence_bytes(), FENCE_1);
    l.sent(5);
    // A late reply to a command of an earlier run arrives first: stale.
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 6), Heard::Stale);
    assert_eq!(offer(&mut l, &frame(ECHO_1), true, 8), Heard::Fence);
    // The turnaround after the echo, then the command.
    assert_eq!(l.poll(9), Due::WaitUntil(10));
    assert_eq!(l.poll(10), Due::Send { fresh: true });
    l.sent(12);
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 14), Heard::Answer);
    assert_eq!(l.stats().fences, 1);
}

#[test]
fn an_echo_with_another_text_settles_nothing() {
    let mut l = Line::new(LineConfig::new(S), 0x12_3456);
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    assert_eq!(l.poll(0), Due::Fence);
    l.sent(5);
    // A host's own test call, or an earlier run's fence: what the line
    // owes from before it was opened.
    let other = frame(b"#99200012345678934\r\n");
    assert_eq!(offer(&mut l, &other, true, 6), Heard::Stale);
    assert_eq!(l.poll(7), Due::WaitUntil(3_005));
}

/// The quarantine after a given-up command: the next command is fenced,
/// so the given-up command's late reply (here completing in the very tick
/// its late window ends) can never be taken as the next one's.
#[test]
fn after_a_given_up_command_the_next_is_fenced_and_its_late_reply_is_stale() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(0);
    for t in [3_000, 6_000] {
        assert_eq!(l.poll(t), Due::Send { fresh: true });
        l.sent(t);
    }
    assert_eq!(l.poll(9_000), Due::Done(Err(Failure::Timeout { sends: 3 })));
    // A 234H next: the fence goes first.
    l.start(&catalogue::ABSOLUTE_MOVE, 9_000);
    assert_eq!(l.poll(9_000), Due::Fence);
    l.sent(9_002);
    // The 212H's late `&` arrives at 6,000 + 3,000 + 3,000: stale.
    assert_eq!(
        offer(&mut l, &frame(b"&99C7446\r\n"), true, 12_000),
        Heard::Stale
    );
    let echo = {
        let mut e = [0u8; 20];
        e.copy_from_slice(ECHO_1);
        e
    };
    assert_eq!(offer(&mut l, &frame(&echo), true, 12_001), Heard::Fence);
    assert_eq!(l.poll(12_003), Due::Send { fresh: true });
    l.sent(12_004);
    assert_eq!(
        offer(&mut l, &frame(b"#992342E\r\n"), true, 12_050),
        Heard::Answer
    );
}

#[test]
fn without_fences_the_quarantine_lasts_through_the_last_tick_a_reply_may_end() {
    let mut cfg = LineConfig::new(S);
    cfg.fences = false;
    cfg.max_sends = 1;
    let mut l = line(cfg);
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(l.poll(3_000), Due::Done(Err(Failure::Timeout { sends: 1 })));
    l.start(&catalogue::AXIS_STATUS_QUERY, 3_000);
    // A reply may still complete at 0 + 3,000 + 3,000: the next send waits
    // one tick more.
    assert_eq!(l.poll(3_000), Due::WaitUntil(6_001));
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 6_000), Heard::Stale);
    assert_eq!(l.poll(6_001), Due::Send { fresh: true });
}

#[test]
fn a_fence_that_gets_no_echo_is_sent_again_then_falls_back_to_waiting() {
    let mut l = Line::new(LineConfig::new(S), 1);
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    assert_eq!(l.poll(0), Due::Fence);
    let first = l.fence_bytes().to_vec();
    l.sent(0);
    // No echo by 3,000: a new fence, with a new text, at once.
    assert_eq!(l.poll(3_000), Due::Fence);
    assert_ne!(l.fence_bytes(), &first[..]);
    assert_eq!(l.stats().fences_failed, 1);
    l.sent(3_000);
    // None by 6,000 either: the controller may not answer 200H. The owed
    // replies and the fences' own (the second's until 9,001) are waited
    // out.
    assert_eq!(l.poll(6_000), Due::WaitUntil(9_001));
    assert_eq!(l.stats().fences_failed, 2);
    assert_eq!(l.poll(9_001), Due::Send { fresh: true });
}

/// A fence's echo lost on the line costs its timeout and no more: the
/// next fence's echo settles everything before it, the first fence's late
/// echo included.
#[test]
fn a_lost_fence_echo_costs_one_timeout() {
    let mut l = Line::new(LineConfig::new(S), 1);
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    assert_eq!(l.poll(0), Due::Fence);
    let first = l.fence_bytes().to_vec();
    l.sent(0);
    assert_eq!(l.poll(3_000), Due::Fence);
    let second = l.fence_bytes().to_vec();
    l.sent(3_000);
    // The first echo comes late: stale (owed), it settles nothing.
    let echo = |f: &[u8]| {
        let mut e = [0u8; 20];
        let text = &f[6..16];
        let n = crate::frame::emit_frame(
            &mut e,
            Header::Response,
            S,
            0x200,
            ChecksumMode::Compute,
            |w| w.put(text),
        )
        .unwrap();
        e[..n].to_vec()
    };
    assert_eq!(
        offer(&mut l, &frame(&echo(&first)), true, 3_100),
        Heard::Stale
    );
    assert_eq!(l.poll(3_101), Due::WaitUntil(6_000));
    assert_eq!(
        offer(&mut l, &frame(&echo(&second)), true, 3_200),
        Heard::Fence
    );
    assert_eq!(l.poll(3_202), Due::Send { fresh: true });
}

#[test]
fn a_late_reply_to_an_earlier_send_answers_the_same_command_once() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(l.poll(3_000), Due::Send { fresh: true });
    l.sent(3_010);
    // The first send's late reply: taken.
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 3_020), Heard::Answer);
    assert!(l.faulted(), "the second send's reply is still owed");
    // The second send's reply is owed: the next command is fenced.
    l.start(&catalogue::AXIS_STATUS_QUERY, 3_021);
    assert_eq!(l.poll(3_023), Due::Fence);
}

#[test]
fn abandoning_a_command_being_sent_owes_its_reply() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.abandon(40);
    l.start(&catalogue::AXIS_STATUS_QUERY, 40);
    assert_eq!(l.poll(40), Due::Fence);
}

// ---------------------------------------------------------------------
// Copies.
// ---------------------------------------------------------------------

fn duplicating() -> Line {
    line(LineConfig::new(S).with_duplicate_window(3_000))
}

#[test]
fn on_a_line_that_repeats_frames_a_reply_keeps_its_command_from_going_out_again() {
    let mut l = duplicating();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 10), Heard::Answer);
    // Its copy may come until 3,010: another 212H waits; a 215H need not.
    l.start(&catalogue::AXIS_STATUS_QUERY, 10);
    assert_eq!(l.poll(12), Due::WaitUntil(3_011));
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 2_000), Heard::Stale);
    // The copy of the copy, until 5,000.
    assert_eq!(l.poll(3_011), Due::WaitUntil(5_001));
    l.start(&catalogue::SYSTEM_STATUS_QUERY, 3_011);
    assert_eq!(l.poll(3_011), Due::Send { fresh: true });
}

#[test]
fn a_copy_of_an_error_reply_keeps_every_command_back() {
    let mut l = duplicating();
    l.start(&catalogue::ABSOLUTE_MOVE, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(
        offer(&mut l, &frame(b"&99C7446\r\n"), true, 10),
        Heard::Rejected(0xC74)
    );
    l.start(&catalogue::ERROR_DETAIL_QUERY, 10);
    assert_eq!(l.poll(12), Due::WaitUntil(3_011));
}

#[test]
fn a_copy_passes_only_for_a_command_that_accepts_what_it_carries() {
    let mut l = duplicating();
    // A 26DH reply for 24 records, then the next frame of 23: no wait; of
    // 24: wait for the copy.
    let c = Command::of(0x26D, Span::one(24), Claim::Proof, 3);
    l.begin(c, 0);
    first_send(&mut l, 0);
    l.sent(0);
    let reply = frame(b"#9926D00180A\r\n");
    let heard = hear(&mut l, reply.code(), Span::one(0x18), 10);
    assert_eq!(heard, Heard::Answer);
    l.begin(Command::of(0x26D, Span::one(23), Claim::Proof, 3), 10);
    assert_eq!(l.poll(12), Due::Send { fresh: true });
    l.abandon(12);
    l.begin(Command::of(0x26D, Span::one(24), Claim::Proof, 3), 12);
    // (The abandoned frame is owed: fenced first.)
    assert_eq!(l.poll(14), Due::Fence);
}

#[test]
fn a_tentative_read_minds_only_copies_that_could_pass_as_errors() {
    let mut l = duplicating();
    l.begin(
        Command::of(0x21F, Span { lo: 1, hi: 24 }, Claim::Proof, 3),
        0,
    );
    first_send(&mut l, 0);
    l.sent(0);
    let heard = hear(&mut l, 0x21F, Span::UNKNOWN, 10);
    assert_eq!(heard, Heard::Answer);
    // The confirming read of the same window waits for the copy; a first
    // read of the next window need not.
    l.begin(
        Command::of(0x21F, Span { lo: 1, hi: 24 }, Claim::Proof, 3),
        10,
    );
    assert_eq!(l.poll(12), Due::WaitUntil(3_011));
    l.begin(
        Command::of(0x21F, Span { lo: 25, hi: 48 }, Claim::Tentative, 3),
        12,
    );
    assert_eq!(l.poll(12), Due::Send { fresh: true });
}

#[test]
fn a_line_just_opened_on_a_line_that_repeats_frames_waits_for_copies_of_its_past() {
    let mut l = Line::new(LineConfig::new(S).with_duplicate_window(500), 0x12_3456);
    l.start(&catalogue::AXIS_STATUS_QUERY, 100);
    assert_eq!(l.poll(100), Due::Fence);
    l.sent(102);
    assert_eq!(offer(&mut l, &frame(ECHO_1), true, 110), Heard::Fence);
    assert_eq!(l.poll(112), Due::WaitUntil(601));
}

/// A controller that does not answer 200H may refuse a fence with an `&`:
/// that is the fence's own reply, not a frame the line cannot place, even
/// when the fence proves order with nothing owed.
#[test]
fn an_error_reply_to_a_fence_is_the_fences_own_not_unplaced() {
    let mut l = spec();
    l.start_proof(0);
    assert_eq!(l.poll(0), Due::Fence);
    l.sent(5);
    assert_eq!(
        offer(&mut l, &frame(b"&99C7446\r\n"), true, 10),
        Heard::Stale
    );
    // Broken, its code unreadable or not: the same.
    l.broken(Some((Header::Error, S, 0xC74)), 11);
    assert_eq!(l.stats().unplaced, 0);
    assert!(!l.repeats());
    // The `&` ends the fence at the turnaround: a second one goes out at
    // once; refused too, the proof waits out the fences' own late replies.
    assert_eq!(l.poll(12), Due::Fence);
    l.sent(15);
    assert_eq!(
        offer(&mut l, &frame(b"&99C7446\r\n"), true, 20),
        Heard::Stale
    );
    assert_eq!(l.poll(22), Due::WaitUntil(6_016));
    assert_eq!(l.poll(6_016), Due::Done(Ok(())));
    assert_eq!(l.stats().fences_failed, 2);
    assert_eq!(l.stats().unplaced, 0);
}

/// A late reply to the first send that comes while the command is sent
/// again (or waits to be) is owed to that send: stale, not unplaced.
#[test]
fn a_late_reply_to_an_earlier_send_between_sends_is_stale() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(0);
    assert_eq!(l.poll(3_000), Due::Send { fresh: true });
    // The resend is on the wire when the first send's reply arrives.
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 3_001), Heard::Stale);
    l.broken(Some((Header::Response, S, 0x212)), 3_002);
    assert_eq!(l.stats().unplaced, 0);
    l.sent(3_005);
    assert_eq!(offer(&mut l, &frame(REPLY_212), true, 3_010), Heard::Answer);
}

/// A proof whose fence gets no echo (a controller that does not answer
/// 200H) waits out the replies instead, as on a line without fences, and
/// ends: it does not fence again and again.
#[test]
fn a_proof_whose_fence_gets_no_echo_ends_by_waiting() {
    let mut l = spec();
    l.start_proof(0);
    assert_eq!(l.poll(0), Due::Fence);
    l.sent(0);
    // No echo by 3,000: one more fence (its echo may have been lost on
    // the line); none by 6,000 either: the second fence's own late reply
    // may come until 9,001.
    assert_eq!(l.poll(3_000), Due::Fence);
    l.sent(3_000);
    assert_eq!(l.poll(6_000), Due::WaitUntil(9_001));
    assert_eq!(l.poll(9_001), Due::Done(Ok(())));
    assert_eq!(l.stats().fences, 2);
}

/// A reply whose header byte was hit is no frame to any decoder: its bytes
/// are dropped as noise. A run of noise ended by LF as long as a short
/// reply, while a reply is awaited, is taken as that reply broken: the
/// command goes again at the turnaround, not after its 3 s timeout.
/// Shorter noise, or noise with nothing awaited, changes nothing.
#[test]
fn a_reply_with_its_header_hit_is_sent_for_again_at_the_turnaround() {
    let mut l = spec();
    l.start(&catalogue::AXIS_STATUS_QUERY, 0);
    first_send(&mut l, 0);
    l.sent(2);
    // Line noise: too short to be a reply.
    l.noise(b"xyz\r\n", 5);
    assert_eq!(l.poll(6), Due::WaitUntil(3_002));
    // `#` hit by a flip (0x23 -> 0x63): the rest of the 212H reply.
    let mut hit = REPLY_212.to_vec();
    hit[0] = b'c';
    l.noise(&hit, 10);
    assert_eq!(l.stats().line_errors, 1);
    assert_eq!(l.poll(10), Due::WaitUntil(12));
    assert_eq!(l.poll(12), Due::Send { fresh: true });
}

/// Noise that may be a reply with its header hit is no reply for sure: a
/// command that cannot be sent again (an unsafe one, or the last send)
/// goes on waiting for its own reply rather than end at the turnaround.
#[test]
fn noise_on_the_last_send_waits_for_the_reply() {
    let mut l = spec();
    l.start(&catalogue::RELATIVE_MOVE, 0);
    first_send(&mut l, 0);
    l.sent(2);
    let mut hit = REPLY_212.to_vec();
    hit[0] = b'c';
    l.noise(&hit, 10);
    assert_eq!(l.poll(12), Due::WaitUntil(3_002));
}
