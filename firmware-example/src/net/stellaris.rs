//! The Ethernet MAC of the TI Stellaris LM3S6965 behind smoltcp's
//! [`phy::Device`]: a FIFO device without DMA, driven word by word through
//! its registers (LM3S6965 datasheet, "Ethernet Controller"; QEMU models it
//! in `hw/net/stellaris_enet.c`, which is what the offsets and framing
//! below were checked against). The registers used are in [`reg`], their
//! bits beside them.
//!
//! **Receive.** Each frame in the FIFO starts with a 16-bit length, the
//! number of bytes of the whole FIFO record: the 2 length bytes, the frame
//! from its destination address on, and its 4-byte FCS. The first word
//! read is therefore `length, dst[0], dst[1]`; the record is read as
//! `ceil(length / 4)` words, and the FCS is dropped. A length that cannot
//! be right (shorter than an Ethernet header, or longer than the FIFO
//! holds) means the driver no longer knows where frames start: it resets
//! the receive FIFO, dropping what it held, and counts it.
//!
//! **Transmit.** The first word written holds the payload length (the
//! frame without its 14-byte header) in its low half and the first two
//! bytes of the frame in its high half; the rest of the frame follows a
//! word at a time, then TR = 1. The MAC pads short frames and appends the
//! FCS. One frame at a time: a token is handed out only while TR reads 0.
//!
//! **MII.** The PHY is on the chip and negotiates the link by itself from
//! reset; the driver does not use the MII management registers (QEMU does
//! not model them either: a read returns whatever was last written).
//!
//! **MAC address.** Silicon leaves IA0/IA1 at zero: TI programs each part's
//! address into the flash user registers USER0/USER1 (3 bytes in each, low
//! byte first), which the board reads and passes to [`Stellaris::init`]
//! (QEMU sets USER0/USER1 from its NIC's address too). [`mac_from_user`]
//! turns them into an address, falling back to a locally administered one
//! if they are unprogrammed.
//!
//! The registers are reached through [`Regs`], so that the same driver
//! runs on the board ([`Mmio`]) and against a model of the device in the
//! unit tests below (QEMU's framing, byte for byte).

use smoltcp::phy::{self, DeviceCapabilities, Medium};
use smoltcp::time::Instant;

/// Register offsets.
pub mod reg {
    /// Raw interrupt status (read) / acknowledge (IACK, write 1s to clear).
    pub const RIS: usize = 0x00;
    /// Interrupt mask: only RX ([`super::INT_RX`]) is enabled.
    pub const IM: usize = 0x04;
    /// Receive control (the `RCTL_` bits).
    pub const RCTL: usize = 0x08;
    /// Transmit control (the `TCTL_` bits).
    pub const TCTL: usize = 0x0C;
    /// The receive FIFO (read) and the transmit FIFO (write), a word at a
    /// time, little-endian.
    pub const DATA: usize = 0x10;
    /// MAC address bytes 0..4.
    pub const IA0: usize = 0x14;
    /// MAC address bytes 4..6.
    pub const IA1: usize = 0x18;
    /// Frames waiting in the receive FIFO.
    pub const NP: usize = 0x34;
    /// Transmission request: write 1 to send the frame in the transmit
    /// FIFO; reads 1 while sending.
    pub const TR: usize = 0x38;
}

/// Interrupt bit: a frame was received.
pub const INT_RX: u32 = 1 << 0;
/// Every interrupt bit (RX, TXER, TXEMP, FOV, RXER, MDINT, PHYINT).
pub const INT_ALL: u32 = 0x7F;
/// RCTL: receiver on.
pub const RCTL_RXEN: u32 = 1 << 0;
/// RCTL: drop frames whose FCS is wrong.
pub const RCTL_BADCRC: u32 = 1 << 3;
/// RCTL: empty the receive FIFO.
pub const RCTL_RSTFIFO: u32 = 1 << 4;
/// TCTL: transmitter on.
pub const TCTL_TXEN: u32 = 1 << 0;
/// TCTL: pad short frames to 60 bytes.
pub const TCTL_PADEN: u32 = 1 << 1;
/// TCTL: append the FCS.
pub const TCTL_CRC: u32 = 1 << 2;

