//! The configuration page read through `embedded-storage`'s
//! [`ReadNorFlash`]: embassy-stm32's `Flash` on the STM32 boards,
//! [`MappedPage`] (the page read where the memory map puts it) on the
//! others. Every board reads its blocks here, so that a store kept in
//! flash pages replaces [`load`] alone.

use embedded_storage::nor_flash::{ErrorType, NorFlashError, NorFlashErrorKind, ReadNorFlash};

use super::image::{config_page, PAGE_LEN};
use crate::config::{Config, Source, BLOCK_LEN};

/// The bridge's configuration from the block at `offset` in `flash`
/// (defaults if blank or invalid; a page that cannot be read counts as a
/// block too short).
pub fn load<F: ReadNorFlash>(flash: &mut F, offset: u32) -> (Config, Source) {
    let mut block = [0u8; BLOCK_LEN];
    match flash.read(offset, &mut block) {
        Ok(()) => Config::from_block(&block),
        Err(_) => Config::from_block(&[]),
    }
}

/// The network settings from their block, [`crate::net::config::BLOCK_OFFSET`]
/// bytes past the bridge's block at `offset`.
#[cfg(feature = "ethernet")]
pub fn load_net<F: ReadNorFlash>(
    flash: &mut F,
    offset: u32,
) -> (crate::net::config::NetConfig, crate::net::config::NetSource) {
    use crate::net::config::{NetConfig, BLOCK_LEN as NET_LEN, BLOCK_OFFSET};
    let mut block = [0u8; NET_LEN];
    let at = offset.saturating_add(BLOCK_OFFSET as u32);
    match flash.read(at, &mut block) {
        Ok(()) => NetConfig::from_block(&block),
        Err(_) => NetConfig::from_block(&[]),
    }
}

/// The configuration page where the memory map puts it (`_bridge_config`),
/// read as memory: offset 0 is the page's first byte, [`PAGE_LEN`] bytes.
pub struct MappedPage;

/// A read past the page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutOfBounds;

impl NorFlashError for OutOfBounds {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::OutOfBounds
    }
}

impl ErrorType for MappedPage {
    type Error = OutOfBounds;
}

impl ReadNorFlash for MappedPage {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), OutOfBounds> {
        let start = offset as usize;
        let end = start.checked_add(bytes.len()).ok_or(OutOfBounds)?;
        let from = config_page().get(start..end).ok_or(OutOfBounds)?;
        bytes.copy_from_slice(from);
        Ok(())
    }

    fn capacity(&self) -> usize {
        PAGE_LEN
    }
}
