extern crate std;

use std::vec;
use std::vec::Vec;

use super::*;
use crate::config::page::{PAGE_LEN, TRAILER_AT};
use crate::config::store::{MemFlash, Store};

fn no_restart() {}

/// A page's host part with `settings` over a blank page.
fn host_page(settings: &Settings) -> Vec<u8> {
    let mut page = vec![0xFF; HOST_LEN];
    settings.overlay(0, &mut page);
    page
}

/// Stages `page` (its host part) as a host does, window by window.
fn stage_all(e: &mut Editor<'_>, page: &[u8]) -> Result<(), Refusal> {
    for (i, w) in page.chunks(WINDOW).enumerate() {
        e.stage(i * WINDOW, w)?;
    }
    Ok(())
}

#[test]
fn a_fresh_gateway_takes_a_password_first_then_changes_with_it() {
    let mut mem = vec![0xFF; 2048];
    let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
    let mut e = Editor::new(&mut store, no_restart, 1);
    let mut s = Settings::DEFAULT;
    s.set("modbus.unit", "5").unwrap();
    let page = host_page(&s);
    // No password yet: a staged page is refused.
    stage_all(&mut e, &page).unwrap();
    assert_eq!(e.apply(b"", host_crc(&page), 0), Err(Refusal::NoPassword));
    assert_eq!(e.request_restart(b"", 0), Err(Refusal::NoPassword));
    // A password is taken without one.
    let applied = e.set_password(b"", b"plant-1234", 10).unwrap();
    assert_eq!(applied.seq, 1);
    assert!(e.verifier().unwrap().accepts(b"plant-1234"));
    // The password discarded the staged page: stage it again.
    assert_eq!(
        e.apply(b"plant-1234", host_crc(&page), 20),
        Err(Refusal::Staging)
    );
    stage_all(&mut e, &page).unwrap();
    assert_eq!(
        e.apply(b"wrong-pass", host_crc(&page), 30),
        Err(Refusal::WrongPassword)
    );
    // Within a second of a wrong password even the right one is refused.
    assert_eq!(
        e.apply(b"plant-1234", host_crc(&page), 500),
        Err(Refusal::Shut)
    );
    let applied = e.apply(b"plant-1234", host_crc(&page), 1_100).unwrap();
    assert_eq!(
        applied,
        Applied {
            seq: 2,
            restart_needed: true
        }
    );
    assert!(e.restart_pending());
    // The new page holds the setting and still the password.
    assert_eq!(e.settings().bridge.modbus.unit, 5);
    assert!(e.settings().password_set);
    assert!(e.verifier().unwrap().accepts(b"plant-1234"));
    assert_eq!(e.failures(), 1);
}

#[test]
fn a_staged_page_must_be_whole_in_order_and_what_the_apply_says() {
    let mut mem = vec![0xFF; 2048];
    let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
    let mut e = Editor::new(&mut store, no_restart, 1);
    e.set_password(b"", b"plant-1234", 0).unwrap();
    let mut s = Settings::DEFAULT;
    s.set("web.reads", "password").unwrap();
    let page = host_page(&s);
    // Out of order.
    assert_eq!(e.stage(64, &page[64..128]), Err(Refusal::Staging));
    e.stage(0, &page[..64]).unwrap();
    assert_eq!(e.stage(128, &page[128..192]), Err(Refusal::Staging));
    // Incomplete.
    e.stage(64, &page[64..128]).unwrap();
    assert_eq!(
        e.apply(b"plant-1234", host_crc(&page), 0),
        Err(Refusal::Staging)
    );
    // Past the host part.
    assert_eq!(e.stage(HOST_LEN - 8, &[0; 16]), Err(Refusal::Staging));
    // Whole, but not what the CRC says.
    stage_all(&mut e, &page).unwrap();
    assert_eq!(
        e.apply(b"plant-1234", host_crc(&page) ^ 1, 0),
        Err(Refusal::Staging)
    );
    // A web change discards it.
    stage_all(&mut e, &page).unwrap();
    let mut other = e.settings();
    other.set("modbus.axes", "3").unwrap();
    e.commit_settings(&other, b"plant-1234", None, 0).unwrap();
    assert_eq!(
        e.apply(b"plant-1234", host_crc(&page), 0),
        Err(Refusal::Staging)
    );
    // Only the web block changed: nothing waits for a restart.
    let mut current = vec![0xFF; HOST_LEN];
    e.read_host(0, &mut current).unwrap();
    let mut s = e.settings();
    s.set("web.port", "8080").unwrap();
    s.overlay(0, &mut current);
    stage_all(&mut e, &current).unwrap();
    let applied = e.apply(b"plant-1234", host_crc(&current), 0).unwrap();
    assert!(!applied.restart_needed);
    assert_eq!(e.web().port, 8080);
}

