//! What every board binary shares: the millisecond clock on SysTick, WFI
//! sleep, the configuration page and its store, the restart, the stack
//! peak, semihosting output and exit, and the fault handlers. Included by each `src/bin/<board>.rs` with
//! `#[path]` (it is not part of the host-testable library).

use core::cell::Cell;
use core::convert::Infallible;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::interrupt::Mutex;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::{exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hio};
use firmware_example::bridge::{Bridge, Error};
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
use firmware_example::config::{
    editor::Editor,
    store::{MemFlash, PageStore, Store},
};
use firmware_example::config::{BlockError, Config, Source, BLOCK_LEN};
use firmware_example::serial::{
    DownstreamRings, FlowControl, IsrEnd, ThreadEnd, UpstreamRings, DOWNSTREAM_MARKS,
    UPSTREAM_MARKS,
};
use firmware_example::status::Stats;

/// System tick rate of [`now_ms`].
pub const TICK_HZ: u32 = 1_000;

static TICKS_MS: AtomicU32 = AtomicU32::new(0);

/// Start the 1 kHz SysTick interrupt behind [`now_ms`], counting the core
/// clock (`core_hz`, the board's reset clock).
pub fn start_tick(mut syst: SYST, core_hz: u32) {
    COUNTS_PER_US.store(core_hz / 1_000_000, Ordering::Relaxed);
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

/// SysTick counts per microsecond (set by [`start_tick`]).
static COUNTS_PER_US: AtomicU32 = AtomicU32::new(1);

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
        let pending = cortex_m::peripheral::SCB::is_pendst_pending();
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
pub type Handoff = Mutex<Cell<Option<IsrEnd<'static>>>>;

/// An empty [`Handoff`].
pub const fn handoff() -> Handoff {
    Mutex::new(Cell::new(None))
}

/// Runs `f` on a line's interrupt end, taking it from `handoff` on first
/// use (`slot` is the handler's own `static mut`).
#[cfg_attr(feature = "board-lm3s6965", allow(dead_code))]
pub fn with_end(
    slot: &mut Option<IsrEnd<'static>>,
    handoff: &Handoff,
    f: impl FnOnce(&mut IsrEnd<'static>),
) {
    if slot.is_none() {
        *slot = cortex_m::interrupt::free(|cs| handoff.borrow(cs).take());
    }
    if let Some(end) = slot {
        f(end);
    }
}

/// Runs `f` on a line's interrupt end where `handoff` keeps it, in a
/// critical section: the end is not copied into a static of the handler's
/// own, which saves its 36 bytes per line (for a board whose RAM is
/// tight). Does nothing before the end was handed over.
#[cfg_attr(not(feature = "board-lm3s6965"), allow(dead_code))]
pub fn in_handoff(handoff: &Handoff, f: impl FnOnce(&mut IsrEnd<'static>)) {
    cortex_m::interrupt::free(|cs| {
        // SAFETY: the cell is only reached inside critical sections: here,
        // and in `setup` which sets it before the interrupt is unmasked;
        // the reference does not outlive this one.
        if let Some(end) = unsafe { &mut *handoff.borrow(cs).as_ptr() } {
            f(end);
        }
    });
}

/// The statics a board gives [`setup`].
pub struct Statics {
    /// Room for the bridge.
    pub bridge: &'static mut MaybeUninit<Bridge>,
    /// The host line.
    pub up: &'static mut UpstreamRings,
    /// The controller line.
    pub down: &'static mut DownstreamRings,
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
    let bridge = s.bridge.write(Bridge::new(cfg, source, boot_seed()));
    #[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
    bridge.attach_editor(editor(boot_seed()));
    let (up_isr, up) = s.up.split(cfg.flow, UPSTREAM_MARKS, s.pend_up);
    let (down_isr, down) = s
        .down
        .split(FlowControl::None, DOWNSTREAM_MARKS, s.pend_down);
    cortex_m::interrupt::free(|cs| {
        s.up_end.borrow(cs).set(Some(up_isr));
        s.down_end.borrow(cs).set(Some(down_isr));
    });
    (bridge, up, down)
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

extern "C" {
    /// The configuration page's two slots in flash, defined by the root
    /// memory map.
    static mut _bridge_config: [u8; 2 * SLOT_LEN];
    /// Lowest address the stack may reach (cortex-m-rt).
    static _stack_end: u32;
    /// Initial stack pointer (cortex-m-rt).
    static _stack_start: u32;
}

/// A slot of the configuration page: a flash erase page (the QEMU boards:
/// 1 KiB, as the LM3S6965's; the STM32G0: 2 KiB).
#[cfg(any(feature = "board-stm32g030", feature = "board-stm32g070"))]
const SLOT_LEN: usize = 2048;
/// A slot of the configuration page: a flash erase page (the QEMU boards:
/// 1 KiB, as the LM3S6965's; the STM32G0: 2 KiB).
#[cfg(not(any(feature = "board-stm32g030", feature = "board-stm32g070")))]
const SLOT_LEN: usize = 1024;

/// The store of a QEMU board: its slots as memory with flash's rules.
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
type BoardStore = Store<MemFlash<'static, SLOT_LEN, 4>>;

#[cfg(feature = "board-lm3s6965")]
extern "C" {
    /// QEMU's stand-in for the lm3s6965's slots: 2 KiB at the end of RAM
    /// (memory-qemu.x), kept by a system reset.
    static mut _config_ram: [u8; 2 * SLOT_LEN];
}

/// The slots the lm3s6965 writes: QEMU maps its flash read-only, so they
/// are kept in RAM that a reset leaves as it was; when that RAM holds no
/// valid page (at power-up, QEMU's RAM is zeroed), the flash's slots are
/// copied into it (as `-device loader` or a programmer left them).
#[cfg(feature = "board-lm3s6965")]
fn writable_slots() -> &'static mut [u8] {
    // SAFETY: the memory map reserves these 2 KiB of RAM for the slots and
    // the flash slots are only read; called once, at boot, by `store`.
    unsafe {
        let ram = &mut *core::ptr::addr_of_mut!(_config_ram);
        if firmware_example::config::store::page_in(ram, SLOT_LEN).is_none() {
            ram.copy_from_slice(&*core::ptr::addr_of!(_bridge_config));
        }
        ram
    }
}

/// The slots mps2-an386 writes: its "flash" is RAM the CPU can write
/// (QEMU copies a loaded image there again at a system reset).
#[cfg(feature = "board-mps2-an386")]
fn writable_slots() -> &'static mut [u8] {
    // SAFETY: the memory map reserves the slots; called once, at boot, by
    // `store`.
    unsafe { &mut *core::ptr::addr_of_mut!(_bridge_config) }
}

/// The board's store, opened at the first call (at boot, before the
/// loop; the editor then holds it).
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
fn store() -> &'static mut BoardStore {
    static mut STORE: Option<BoardStore> = None;
    // SAFETY: boot code only, one call after the other: `load_config`'s
    // reference ends before `editor` takes the one that lasts.
    unsafe {
        let slot = &mut *core::ptr::addr_of_mut!(STORE);
        slot.get_or_insert_with(|| Store::open(MemFlash::new(writable_slots()), 0))
    }
}

/// Reads the page in force at `at` (FFH where there is none).
pub fn read_page(at: usize, buf: &mut [u8]) {
    #[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
    if store().read(at, buf).is_err() {
        buf.fill(0xFF);
    }
    #[cfg(not(any(feature = "board-lm3s6965", feature = "board-mps2-an386")))]
    {
        // SAFETY: the memory map reserves the slots; they are only read.
        let slots = unsafe { &*core::ptr::addr_of!(_bridge_config) };
        match firmware_example::config::store::page_in(slots, SLOT_LEN)
            .and_then(|(page, _)| page.get(at..at + buf.len()))
        {
            Some(src) => buf.copy_from_slice(src),
            None => buf.fill(0xFF),
        }
    }
}

/// The configuration from the bridge's block in the page in force
/// (defaults if blank or invalid).
pub fn load_config() -> (Config, Source) {
    let mut block = [0u8; BLOCK_LEN];
    read_page(firmware_example::config::page::BRIDGE_AT, &mut block);
    Config::from_block(&block)
}

/// Restarts the board (a system reset).
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
fn restart() {
    cortex_m::peripheral::SCB::sys_reset();
}

/// The writes of the configuration page, over the board's store (once,
/// at boot); `seed` differs at each boot.
#[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
pub fn editor(seed: u32) -> &'static mut Editor<'static> {
    static mut EDITOR: MaybeUninit<Editor<'static>> = MaybeUninit::uninit();
    let store: &'static mut dyn PageStore = store();
    // SAFETY: called once, at boot; the only reference to this static.
    unsafe { (*core::ptr::addr_of_mut!(EDITOR)).write(Editor::new(store, restart, seed)) }
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

/// Text to the host through semihosting, without `core::fmt` (its
/// machinery costs several KiB of flash): strings, decimals and hex, each
/// written as it comes. Failures are ignored (this also runs on the way
/// down, where a second panic must not happen).
pub struct Out(Option<hio::HostStream>);

impl Out {
    /// The host's standard output (writes go nowhere without a host).
    pub fn new() -> Self {
        Self(hio::hstdout().ok())
    }

    /// Writes `s`.
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.bytes(s.as_bytes())
    }

    fn bytes(&mut self, b: &[u8]) -> &mut Self {
        if let Some(host) = self.0.as_mut() {
            let _ = host.write_all(b);
        }
        self
    }

    /// Writes `n` in decimal.
    pub fn dec(&mut self, n: u64) -> &mut Self {
        let mut digits = [b'0'; 20];
        let mut at = digits.len();
        let mut n = n;
        for d in digits.iter_mut().rev() {
            *d = b'0' + (n % 10) as u8;
            at -= 1;
            n /= 10;
            if n == 0 {
                break;
            }
        }
        self.bytes(digits.get(at..).unwrap_or(&[]))
    }

    /// Writes `n` as `0x` and eight lower-case hex digits (`{:#010x}`).
    pub fn hex(&mut self, n: u32) -> &mut Self {
        let mut digits = [0u8; 10];
        digits[0] = b'0';
        digits[1] = b'x';
        for (i, d) in digits[2..].iter_mut().enumerate() {
            let nibble = (n >> (28 - 4 * i)) & 0xF;
            *d = b"0123456789abcdef"[nibble as usize];
        }
        self.bytes(&digits)
    }
}

/// The start-up line the QEMU tests wait for:
/// `firmware-example: bridge up on <board> (config <source>, flow <flow>)`,
/// the configuration's source and the flow control spelled as their
/// `Debug` forms.
// The STM32G0 boards print no banner: they run without a semihosting host.
#[cfg_attr(
    any(feature = "board-stm32g030", feature = "board-stm32g070"),
    allow(dead_code)
)]
pub fn banner(board: &str, source: Source, flow: FlowControl) {
    let mut out = Out::new();
    out.str("firmware-example: bridge up on ")
        .str(board)
        .str(" (config ");
    match source {
        Source::Default => out.str("Default"),
        Source::Block => out.str("Block"),
        Source::Blank => out.str("Blank"),
        Source::Invalid(e) => {
            out.str("Invalid(");
            match e {
                BlockError::TooShort => out.str("TooShort"),
                BlockError::Crc => out.str("Crc"),
                BlockError::Version => out.str("Version"),
                BlockError::Field(at) => out.str("Field(").dec(u64::from(at)).str(")"),
            };
            out.str(")")
        }
    };
    out.str(", flow ").str(match flow {
        FlowControl::None => "None",
        FlowControl::XonXoff => "XonXoff",
        FlowControl::RtsCts => "RtsCts",
    });
    out.str(")\n");
}

