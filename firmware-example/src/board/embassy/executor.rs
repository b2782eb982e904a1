//! embassy's executor in thread mode, sleeping in WFI: a task woken from
//! an interrupt (a UART's, or the tick's timer) ends the sleep. (embassy's
//! own thread executor waits with WFE, which QEMU runs as a busy loop.)

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::raw::Executor;
use embassy_executor::Spawner;

/// Set when a task is woken; cleared before each round of polls.
static PENDED: AtomicBool = AtomicBool::new(false);

/// embassy's hook for a woken task (called from interrupts or tasks).
#[export_name = "__pender"]
fn pender(_context: *mut ()) {
    PENDED.store(true, Ordering::Release);
}

/// Starts the executor: `start` spawns the tasks, then the executor polls
/// the woken ones and sleeps while none is, for ever.
pub fn run(start: impl FnOnce(Spawner)) -> ! {
    static mut EXECUTOR: MaybeUninit<Executor> = MaybeUninit::uninit();
    // SAFETY: `run` is called once (it never returns); this is the only
    // reference to the static.
    let executor: &'static Executor =
        unsafe { (*addr_of_mut!(EXECUTOR)).write(Executor::new(core::ptr::null_mut())) };
    start(executor.spawner());
    loop {
        // SAFETY: polled from thread mode only, never re-entered.
        unsafe { executor.poll() };
        // Masked, so that a wake between the check and the WFI still ends
        // the WFI (a pending interrupt does, even while masked).
        cortex_m::interrupt::free(|_| {
            if !PENDED.load(Ordering::Acquire) {
                cortex_m::asm::wfi();
            }
        });
        PENDED.store(false, Ordering::Release);
    }
}
