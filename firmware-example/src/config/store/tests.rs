//! The store against a flash model that loses power at a chosen step:
//! every step of every write, on both slots, and the page read at the
//! next start is always the old one or the new one.

extern crate std;

use std::vec;
use std::vec::Vec;

use super::*;

/// A NOR flash that counts its steps (one erased page, one written word)
/// and loses power at step `cut`: that step is left half done (an erase
/// leaves the page's first half erased and the rest as it was; a word
/// being written gets every other bit of the new value) and every step
/// after it fails. Reads go on working, as after the next power-up.
struct CutFlash<const ERASE: usize, const WRITE: usize> {
    mem: Vec<u8>,
    steps: usize,
    cut: Option<usize>,
}

impl<const ERASE: usize, const WRITE: usize> CutFlash<ERASE, WRITE> {
    fn new(mem: Vec<u8>, cut: Option<usize>) -> Self {
        CutFlash { mem, steps: 0, cut }
    }

    /// Takes a step: `Ok(true)` to do it, `Ok(false)` to do half of it
    /// (the cut), `Err` once the power is gone.
    fn step(&mut self) -> Result<bool, NorFlashErrorKind> {
        let n = self.steps;
        self.steps += 1;
        match self.cut {
            Some(c) if n == c => Ok(false),
            Some(c) if n > c => Err(NorFlashErrorKind::Other),
            _ => Ok(true),
        }
    }
}

impl<const ERASE: usize, const WRITE: usize> ErrorType for CutFlash<ERASE, WRITE> {
    type Error = NorFlashErrorKind;
}

impl<const ERASE: usize, const WRITE: usize> ReadNorFlash for CutFlash<ERASE, WRITE> {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        check_read(self, offset, bytes.len())?;
        let at = offset as usize;
        bytes.copy_from_slice(&self.mem[at..at + bytes.len()]);
        Ok(())
    }
    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl<const ERASE: usize, const WRITE: usize> NorFlash for CutFlash<ERASE, WRITE> {
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to)?;
        for page in (from as usize..to as usize).step_by(ERASE) {
            let whole = self.step()?;
            let end = if whole {
                page + ERASE
            } else {
                page + ERASE / 2
            };
            self.mem[page..end].fill(0xFF);
            if !whole {
                return Err(NorFlashErrorKind::Other);
            }
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, bytes.len())?;
        for (i, word) in bytes.chunks(WRITE).enumerate() {
            let whole = self.step()?;
            let at = offset as usize + i * WRITE;
            for (j, (d, s)) in self.mem[at..at + WRITE].iter_mut().zip(word).enumerate() {
                let mask = if whole || j % 2 == 0 { 0xFF } else { 0xAA };
                *d &= *s | !mask;
            }
            if !whole {
                return Err(NorFlashErrorKind::Other);
            }
        }
        Ok(())
    }
}

/// A page whose host part is `fill`, `n` after `n`.
fn page_of(fill: u8) -> Vec<u8> {
    (0..TRAILER_AT)
        .map(|i| fill.wrapping_add(i as u8))
        .collect()
}

/// Writes `page` as the new page in force.
fn write_page<S: PageStore>(store: &mut S, page: &[u8]) -> Result<u32, StoreError> {
    store.begin()?;
    for (i, window) in page.chunks(WINDOW).enumerate() {
        store.write(i * WINDOW, window)?;
    }
    store.commit()
}

/// The page in force, as read at start.
fn page_read<S: PageStore>(store: &mut S) -> Vec<u8> {
    let mut page = vec![0u8; TRAILER_AT];
    store.read(0, &mut page).unwrap();
    page
}

/// Every step of a write of `new` over a flash holding `before` (whose
/// page in force is `old`, or none): cut there, start again, and find
/// `old` or `new`; past the last step, `new`. Returns the steps a whole
/// write takes.
fn cut_at_every_step<const ERASE: usize, const WRITE: usize>(
    before: &[u8],
    old: Option<&[u8]>,
    new: &[u8],
) -> usize {
    let mut cut = 0;
    loop {
        let flash = CutFlash::<ERASE, WRITE>::new(before.to_vec(), Some(cut));
        let mut store = Store::open(flash, 0);
        let result = write_page(&mut store, new);
        let steps = store.flash().steps;
        let mem = std::mem::take(&mut store.flash().mem);
        // The next start.
        let mut after = Store::open(CutFlash::<ERASE, WRITE>::new(mem, None), 0);
        let read = page_read(&mut after);
        if cut >= steps {
            assert!(result.is_ok(), "no cut, yet {result:?}");
            assert_eq!(read, new, "a whole write");
            return steps;
        }
        assert!(
            result.is_err(),
            "cut at step {cut} of {steps} went unnoticed"
        );
        let is_old = match old {
            Some(old) => read == old,
            None => after.current().is_none(),
        };
        assert!(
            is_old || read == new,
            "cut at step {cut}: the page read at start is neither the old nor the new"
        );
        cut += 1;
    }
}

fn cut_both_slots<const ERASE: usize, const WRITE: usize>() {
    let len = 2 * slot_len(ERASE);
    let (p1, p2, p3) = (page_of(1), page_of(2), page_of(3));
    // The first page on a blank flash: blank or the new page.
    let blank = vec![0xFF; len];
    let steps = cut_at_every_step::<ERASE, WRITE>(&blank, None, &p1);
    // One erase, the page's words, the trailer's.
    assert_eq!(
        steps,
        slot_len(ERASE) / ERASE + TRAILER_AT / WRITE + 8 / WRITE
    );
    // Then into slot B (A in force), then into A again (B in force).
    let mut store = Store::open(CutFlash::<ERASE, WRITE>::new(blank, None), 0);
    write_page(&mut store, &p1).unwrap();
    assert_eq!(store.current().map(|s| s.index), Some(0));
    let with_p1 = store.flash().mem.clone();
    cut_at_every_step::<ERASE, WRITE>(&with_p1, Some(&p1), &p2);
    write_page(&mut store, &p2).unwrap();
    assert_eq!(store.current(), Some(Slot { index: 1, seq: 2 }));
    let with_p2 = store.flash().mem.clone();
    cut_at_every_step::<ERASE, WRITE>(&with_p2, Some(&p2), &p3);
}

