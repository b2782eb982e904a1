//! The bridge's configuration messages (B20..B24, `config::wire`) on
//! arbitrary host bytes, answered through an editor over a page store in
//! RAM (two 1 KiB slots, 32-bit writes, as on the QEMU boards).
//!
//! Input: operations, each an op byte and its arguments:
//!
//! - `0 k`: a canned frame `k`: a read of window `k`; a stage of window `k`
//!   of a page whose Modbus unit is the next byte; an apply of that page
//!   with the password (or a wrong one, or a wrong CRC); the password set
//!   on a fresh gateway, or changed with the current one; a restart with
//!   the password; a read of the verifier block with it;
//! - `1 n bytes..`: up to `n` bytes of the input as they are;
//! - `2 t`: `t` x 100 ms pass;
//! - anything else: one more round.
//!
//! Each is fed to the bridge and polled until it waits; the controller
//! never answers.
//!
//! Checked: no panic; every frame the bridge sends up is well-formed: an
//! `&` with a bridge code, or a reply to one of its own IDs; a restart
//! happens only after a B23 answered `#`; the page in force is always
//! whole (its slot's CRC right) and every block in it checks.
#![no_main]

use std::mem::MaybeUninit;
use std::ptr::addr_of_mut;

use firmware_example::bridge::{Bridge, Poll};
use firmware_example::codes;
use firmware_example::config::access::WebConfig;
use firmware_example::config::editor::{host_crc, Editor};
use firmware_example::config::page::{HOST_LEN, NET_AT, WEB_AT, WINDOW};
use firmware_example::config::settings::Settings;
use firmware_example::config::store::{self, MemFlash, PageStore, Store};
use firmware_example::config::{Config, Source, MAGIC};
use firmware_example::net::config::NetConfig;
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::{emit_frame, Header, Station};
use libfuzzer_sys::fuzz_target;
use test_support::VecPort;

const PASSWORD: &[u8] = b"plant-1234";

static mut PAGE: [u8; 2048] = [0xFF; 2048];
static mut STORE: MaybeUninit<Store<MemFlash<'static, 1024, 4>>> = MaybeUninit::uninit();
static mut EDITOR: MaybeUninit<Editor<'static>> = MaybeUninit::uninit();

fn no_restart() {}

