//! The configuration page on a board: its two slots where the memory map
//! puts them (`_bridge_config`, the last flash pages), the blocks read
//! from the page in force ([`crate::config::page`] says where each is),
//! and on the QEMU boards the store and editor that write a new page from
//! the field (messages B20H-B24H, `iai bridge config`).
//!
//! The QEMU boards write: QEMU maps the LM3S6965's flash read-only, so its
//! slots are kept in 2 KiB of RAM that a system reset leaves as it was
//! (`_config_ram`, `memory-qemu.x`), filled from the flash slots when it
//! holds no valid page (power-up); mps2-an386's "flash" is RAM the CPU
//! can write. The STM32 boards read their slots as memory (written by a
//! programmer or `-device loader`); the editor is not attached there, so
//! the bridge refuses page writes.

use crate::config::page::BRIDGE_AT;
use crate::config::{Config, Source, BLOCK_LEN};

#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
use core::mem::MaybeUninit;

#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
use crate::config::{
    editor::Editor,
    store::{MemFlash, PageStore, Store},
};

/// A slot of the configuration page: a flash erase page (the QEMU boards:
/// 1 KiB, as the LM3S6965's; the STM32G0 and STM32L4: 2 KiB).
#[cfg(any(
    feature = "board-stm32g030",
    feature = "board-stm32g070",
    feature = "board-b-l475e-iot01a"
))]
pub const SLOT_LEN: usize = 2048;
/// A slot of the configuration page: a flash erase page (the QEMU boards:
/// 1 KiB, as the LM3S6965's; the STM32G0 and STM32L4: 2 KiB).
#[cfg(not(any(
    feature = "board-stm32g030",
    feature = "board-stm32g070",
    feature = "board-b-l475e-iot01a"
)))]
pub const SLOT_LEN: usize = 1024;

extern "C" {
    /// The configuration page's two slots, defined by the root memory map
    /// (`memory.x`): just past the FLASH region.
    static mut _bridge_config: [u8; 2 * SLOT_LEN];
}

/// The store of a QEMU board: its slots as memory with flash's rules.
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
type BoardStore = Store<MemFlash<'static, SLOT_LEN, 4>>;

#[cfg(feature = "board-lm3s6965")]
extern "C" {
    /// QEMU's stand-in for the LM3S6965's slots: 2 KiB at the end of RAM
    /// (`memory-qemu.x`), kept by a system reset.
    static mut _config_ram: [u8; 2 * SLOT_LEN];
}

/// The slots the LM3S6965 writes (see the module docs).
#[cfg(feature = "board-lm3s6965")]
fn writable_slots() -> &'static mut [u8] {
    // SAFETY: the memory map reserves these 2 KiB of RAM for the slots and
    // the flash slots are only read; called once, at boot, by `store`.
    unsafe {
        let ram = &mut *core::ptr::addr_of_mut!(_config_ram);
        if crate::config::store::page_in(ram, SLOT_LEN).is_none() {
            ram.copy_from_slice(&*core::ptr::addr_of!(_bridge_config));
        }
        ram
    }
}

/// The slots mps2-an386 writes: its "flash" is RAM (QEMU copies a loaded
/// image there again at a system reset).
#[cfg(feature = "board-mps2-an386")]
fn writable_slots() -> &'static mut [u8] {
    // SAFETY: the memory map reserves the slots; called once, at boot, by
    // `store`.
    unsafe { &mut *core::ptr::addr_of_mut!(_bridge_config) }
}

/// The board's store, opened at the first call (at boot, before the loop;
/// the editor then holds it).
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
fn store() -> &'static mut BoardStore {
    static mut STORE: Option<BoardStore> = None;
    // SAFETY: boot code only, one call after the other: the readers'
    // references end before `editor` takes the one that lasts.
    unsafe {
        let slot = &mut *core::ptr::addr_of_mut!(STORE);
        slot.get_or_insert_with(|| Store::open(MemFlash::new(writable_slots()), 0))
    }
}

/// Reads the page in force at `at` into `buf` (FFH where there is none).
/// Boot code: call it before [`attach_editor`].
pub fn read_page(at: usize, buf: &mut [u8]) {
    #[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
    if store().read(at, buf).is_err() {
        buf.fill(0xFF);
    }
    #[cfg(not(any(feature = "board-lm3s6965", feature = "board-mps2-an386")))]
    {
        // SAFETY: the memory map reserves the slots; they are only read.
        let slots = unsafe { &*core::ptr::addr_of!(_bridge_config) };
        match crate::config::store::page_in(slots, SLOT_LEN)
            .and_then(|(page, _)| page.get(at..at.saturating_add(buf.len())))
        {
            Some(src) => buf.copy_from_slice(src),
            None => buf.fill(0xFF),
        }
    }
}

/// The bridge's configuration from its block in the page in force
/// (defaults if blank or invalid).
pub fn load_config() -> (Config, Source) {
    let mut block = [0u8; BLOCK_LEN];
    read_page(BRIDGE_AT, &mut block);
    Config::from_block(&block)
}

/// The network settings from their block.
#[cfg(feature = "ethernet")]
pub fn load_net() -> (crate::net::config::NetConfig, crate::net::config::NetSource) {
    use crate::net::config::{NetConfig, BLOCK_LEN as NET_LEN};
    let mut block = [0u8; NET_LEN];
    read_page(crate::config::page::NET_AT, &mut block);
    NetConfig::from_block(&block)
}

/// The Sparkplug B settings from their block (defaults if blank or
/// invalid: Sparkplug off).
#[cfg(feature = "ethernet")]
pub fn load_sparkplug() -> crate::net::sparkplug::config::SparkplugConfig {
    use crate::net::sparkplug::config::{SparkplugConfig, BLOCK_LEN as SP_LEN};
    let mut block = [0u8; SP_LEN];
    read_page(crate::config::page::SPARKPLUG_AT, &mut block);
    SparkplugConfig::from_block(&block).0
}

/// The web page's TCP port from its block.
#[cfg(feature = "ethernet")]
pub fn web_port() -> u16 {
    use crate::config::access::{WebConfig, WEB_LEN};
    let mut block = [0u8; WEB_LEN];
    read_page(crate::config::page::WEB_AT, &mut block);
    WebConfig::from_block(&block).port
}

/// Restarts the board (a system reset): how a new page takes effect.
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
fn restart() {
    cortex_m::peripheral::SCB::sys_reset();
}

/// Gives `bridge` the writes of the configuration page, over the board's
/// store. Once, at boot, after the last block was read: the editor holds
/// the store from then on.
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
pub fn attach_editor(bridge: &mut crate::bridge::Bridge) {
    static mut EDITOR: MaybeUninit<Editor<'static>> = MaybeUninit::uninit();
    let store: &'static mut dyn PageStore = store();
    let seed = super::image::boot_seed();
    // SAFETY: called once, at boot; the only reference to this static.
    let editor =
        unsafe { (*core::ptr::addr_of_mut!(EDITOR)).write(Editor::new(store, restart, seed)) };
    bridge.attach_editor(editor);
}
