//! The bridge on an STM32G030x8 (Cortex-M0+, 8 KiB RAM, 64 KiB flash; e.g.
//! STM32G030C8): the small part the size goal aims at. Its RAM is the 8 KiB
//! the goal names; its flash is the x8's, as the Cortex-M0 image does not
//! fit the x6's 32 KiB (see `memory-stm32g030.x`). Its upstream port speaks
//! protocol B only: the image that lets the configuration block choose
//! Modbus RTU as well does not fit this part (see `stm32g070.rs`).
//!
//! Built and linked for its size figures only: QEMU has no model of it, and
//! it has not run on silicon. Pins, clock and watchdog: `src/stm32g0.rs`.
#![no_std]
#![no_main]
// The PAC's `bits` writers are safe on some registers and not on others.
#![allow(unused_unsafe)]

#[path = "../runtime.rs"]
mod runtime;
#[path = "../stm32g0.rs"]
mod stm32g0_board;

use cortex_m_rt::entry;
use firmware_example::serial::FlowControl;
use stm32g0_board as board;

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals already taken");
    };
    runtime::start_tick(core.SYST, board::CORE_CLOCK_HZ);
    let (cfg, source) = runtime::load_config();
    let rts_cts = cfg.flow == FlowControl::RtsCts;
    board::init_pins(rts_cts);
    board::init_usart(
        board::up_regs(),
        cfg.upstream_baud,
        board::Format::Plain,
        rts_cts,
    );
    board::init_usart(
        board::down_regs(),
        cfg.downstream_baud,
        board::Format::Plain,
        false,
    );

    // SAFETY: `main` runs once; these are the only references to these
    // statics, and the interrupts that use the ends are unmasked only
    // after `setup` handed them over.
    let statics = unsafe { board::statics() };
    let (bridge, mut up, mut down) = runtime::setup(statics, cfg, source);
    board::unmask_usarts();
    board::start_watchdog();
    runtime::serve(bridge, &mut up, &mut down, board::feed_watchdog)
}
