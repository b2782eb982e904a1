//! The configuration page through the bridge's own station, message by
//! message (B20H read, B21H stage, B22H apply, B23H restart, B24H
//! password; `firmware-example/src/config/wire.rs`), with the frames `iai
//! bridge config` sends (`iai_cli::bridge`), on a bridge whose page store
//! is a flash model; and where each board keeps its slots.

use firmware_example::bridge::{Bridge, Poll};
use firmware_example::codes;
use firmware_example::config::editor::{host_crc, Editor};
use firmware_example::config::page::{ACCESS_AT, HOST_LEN, WINDOW};
use firmware_example::config::settings::Settings;
use firmware_example::config::store::{MemFlash, PageStore, Store};
use firmware_example::config::{Config, Source};
use iai_cli::bridge::{config_frame, hex, settings_from_toml, settings_toml, BOARDS};
use iai_protocol_b::checksum::BypassPolicy;
use iai_protocol_b::decoder::{Event, FrameDecoder, Status};
use iai_protocol_b::frame::Header;
use test_support::VecPort;

fn no_restart() {}

/// A bridge on the default configuration whose page store is 2 KiB of
/// flash model (two 1 KiB slots, 32-bit writes, as the LM3S6965's).
fn gateway() -> Bridge {
    let mem: &'static mut [u8] = Box::leak(vec![0xFF; 2048].into_boxed_slice());
    let store: &'static mut dyn PageStore =
        Box::leak(Box::new(Store::open(MemFlash::<1024, 4>::new(mem), 0)));
    let editor = Box::leak(Box::new(Editor::new(store, no_restart, 7)));
    let mut b = Bridge::new(Config::DEFAULT, Source::Blank, 0);
    b.attach_editor(editor);
    b
}

/// Sends `frame` to the bridge at tick `now` and returns its answer (the
/// one frame it sends up).
fn ask(b: &mut Bridge, frame: &[u8], now: u32) -> (Header, u16, String) {
    let (mut up, mut down) = (VecPort::default(), VecPort::default());
    up.input = frame.to_vec();
    for _ in 0..100 {
        if let Poll::Wait(_) = b.poll(&mut up, &mut down, now).unwrap() {
            if up.input.is_empty() {
                break;
            }
        }
    }
    let mut dec: FrameDecoder<512> = FrameDecoder::with_policy(BypassPolicy::Reject);
    let mut got = None;
    for &byte in &up.output {
        if let Status::Complete(Event::Frame(f)) = dec.push(byte) {
            assert!(got.is_none(), "one answer only");
            got = Some((
                f.header(),
                f.code(),
                String::from_utf8(f.body().to_vec()).unwrap(),
            ));
        }
    }
    got.unwrap_or_else(|| panic!("no answer to {:?}", String::from_utf8_lossy(frame)))
}

fn cmd(id: u16, body: &str) -> Vec<u8> {
    config_frame(0xBB, id, body.as_bytes())
}

/// Reads the page's host part through B20H.
fn read(b: &mut Bridge) -> (Vec<u8>, String) {
    let mut host = Vec::new();
    let mut head = String::new();
    for at in (0..HOST_LEN).step_by(WINDOW) {
        let (h, id, body) = ask(b, &cmd(codes::CONFIG_READ, &format!("{at:03X}")), 0);
        assert_eq!((h, id), (Header::Response, codes::CONFIG_READ), "{body}");
        head = body[..12].to_string();
        for pair in body.as_bytes()[12..].chunks(2) {
            host.push(u8::from_str_radix(std::str::from_utf8(pair).unwrap(), 16).unwrap());
        }
    }
    (host, head)
}

/// Stages `host` through B21H, window by window.
fn stage(b: &mut Bridge, host: &[u8]) {
    for (i, w) in host.chunks(WINDOW).enumerate() {
        let at = i * WINDOW;
        let (h, _, body) = ask(
            b,
            &cmd(codes::CONFIG_STAGE, &format!("{at:03X}{}", hex(w))),
            0,
        );
        assert_eq!(
            (h, body),
            (Header::Response, format!("{:03X}", at + w.len()))
        );
    }
}

