//! The web page against a second smoltcp interface over an in-memory wire,
//! in simulated time ([`crate::net::testkit`]): the pages, the form with
//! and without the password, a form from another page, every limit, a
//! flood of connections beside protocol B and Modbus TCP, reads closed.

extern crate std;
use std::boxed::Box;
use std::string::String;
use std::vec;
use std::vec::Vec;

use super::*;
use crate::config::editor::Editor;
use crate::config::store::{MemFlash, PageStore, Store};
use crate::net::config::Addressing;
use crate::net::modbus::MODBUS_PORT;
use crate::net::testkit::{net_config, Rig, PB_PORT};
use iai_protocol_b::frame::{emit_frame, Header, Station};

/// The bridge's status query (B00H to station BB).
fn status_query() -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = emit_frame(
        &mut buf,
        Header::Command,
        Station(0xBB),
        0xB00,
        Default::default(),
        |_| Ok(()),
    )
    .unwrap();
    buf[..n].to_vec()
}

const WEB: u16 = 80;

fn no_restart() {}

/// The network side with the web page, its bridge keeping its page in a
/// flash model.
fn rig() -> Rig<'static> {
    let mut rig = Rig::new(net_config(Addressing::Static));
    let mem: &'static mut [u8] = Box::leak(vec![0xFF; 2048].into_boxed_slice());
    let store: &'static mut dyn PageStore =
        Box::leak(Box::new(Store::open(MemFlash::<1024, 4>::new(mem), 0)));
    rig.bridge
        .attach_editor(Box::leak(Box::new(Editor::new(store, no_restart, 3))));
    rig.net
        .add_http(Box::leak(Box::new(HttpBuffers::new())), WEB);
    rig.serve_bridge = true;
    rig.run(10, 1);
    rig
}

/// Client `n` (from local port `local`) sends `request` to the web port
/// and reads until the server closes: the answer.
fn exchange(rig: &mut Rig<'_>, n: usize, local: u16, request: &[u8]) -> String {
    rig.connect(n, WEB, local);
    rig.send_when_connected(n, &request[..request.len().min(1024)], 1_000);
    let mut rest = request.get(1024..).unwrap_or(&[]).to_vec();
    let mut got = Vec::new();
    for _ in 0..20_000 {
        rig.run(1, 1);
        if !rest.is_empty() && rig.client(n).can_send() {
            let k = rig.client(n).send_slice(&rest).unwrap_or(0);
            rest.drain(..k);
        }
        got.extend(rig.received(n));
        if !rig.client(n).may_recv() {
            break;
        }
    }
    rig.client(n).abort();
    rig.run(5, 1);
    String::from_utf8_lossy(&got).into_owned()
}

fn get(rig: &mut Rig<'_>, path: &str) -> String {
    let req = std::format!("GET {path} HTTP/1.1\r\nHost: 10.0.0.1\r\n\r\n");
    exchange(rig, 0, 41_000 + (rig.now % 1000) as u16, req.as_bytes())
}

/// A form POSTed to `path` as a browser on this gateway's page sends it.
fn post(rig: &mut Rig<'_>, path: &str, body: &str) -> String {
    post_from(rig, path, body, "http://10.0.0.1")
}