/// End the QEMU run with the given status.
pub fn exit(status: debug::ExitStatus) -> ! {
    debug::exit(status);
    // Only reached when no debugger or QEMU handles semihosting.
    loop {
        cortex_m::asm::wfi();
    }
}

/// Runs the bridge loop over the board's two lines until the host's quit
/// sequence, calling `idle` on every pass (feed the watchdog there), then
/// prints the end-of-run report ([`finish`]). With the `stall` feature the
/// loop never starts, so that the watchdog must reset the board.
#[cfg_attr(
    any(feature = "board-lm3s6965", feature = "board-stm32g070"),
    allow(dead_code)
)]
pub fn serve(
    bridge: &mut Bridge,
    up: &mut ThreadEnd<'static>,
    down: &mut ThreadEnd<'static>,
    idle: impl FnMut(),
) -> ! {
    if cfg!(feature = "stall") {
        Out::new().str("firmware-example: stalling the loop\n");
        #[allow(clippy::empty_loop)]
        loop {}
    }
    let result = firmware_example::bridge::run(bridge, up, down, now_ms, sleep_unless, idle);
    finish(result, up.pauses())
}

/// [`serve`] with the Modbus gateway on its own port beside the bridge
/// (see [`firmware_example::modbus::run`]).
#[cfg_attr(not(feature = "board-lm3s6965"), allow(dead_code))]
pub fn serve_gateway<M: firmware_example::serial::Port<Error = Infallible>>(
    bridge: &mut Bridge,
    gateway: &mut firmware_example::modbus::Gateway,
    up: &mut ThreadEnd<'static>,
    down: &mut ThreadEnd<'static>,
    modbus: &mut M,
    idle: impl FnMut(),
) -> ! {
    if cfg!(feature = "stall") {
        Out::new().str("firmware-example: stalling the loop\n");
        #[allow(clippy::empty_loop)]
        loop {}
    }
    let result = firmware_example::modbus::run(
        bridge,
        gateway,
        up,
        down,
        modbus,
        now_ms,
        now_us,
        sleep_unless,
        idle,
    );
    finish(result, up.pauses())
}

