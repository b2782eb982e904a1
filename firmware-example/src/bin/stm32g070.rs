//! The two-UART gateway on an STM32G070 (Cortex-M0+, 128 KiB flash,
//! 36 KiB RAM; e.g. STM32G070KB): one upstream port, which speaks what the
//! configuration block chooses (byte 19, bit 2): protocol B through the
//! bridge, or Modbus RTU through the PLC gateway, the bridge then keeping
//! the controller line with no protocol-B host.
//!
//! Why not the STM32G030x8 of the bridge alone: the image with both
//! engines takes more flash than its 64 KiB (and its two engines' state
//! more than its 8 KiB of RAM); `tools/size-report.sh` prints both figures
//! against it. Pins, clock and watchdog: `firmware_example::board::stm32g0`.
//!
//! Built and linked for its size figures only: QEMU has no model of it,
//! and it has not run on silicon.
#![no_std]
#![no_main]

#[cortex_m_rt::entry]
fn main() -> ! {
    firmware_example::board::stm32g0::run_one_upstream()
}
