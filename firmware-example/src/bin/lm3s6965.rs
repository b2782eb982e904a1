//! The bridge and the Modbus RTU gateway on a TI Stellaris LM3S6965 (QEMU
//! `lm3s6965evb`, Cortex-M3): the host on UART0, the controller on UART1,
//! a PLC's Modbus RTU line on UART2, all PL011s with 16-byte FIFOs; RTS
//! and CTS of the host line on PB0 and PB1. The watchdog resets the MCU if
//! the loop stops feeding it for two periods. The configuration comes from
//! the page in force in the two slots at `_bridge_config` (kept in RAM
//! under QEMU, see `memory-qemu.x`), which the host can rewrite. See
//! `firmware_example::board::lm3s6965`.
#![no_std]
#![no_main]

use firmware_example::board::lm3s6965::{self, Board, Pin, Port, Uart};

const BOARD: Board = Board {
    name: "lm3s6965evb",
    // The 12 MHz crystal; the firmware keeps the reset clock.
    core_clock_hz: 12_000_000,
    // PA0 RX, PA1 TX.
    host: Uart::Uart0,
    // PD2 RX, PD3 TX.
    controller: Uart::Uart1,
    // PG0 RX, PG1 TX.
    modbus: Uart::Uart2,
    rts: Pin(Port::B, 0),
    cts: Pin(Port::B, 1),
    watchdog_ms: 2_000,
};

#[cortex_m_rt::entry]
fn main() -> ! {
    lm3s6965::run_gateway(&BOARD)
}