/// The MAC's address in the LM3S6965's memory map (QEMU `lm3s6965evb`:
/// the same), and its interrupt (IRQ 42).
pub const BASE: usize = 0x4004_8000;

/// Largest frame handled, without FCS: a 1,500-byte payload and the header.
pub const FRAME_CAP: usize = 1514;
/// Ethernet header: destination, source, EtherType.
const HEADER: usize = 14;
/// The receive FIFO's size (2 KiB on the chip): no record is longer.
const FIFO_BYTES: usize = 2048;
/// Bytes of a FIFO record besides the frame: length and FCS.
const RECORD_EXTRA: usize = 6;

/// The MAC's registers, a 32-bit word each.
pub trait Regs {
    /// Reads the register at `offset`.
    fn read(&self, offset: usize) -> u32;
    /// Writes `value` to the register at `offset`.
    fn write(&self, offset: usize, value: u32);
}

/// The registers at [`BASE`] on the board.
#[derive(Debug, Clone, Copy)]
pub struct Mmio;

impl Regs for Mmio {
    fn read(&self, offset: usize) -> u32 {
        // SAFETY: BASE + offset is one of the MAC's registers (every offset
        // used is in `reg`), word aligned; reading has no side effect
        // beyond the device's own (DATA pops the FIFO, as intended).
        unsafe { core::ptr::read_volatile((BASE + offset) as *const u32) }
    }

    fn write(&self, offset: usize, value: u32) {
        // SAFETY: as for `read`.
        unsafe { core::ptr::write_volatile((BASE + offset) as *mut u32, value) }
    }
}

/// What the driver counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DriverStats {
    /// Frames handed to the stack.
    pub rx_frames: u32,
    /// Frames sent.
    pub tx_frames: u32,
    /// Frames too long for the receive buffer (read out and dropped).
    pub rx_dropped: u32,
    /// Receive FIFO resets after a length that cannot be right.
    pub rx_resets: u32,
}

/// The driver: the registers and one buffer per direction (the FIFOs are
/// read and written a word at a time, so each frame is copied once).
pub struct Stellaris<R: Regs> {
    regs: R,
    rx: &'static mut [u8; FRAME_CAP],
    tx: &'static mut [u8; FRAME_CAP],
    stats: DriverStats,
}

/// The MAC address in the flash user registers USER0 and USER1 (3 bytes
/// each, low byte first), or a locally administered address made from
/// them if they are unprogrammed (all ones) or name a group address.
pub fn mac_from_user(user0: u32, user1: u32) -> [u8; 6] {
    let [a, b, c, _] = user0.to_le_bytes();
    let [d, e, f, _] = user1.to_le_bytes();
    let mac = [a, b, c, d, e, f];
    if user0 == u32::MAX || user1 == u32::MAX || a & 1 != 0 || mac == [0; 6] {
        // Locally administered, unicast: 02:00 and the low bytes.
        [0x02, 0x00, c, d, e, f]
    } else {
        mac
    }
}

impl<R: Regs> Stellaris<R> {
    /// A driver over `regs` with its two frame buffers (not yet started:
    /// see [`Stellaris::init`]).
    pub fn new(
        regs: R,
        rx: &'static mut [u8; FRAME_CAP],
        tx: &'static mut [u8; FRAME_CAP],
    ) -> Self {
        Stellaris {
            regs,
            rx,
            tx,
            stats: DriverStats::default(),
        }
    }

