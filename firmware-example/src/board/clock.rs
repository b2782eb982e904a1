//! The board's clock: a 1 kHz SysTick interrupt counts milliseconds, and
//! SysTick's counter gives the microseconds between two ticks; WFI sleep
//! that any interrupt (the tick at the latest) ends.

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::exception;

/// Rate of [`now_ms`]'s tick.
pub const TICK_HZ: u32 = 1_000;

/// Milliseconds since [`start_tick`] (wrapping).
static TICKS_MS: AtomicU32 = AtomicU32::new(0);
/// Times [`TICKS_MS`] wrapped: the high word of [`now_ms_64`].
static EPOCHS: AtomicU32 = AtomicU32::new(0);
/// SysTick counts per microsecond (set by [`start_tick`]).
static COUNTS_PER_US: AtomicU32 = AtomicU32::new(1);

/// Starts the 1 kHz SysTick interrupt behind [`now_ms`], counting the core
/// clock (`core_hz`, the board's clock).
pub fn start_tick(mut syst: SYST, core_hz: u32) {
    COUNTS_PER_US.store((core_hz / 1_000_000).max(1), Ordering::Relaxed);
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload((core_hz / TICK_HZ).saturating_sub(1));
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Milliseconds since [`start_tick`]; wraps after about 49.7 days.
pub fn now_ms() -> u32 {
    TICKS_MS.load(Ordering::Relaxed)
}

/// Milliseconds since [`start_tick`], never wrapping.
pub fn now_ms_64() -> u64 {
    loop {
        let high = EPOCHS.load(Ordering::Acquire);
        let low = TICKS_MS.load(Ordering::Acquire);
        if EPOCHS.load(Ordering::Acquire) == high {
            return u64::from(high) << 32 | u64::from(low);
        }
    }
}

/// Microseconds since [`start_tick`] (wraps after about 71 minutes): the
/// millisecond count plus SysTick's progress through the current
/// millisecond. Callable from an interrupt handler: a tick that wrapped
/// while its exception is still pending is counted.
pub fn now_us() -> u32 {
    let per_us = COUNTS_PER_US.load(Ordering::Relaxed).max(1);
    let reload = per_us * 1_000 - 1;
    loop {
        let ms = now_ms();
        let left = SYST::get_current();
        let pending = SCB::is_pendst_pending();
        if now_ms() != ms {
            continue;
        }
        let mut us = ms.wrapping_mul(1_000) + (reload - left.min(reload)) / per_us;
        if pending && left > reload / 2 {
            // The counter wrapped; its tick is not counted yet.
            us = us.wrapping_add(1_000);
        }
        return us;
    }
}

#[exception]
fn SysTick() {
    // Load and store: Cortex-M0 has no atomic add, and only this handler
    // writes the tick.
    let t = TICKS_MS.load(Ordering::Relaxed).wrapping_add(1);
    if t == 0 {
        let e = EPOCHS.load(Ordering::Relaxed);
        EPOCHS.store(e.wrapping_add(1), Ordering::Release);
    }
    TICKS_MS.store(t, Ordering::Release);
    #[cfg(feature = "embassy")]
    super::embassy::time::on_tick();
}

/// Sleeps in WFI unless `ready()` says there is work. `ready` runs with
/// interrupts masked, so an interrupt that makes work between the check
/// and the WFI still wakes it (a pending interrupt ends WFI even while
/// masked). The 1 kHz tick bounds every sleep to a millisecond.
pub fn sleep_unless(ready: &mut dyn FnMut() -> bool) {
    cortex_m::interrupt::free(|_| {
        if !ready() {
            cortex_m::asm::wfi();
        }
    });
}
