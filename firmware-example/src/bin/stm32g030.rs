//! The bridge on an STM32G030x8 (Cortex-M0+, 8 KiB RAM, 64 KiB flash; e.g.
//! STM32G030C8): the small part the size goal aims at. Its flash is the
//! x8's, as the Cortex-M0 image does not fit the x6's 32 KiB (see
//! `memory-stm32g030.x`). Its upstream port speaks protocol B only: the
//! image that lets the configuration block choose Modbus RTU as well does
//! not fit this part (see `stm32g070.rs`). Pins, clock and watchdog:
//! `firmware_example::board::stm32g0`.
//!
//! Built and linked for its size figures only: QEMU has no model of it,
//! and it has not run on silicon.
#![no_std]
#![no_main]

#[cortex_m_rt::entry]
fn main() -> ! {
    firmware_example::board::stm32g0::run_bridge()
}