#[test]
fn a_block_that_does_not_check_is_refused_and_nothing_changes() {
    let mut mem = vec![0xFF; 2048];
    let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
    let mut e = Editor::new(&mut store, no_restart, 1);
    e.set_password(b"", b"plant-1234", 0).unwrap();
    let mut page = host_page(&{
        let mut s = Settings::DEFAULT;
        s.set("modbus.unit", "9").unwrap();
        s
    });
    // Same stations on both sides, the block's CRC made right.
    page[6] = 0xBB;
    let crc = crate::config::crc32(&page[..crate::config::BLOCK_LEN - 4]);
    page[crate::config::BLOCK_LEN - 4..crate::config::BLOCK_LEN]
        .copy_from_slice(&crc.to_le_bytes());
    stage_all(&mut e, &page).unwrap();
    assert_eq!(
        e.apply(b"plant-1234", host_crc(&page), 0),
        Err(Refusal::Invalid("bridge"))
    );
    assert_eq!(e.sequence(), Some(1));
    assert_eq!(e.settings().bridge.modbus.unit, 1);
}

#[test]
fn a_web_change_writes_only_its_blocks_and_keeps_the_rest_of_the_page() {
    let mut mem = vec![0xFF; 2048];
    // Bytes of a block this firmware does not know (the Sparkplug node's).
    {
        let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
        store.begin().unwrap();
        store
            .write(256, b"IAIS-someone-else's-block-bytes!")
            .unwrap();
        store.commit().unwrap();
    }
    let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
    let mut e = Editor::new(&mut store, no_restart, 1);
    let mut s = e.settings();
    s.set("modbus.unit", "7").unwrap();
    // A fresh gateway: the change must come with a new password.
    assert_eq!(
        e.commit_settings(&s, b"", None, 0),
        Err(Refusal::NoPassword)
    );
    let applied = e.commit_settings(&s, b"", Some(b"plant-1234"), 0).unwrap();
    assert!(applied.restart_needed);
    let mut other = [0u8; 32];
    e.read_host(256, &mut other).unwrap();
    assert_eq!(&other, b"IAIS-someone-else's-block-bytes!");
    assert_eq!(e.settings().bridge.modbus.unit, 7);
    assert!(e.verifier().unwrap().accepts(b"plant-1234"));
    // Only the web block: at once, no restart needed.
    let mut s = e.settings();
    s.set("web.port", "8080").unwrap();
    let applied = e.commit_settings(&s, b"plant-1234", None, 0).unwrap();
    assert!(!applied.restart_needed);
    assert_eq!(e.web().port, 8080);
    // A bad value of a new password changes nothing.
    let seq = e.sequence();
    assert_eq!(
        e.commit_settings(&s, b"plant-1234", Some(b"short"), 0),
        Err(Refusal::BadPassword(
            crate::config::access::PasswordError::Length
        ))
    );
    assert_eq!(e.sequence(), seq);
    // The trailer is the store's.
    let mut trailer = [0u8; 8];
    e.store().read(TRAILER_AT, &mut trailer).unwrap();
    assert_eq!(trailer[..4], 3u32.to_le_bytes());
    let _ = PAGE_LEN;
}

static RESTARTED: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

fn count_restart() {
    RESTARTED.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
}

#[test]
fn a_restart_comes_200_ms_after_it_was_granted() {
    let mut mem = vec![0xFF; 2048];
    let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
    let mut e = Editor::new(&mut store, count_restart, 1);
    e.set_password(b"", b"plant-1234", 0).unwrap();
    assert_eq!(
        e.request_restart(b"plant-12345", 1_000),
        Err(Refusal::WrongPassword)
    );
    e.request_restart(b"plant-1234", 3_000).unwrap();
    e.poll(3_199);
    assert_eq!(RESTARTED.load(core::sync::atomic::Ordering::Relaxed), 0);
    e.poll(3_200);
    assert_eq!(RESTARTED.load(core::sync::atomic::Ordering::Relaxed), 1);
    assert_eq!(e.restarts, 1);
    e.poll(9_000);
    assert_eq!(e.restarts, 1);
}

#[test]
fn a_changed_bridge_block_over_one_in_force_waits_for_a_restart() {
    let mut mem = vec![0xFF; 2048];
    let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
    let mut e = Editor::new(&mut store, no_restart, 1);
    let mut s = e.settings();
    s.set("bridge.policy", "allow-list").unwrap();
    e.commit_settings(&s, b"", Some(b"plant-1234"), 0).unwrap();
    let mut host = vec![0xFF; HOST_LEN];
    e.read_host(0, &mut host).unwrap();
    let mut s = Settings::from_page(&host, true);
    s.set("bridge.policy", "read-only").unwrap();
    s.overlay(0, &mut host);
    stage_all(&mut e, &host).unwrap();
    let applied = e.apply(b"plant-1234", host_crc(&host), 0).unwrap();
    assert!(applied.restart_needed);
}
