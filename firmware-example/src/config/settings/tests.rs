extern crate std;

use std::string::String;
use std::vec;
use std::vec::Vec;

use super::*;
use crate::config::page::{HOST_LEN, PAGE_LEN};

struct Text(Vec<u8>);

impl Sink for Text {
    fn put(&mut self, bytes: &[u8]) {
        self.0.extend_from_slice(bytes);
    }
}

fn shown(s: &Settings, key: &str) -> String {
    let setting = find(key).unwrap();
    let mut t = Text(Vec::new());
    format(setting.kind, &(setting.get)(s), &mut t);
    String::from_utf8(t.0).unwrap()
}

/// A value for every setting other than its default, as `iai bridge
/// config set` takes it.
const SAMPLES: [(&str, &str); 22] = [
    ("bridge.station", "0A"),
    ("bridge.controller_station", "12"),
    ("bridge.host_baud", "9600"),
    ("bridge.controller_baud", "38400"),
    ("bridge.flow", "rtscts"),
    ("bridge.policy", "allow-list"),
    ("bridge.allow", "212,215-217,26D"),
    ("bridge.upstream", "modbus-rtu"),
    ("bridge.duplicate_window_ms", "8000"),
    ("bridge.xoff_hold_ms", "250"),
    ("bridge.quit_sequence", "on"),
    ("modbus.unit", "17"),
    ("modbus.baud", "19200"),
    ("modbus.parity", "odd"),
    ("modbus.poll_ms", "250"),
    ("modbus.axes", "2"),
    ("net.addressing", "static"),
    ("net.address", "10.0.2.15/24"),
    ("net.gateway", "10.0.2.2"),
    ("net.port", "6020"),
    ("web.port", "8080"),
    ("web.reads", "password"),
];

#[test]
fn every_setting_is_written_into_its_block_and_read_back_from_the_page() {
    // Every key of the table but the password has a sample.
    let keys: Vec<&str> = TABLE.iter().map(|s| s.key).collect();
    for (key, _) in SAMPLES {
        assert!(keys.contains(&key), "{key}");
    }
    assert_eq!(SAMPLES.len() + 1, TABLE.len());
    let mut s = Settings::DEFAULT;
    for (key, value) in SAMPLES {
        assert_ne!(shown(&s, key), value, "{key}: the sample is the default");
        s.set(key, value).unwrap();
        assert_eq!(shown(&s, key), value, "{key}");
    }
    s.check().unwrap();
    // Into a blank page, and back.
    let mut page = vec![0xFF; PAGE_LEN];
    for at in (0..HOST_LEN).step_by(64) {
        s.overlay(at, &mut page[at..(at + 64).min(HOST_LEN)]);
    }
    let back = Settings::from_page(&page, false);
    for (key, value) in SAMPLES {
        assert_eq!(shown(&back, key), value, "{key} read back from the page");
    }
    assert_eq!(back.bridge, s.bridge);
    assert_eq!(back.net, s.net);
    assert_eq!(back.web, s.web);
    // What the typed blocks now say.
    assert_eq!(back.bridge.modbus.unit, 17);
    assert_eq!(
        back.bridge.policy,
        Policy::Allow(AllowList::of(&[0x212, 0x215, 0x216, 0x217, 0x26D]))
    );
    assert_eq!(back.net.port, 6020);
    assert_eq!(back.web.reads, Reads::Password);
}

#[test]
fn a_blank_page_is_every_default_and_unchanged_blocks_keep_their_bytes() {
    let blank = vec![0xFF; PAGE_LEN];
    assert_eq!(Settings::from_page(&blank, false), Settings::DEFAULT);
    assert_eq!(shown(&Settings::DEFAULT, "modbus.unit"), "1");
    assert_eq!(shown(&Settings::DEFAULT, "bridge.station"), "BB");
    assert_eq!(shown(&Settings::DEFAULT, "bridge.allow"), "none");
    assert_eq!(shown(&Settings::DEFAULT, "net.address"), "192.168.1.20/24");
    assert_eq!(shown(&Settings::DEFAULT, "net.gateway"), "none");
    assert_eq!(shown(&Settings::DEFAULT, "access.password"), "not set");
    assert_eq!(shown(&Settings::DEFAULT, "bridge.xoff_hold_ms"), "5000");
    // A value set to what it is changes nothing.
    let mut s = Settings::DEFAULT;
    s.set("modbus.unit", "1").unwrap();
    assert!(!s.any_changed());
    // Only the changed block is written.
    let mut s = Settings::DEFAULT;
    s.set("modbus.unit", "5").unwrap();
    let mut page = vec![0xFF; PAGE_LEN];
    s.overlay(0, &mut page[..HOST_LEN]);
    assert_eq!(&page[..4], b"IAIB");
    assert!(page[NET_AT..HOST_LEN].iter().all(|&b| b == 0xFF));
}

#[test]
fn the_policy_and_its_list_may_come_in_either_order() {
    let mut a = Settings::DEFAULT;
    a.set("bridge.allow", "212").unwrap();
    a.set("bridge.policy", "allow-list").unwrap();
    let mut b = Settings::DEFAULT;
    b.set("bridge.policy", "allow-list").unwrap();
    b.set("bridge.allow", "212").unwrap();
    assert_eq!(a.bridge.policy, Policy::Allow(AllowList::of(&[0x212])));
    assert_eq!(a.bridge, b.bridge);
}

#[test]
fn refusals_name_the_setting_and_why() {
    let mut s = Settings::DEFAULT;
    let err = |s: &mut Settings, k: &str, v: &str| s.set(k, v).unwrap_err();
    assert_eq!(
        err(&mut s, "modbus.unit", "248"),
        SetError {
            key: Some("modbus.unit"),
            reason: "out of range"
        }
    );
    assert_eq!(
        err(&mut s, "modbus.unit", "x").reason,
        "not a decimal number"
    );
    assert_eq!(err(&mut s, "modbus.units", "1").key, None);
    assert!(err(&mut s, "bridge.host_baud", "1200")
        .reason
        .contains("baud"));
    assert!(err(&mut s, "bridge.station", "B")
        .reason
        .contains("two hex"));
    assert!(err(&mut s, "bridge.allow", "212,300")
        .reason
        .contains("200 to 2FF"));
    assert!(err(&mut s, "bridge.allow", "217-212")
        .reason
        .contains("ends before"));
    assert!(err(&mut s, "net.address", "10.0.2.15/31")
        .reason
        .contains("prefix"));
    assert!(err(&mut s, "net.address", "224.0.0.1/24")
        .reason
        .contains("host"));
    assert!(err(&mut s, "net.gateway", "10.0.2").reason.contains("none"));
    assert!(err(&mut s, "access.password", "secret12")
        .reason
        .contains("by itself"));
    assert!(err(&mut s, "bridge.xoff_hold_ms", "99")
        .reason
        .contains("range"));
    // Nothing was changed by a refusal.
    assert_eq!(s, Settings::DEFAULT);
    // Two settings that must differ.
    s.set("bridge.station", "99").unwrap();
    assert_eq!(s.check().unwrap_err().key, Some("bridge.station"));
}

#[test]
fn ids_print_as_runs() {
    let mut s = Settings::DEFAULT;
    s.set("bridge.allow", "200-2FF").unwrap();
    assert_eq!(shown(&s, "bridge.allow"), "200-2FF");
    s.set("bridge.allow", "26d, 212 ,213").unwrap();
    assert_eq!(shown(&s, "bridge.allow"), "212-213,26D");
    s.set("bridge.allow", "none").unwrap();
    assert_eq!(shown(&s, "bridge.allow"), "none");
}