fn post_from(rig: &mut Rig<'_>, path: &str, body: &str, origin: &str) -> String {
    let req = std::format!(
        "POST {path} HTTP/1.1\r\nHost: 10.0.0.1\r\nOrigin: {origin}\r\n\
         Content-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    exchange(rig, 0, 42_000 + (rig.now % 1000) as u16, req.as_bytes())
}

fn status_of(answer: &str) -> &str {
    answer.get(9..12).unwrap_or("")
}

fn unit(rig: &mut Rig<'_>) -> u8 {
    rig.bridge.editor().unwrap().settings().bridge.modbus.unit
}

/// A password set through the form on a fresh gateway.
fn with_password(rig: &mut Rig<'_>) {
    let a = post(
        rig,
        "/config",
        "new_password=plant-1234&new_password2=plant-1234",
    );
    assert_eq!(status_of(&a), "200", "{a}");
}

#[test]
fn the_status_page_shows_each_axis_and_its_position_in_mm() {
    let mut rig = rig();
    let c = &mut rig.gateway.regs.cache;
    c.axes[0].current_position = 25_500;
    c.axes[0].axis_status = 0x08 | 0x04 | 0x10; // servo on, homed, completed
    c.axes[1].current_position = -40;
    c.axes[1].error_code = 0x0C1;
    c.error = (0x0C1, [1, 2, 3, 4]);
    c.link_up = true;
    c.axes_at.set(0);
    let page = get(&mut rig, "/");
    assert!(page.starts_with("HTTP/1.1 200 OK\r\n"), "{page}");
    assert!(page.contains("X-Frame-Options: DENY"));
    assert!(
        page.contains("<td class=\"n\" id=\"pos1\">25.500</td>"),
        "{page}"
    );
    assert!(page.contains("servo on, homed, idle, completed"), "{page}");
    assert!(page.contains("id=\"pos2\">-0.040</td>"), "{page}");
    assert!(
        page.contains("0C1 (216H: 00000001, 00000002, 00000003, 00000004)"),
        "{page}"
    );
    assert!(page.contains("class=\"ok\">up"), "{page}");
    assert!(page.contains("<td>records</td>"), "{page}");
    assert!(page.contains("</html>"));
    // Someone looked: the gateway polls from now on.
    assert!(rig.gateway.regs.active);
    // The live part alone, for the script.
    let live = get(&mut rig, "/live");
    assert!(live.contains("id=\"pos1\">25.500<"), "{live}");
    assert!(!live.contains("<html"), "{live}");
}

#[test]
fn a_fresh_gateway_asks_for_a_password_before_it_takes_a_change() {
    let mut rig = rig();
    let form = get(&mut rig, "/config");
    assert!(form.contains("id=\"no-password\""), "{form}");
    assert!(
        form.contains("<input id=\"net.address\" name=\"net.address\" value=\"10.0.0.1/24\"")
            || form.contains("name=\"net.address\""),
        "{form}"
    );
    let refused = post(&mut rig, "/config", "modbus.unit=5&password=");
    assert_eq!(status_of(&refused), "403", "{refused}");
    assert!(refused.contains("no password is set yet"), "{refused}");
    let differ = post(
        &mut rig,
        "/config",
        "modbus.unit=5&new_password=plant-1234&new_password2=plant-4321",
    );
    assert_eq!(status_of(&differ), "400");
    assert!(differ.contains("the two new passwords differ"), "{differ}");
    assert_eq!(unit(&mut rig), 1, "nothing written");
    let saved = post(
        &mut rig,
        "/config",
        "modbus.unit=5&new_password=plant-1234&new_password2=plant-1234",
    );
    assert_eq!(status_of(&saved), "200", "{saved}");
    assert!(saved.contains("Saved as sequence 1"), "{saved}");
    assert!(saved.contains("take effect at the next start"), "{saved}");
    assert_eq!(unit(&mut rig), 5);
}

#[test]
fn a_wrong_password_changes_nothing_and_shuts_the_form_for_a_second() {
    let mut rig = rig();
    with_password(&mut rig);
    let wrong = post(&mut rig, "/config", "modbus.unit=9&password=plant-0000");
    assert_eq!(status_of(&wrong), "403", "{wrong}");
    assert!(wrong.contains("wrong password: nothing was written"));
    let soon = post(&mut rig, "/config", "modbus.unit=9&password=plant-1234");
    assert_eq!(status_of(&soon), "429", "{soon}");
    assert!(soon.contains("Retry-After: 1"));
    assert_eq!(unit(&mut rig), 1);
    rig.run(1_000, 10);
    let ok = post(&mut rig, "/config", "modbus.unit=9&password=plant-1234");
    assert_eq!(status_of(&ok), "200", "{ok}");
    assert_eq!(unit(&mut rig), 9);
    // The same values again: nothing written.
    let same = post(&mut rig, "/config", "modbus.unit=9&password=plant-1234");
    assert!(same.contains("Nothing changed"), "{same}");
}

#[test]
fn a_form_from_another_page_is_refused() {
    let mut rig = rig();
    with_password(&mut rig);
    for origin in [
        "http://evil.example",
        "null",
        "http://10.0.0.1.evil.example",
    ] {
        let a = post_from(
            &mut rig,
            "/config",
            "modbus.unit=9&password=plant-1234",
            origin,
        );
        assert_eq!(status_of(&a), "403", "{origin}: {a}");
        assert!(a.contains("a form from another page is refused"), "{a}");
    }
    let restart = post_from(
        &mut rig,
        "/restart",
        "password=plant-1234",
        "http://evil.example",
    );
    assert_eq!(status_of(&restart), "403");
    assert_eq!(unit(&mut rig), 1);
    assert!(!rig.bridge.editor().unwrap().restarting());
}

#[test]
fn every_limit_is_a_clear_4xx_and_nothing_is_written() {
    let mut rig = rig();
    with_password(&mut rig);
    let seq = rig.bridge.editor().unwrap().sequence();
    // A value the setting refuses names it.
    let a = post(&mut rig, "/config", "modbus.unit=300&password=plant-1234");
    assert_eq!(status_of(&a), "400");
    assert!(a.contains("modbus.unit: out of range"), "{a}");
    let a = post(&mut rig, "/config", "modbus.units=3&password=plant-1234");
    assert!(a.contains("no setting has this key"), "{a}");
    let a = post(&mut rig, "/config", "bridge.allow=%ZZ&password=plant-1234");
    assert!(a.contains("a % not followed by two hex digits"), "{a}");
    // A head over 1,024 bytes.
    let big = std::format!(
        "GET / HTTP/1.1\r\nHost: 10.0.0.1\r\nX-Pad: {}\r\n\r\n",
        "a".repeat(1_100)
    );
    let a = exchange(&mut rig, 0, 43_001, big.as_bytes());
    assert_eq!(status_of(&a), "431", "{a}");
    // A body over 2,048 bytes, announced: refused before it is read.
    let a = exchange(
        &mut rig,
        0,
        43_002,
        b"POST /config HTTP/1.1\r\nHost: 10.0.0.1\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: 5000\r\n\r\nmodbus.unit=2",
    );
    assert_eq!(status_of(&a), "413", "{a}");
    let a = exchange(
        &mut rig,
        0,
        43_003,
        b"POST /config HTTP/1.1\r\nHost: 10.0.0.1\r\nContent-Type: application/x-www-form-urlencoded\r\n\r\n",
    );
    assert_eq!(status_of(&a), "411", "{a}");
    let a = exchange(
        &mut rig,
        0,
        43_004,
        b"POST /config HTTP/1.1\r\nHost: 10.0.0.1\r\nContent-Type: text/plain\r\nContent-Length: 3\r\n\r\na=1",
    );
    assert_eq!(status_of(&a), "415", "{a}");
    assert_eq!(status_of(&get(&mut rig, "/nothing")), "404");
    let a = exchange(
        &mut rig,
        0,
        43_005,
        b"PUT / HTTP/1.1\r\nHost: 10.0.0.1\r\n\r\n",
    );
    assert_eq!(status_of(&a), "405");
    let a = exchange(
        &mut rig,
        0,
        43_006,
        b"\x16\x03\x01\x00\xa5\x01\x00\x00\xa1\x03\x03\r\n\r\n",
    );
    assert_eq!(status_of(&a), "400", "{a}");
    // A head that stops coming: 408 after 5 s.
    let a = exchange(&mut rig, 0, 43_007, b"GET / HTTP/1.1\r\nHost: 10.0.");
    assert_eq!(status_of(&a), "408", "{a}");
    assert!(rig.now > 5_000);
    // A body that stops coming.
    let a = exchange(
        &mut rig,
        0,
        43_008,
        b"POST /config HTTP/1.1\r\nHost: 10.0.0.1\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: 100\r\n\r\nmodbus.unit=2&pass",
    );
    assert_eq!(status_of(&a), "408", "{a}");
    assert_eq!(
        rig.bridge.editor().unwrap().sequence(),
        seq,
        "nothing written"
    );
    assert_eq!(unit(&mut rig), 1);
}

#[test]
fn a_flood_of_connections_leaves_protocol_b_and_modbus_answered() {
    let mut rig = rig();
    rig.gateway.regs.cache.axes[0].current_position = 12_000;
    // Two connections that say nothing, then a third: the oldest silent
    // one is dropped for it, and it is served.
    rig.connect(0, WEB, 44_000);
    rig.run(50, 1);
    rig.connect(1, WEB, 44_001);
    rig.run(50, 1);
    let served = exchange(
        &mut rig,
        2,
        44_002,
        b"GET /live HTTP/1.1\r\nHost: 10.0.0.1\r\n\r\n",
    );
    assert_eq!(status_of(&served), "200", "{served}");
    assert!(!rig.client(0).is_open(), "{}", rig.client(0).state());
    rig.client(1).abort();
    rig.run(100, 1);
    // Three that each started a request: the third is answered 429.
    for (n, port) in [(0, 44_010), (1, 44_011)] {
        rig.connect(n, WEB, port);
        rig.send_when_connected(n, b"GET / HTTP/1.1\r\n", 1_000);
    }
    rig.run(20, 1);
    let refused = exchange(
        &mut rig,
        2,
        44_012,
        b"GET / HTTP/1.1\r\nHost: 10.0.0.1\r\n\r\n",
    );
    assert_eq!(status_of(&refused), "429", "{refused}");
    assert!(refused.contains("too many connections"), "{refused}");
    // Meanwhile Modbus TCP and protocol B are answered.
    rig.connect(3, MODBUS_PORT, 44_020);
    rig.send_when_connected(3, &[0, 7, 0, 0, 0, 6, 1, 4, 0x90, 0, 0, 2], 1_000);
    rig.run(20, 1);
    assert_eq!(
        rig.received(3),
        [0, 7, 0, 0, 0, 7, 1, 4, 4, 0, 0, 0x2E, 0xE0]
    );
    rig.connect(4, PB_PORT, 44_021);
    rig.send_when_connected(4, &status_query(), 1_000);
    rig.run(50, 1);
    let reply = rig.received(4);
    assert!(
        reply.starts_with(b"#BBB00"),
        "{:?}",
        String::from_utf8_lossy(&reply)
    );
    let stats = rig.net.http().unwrap().stats();
    assert_eq!(stats.flood, 2);
    // The two slow heads end in 408 and free their sockets.
    rig.run(5_100, 10);
    for n in 0..2 {
        let a = String::from_utf8_lossy(&rig.received(n)).into_owned();
        assert_eq!(status_of(&a), "408", "{a}");
    }
}

#[test]
fn closed_reads_need_the_password_by_basic_authentication() {
    let mut rig = rig();
    with_password(&mut rig);
    let a = post(
        &mut rig,
        "/config",
        "web.reads=password&password=plant-1234",
    );
    assert_eq!(status_of(&a), "200", "{a}");
    assert!(a.contains("In effect now"), "{a}");
    let denied = get(&mut rig, "/");
    assert_eq!(status_of(&denied), "401", "{denied}");
    assert!(denied.contains("WWW-Authenticate: Basic realm=\"IAI gateway\""));
    rig.run(1_000, 10);
    // `gateway:plant-1234`.
    let req = b"GET /live HTTP/1.1\r\nHost: 10.0.0.1\r\nAuthorization: Basic Z2F0ZXdheTpwbGFudC0xMjM0\r\n\r\n";
    let ok = exchange(&mut rig, 0, 45_000, req);
    assert_eq!(status_of(&ok), "200", "{ok}");
}

#[test]
fn a_restart_is_answered_then_carried_out() {
    let mut rig = rig();
    with_password(&mut rig);
    let a = post(&mut rig, "/restart", "password=plant-1234");
    assert_eq!(status_of(&a), "200", "{a}");
    assert!(a.contains("The gateway restarts"), "{a}");
    rig.run(300, 10);
    assert_eq!(rig.bridge.editor().unwrap().restarts, 1);
}

#[test]
fn the_last_frames_download_as_text() {
    let mut rig = rig();
    rig.connect(4, PB_PORT, 46_000);
    rig.send_when_connected(4, &status_query(), 1_000);
    rig.run(50, 1);
    rig.received(4);
    let a = get(&mut rig, "/frames.txt");
    assert!(
        a.contains("Content-Disposition: attachment; filename=\"frames.txt\""),
        "{a}"
    );
    let q = String::from_utf8(status_query()).unwrap();
    assert!(a.contains(&std::format!(" > {}\n", q.trim_end())), "{a}");
    // The status reply: its first field is the layout.
    let layout = std::format!(" < #BBB{:04X}", crate::status::LAYOUT);
    assert!(a.contains(&layout), "{a}");
    assert!(a.contains("bytes)\n"), "{a}");
}

/// Every part of every page fits the transmit buffer at its longest (a
/// part is rendered only when it fits whole): counters at their maximum,
/// an allow-list of every other ID, eight axes in alarm, long frames.
#[test]
fn every_part_of_every_page_fits_the_transmit_buffer() {
    let mut rig = rig();
    with_password(&mut rig);
    let mut s = rig.bridge.editor().unwrap().settings();
    let every_other: std::string::String = (0..128)
        .map(|i| std::format!("{:03X}", 0x200 + 2 * i))
        .collect::<Vec<_>>()
        .join(",");
    s.set("bridge.allow", &every_other).unwrap();
    s.set("bridge.policy", "allow-list").unwrap();
    rig.bridge
        .editor()
        .unwrap()
        .commit_settings(&s, b"plant-1234", None, 0)
        .unwrap();
    for a in rig.gateway.regs.cache.axes.iter_mut() {
        a.current_position = i32::MIN;
        a.error_code = 0xFFF;
        a.axis_status = 0xFF;
    }
    rig.gateway.regs.cache.error = (0xFFF, [u32::MAX; 4]);
    rig.gateway.regs.cache.polls_ok = u16::MAX;
    let long = [b'!'; 2_000];
    for _ in 0..20 {
        rig.bridge.history_for_tests(&long, u32::MAX);
    }
    let net = NetView {
        address: None,
        port: u16::MAX,
        hosts: crate::net::host::HostStats {
            hosts: u32::MAX,
            refused: u32::MAX,
            cut_short: u32::MAX,
            stalled: u32::MAX,
        },
        host_connected: true,
        modbus: Some(crate::net::modbus::ModbusTcpStats {
            connections: u32::MAX,
            requests: u32::MAX,
            idle_closed: u32::MAX,
            framing_reset: u32::MAX,
        }),
    };
    let mut view = View {
        bridge: &mut rig.bridge,
        gateway: Some(&mut rig.gateway),
        net,
        now: u32::MAX,
    };
    let mut longest = (0, "");
    for (page, name) in [
        (Page::Status, "status"),
        (Page::Config, "config"),
        (Page::Frames, "frames"),
        (
            Page::refused(
                Status::HeadersTooLarge,
                "the request's head is over 1,024 bytes",
            ),
            "refused",
        ),
    ] {
        let mut n = 0;
        loop {
            let mut buf = vec![0u8; 4096];
            let mut out = crate::text::Buf::new(&mut buf);
            if !pages::part(page, n, &mut view, &mut out) {
                break;
            }
            if out.len() > longest.0 {
                longest = (out.len(), name);
            }
            n += 1;
        }
    }
    std::println!("longest part: {} bytes ({})", longest.0, longest.1);
    assert!(longest.0 <= TX, "{longest:?}");
}
