//! The bridge's command policy on arbitrary host bytes.
//!
//! Input layout: byte 0 picks the policy (0 forward all, 1 read-only,
//! 2 allow-list) and the flow control (bits 4-5); with an allow-list the
//! next 32 bytes are its bitmap (IDs 200H..2FFH); byte after that: ticks
//! (x 256 ms) between polls; everything else is what the host sends, fed in
//! 16-byte pieces. The controller never answers (every forwarded command
//! times out).
//!
//! Checked: no panic; every frame the bridge writes downstream is a
//! command for the controller's station whose ID the policy allows; every
//! frame it writes upstream is a valid `&` from the bridge or a status
//! reply (the controller said nothing, so nothing can be relayed).
#![no_main]

use std::convert::Infallible;

use firmware_example::bridge::{Bridge, Port};
use firmware_example::codes;
use firmware_example::config::{AllowList, Config, Policy, Source};
use firmware_example::serial::FlowControl;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder};
use iai_protocol_b::frame::Header;
use libfuzzer_sys::fuzz_target;

#[derive(Default)]
struct Fake {
    input: Vec<u8>,
    output: Vec<u8>,
}

impl embedded_io::ErrorType for Fake {
    type Error = Infallible;
}
impl embedded_io::ReadReady for Fake {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(!self.input.is_empty())
    }
}
impl embedded_io::Read for Fake {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let n = buf.len().min(self.input.len());
        buf[..n].copy_from_slice(&self.input[..n]);
        self.input.drain(..n);
        Ok(n)
    }
}
impl embedded_io::WriteReady for Fake {
    fn write_ready(&mut self) -> Result<bool, Infallible> {
        Ok(true)
    }
}
impl embedded_io::Write for Fake {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.output.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
impl Port for Fake {}

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
    let mut bridge = Bridge::new(cfg, Source::Default, 0x5EED);
    let (mut up, mut down) = (Fake::default(), Fake::default());
    let mut now = 0u32;
    for piece in host.chunks(16).chain(std::iter::repeat_n(&[][..], 8)) {
        up.input.extend_from_slice(piece);
        for _ in 0..64 {
            let _ = bridge.poll(&mut up, &mut down, now);
        }
        now = now.wrapping_add(u32::from(step) * 256 + 1);
    }

    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Accept);
    for &b in &down.output {
        if let Event::Frame(f) = dec.push(b) {
            assert_eq!(f.header(), Header::Command);
            assert_eq!(f.station(), cfg.controller_station);
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
            Event::Frame(f) => match f.header() {
                Header::Error => assert!(codes::is_bridge_code(f.code())),
                Header::Response => assert!(
                    f.station() == cfg.bridge_station && f.code() == codes::STATUS_QUERY
                        || f.code() == 0x26D
                ),
                Header::Command => panic!("a command went upstream"),
            },
            Event::Error(e) => panic!("a broken frame went upstream: {e}"),
            Event::NeedMore => {}
        }
    }
});