/// The end of a bridge run: print the counters (in `Stats`'s `Debug`
/// layout) and the stack peak, exit.
pub fn finish(result: Result<Stats, Error<Infallible, Infallible>>, up_pauses: u32) -> ! {
    let peak = stack_peak();
    let stats = match result {
        Ok(stats) => stats,
        Err(Error::Upstream(e) | Error::Downstream(e)) => match e {},
    };
    let mut out = Out::new();
    out.str("firmware-example: quit at ")
        .dec(u64::from(now_ms()))
        .str(" ms\nfirmware-example: Stats { ");
    for (i, (name, value)) in Stats::NAMES.iter().zip(stats.values()).enumerate() {
        if i > 0 {
            out.str(", ");
        }
        out.str(name).str(": ").dec(value);
    }
    out.str(" }\nfirmware-example: upstream pauses ")
        .dec(u64::from(up_pauses))
        .str("\nfirmware-example: stack peak ")
        .dec(peak as u64)
        .str(" bytes\n");
    exit(debug::EXIT_SUCCESS)
}

/// Prints where the panic happened and its message if that is a plain
/// string (`panicked at <file>:<line>:<column>:` then the message, as
/// `PanicInfo`'s `Display` would); a message with arguments is not
/// printed, as formatting it would link `core::fmt`.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    cortex_m::interrupt::disable();
    let mut out = Out::new();
    out.str("firmware-example: panicked");
    if let Some(at) = info.location() {
        out.str(" at ")
            .str(at.file())
            .str(":")
            .dec(u64::from(at.line()))
            .str(":")
            .dec(u64::from(at.column()))
            .str(":");
    }
    out.str("\n")
        .str(
            info.message()
                .as_str()
                .unwrap_or("(message with arguments)"),
        )
        .str("\n");
    exit(debug::EXIT_FAILURE)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    Out::new()
        .str("firmware-example: HardFault at pc=")
        .hex(frame.pc())
        .str(" lr=")
        .hex(frame.lr())
        .str("\n");
    exit(debug::EXIT_FAILURE)
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    cortex_m::interrupt::disable();
    let mut out = Out::new();
    out.str("firmware-example: unexpected interrupt or exception ");
    if irqn < 0 {
        out.str("-");
    }
    out.dec(u64::from(irqn.unsigned_abs())).str("\n");
    exit(debug::EXIT_FAILURE)
}

