//! The page store: the configuration page ([`super::page`]) in two flash
//! slots, A and B, over `embedded_storage::nor_flash::NorFlash` (what
//! embassy-stm32's `Flash` implements), so that a power cut at any step of
//! a write leaves the old page or the new one, never neither.
//!
//! Each slot holds a page whose last 8 bytes are a sequence number and the
//! CRC-32C of everything before it (Castagnoli's polynomial, not the
//! blocks' own: see [`Crc32::castagnoli`]); a slot whose CRC fails (never
//! written, erased, or cut short) does not count. The page in force is the valid
//! slot with the newer sequence number; none valid means a blank page
//! (every block at its defaults). A write goes to the other slot: erase it,
//! write the page, then the trailer last, read it all back; only then is
//! it the page in force. A cut before the trailer leaves the slot invalid
//! and the old page in force; the old slot is erased only by the write
//! after next.
//!
//! A slot is [`PAGE_LEN`] bytes rounded up to the flash's erase size (1 KiB
//! on the LM3S6965 and under QEMU, 2 KiB on the STM32G0, whose slot then
//! holds the page and 1 KiB left erased). Writes are whole `WRITE_SIZE`
//! words (4 bytes on the LM3S6965, 8 on the STM32G0); the store needs at
//! most 8 and at most [`WINDOW`]-byte reads.
//!
//! [`MemFlash`] is `NorFlash` over plain memory (the QEMU boards, whose
//! flash the CPU cannot write or whose "flash" is RAM: see the README) with
//! flash's rules: erase sets whole pages to FFH, a write only clears bits.

use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashError, NorFlashErrorKind,
    ReadNorFlash,
};

use super::page::{PAGE_LEN, TRAILER_AT, WINDOW};
use super::Crc32;

/// A slot's bytes for a flash erased in pages of `erase` bytes.
pub const fn slot_len(erase: usize) -> usize {
    if erase == 0 {
        PAGE_LEN
    } else {
        PAGE_LEN.div_ceil(erase) * erase
    }
}

/// Why the store could not read or write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreError {
    /// The flash refused an operation.
    Flash(NorFlashErrorKind),
    /// A write before [`PageStore::begin`], or a commit without one.
    NotBegun,
    /// Outside the page, or not whole flash words.
    Range,
    /// The page read back different from what was written.
    Verify,
    /// This board keeps no page it can write.
    NoStore,
}

/// A valid slot: which one and its sequence number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Slot {
    /// 0 for A, 1 for B.
    pub index: u8,
    /// Its sequence number.
    pub seq: u32,
}

/// The newer of two slots' sequence numbers (`None`: invalid), counting
/// in wrapping order; A if both are equal.
pub fn newest(a: Option<u32>, b: Option<u32>) -> Option<Slot> {
    match (a, b) {
        (Some(a), Some(b)) if b.wrapping_sub(a) as i32 > 0 => Some(Slot { index: 1, seq: b }),
        (Some(a), _) => Some(Slot { index: 0, seq: a }),
        (None, Some(b)) => Some(Slot { index: 1, seq: b }),
        (None, None) => None,
    }
}

/// The sequence number a slot's trailer holds if the slot is valid:
/// `read(offset, buf)` reads the slot's bytes (`false`: it cannot).
pub fn check_slot(mut read: impl FnMut(usize, &mut [u8]) -> bool) -> Option<u32> {
    let mut trailer = [0u8; 8];
    if !read(TRAILER_AT, &mut trailer) {
        return None;
    }
    let [s0, s1, s2, s3, c0, c1, c2, c3] = trailer;
    let mut crc = Crc32::castagnoli();
    let mut buf = [0u8; WINDOW];
    let mut at = 0;
    while at < TRAILER_AT {
        let n = WINDOW.min(TRAILER_AT - at);
        let chunk = buf.get_mut(..n)?;
        if !read(at, chunk) {
            return None;
        }
        crc = crc.update(chunk);
        at += n;
    }
    let seq = u32::from_le_bytes([s0, s1, s2, s3]);
    let sum = crc.update(&[s0, s1, s2, s3]).finish();
    (seq != u32::MAX && sum == u32::from_le_bytes([c0, c1, c2, c3])).then_some(seq)
}

/// Writes `page`'s trailer: sequence number `seq` and the CRC-32C of all
/// that comes before it (what a programmed image of the page needs).
pub fn seal(page: &mut [u8; PAGE_LEN], seq: u32) {
    let seq = seq.to_le_bytes();
    let sum = Crc32::castagnoli()
        .update(page.get(..TRAILER_AT).unwrap_or(&[]))
        .update(&seq)
        .finish();
    if let Some(t) = page.get_mut(TRAILER_AT..TRAILER_AT + 4) {
        t.copy_from_slice(&seq);
    }
    if let Some(t) = page.get_mut(TRAILER_AT + 4..) {
        t.copy_from_slice(&sum.to_le_bytes());
    }
}