/// A fresh editor over erased slots (this run's own: libFuzzer runs one
/// input at a time, and the last run's bridge is gone).
fn editor() -> &'static mut Editor<'static> {
    // SAFETY: see above: nothing else refers to these statics now.
    unsafe {
        let page = &mut *addr_of_mut!(PAGE);
        page.fill(0xFF);
        let store = (*addr_of_mut!(STORE)).write(Store::open(MemFlash::new(page), 0));
        let store: &'static mut dyn PageStore = store;
        (*addr_of_mut!(EDITOR)).write(Editor::new(store, no_restart, 1))
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect()
}

fn frame(id: u16, body: &str) -> Vec<u8> {
    let mut buf = vec![0u8; body.len() + 16];
    let n = emit_frame(
        &mut buf,
        Header::Command,
        Station(0xBB),
        id,
        Default::default(),
        |w| w.put(body.as_bytes()),
    )
    .unwrap_or(0);
    buf.truncate(n);
    buf
}

/// A page whose Modbus unit is `unit` (1..=247 after a wrap).
fn page(unit: u8) -> Vec<u8> {
    let mut s = Settings::DEFAULT;
    let _ = s.set("modbus.unit", &(u32::from(unit) % 247 + 1).to_string());
    let mut p = vec![0xFF; HOST_LEN];
    s.overlay(0, &mut p);
    p
}

fuzz_target!(|data: &[u8]| {
    let mut bridge = Bridge::new(Config::DEFAULT, Source::Default, 0x5EED);
    bridge.attach_editor(editor());
    let (mut up, mut down) = (VecPort::default(), VecPort::default());
    let mut now = 0u32;
    let mut unit = 5u8;
    let mut rest = data;
    let mut poll = |bridge: &mut Bridge, up: &mut VecPort, now: u32| {
        for _ in 0..64 {
            match bridge.poll(up, &mut down, now) {
                Ok(Poll::Busy) => {}
                Ok(Poll::Wait(w)) if w.deadline == Some(now) => {}
                _ => break,
            }
        }
    };
    while let Some((&op, tail)) = rest.split_first() {
        rest = tail;
        match op % 4 {
            0 => {
                let Some((&k, tail)) = rest.split_first() else {
                    break;
                };
                rest = tail;
                if let Some((&u, tail)) = rest.split_first() {
                    unit = u;
                    rest = tail;
                }
                let p = page(unit);
                let w = usize::from(k >> 3) % HOST_LEN.div_ceil(WINDOW);
                let at = w * WINDOW;
                let window = &p[at..(at + WINDOW).min(HOST_LEN)];
                let bytes = match k & 7 {
                    0 => frame(codes::CONFIG_READ, &format!("{at:03X}")),
                    1 => frame(codes::CONFIG_STAGE, &format!("{at:03X}{}", hex(window))),
                    2 => frame(
                        codes::CONFIG_APPLY,
                        &format!("{:08X}{}", host_crc(&p), hex(PASSWORD)),
                    ),
                    3 => frame(
                        codes::CONFIG_APPLY,
                        &format!("{:08X}{}", host_crc(&p) ^ 1, hex(b"wrong-pass")),
                    ),
                    4 => frame(codes::CONFIG_PASSWORD, &format!("00{}", hex(PASSWORD))),
                    5 => frame(
                        codes::CONFIG_PASSWORD,
                        &format!("{:02X}{}{}", PASSWORD.len(), hex(PASSWORD), hex(PASSWORD)),
                    ),
                    6 => frame(codes::RESTART, &hex(PASSWORD)),
                    _ => frame(codes::CONFIG_READ, &format!("3B8{}", hex(PASSWORD))),
                };
                up.input.extend_from_slice(&bytes);
            }
            1 => {
                let Some((&n, tail)) = rest.split_first() else {
                    break;
                };
                let n = usize::from(n).min(tail.len());
                up.input.extend_from_slice(&tail[..n]);
                rest = &tail[n..];
            }
            2 => {
                let Some((&t, tail)) = rest.split_first() else {
                    break;
                };
                rest = tail;
                now = now.wrapping_add(u32::from(t) * 100);
            }
            _ => now = now.wrapping_add(1),
        }
        poll(&mut bridge, &mut up, now);
    }
    for _ in 0..4 {
        now = now.wrapping_add(250);
        poll(&mut bridge, &mut up, now);
    }

    // What went up: well-formed, the bridge's own.
    let mut dec: FrameDecoder<4096> = FrameDecoder::with_policy(BypassPolicy::Reject);
    let mut restarts_granted = 0u32;
    for &b in &up.output {
        match dec.push(b) {
            Status::Complete(Event::Frame(f)) => match f.header() {
                Header::Error => assert!(codes::RANGE.contains(&f.code()), "& {:03X}", f.code()),
                Header::Response => {
                    assert!(
                        codes::RANGE.contains(&f.code()),
                        "a reply {:03X} went up",
                        f.code()
                    );
                    if f.code() == codes::RESTART {
                        restarts_granted += 1;
                    }
                }
                Header::Command => panic!("a command went upstream"),
            },
            Status::Complete(Event::Error(e)) => panic!("a broken frame went upstream: {e}"),
            Status::Partial => {}
        }
    }
    let e = bridge.editor().expect("attached");
    assert!(e.restarts <= restarts_granted, "{} restarts", e.restarts);

    // The page in force: whole, every block in it checks.
    let mut p = vec![0u8; 1024];
    e.store().read(0, &mut p).expect("readable");
    if e.sequence().is_some() {
        // SAFETY: the editor is done with the slots for now.
        let slots = unsafe { &*addr_of_mut!(PAGE) };
        let (in_force, slot) = store::page_in(slots, 1024).expect("the page in force is whole");
        assert_eq!(Some(slot.seq), e.sequence());
        assert_eq!(in_force, &p[..]);
        if p[..4] == MAGIC {
            assert!(
                Config::parse(&p).is_ok(),
                "the bridge's block does not check"
            );
        }
        if p[NET_AT..NET_AT + 4] == *b"IAIN" {
            assert!(NetConfig::parse(&p[NET_AT..]).is_ok());
        }
        if p[WEB_AT..WEB_AT + 4] == *b"IAIW" {
            assert!(WebConfig::parse(&p[WEB_AT..]).is_ok());
        }
    }
});