/// The memory routines the compiler calls (`memcpy`, `memset`, `memcmp`
/// and their `__aeabi_*` forms), in place of compiler_builtins' (whose
/// symbols are weak, so these win at link time). Theirs are unrolled for
/// speed and take about 1.9 KB of flash; these copy, fill and compare a
/// byte per step (a word per step where the caller guarantees 4-byte
/// alignment) in a few dozen bytes. The bridge moves at most a few KB per
/// frame, at serial-line rates. The stores are volatile so that the
/// optimiser cannot turn the loops back into calls to these functions, and
/// no routine calls another by its C name (the optimiser takes a call to
/// `memmove` for the built-in and lowers it to `__aeabi_memmove`, which
/// would then call itself).
pub mod mem {
    /// Copies `n` bytes forwards.
    ///
    /// # Safety
    /// As `memcpy`: `src` readable and `dst` writable for `n` bytes; if
    /// they overlap, `dst` is not above `src`.
    #[inline(always)]
    unsafe fn forward(dst: *mut u8, src: *const u8, n: usize) {
        for i in 0..n {
            // SAFETY: the caller's contract.
            unsafe { dst.add(i).write_volatile(src.add(i).read()) };
        }
    }

    /// Copies `n` bytes, a word per step while at least 4 remain.
    ///
    /// # Safety
    /// As `forward`, and `dst` and `src` 4-byte aligned.
    #[inline(always)]
    unsafe fn forward_words(dst: *mut u8, src: *const u8, n: usize) {
        let words = n / 4;
        for i in 0..words {
            // SAFETY: the caller's contract; both are 4-byte aligned.
            unsafe {
                (dst as *mut u32)
                    .add(i)
                    .write_volatile((src as *const u32).add(i).read())
            };
        }
        let done = words * 4;
        // SAFETY: the caller's contract, for the rest.
        unsafe { forward(dst.add(done), src.add(done), n - done) };
    }

