//! The bridge's command policy on arbitrary host bytes.
//!
//! Input layout: byte 0 picks the policy (0 forward all, 1 read-only,
//! 2 allow-list) and the flow control (bits 4-5); with an allow-list the
//! next 32 bytes are its bitmap (IDs 200H..2FFH); byte after that: ticks
//! (x 256 ms) between pieces; everything else is what the host sends, fed in
//! 16-byte pieces, each followed by polls until the bridge waits (at most
//! 64). The controller never answers (every forwarded command times out).
//!
//! Checked: no panic; every frame the bridge writes downstream is a
//! command for the controller's station whose ID the policy allows,
//! except the bridge's own fences: its downstream line fences its first
//! command and every command after one left unanswered with a 200H whose
//! ten characters are the six hex digits of the seed (`005EED`) and a
//! sequence number counting from 1; those are not host commands, they are
//! recognised in that order (never more than `line_stats().fences`) and
//! left out; every frame it writes upstream is a valid `&` with a bridge
//! code (`codes::RANGE`), an answer from the bridge's own station (its
//! status, the echo of a test call to it, a configuration message's) or a
//! 26DH's count (the controller said nothing, so nothing can be relayed).
#![no_main]

use firmware_example::bridge::{Bridge, Poll};
use firmware_example::codes;
use firmware_example::config::{AllowList, Config, Policy, Source};
use firmware_example::serial::FlowControl;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::Header;
use libfuzzer_sys::fuzz_target;
use test_support::VecPort;

/// The bridge's fence seed.
const SEED: u32 = 0x5EED;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let (policy, rest) = match mode & 3 {
        0 => (Policy::ForwardAll, rest),
        1 => (Policy::ReadOnly, rest),
        _ => {
            let Some(map) = rest.get(..32) else { return };
            let ids: Vec<u16> = (0..256u16)
                .filter(|i| map[usize::from(i / 8)] & (1 << (i % 8)) != 0)
                .map(|i| 0x200 + i)
                .collect();
            (Policy::Allow(AllowList::of(&ids)), &rest[32..])
        }
    };
    let flow = FlowControl::from_code((mode >> 4) & 3).unwrap_or(FlowControl::None);
    let Some((&step, host)) = rest.split_first() else {
        return;
    };
    let cfg = Config {
        policy,
        flow,
        ..Config::DEFAULT
    };
    let mut bridge = Bridge::new(cfg, Source::Default, SEED);
    let (mut up, mut down) = (VecPort::default(), VecPort::default());
    let mut now = 0u32;
    for piece in host.chunks(16).chain(std::iter::repeat_n(&[][..], 8)) {
        up.input.extend_from_slice(piece);
        // Until it waits for something (nothing more moves at this tick
        // without new bytes), at most 64 polls.
        for _ in 0..64 {
            match bridge.poll(&mut up, &mut down, now) {
                Ok(Poll::Busy) => {}
                Ok(Poll::Wait(w)) if w.deadline == Some(now) => {}
                _ => break,
            }
        }
        now = now.wrapping_add(u32::from(step) * 256 + 1);
    }

    // The bridge's own fences: 200H with the seed's text, in sequence.
    let fences = bridge.line_stats().fences;
    let mut next_fence = 1u32;
    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Accept);
    for &b in &down.output {
        if let Status::Complete(Event::Frame(f)) = dec.push(b) {
            assert_eq!(f.header(), Header::Command);
            assert_eq!(f.station(), cfg.controller_station);
            // A fence's text: six hex digits of the nonce (stirred by the
            // host's traffic), four of its sequence number.
            let seq = format!("{next_fence:04X}");
            let fence_like = f.body().len() == 10
                && f.body().iter().all(|b| b.is_ascii_hexdigit())
                && f.body().ends_with(seq.as_bytes());
            if next_fence <= fences && f.code() == 0x200 && fence_like {
                next_fence += 1;
                continue;
            }
            assert!(
                policy.allows(f.code()),
                "{:03X} reached the controller",
                f.code()
            );
        }
    }
    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Reject);
    for &b in &up.output {
        match dec.push(b) {
            Status::Complete(Event::Frame(f)) => match f.header() {
                Header::Error => assert!(codes::RANGE.contains(&f.code())),
                // The bridge's own answers (its status, a test call's
                // echo, its configuration messages), or a 26DH's count.
                Header::Response => assert!(f.station() == cfg.bridge_station || f.code() == 0x26D),
                Header::Command => panic!("a command went upstream"),
            },
            Status::Complete(Event::Error(e)) => panic!("a broken frame went upstream: {e}"),
            Status::Partial => {}
        }
    }
});