    /// Programs the MAC address, empties the receive FIFO, starts both
    /// directions (frames with a bad FCS dropped, short frames padded, the
    /// FCS appended) and enables the receive interrupt only.
    pub fn init(&mut self, mac: [u8; 6]) {
        let r = &self.regs;
        r.write(reg::RCTL, 0);
        r.write(reg::TCTL, 0);
        r.write(reg::IM, 0);
        let [a, b, c, d, e, f] = mac;
        r.write(reg::IA0, u32::from_le_bytes([a, b, c, d]));
        r.write(reg::IA1, u32::from_le_bytes([e, f, 0, 0]));
        r.write(reg::RCTL, RCTL_RSTFIFO);
        r.write(reg::RCTL, RCTL_RXEN | RCTL_BADCRC);
        r.write(reg::TCTL, TCTL_TXEN | TCTL_PADEN | TCTL_CRC);
        r.write(reg::RIS, INT_ALL);
        r.write(reg::IM, INT_RX);
    }

    /// Whether a frame waits in the receive FIFO (the board's loop sleeps
    /// unless one does).
    pub fn rx_pending(&self) -> bool {
        self.regs.read(reg::NP) & 0x3F != 0
    }

    /// What the driver counted.
    pub fn stats(&self) -> DriverStats {
        self.stats
    }

    /// The register access (for the board's interrupt handler and tests).
    pub fn regs(&self) -> &R {
        &self.regs
    }

    /// Reads the next frame from the receive FIFO into the receive buffer;
    /// its length, or `None` if none waits (or the one there was dropped).
    fn read_frame(&mut self) -> Option<usize> {
        if !self.rx_pending() {
            return None;
        }
        let r = &self.regs;
        let first = r.read(reg::DATA);
        let [_, _, d0, d1] = first.to_le_bytes();
        let record = (first & 0xFFFF) as usize;
        if !(RECORD_EXTRA + HEADER..=FIFO_BYTES).contains(&record) {
            // Lost track of where frames start: drop everything.
            r.write(reg::RCTL, RCTL_RSTFIFO);
            r.write(reg::RCTL, RCTL_RXEN | RCTL_BADCRC);
            self.stats.rx_resets = self.stats.rx_resets.wrapping_add(1);
            return None;
        }
        let len = record - RECORD_EXTRA;
        let words = record.div_ceil(4);
        let keep = len <= FRAME_CAP;
        if keep {
            if let Some(head) = self.rx.get_mut(..2) {
                head.copy_from_slice(&[d0, d1]);
            }
        }
        // Bytes 2.. of the frame, then the FCS (dropped), then padding.
        let mut at: usize = 2;
        for _ in 1..words {
            let w = r.read(reg::DATA).to_le_bytes();
            if keep {
                // Element by element: no length check that could panic.
                let end = at.saturating_add(4).min(len);
                if let Some(dst) = self.rx.get_mut(at.min(end)..end) {
                    for (d, s) in dst.iter_mut().zip(w) {
                        *d = s;
                    }
                }
            }
            at = at.saturating_add(4);
        }
        if keep {
            self.stats.rx_frames = self.stats.rx_frames.wrapping_add(1);
            Some(len)
        } else {
            self.stats.rx_dropped = self.stats.rx_dropped.wrapping_add(1);
            None
        }
    }
}

/// A received frame.
pub struct RxToken<'a> {
    frame: &'a [u8],
}

impl phy::RxToken for RxToken<'_> {
    fn consume<T, F>(self, f: F) -> T
    where
        F: FnOnce(&[u8]) -> T,
    {
        f(self.frame)
    }
}

/// Room for one frame to send.
pub struct TxToken<'a, R: Regs> {
    regs: &'a R,
    buf: &'a mut [u8; FRAME_CAP],
    sent: &'a mut u32,
}

impl<R: Regs> phy::TxToken for TxToken<'_, R> {
    fn consume<T, F>(self, len: usize, f: F) -> T
    where
        F: FnOnce(&mut [u8]) -> T,
    {
        // smoltcp asks for at most the MTU (FRAME_CAP); anything else is
        // built in the buffer and not sent.
        let fits = (HEADER..=FRAME_CAP).contains(&len);
        let frame = match self.buf.get_mut(..len) {
            Some(frame) => frame,
            None => self.buf.as_mut_slice(),
        };
        let result = f(frame);
        if fits {
            send(self.regs, frame);
            *self.sent = self.sent.wrapping_add(1);
        }
        result
    }
}