    /// Fills `n` bytes with `c`.
    ///
    /// # Safety
    /// As `memset`: `dst` writable for `n` bytes.
    #[inline(always)]
    unsafe fn fill(dst: *mut u8, c: u8, n: usize) {
        for i in 0..n {
            // SAFETY: the caller's contract.
            unsafe { dst.add(i).write_volatile(c) };
        }
    }

    /// Copies `n` bytes; `dst` and `src` may overlap.
    ///
    /// # Safety
    /// As `memmove`: `src` readable and `dst` writable for `n` bytes.
    #[inline(always)]
    unsafe fn move_bytes(dst: *mut u8, src: *const u8, n: usize) {
        if (dst as usize) <= (src as usize) {
            // SAFETY: the caller's contract; `dst` is not above `src`.
            unsafe { forward(dst, src, n) };
        } else {
            for i in (0..n).rev() {
                // SAFETY: the caller's contract; backwards, as `dst` is
                // above `src`.
                unsafe { dst.add(i).write_volatile(src.add(i).read()) };
            }
        }
    }

    /// Compares `n` bytes: 0 if equal, else the difference of the first
    /// bytes that differ.
    ///
    /// # Safety
    /// As `memcmp`: `a` and `b` readable for `n` bytes.
    #[inline(always)]
    unsafe fn compare(a: *const u8, b: *const u8, n: usize) -> i32 {
        for i in 0..n {
            // SAFETY: the caller's contract.
            let (x, y) = unsafe { (a.add(i).read_volatile(), b.add(i).read_volatile()) };
            if x != y {
                return i32::from(x) - i32::from(y);
            }
        }
        0
    }

    /// `memcpy`.
    ///
    /// # Safety
    /// `src` readable and `dst` writable for `n` bytes, not overlapping.
    #[no_mangle]
    pub unsafe extern "C" fn memcpy(dst: *mut u8, src: *const u8, n: usize) -> *mut u8 {
        // SAFETY: the caller's contract.
        unsafe { forward(dst, src, n) };
        dst
    }