/// Fills `image` (both slots, `slot_len` bytes each) with what a
/// programmer writes: `page` in slot A as sequence 1, the rest erased
/// (slot B too, so that no older page there is newer).
pub fn image(page: &[u8; PAGE_LEN], slot_len: usize, image: &mut [u8]) {
    image.fill(0xFF);
    let mut sealed = *page;
    seal(&mut sealed, 1);
    if slot_len >= PAGE_LEN {
        if let Some(a) = image.get_mut(..PAGE_LEN) {
            a.copy_from_slice(&sealed);
        }
    }
}

/// The page in force in two slots laid out in memory one after the other
/// (`slots`: both, `slot_len` bytes each), for a board that reads its
/// flash as memory at start; `None` if neither slot is valid.
pub fn page_in(slots: &[u8], slot_len: usize) -> Option<(&[u8], Slot)> {
    let slot = |i: usize| slots.get(i * slot_len..i * slot_len + PAGE_LEN);
    let valid = |s: Option<&[u8]>| {
        let s = s?;
        check_slot(|at, buf| match s.get(at..at + buf.len()) {
            Some(src) => {
                // A zip: `copy_from_slice` would keep its length check.
                for (d, b) in buf.iter_mut().zip(src) {
                    *d = *b;
                }
                true
            }
            None => false,
        })
    };
    let best = newest(valid(slot(0)), valid(slot(1)))?;
    Some((slot(usize::from(best.index))?, best))
}

/// The page store as the bridge and the web page use it: the page in
/// force, read; a new page, written and committed. Object-safe, so that
/// the bridge holds any flash behind it.
pub trait PageStore {
    /// The page in force, if any slot is valid.
    fn current(&self) -> Option<Slot>;
    /// Reads the page in force at `at` (FFH throughout when there is none).
    fn read(&mut self, at: usize, buf: &mut [u8]) -> Result<(), StoreError>;
    /// Starts a new page: erases the slot not in force.
    fn begin(&mut self) -> Result<(), StoreError>;
    /// Writes `bytes` of the new page at `at` (below the trailer, whole
    /// flash words, each word once).
    fn write(&mut self, at: usize, bytes: &[u8]) -> Result<(), StoreError>;
    /// Reads the new page back at `at`.
    fn read_new(&mut self, at: usize, buf: &mut [u8]) -> Result<(), StoreError>;
    /// Writes the new page's trailer and reads it all back: it is the page
    /// in force from now on. Its sequence number.
    fn commit(&mut self) -> Result<u32, StoreError>;
}

/// [`PageStore`] on a `NorFlash`: slot A at `base`, slot B right after it.
pub struct Store<F> {
    flash: F,
    base: u32,
    current: Option<Slot>,
    /// The slot a new page is being written to.
    writing: Option<u8>,
}

impl<F: NorFlash> Store<F> {
    /// Bytes of one slot on this flash.
    pub const SLOT_LEN: usize = slot_len(F::ERASE_SIZE);

    // Whole-word writes of the trailer and of host windows, whole reads of
    // the windows the checks use.
    const WORDS_FIT: () = assert!(
        F::WRITE_SIZE <= 8
            && 8usize.is_multiple_of(F::WRITE_SIZE)
            && WINDOW.is_multiple_of(F::READ_SIZE)
    );

    /// The store on `flash`, its slots at `base`; finds the page in force.
    pub fn open(flash: F, base: u32) -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::WORDS_FIT;
        let mut store = Store {
            flash,
            base,
            current: None,
            writing: None,
        };
        let a = store.check(0);
        let b = store.check(1);
        store.current = newest(a, b);
        store
    }

    /// The flash.
    pub fn flash(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Offset of `at` in slot `index`.
    fn offset(&self, index: u8, at: usize) -> Option<u32> {
        let slot = usize::from(index).checked_mul(Self::SLOT_LEN)?;
        u32::try_from(slot.checked_add(at)?)
            .ok()?
            .checked_add(self.base)
    }

    fn read_slot(&mut self, index: u8, at: usize, buf: &mut [u8]) -> Result<(), StoreError> {
        if at.checked_add(buf.len()).is_none_or(|end| end > PAGE_LEN) {
            return Err(StoreError::Range);
        }
        let offset = self.offset(index, at).ok_or(StoreError::Range)?;
        self.flash
            .read(offset, buf)
            .map_err(|e| StoreError::Flash(e.kind()))
    }

    fn check(&mut self, index: u8) -> Option<u32> {
        check_slot(|at, buf| self.read_slot(index, at, buf).is_ok())
    }
}

impl<F: NorFlash> PageStore for Store<F> {
    fn current(&self) -> Option<Slot> {
        self.current
    }

