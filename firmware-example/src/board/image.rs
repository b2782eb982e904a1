//! What the memory map and the runtime give every image: the stack's
//! peak, and a seed that differs at each boot (the configuration page:
//! [`super::config_page`]).

use core::mem::MaybeUninit;

extern "C" {
    /// Lowest address the stack may reach (cortex-m-rt).
    static _stack_end: u32;
    /// Initial stack pointer (cortex-m-rt).
    static _stack_start: u32;
}

/// Peak stack use since reset, in bytes: cortex-m-rt's `paint-stack`
/// fills the stack area with `STACK_PAINT_VALUE` before `main`; the
/// lowest word that no longer holds it is the deepest the stack went.
pub fn stack_peak() -> usize {
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut p = bottom;
    while p < top {
        // SAFETY: [bottom, top) is the stack area in RAM, word aligned.
        let w = unsafe { (p as *const u32).read_volatile() };
        if w != cortex_m_rt::STACK_PAINT_VALUE {
            break;
        }
        p += 4;
    }
    top - p
}

/// A seed for the downstream line's fence texts that differs at each boot:
/// a word of RAM the runtime never initialises (`.uninit`), read and
/// stepped at every start. After a reset (the watchdog's) it holds the
/// last boot's seed, so the next differs; at power-up, whatever the RAM
/// held.
pub fn boot_seed() -> u32 {
    #[link_section = ".uninit.BOOT_SEED"]
    static mut BOOT_SEED: MaybeUninit<u32> = MaybeUninit::uninit();
    let p = core::ptr::addr_of_mut!(BOOT_SEED).cast::<u32>();
    let last: u32;
    // SAFETY: `p` is this function's own word of RAM, aligned; the load is
    // done in assembly so that whatever the word holds is read as plain
    // bits (the compiler would call an uninitialised read undefined).
    unsafe {
        core::arch::asm!(
            "ldr {last}, [{p}]",
            p = in(reg) p,
            last = out(reg) last,
            options(nostack, readonly, preserves_flags)
        );
    }
    let next = last.wrapping_mul(0x9E37_79B1).wrapping_add(0x7F4A_7C15);
    // SAFETY: as above; nothing else uses the word.
    unsafe { p.write_volatile(next) };
    next
}