#[test]
fn a_fresh_gateway_takes_a_password_before_any_change() {
    let mut b = gateway();
    // Nothing written yet: every byte erased, sequence FFFFFFFF, flags 0.
    let (host, head) = read(&mut b);
    assert_eq!(head, "380FFFFFFFF0");
    assert!(host.iter().all(|&x| x == 0xFF));
    let mut s = Settings::from_page(&host, false);
    s.set("modbus.unit", "5").unwrap();
    let mut page = host.clone();
    s.overlay(0, &mut page);
    stage(&mut b, &page);
    let apply = format!("{:08X}{}", host_crc(&page), hex(b"plant-1234"));
    assert_eq!(
        ask(&mut b, &cmd(codes::CONFIG_APPLY, &apply), 0),
        (Header::Error, codes::NO_PASSWORD, String::new())
    );
    // `iai bridge config set access.password=plant-1234`: B24H, no
    // current password (length 00), the new one: the page's sequence 1.
    let set = format!("00{}", hex(b"plant-1234"));
    assert_eq!(
        ask(&mut b, &cmd(codes::CONFIG_PASSWORD, &set), 0),
        (Header::Response, codes::CONFIG_PASSWORD, "00000001".into())
    );
    // Now the staged page (staged again: the password's page took the
    // slot it was staged in) applies: sequence 2, a restart needed.
    stage(&mut b, &page);
    let wrong = format!("{:08X}{}", host_crc(&page), hex(b"plant-4321"));
    assert_eq!(
        ask(&mut b, &cmd(codes::CONFIG_APPLY, &wrong), 0),
        (Header::Error, codes::WRONG_PASSWORD, String::new())
    );
    // Within a second of a wrong password, the right one is refused too.
    assert_eq!(
        ask(&mut b, &cmd(codes::CONFIG_APPLY, &apply), 999).1,
        codes::WRONG_PASSWORD
    );
    assert_eq!(
        ask(&mut b, &cmd(codes::CONFIG_APPLY, &apply), 1_000),
        (Header::Response, codes::CONFIG_APPLY, "000000021".into())
    );
    // Read back: the setting, sequence 2, a password set, a restart due.
    let (host, head) = read(&mut b);
    assert_eq!(head, "380000000023");
    assert_eq!(Settings::from_page(&host, true).bridge.modbus.unit, 5);
    // The verifier block, with the password only.
    let denied = ask(
        &mut b,
        &cmd(codes::CONFIG_READ, &format!("{ACCESS_AT:03X}")),
        2_000,
    );
    assert_eq!(denied.1, codes::WRONG_PASSWORD);
    let granted = ask(
        &mut b,
        &cmd(
            codes::CONFIG_READ,
            &format!("{ACCESS_AT:03X}{}", hex(b"plant-1234")),
        ),
        3_000,
    );
    assert_eq!(granted.0, Header::Response);
    assert!(granted.2.starts_with("3B8000000023" /* then "IAIA" */));
    assert_eq!(&granted.2[12..20], "49414941");
}

#[test]
fn a_restart_comes_200_ms_after_its_answer() {
    let mut b = gateway();
    let set = format!("00{}", hex(b"plant-1234"));
    ask(&mut b, &cmd(codes::CONFIG_PASSWORD, &set), 0);
    assert_eq!(
        ask(&mut b, &cmd(codes::RESTART, &hex(b"plant-0000")), 0).1,
        codes::WRONG_PASSWORD
    );
    assert_eq!(
        ask(&mut b, &cmd(codes::RESTART, &hex(b"plant-1234")), 5_000),
        (Header::Response, codes::RESTART, String::new())
    );
    let (mut up, mut down) = (VecPort::default(), VecPort::default());
    b.poll(&mut up, &mut down, 5_199).unwrap();
    assert_eq!(b.editor().unwrap().restarts, 0);
    b.poll(&mut up, &mut down, 5_200).unwrap();
    assert_eq!(b.editor().unwrap().restarts, 1);
}

