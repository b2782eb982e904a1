//! The bridge on a TI Stellaris LM3S6965 (QEMU `lm3s6965evb`) with its host
//! side on Ethernet: protocol B over TCP on port 5020 (unless the network
//! block names another), Modbus TCP on port 502, the status web page on
//! port 80 (unless its block names another) and a Sparkplug B node when
//! its block names a broker, through the on-chip MAC and smoltcp; the
//! controller on UART1 (PD2 RX, PD3 TX). UART0 is not used. See `firmware_example::board::lm3s6965::ethernet`.
//!
//! Under QEMU: `-nic user,model=stellaris,hostfwd=tcp:127.0.0.1:HOSTPORT-:5020`
//! (and `hostfwd=tcp:127.0.0.1:MBPORT-:502` for Modbus TCP, `...:WEBPORT-:80`
//! for the web page; `restrict=on`
//! keeps the guest from reaching anything else).
#![no_std]
#![no_main]

use firmware_example::board::lm3s6965::ethernet::{self, Board};
use firmware_example::board::lm3s6965::Uart;

const BOARD: Board = Board {
    name: "lm3s6965evb-eth",
    // The 12 MHz crystal; the firmware keeps the reset clock.
    core_clock_hz: 12_000_000,
    controller: Uart::Uart1,
    watchdog_ms: 2_000,
};

#[cortex_m_rt::entry]
fn main() -> ! {
    ethernet::run(&BOARD)
}
