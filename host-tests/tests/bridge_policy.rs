//! The command policy, property-tested: whatever the host sends and
//! whatever the policy, no command the policy refuses reaches the
//! controller, every well-formed refused command is answered `&` B06, and
//! the bridge never addresses another station than the controller's.
//! (`fuzz/fuzz_targets/bridge_policy.rs` checks the same with libFuzzer.)

use firmware_example::bridge::{Bridge, Poll};
use firmware_example::codes;
use firmware_example::config::{AllowList, Config, Policy, Source, READ_ONLY};
use iai_protocol_b::checksum::{BypassPolicy, ChecksumMode};
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::{emit_frame, Header, Station};
use proptest::prelude::*;
use test_support::VecPort;

/// Every frame in `bytes`, except the bridge's own fences (a 200H whose
/// text begins with the six digits of its seed): they are the line's
/// commands, not the host's.
/// The frames in `bytes`, but the bridge's own fences: a 200H whose text
/// is none of `host_texts`, the 200H texts the host sent (a fence's text
/// is the bridge's nonce, stirred by the host's bytes).
fn frames(bytes: &[u8], host_texts: &[Vec<u8>]) -> Vec<(Header, u8, u16)> {
    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Accept);
    let mut out = Vec::new();
    for &b in bytes {
        if let Status::Complete(Event::Frame(f)) = dec.push(b) {
            let fence = f.code() == 0x200 && !host_texts.iter().any(|t| t[..] == *f.body());
            if !fence {
                out.push((f.header(), f.station().0, f.code()));
            }
        }
    }
    out
}

fn policy() -> impl Strategy<Value = Policy> {
    prop_oneof![
        Just(Policy::ForwardAll),
        Just(Policy::ReadOnly),
        proptest::collection::vec(0x200u16..0x300, 0..12)
            .prop_map(|ids| Policy::Allow(AllowList::of(&ids))),
    ]
}

/// One host command: station, ID, body digits, checksum right or not.
fn command() -> impl Strategy<Value = (u8, u16, Vec<u8>, bool)> {
    (
        prop_oneof![Just(0x99u8), Just(0xBB), any::<u8>()],
        prop_oneof![
            proptest::sample::select(READ_ONLY.to_vec()),
            Just(0x25Bu16),
            Just(0x26D),
            0x200u16..0x300,
            0u16..0x1000,
        ],
        proptest::collection::vec(
            proptest::sample::select(b"0123456789ABCDEF".to_vec()),
            0..40,
        ),
        any::<bool>(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn refused_commands_never_reach_the_controller(
        policy in policy(),
        cmds in proptest::collection::vec(command(), 1..8),
    ) {
        let cfg = Config { policy, ..Config::DEFAULT };
        let mut bridge = Bridge::new(cfg, Source::Default, 7);
        let (mut up, mut down) = (VecPort::default(), VecPort::default());
        let mut now = 0u32;
        let mut refused_ok = 0;
        let mut host_texts = Vec::new();
        for (station, id, body, good_sum) in &cmds {
            // A 200H carries exactly ten characters of text, which may be
            // anything, CR LF and header bytes included: a shorter one
            // takes in the next command as its text, and nothing can tell
            // the two apart until more bytes come (protocol B has no
            // length field). Hosts send the ten; so does this test.
            let body: Vec<u8> = if *id == 0x200 {
                body.iter().copied().chain(std::iter::repeat(b'0')).take(10).collect()
            } else {
                body.clone()
            };
            if *id == 0x200 {
                host_texts.push(body.clone());
            }
            let mut buf = [0u8; 64];
            let n = emit_frame(&mut buf, Header::Command, Station(*station), *id,
                ChecksumMode::Compute, |w| w.put(&body)).unwrap();
            let mut f = buf[..n].to_vec();
            if !good_sum {
                f[n - 3] = if f[n - 3] == b'0' { b'1' } else { b'0' };
            }
            if *good_sum && *station == 0x99 && !policy.allows(*id) {
                refused_ok += 1;
            }
            up.input.extend_from_slice(&f);
            // Let every exchange finish or time out.
            for _ in 0..4 {
                for _ in 0..100_000 {
                    if let Poll::Wait(_) = bridge.poll(&mut up, &mut down, now).unwrap() {
                        break;
                    }
                }
                now += 1_500;
            }
        }
        // The controller never answers: let the last exchanges run to
        // their end (fences tried twice, three sends of 3 s each), so that
        // a refusal queued behind one is written.
        for _ in 0..20 {
            for _ in 0..100_000 {
                if let Poll::Wait(_) = bridge.poll(&mut up, &mut down, now).unwrap() {
                    break;
                }
            }
            now += 1_500;
        }
        for (header, station, id) in frames(&down.output, &host_texts) {
            prop_assert_eq!(header, Header::Command);
            prop_assert_eq!(station, 0x99);
            prop_assert!(policy.allows(id), "{:03X} reached the controller", id);
        }
        let refusals = frames(&up.output, &host_texts)
            .into_iter()
            .filter(|&(h, s, c)| h == Header::Error && s == 0x99 && c == codes::REFUSED)
            .count();
        prop_assert_eq!(refusals, refused_ok);
        prop_assert_eq!(bridge.stats().refused as usize, refused_ok);
    }
}

/// The read-only preset is exactly the catalogue's reading messages: every
/// query (name "... Query ...", or a purpose that starts "Read") plus 200H,
/// the test call (an echo).
#[test]
fn read_only_preset_matches_the_catalogue() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/spec/messages.toml");
    let text = std::fs::read_to_string(path).expect("messages.toml");
    let doc: toml::Table = text.parse().expect("valid TOML");
    let mut reading: Vec<u16> = doc["message"]
        .as_array()
        .expect("[[message]]")
        .iter()
        .filter_map(|m| {
            let id = u16::from_str_radix(m["id"].as_str()?, 16).ok()?;
            let name = m["name"].as_str().unwrap_or("");
            let purpose = m.get("purpose").and_then(|p| p.as_str()).unwrap_or("");
            (id == 0x200 || name.contains("Query") || purpose.starts_with("Read")).then_some(id)
        })
        .collect();
    reading.sort();
    let mut preset = READ_ONLY.to_vec();
    preset.sort();
    assert_eq!(preset, reading);
}