#[test]
fn malformed_bodies_and_a_bridge_without_a_store() {
    let mut b = gateway();
    assert_eq!(
        ask(&mut b, &cmd(codes::CONFIG_READ, "3C"), 0).1,
        codes::MALFORMED
    );
    assert_eq!(
        ask(&mut b, &cmd(codes::CONFIG_STAGE, "000ABC"), 0).1,
        codes::MALFORMED
    );
    // Out of order: a window before offset 0.
    assert_eq!(
        ask(
            &mut b,
            &cmd(codes::CONFIG_STAGE, &format!("040{}", "00".repeat(64))),
            0
        )
        .1,
        codes::STAGING
    );
    let mut plain = Bridge::new(Config::DEFAULT, Source::Blank, 0);
    assert_eq!(
        ask(&mut plain, &cmd(codes::CONFIG_READ, "000"), 0).1,
        codes::STORE_FAILED
    );
    assert_eq!(ask(&mut plain, &cmd(0xB2F, ""), 0).1, codes::UNKNOWN_QUERY);
}

#[test]
fn toml_as_get_prints_it_applies_back_to_the_same_settings() {
    let mut s = Settings::DEFAULT;
    for (k, v) in [
        ("modbus.unit", "17"),
        ("bridge.allow", "212,26D"),
        ("bridge.policy", "allow-list"),
        ("net.addressing", "static"),
        ("bridge.quit_sequence", "on"),
        ("bridge.controller_station", "12"),
    ] {
        s.set(k, v).unwrap();
    }
    let text = settings_toml(&s, Some(3));
    assert!(text.contains("[modbus]\nunit = 17"), "{text}");
    assert!(text.contains("# password: not set"), "{text}");
    let mut back = Settings::DEFAULT;
    assert_eq!(settings_from_toml(&mut back, &text), Ok(None));
    assert_eq!((back.bridge, back.net, back.web), (s.bridge, s.net, s.web));
    // Every error in a file is named.
    let bad = "[modbus]\nunit = 300\nparity = \"evn\"\n[bridge]\nstation = 187\n";
    let e = settings_from_toml(&mut Settings::default(), bad).unwrap_err();
    assert!(e.contains("modbus.unit = \"300\": out of range"), "{e}");
    assert!(
        e.contains("modbus.parity = \"evn\": not one of the choices"),
        "{e}"
    );
    assert!(e.contains("two hex digits"), "{e}");
    let pw = "[access]\npassword = \"plant-1234\"\n";
    assert_eq!(
        settings_from_toml(&mut Settings::default(), pw),
        Ok(Some("plant-1234".into()))
    );
}

/// `iai bridge config block` writes an image at the address each board's
/// memory map gives its slots: the last two erase pages below the end of
/// the flash (CONFIG_PAGE bytes).
#[test]
fn board_slots_are_where_the_memory_maps_put_them() {
    let root = host_tests::qemu::workspace_root();
    for (map, boards) in [
        ("memory-qemu.x", &["lm3s6965", "mps2-an386"][..]),
        ("memory-stm32g030.x", &["stm32g030"]),
        ("memory-stm32g070.x", &["stm32g070"]),
    ] {
        let text = std::fs::read_to_string(root.join(map)).unwrap();
        let kib = |s: &str| -> u32 {
            let s = s.trim().trim_end_matches(';');
            s.split('-')
                .map(|t| t.trim().trim_end_matches('K').parse::<u32>().unwrap() * 1024)
                .reduce(|a, b| a - b)
                .unwrap()
        };
        let page = kib(text
            .lines()
            .find_map(|l| l.strip_prefix("CONFIG_PAGE = "))
            .unwrap());
        let flash = text
            .lines()
            .find(|l| l.trim_start().starts_with("FLASH"))
            .unwrap();
        let origin = u32::from_str_radix(
            flash
                .split("ORIGIN = 0x")
                .nth(1)
                .unwrap()
                .split(',')
                .next()
                .unwrap(),
            16,
        )
        .unwrap();
        let length = kib(flash.split("LENGTH = ").nth(1).unwrap());
        for name in boards {
            let b = BOARDS.iter().find(|b| b.name == *name).unwrap();
            assert_eq!(b.address, origin + length, "{name}: {map}");
            assert_eq!(2 * b.slot_len as u32, page, "{name}: {map}");
        }
    }
}