    /// `memmove`.
    ///
    /// # Safety
    /// `src` readable and `dst` writable for `n` bytes; they may overlap.
    #[no_mangle]
    pub unsafe extern "C" fn memmove(dst: *mut u8, src: *const u8, n: usize) -> *mut u8 {
        // SAFETY: the caller's contract.
        unsafe { move_bytes(dst, src, n) };
        dst
    }

    /// `memset`.
    ///
    /// # Safety
    /// `dst` writable for `n` bytes.
    #[no_mangle]
    pub unsafe extern "C" fn memset(dst: *mut u8, c: i32, n: usize) -> *mut u8 {
        // SAFETY: the caller's contract.
        unsafe { fill(dst, c as u8, n) };
        dst
    }

    /// `memcmp` (also `bcmp`, which only needs zero or not).
    ///
    /// # Safety
    /// `a` and `b` readable for `n` bytes.
    #[no_mangle]
    pub unsafe extern "C" fn memcmp(a: *const u8, b: *const u8, n: usize) -> i32 {
        // SAFETY: the caller's contract.
        unsafe { compare(a, b, n) }
    }

    /// `bcmp`.
    ///
    /// # Safety
    /// As [`memcmp`].
    #[no_mangle]
    pub unsafe extern "C" fn bcmp(a: *const u8, b: *const u8, n: usize) -> i32 {
        // SAFETY: the caller's contract.
        unsafe { compare(a, b, n) }
    }

    /// `__aeabi_memcpy`.
    ///
    /// # Safety
    /// As [`memcpy`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memcpy(dst: *mut u8, src: *const u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { forward(dst, src, n) };
    }

    /// `__aeabi_memcpy4`.
    ///
    /// # Safety
    /// As [`memcpy`], and both 4-byte aligned.
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memcpy4(dst: *mut u8, src: *const u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { forward_words(dst, src, n) };
    }

    /// `__aeabi_memcpy8`.
    ///
    /// # Safety
    /// As [`memcpy`], and both 8-byte aligned.
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memcpy8(dst: *mut u8, src: *const u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { forward_words(dst, src, n) };
    }

    /// `__aeabi_memmove` (and its aligned forms below).
    ///
    /// # Safety
    /// As [`memmove`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memmove(dst: *mut u8, src: *const u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { move_bytes(dst, src, n) };
    }

    /// `__aeabi_memmove4`.
    ///
    /// # Safety
    /// As [`memmove`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memmove4(dst: *mut u8, src: *const u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { move_bytes(dst, src, n) };
    }

    /// `__aeabi_memmove8`.
    ///
    /// # Safety
    /// As [`memmove`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memmove8(dst: *mut u8, src: *const u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { move_bytes(dst, src, n) };
    }

    /// `__aeabi_memset` (note the argument order: length, then value).
    ///
    /// # Safety
    /// As [`memset`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memset(dst: *mut u8, n: usize, c: i32) {
        // SAFETY: the caller's contract.
        unsafe { fill(dst, c as u8, n) };
    }

    /// `__aeabi_memset4`.
    ///
    /// # Safety
    /// As [`memset`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memset4(dst: *mut u8, n: usize, c: i32) {
        // SAFETY: the caller's contract.
        unsafe { fill(dst, c as u8, n) };
    }

    /// `__aeabi_memset8`.
    ///
    /// # Safety
    /// As [`memset`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memset8(dst: *mut u8, n: usize, c: i32) {
        // SAFETY: the caller's contract.
        unsafe { fill(dst, c as u8, n) };
    }

    /// `__aeabi_memclr`.
    ///
    /// # Safety
    /// As [`memset`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memclr(dst: *mut u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { fill(dst, 0, n) };
    }

    /// `__aeabi_memclr4`.
    ///
    /// # Safety
    /// As [`memset`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memclr4(dst: *mut u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { fill(dst, 0, n) };
    }

    /// `__aeabi_memclr8`.
    ///
    /// # Safety
    /// As [`memset`].
    #[no_mangle]
    pub unsafe extern "aapcs" fn __aeabi_memclr8(dst: *mut u8, n: usize) {
        // SAFETY: the caller's contract.
        unsafe { fill(dst, 0, n) };
    }
}