    fn read(&mut self, at: usize, buf: &mut [u8]) -> Result<(), StoreError> {
        match self.current {
            Some(slot) => self.read_slot(slot.index, at, buf),
            None if at.checked_add(buf.len()).is_some_and(|end| end <= PAGE_LEN) => {
                buf.fill(0xFF);
                Ok(())
            }
            None => Err(StoreError::Range),
        }
    }

    fn begin(&mut self) -> Result<(), StoreError> {
        let index = match self.current {
            Some(Slot { index: 0, .. }) => 1,
            _ => 0,
        };
        self.writing = None;
        let from = self.offset(index, 0).ok_or(StoreError::Range)?;
        let to = self
            .offset(index, Self::SLOT_LEN)
            .ok_or(StoreError::Range)?;
        self.flash
            .erase(from, to)
            .map_err(|e| StoreError::Flash(e.kind()))?;
        self.writing = Some(index);
        Ok(())
    }

    fn write(&mut self, at: usize, bytes: &[u8]) -> Result<(), StoreError> {
        let index = self.writing.ok_or(StoreError::NotBegun)?;
        let whole = at.is_multiple_of(F::WRITE_SIZE) && bytes.len().is_multiple_of(F::WRITE_SIZE);
        if !whole
            || at
                .checked_add(bytes.len())
                .is_none_or(|end| end > TRAILER_AT)
        {
            return Err(StoreError::Range);
        }
        let offset = self.offset(index, at).ok_or(StoreError::Range)?;
        self.flash
            .write(offset, bytes)
            .map_err(|e| StoreError::Flash(e.kind()))
    }

    fn read_new(&mut self, at: usize, buf: &mut [u8]) -> Result<(), StoreError> {
        let index = self.writing.ok_or(StoreError::NotBegun)?;
        self.read_slot(index, at, buf)
    }

    fn commit(&mut self) -> Result<u32, StoreError> {
        let index = self.writing.take().ok_or(StoreError::NotBegun)?;
        let mut seq = self.current.map_or(1, |c| c.seq.wrapping_add(1));
        if seq == u32::MAX {
            seq = 0;
        }
        let seq_bytes = seq.to_le_bytes();
        let mut crc = Crc32::castagnoli();
        let mut buf = [0u8; WINDOW];
        let mut at = 0;
        while at < TRAILER_AT {
            let n = WINDOW.min(TRAILER_AT - at);
            let chunk = buf.get_mut(..n).ok_or(StoreError::Range)?;
            self.read_slot(index, at, chunk)?;
            crc = crc.update(chunk);
            at += n;
        }
        let sum = crc.update(&seq_bytes).finish().to_le_bytes();
        let [s0, s1, s2, s3] = seq_bytes;
        let [c0, c1, c2, c3] = sum;
        let offset = self.offset(index, TRAILER_AT).ok_or(StoreError::Range)?;
        self.flash
            .write(offset, &[s0, s1, s2, s3, c0, c1, c2, c3])
            .map_err(|e| StoreError::Flash(e.kind()))?;
        if self.check(index) != Some(seq) {
            return Err(StoreError::Verify);
        }
        self.current = Some(Slot { index, seq });
        Ok(seq)
    }
}

/// `NorFlash` over memory the CPU can write, with flash's rules: erase
/// sets whole `ERASE`-byte pages to FFH, a write of whole `WRITE`-byte
/// words only clears bits (what is written over unerased bytes is their
/// AND, as on NOR flash).
pub struct MemFlash<'a, const ERASE: usize, const WRITE: usize> {
    mem: &'a mut [u8],
}

impl<'a, const ERASE: usize, const WRITE: usize> MemFlash<'a, ERASE, WRITE> {
    /// Flash over `mem`.
    pub fn new(mem: &'a mut [u8]) -> Self {
        MemFlash { mem }
    }

    /// The memory.
    pub fn memory(&self) -> &[u8] {
        self.mem
    }
}

impl<const ERASE: usize, const WRITE: usize> ErrorType for MemFlash<'_, ERASE, WRITE> {
    type Error = NorFlashErrorKind;
}

impl<const ERASE: usize, const WRITE: usize> ReadNorFlash for MemFlash<'_, ERASE, WRITE> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        check_read(self, offset, bytes.len())?;
        let at = offset as usize;
        let src = self
            .mem
            .get(at..at + bytes.len())
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl<const ERASE: usize, const WRITE: usize> NorFlash for MemFlash<'_, ERASE, WRITE> {
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to)?;
        self.mem
            .get_mut(from as usize..to as usize)
            .ok_or(NorFlashErrorKind::OutOfBounds)?
            .fill(0xFF);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, bytes.len())?;
        let at = offset as usize;
        let dst = self
            .mem
            .get_mut(at..at + bytes.len())
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        for (d, s) in dst.iter_mut().zip(bytes) {
            *d &= *s;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