#[test]
fn a_power_cut_at_any_step_leaves_the_old_or_the_new_page_on_1_kib_pages_and_words() {
    // The LM3S6965: 1 KiB erase pages, 32-bit writes.
    cut_both_slots::<1024, 4>();
}

#[test]
fn a_power_cut_at_any_step_leaves_the_old_or_the_new_page_on_2_kib_pages_and_double_words() {
    // The STM32G0: 2 KiB erase pages, 64-bit writes; a slot is a whole
    // page, the page in its first half.
    cut_both_slots::<2048, 8>();
}

#[test]
fn a_slot_is_the_page_rounded_up_to_whole_erase_pages() {
    assert_eq!(slot_len(256), 1024);
    assert_eq!(slot_len(1024), 1024);
    assert_eq!(slot_len(2048), 2048);
    assert_eq!(slot_len(4096), 4096);
}

#[test]
fn the_newer_slot_wins_in_wrapping_order() {
    assert_eq!(newest(Some(1), Some(2)), Some(Slot { index: 1, seq: 2 }));
    assert_eq!(newest(Some(3), Some(2)), Some(Slot { index: 0, seq: 3 }));
    assert_eq!(newest(None, Some(7)), Some(Slot { index: 1, seq: 7 }));
    assert_eq!(newest(Some(7), None), Some(Slot { index: 0, seq: 7 }));
    assert_eq!(newest(None, None), None);
    // 0 follows FFFFFFFEH (FFFFFFFFH is erased flash, never a number).
    assert_eq!(
        newest(Some(0xFFFF_FFFE), Some(0)),
        Some(Slot { index: 1, seq: 0 })
    );
}

#[test]
fn writes_are_whole_words_below_the_trailer_and_only_after_begin() {
    let mut mem = vec![0xFF; 2048];
    let mut store = Store::open(MemFlash::<1024, 4>::new(&mut mem), 0);
    assert_eq!(store.write(0, &[0; 4]), Err(StoreError::NotBegun));
    assert_eq!(store.commit(), Err(StoreError::NotBegun));
    store.begin().unwrap();
    assert_eq!(store.write(2, &[0; 4]), Err(StoreError::Range));
    assert_eq!(store.write(0, &[0; 3]), Err(StoreError::Range));
    assert_eq!(store.write(TRAILER_AT, &[0; 8]), Err(StoreError::Range));
    store.write(0, b"IAIB").unwrap();
    assert_eq!(store.commit(), Ok(1));
    let mut head = [0u8; 4];
    store.read(0, &mut head).unwrap();
    assert_eq!(&head, b"IAIB");
    // The page in memory, as a board reads it at start.
    let (page, slot) = page_in(&mem, 1024).unwrap();
    assert_eq!(
        (&page[..4], slot),
        (&b"IAIB"[..], Slot { index: 0, seq: 1 })
    );
}

#[test]
fn mem_flash_writes_only_clear_bits() {
    let mut mem = vec![0u8; 1024];
    let mut flash = MemFlash::<1024, 4>::new(&mut mem);
    flash.erase(0, 1024).unwrap();
    flash.write(0, &[0xF0, 0x0F, 0xFF, 0x00]).unwrap();
    flash.write(0, &[0x3C, 0x3C, 0x3C, 0x3C]).unwrap();
    assert_eq!(&flash.memory()[..4], &[0x30, 0x0C, 0x3C, 0x00]);
    assert_eq!(flash.erase(0, 512), Err(NorFlashErrorKind::NotAligned));
    assert_eq!(flash.write(1, &[0; 4]), Err(NorFlashErrorKind::NotAligned));
}

#[test]
fn a_sealed_page_is_in_force_as_programmed() {
    let mut page = [0xFFu8; PAGE_LEN];
    page[..4].copy_from_slice(b"IAIB");
    seal(&mut page, 1);
    let mut slots = vec![0xFF; 2 * 2048];
    slots[..PAGE_LEN].copy_from_slice(&page);
    let (read, slot) = page_in(&slots, 2048).unwrap();
    assert_eq!((read, slot), (&page[..], Slot { index: 0, seq: 1 }));
    let store = Store::open(MemFlash::<2048, 8>::new(&mut slots), 0);
    assert_eq!(store.current(), Some(Slot { index: 0, seq: 1 }));
}

#[test]
fn the_slot_crc_tells_apart_two_valid_bridge_blocks_at_the_page_start() {
    // Each block ends in its own CRC-32: a CRC-32 over them would reach the
    // same value for both.
    let mut a = [0xFFu8; PAGE_LEN];
    let mut b = [0xFFu8; PAGE_LEN];
    let mut cfg = crate::config::Config::DEFAULT;
    a[..crate::config::BLOCK_LEN].copy_from_slice(&cfg.to_block());
    cfg.modbus.unit = 2;
    b[..crate::config::BLOCK_LEN].copy_from_slice(&cfg.to_block());
    let plain = |p: &[u8]| crate::config::crc32(&p[..crate::config::BLOCK_LEN]);
    assert_eq!(plain(&a), plain(&b));
    seal(&mut a, 5);
    seal(&mut b, 5);
    assert_ne!(a[TRAILER_AT..], b[TRAILER_AT..]);
}