/// Writes `frame` (header included, no FCS) into the transmit FIFO and
/// asks the MAC to send it.
fn send<R: Regs>(regs: &R, frame: &[u8]) {
    let payload = frame.len().saturating_sub(HEADER) as u32;
    let (head, rest) = frame.split_at(frame.len().min(2));
    let mut first = [0u8; 2];
    if let Some(dst) = first.get_mut(..head.len()) {
        dst.copy_from_slice(head);
    }
    regs.write(
        reg::DATA,
        payload & 0xFFFF | u32::from(first[0]) << 16 | u32::from(first[1]) << 24,
    );
    for chunk in rest.chunks(4) {
        let mut w = [0u8; 4];
        for (d, s) in w.iter_mut().zip(chunk) {
            *d = *s;
        }
        regs.write(reg::DATA, u32::from_le_bytes(w));
    }
    regs.write(reg::TR, 1);
}

impl<R: Regs> phy::Device for Stellaris<R> {
    type RxToken<'a>
        = RxToken<'a>
    where
        Self: 'a;
    type TxToken<'a>
        = TxToken<'a, R>
    where
        Self: 'a;

    fn receive(&mut self, _timestamp: Instant) -> Option<(Self::RxToken<'_>, Self::TxToken<'_>)> {
        // Only while a reply could go out at once (smoltcp answers ARP and
        // TCP within the same call).
        if self.regs.read(reg::TR) & 1 != 0 {
            return None;
        }
        let len = self.read_frame()?;
        let frame = self.rx.get(..len)?;
        Some((
            RxToken { frame },
            TxToken {
                regs: &self.regs,
                buf: &mut *self.tx,
                sent: &mut self.stats.tx_frames,
            },
        ))
    }

