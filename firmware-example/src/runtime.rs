//! What every board binary shares: the millisecond clock on SysTick, WFI
//! sleep, the configuration block, the stack peak, semihosting output and
//! exit, and the fault handlers. Included by each `src/bin/<board>.rs` with
//! `#[path]` (it is not part of the host-testable library).

use core::cell::RefCell;
use core::fmt::Write as _;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::interrupt::Mutex;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::{exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hio};
use firmware_example::bridge::Bridge;
use firmware_example::config::{Config, Source, BLOCK_LEN};
use firmware_example::serial::{
    DownstreamLine, FlowControl, IsrEnd, ThreadEnd, UpstreamLine, DOWNSTREAM_MARKS, UPSTREAM_MARKS,
};

/// System tick rate of [`now_ms`].
pub const TICK_HZ: u32 = 1_000;

static TICKS_MS: AtomicU32 = AtomicU32::new(0);

/// Start the 1 kHz SysTick interrupt behind [`now_ms`], counting the core
/// clock (`core_hz`, the board's reset clock).
pub fn start_tick(mut syst: SYST, core_hz: u32) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(core_hz / TICK_HZ - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Milliseconds since [`start_tick`]; wraps after about 49.7 days.
pub fn now_ms() -> u32 {
    TICKS_MS.load(Ordering::Relaxed)
}

#[exception]
fn SysTick() {
    // Load and store: Cortex-M0 has no atomic add, and only this handler
    // writes the tick.
    let t = TICKS_MS.load(Ordering::Relaxed);
    TICKS_MS.store(t.wrapping_add(1), Ordering::Relaxed);
}

/// Sleep in WFI unless `ready()` says there is work. `ready` runs with
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

/// Where `main` hands a line's interrupt end to its handler.
pub type Handoff = Mutex<RefCell<Option<IsrEnd<'static>>>>;

/// An empty [`Handoff`].
pub const fn handoff() -> Handoff {
    Mutex::new(RefCell::new(None))
}

/// Runs `f` on a line's interrupt end, taking it from `handoff` on first
/// use (`slot` is the handler's own `static mut`).
pub fn with_end(
    slot: &mut Option<IsrEnd<'static>>,
    handoff: &Handoff,
    f: impl FnOnce(&mut IsrEnd<'static>),
) {
    if slot.is_none() {
        *slot = cortex_m::interrupt::free(|cs| handoff.borrow(cs).borrow_mut().take());
    }
    if let Some(end) = slot {
        f(end);
    }
}

/// The statics a board gives [`setup`].
pub struct Statics {
    /// Room for the bridge.
    pub bridge: &'static mut MaybeUninit<Bridge>,
    /// The host line.
    pub up: &'static mut UpstreamLine,
    /// The controller line.
    pub down: &'static mut DownstreamLine,
    /// Pends the host UART's interrupt.
    pub pend_up: &'static dyn Fn(),
    /// Pends the controller UART's interrupt.
    pub pend_down: &'static dyn Fn(),
    /// Hand-off to the host UART's handler.
    pub up_end: &'static Handoff,
    /// Hand-off to the controller UART's handler.
    pub down_end: &'static Handoff,
}

/// Builds the bridge from `cfg`, splits both lines and hands their
/// interrupt ends over; the caller unmasks the interrupts afterwards.
/// Not inlined, so that its stack frame (the bridge is built on the way
/// into its static) is gone before the loop runs.
#[inline(never)]
pub fn setup(
    s: Statics,
    cfg: Config,
    source: Source,
) -> (&'static mut Bridge, ThreadEnd<'static>, ThreadEnd<'static>) {
    let bridge = s.bridge.write(Bridge::new(cfg, source));
    let (up_isr, up) = s.up.split(cfg.flow, UPSTREAM_MARKS, s.pend_up);
    let (down_isr, down) = s
        .down
        .split(FlowControl::None, DOWNSTREAM_MARKS, s.pend_down);
    cortex_m::interrupt::free(|cs| {
        s.up_end.borrow(cs).replace(Some(up_isr));
        s.down_end.borrow(cs).replace(Some(down_isr));
    });
    (bridge, up, down)
}

extern "C" {
    /// The configuration block's address, defined by the root memory map.
    static _bridge_config: [u8; BLOCK_LEN];
    /// Lowest address the stack may reach (cortex-m-rt).
    static _stack_end: u32;
    /// Initial stack pointer (cortex-m-rt).
    static _stack_start: u32;
}

/// The configuration from the block in flash (defaults if blank or
/// invalid).
pub fn load_config() -> (Config, Source) {
    // SAFETY: the memory map reserves this flash page for the block; it is
    // only read.
    let block = unsafe { &*core::ptr::addr_of!(_bridge_config) };
    Config::from_block(block)
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

/// Print to the host through semihosting, ignoring failures (this is also
/// used on the way down, where a second panic must not happen).
pub fn host_print(args: core::fmt::Arguments<'_>) {
    if let Ok(mut stdout) = hio::hstdout() {
        let _ = stdout.write_fmt(args);
    }
}

/// End the QEMU run with the given status.
pub fn exit(status: debug::ExitStatus) -> ! {
    debug::exit(status);
    // Only reached when no debugger or QEMU handles semihosting.
    loop {
        cortex_m::asm::wfi();
    }
}

/// The end of a bridge run: print the counters and the stack peak, exit.
pub fn finish<E: core::fmt::Debug>(
    result: Result<firmware_example::bridge::Stats, E>,
    up_pauses: u32,
) -> ! {
    let peak = stack_peak();
    match result {
        Ok(stats) => {
            host_print(format_args!(
                "firmware-example: quit at {} ms\nfirmware-example: {:?}\nfirmware-example: upstream pauses {}\nfirmware-example: stack peak {} bytes\n",
                now_ms(),
                stats,
                up_pauses,
                peak
            ));
            exit(debug::EXIT_SUCCESS)
        }
        Err(e) => {
            host_print(format_args!("firmware-example: bridge error: {:?}\n", e));
            exit(debug::EXIT_FAILURE)
        }
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    cortex_m::interrupt::disable();
    host_print(format_args!("firmware-example: {}\n", info));
    exit(debug::EXIT_FAILURE)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    host_print(format_args!(
        "firmware-example: HardFault at pc={:#010x} lr={:#010x}\n",
        frame.pc(),
        frame.lr()
    ));
    exit(debug::EXIT_FAILURE)
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    panic!("unexpected interrupt or exception {}", irqn);
}
