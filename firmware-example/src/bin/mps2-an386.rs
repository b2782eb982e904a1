//! The bridge on an Arm MPS2 with the AN386 image (QEMU `mps2-an386`,
//! Cortex-M4F): the host on UART0, the controller on UART1 (CMSDK APB
//! UARTs, no modem lines: XON/XOFF or no flow control). The CMSDK watchdog
//! resets the board if the loop stops feeding it for two periods. See
//! `firmware_example::board::mps2_an386`.
#![no_std]
#![no_main]

use firmware_example::board::mps2_an386::{self, Board, Uart};

const BOARD: Board = Board {
    name: "mps2-an386",
    // SYSCLK as QEMU models it (the APB clock too).
    core_clock_hz: 25_000_000,
    host: Uart::Uart0,
    controller: Uart::Uart1,
    watchdog_ms: 2_000,
};

#[cortex_m_rt::entry]
fn main() -> ! {
    mps2_an386::run(&BOARD)
}