    fn transmit(&mut self, _timestamp: Instant) -> Option<Self::TxToken<'_>> {
        if self.regs.read(reg::TR) & 1 != 0 {
            return None;
        }
        Some(TxToken {
            regs: &self.regs,
            buf: &mut *self.tx,
            sent: &mut self.stats.tx_frames,
        })
    }

    fn capabilities(&self) -> DeviceCapabilities {
        let mut caps = DeviceCapabilities::default();
        caps.medium = Medium::Ethernet;
        caps.max_transmission_unit = FRAME_CAP;
        caps.max_burst_size = Some(1);
        caps
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use core::cell::RefCell;
    use std::boxed::Box;
    use std::collections::VecDeque;
    use std::vec::Vec;

    use smoltcp::phy::{Device, RxToken as _, TxToken as _};

    use super::*;

    /// The MAC as QEMU's `stellaris_enet.c` models it: receive records of
    /// length (2 bytes, counting itself, the frame and the FCS), frame,
    /// FCS, read a word at a time; a transmit FIFO whose first word holds
    /// the payload length and the frame's first two bytes.
    #[derive(Default)]
    struct Model {
        rx: RefCell<VecDeque<u8>>,
        frames: RefCell<usize>,
        tx: RefCell<Vec<u8>>,
        sent: RefCell<Vec<Vec<u8>>>,
        resets: RefCell<usize>,
    }

    impl Model {
        fn deliver(&self, frame: &[u8]) {
            let record = frame.len() + RECORD_EXTRA;
            let mut rx = self.rx.borrow_mut();
            rx.extend((record as u16).to_le_bytes());
            rx.extend(frame.iter().copied());
            rx.extend([0xDE, 0xAD, 0xBE, 0xEF]);
            rx.extend(core::iter::repeat_n(0, record.next_multiple_of(4) - record));
            *self.frames.borrow_mut() += 1;
        }
    }

    impl Regs for &Model {
        fn read(&self, offset: usize) -> u32 {
            match offset {
                reg::NP => *self.frames.borrow() as u32,
                reg::DATA => {
                    let mut rx = self.rx.borrow_mut();
                    let mut w = [0u8; 4];
                    for b in &mut w {
                        *b = rx.pop_front().unwrap_or(0);
                    }
                    u32::from_le_bytes(w)
                }
                _ => 0,
            }
        }

        fn write(&self, offset: usize, value: u32) {
            match offset {
                reg::DATA => self.tx.borrow_mut().extend(value.to_le_bytes()),
                reg::TR => {
                    let words = core::mem::take(&mut *self.tx.borrow_mut());
                    let payload = usize::from(u16::from_le_bytes([words[0], words[1]]));
                    self.sent
                        .borrow_mut()
                        .push(words[2..2 + HEADER + payload].to_vec());
                }
                reg::RCTL if value & RCTL_RSTFIFO != 0 => {
                    self.rx.borrow_mut().clear();
                    *self.frames.borrow_mut() = 0;
                    *self.resets.borrow_mut() += 1;
                }
                _ => {}
            }
        }
    }

    fn driver(model: &Model) -> Stellaris<&Model> {
        let rx = Box::leak(Box::new([0u8; FRAME_CAP]));
        let tx = Box::leak(Box::new([0u8; FRAME_CAP]));
        let mut d = Stellaris::new(model, rx, tx);
        d.init([2, 0, 0, 0, 0, 1]);
        d
    }

    /// Takes the next frame the driver hands to the stack.
    fn take(d: &mut Stellaris<&Model>, model: &Model) -> Option<Vec<u8>> {
        let (rx, _) = d.receive(Instant::from_millis(0))?;
        let frame = rx.consume(|f| f.to_vec());
        *model.frames.borrow_mut() -= 1;
        Some(frame)
    }

    fn frame(len: usize, seed: u8) -> Vec<u8> {
        (0..len)
            .map(|i| (i as u8).wrapping_mul(31) ^ seed)
            .collect()
    }

    #[test]
    fn frames_in_and_out_byte_for_byte() {
        let model = Model::default();
        let mut d = driver(&model);
        assert_eq!(*model.resets.borrow(), 1, "init empties the FIFO");
        for len in [14, 15, 16, 17, 60, 61, 62, 63, 1513, FRAME_CAP] {
            let f = frame(len, len as u8);
            model.deliver(&f);
            assert_eq!(take(&mut d, &model).as_deref(), Some(&f[..]), "{len}");
            let tx = d.transmit(Instant::from_millis(0)).unwrap();
            tx.consume(len, |buf| buf.copy_from_slice(&f));
            assert_eq!(model.sent.borrow().last(), Some(&f), "{len}");
        }
        assert!(take(&mut d, &model).is_none());
        assert_eq!(d.stats().rx_frames, 10);
        assert_eq!(d.stats().tx_frames, 10);
    }

    #[test]
    fn oversized_frames_are_dropped_and_bad_lengths_reset_the_fifo() {
        let model = Model::default();
        let mut d = driver(&model);
        // Too long for the buffer: read out, dropped; the next one is whole.
        model.deliver(&frame(FRAME_CAP + 4, 1));
        let next = frame(100, 2);
        model.deliver(&next);
        assert!(take(&mut d, &model).is_none());
        assert_eq!(d.stats().rx_dropped, 1);
        assert_eq!(take(&mut d, &model).as_deref(), Some(&next[..]));
        // A length no record can have: the FIFO is reset, nothing passes.
        {
            let mut rx = model.rx.borrow_mut();
            rx.extend([3, 0, 0xAA, 0xBB]);
            *model.frames.borrow_mut() += 1;
        }
        model.deliver(&frame(80, 3));
        assert!(take(&mut d, &model).is_none());
        assert_eq!(d.stats().rx_resets, 1);
        assert!(take(&mut d, &model).is_none());
        assert_eq!(d.stats().rx_frames, 1);
    }

    #[test]
    fn locally_administered_mac_when_unprogrammed() {
        assert_eq!(
            mac_from_user(0x0012_5452, 0x0056_3412),
            [0x52, 0x54, 0x12, 0x12, 0x34, 0x56]
        );
        let m = mac_from_user(u32::MAX, u32::MAX);
        assert_eq!(m[0], 0x02);
    }
}
