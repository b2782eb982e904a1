//! The bridge and the Modbus RTU gateway on the B-L475E-IOT01A (STM32L475,
//! Cortex-M4F), as QEMU 10's `b-l475e-iot01a` runs it: the same embassy
//! tasks as the STM32G0 boards, on USARTs driven by hand (see
//! `firmware_example::board::stm32l4` for why not embassy-stm32 there).
//! The configuration comes from the block at `_bridge_config` (last flash
//! page, see `memory-stm32l475.x`).
//!
//! Under QEMU the serial ports are `-serial` 0 (USART1), 1 (USART2), 2
//! (USART3, unused) and 3 (UART4).
#![no_std]
#![no_main]

use firmware_example::board::stm32l4::{self, Board, Usart};

const BOARD: Board = Board {
    name: "b-l475e-iot01a",
    // The ST-LINK's virtual COM port (PB6 TX, PB7 RX).
    host: Usart::Usart1,
    // The Arduino header's D1 and D0 (PA0 TX, PA1 RX).
    controller: Usart::Uart4,
    // The PMOD connector (PD5 TX, PD6 RX).
    modbus: Usart::Usart2,
    watchdog_ms: 2_000,
};

#[cortex_m_rt::entry]
fn main() -> ! {
    stm32l4::run(&BOARD)
}
