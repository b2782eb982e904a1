//! Example firmware for QEMU: bridges a host (upstream, first serial port)
//! and a controller (downstream, second serial port) over interrupt-driven
//! UARTs.
//!
//! Layers, from the bottom:
//! * [`board`]: register-level UART drivers for the selected QEMU board, the
//!   SysTick millisecond clock ([`board::now_ms`]) and WFI sleep;
//! * [`uart`]: ring-buffered, interrupt-driven ports implementing the
//!   `embedded-io` traits;
//! * [`bridge`]: board-independent protocol bridging: 26DH position tables
//!   of any size are split into controller-sized, confirmed commands; every
//!   other command is checked and passed through (see the module docs for
//!   the behaviour and the bridge's `&` error codes `B01`..`B05`).
//!
//! All state lives in statics: the bridge (8,104 B) and the UART rings
//! (4 x 256 bytes); `tools/size-report.sh` prints the figures.
//!
//! The run ends through semihosting: with success when the upstream sends
//! ESC 'Q' '!' outside a transfer, with failure on a panic, a HardFault or
//! a port error. With the `bench` feature the firmware measures the core's
//! codec instead (see [`bench`]) and exits.

#![no_std]
#![no_main]
#![cfg_attr(feature = "bench", allow(dead_code, unused_imports, unreachable_code))]

mod log;

#[cfg(feature = "bench")]
mod bench;
mod board;
mod bridge;
mod uart;

#[cfg(feature = "defmt")]
use defmt_semihosting as _;

use core::fmt::Write as _;

use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hio};

/// Print to the host through semihosting, ignoring failures (this is also
/// used on the way down, where a second panic must not happen).
fn host_print(args: core::fmt::Arguments<'_>) {
    if let Ok(mut stdout) = hio::hstdout() {
        let _ = stdout.write_fmt(args);
    }
}

/// End the QEMU run with the given status.
fn exit(status: debug::ExitStatus) -> ! {
    debug::exit(status);
    // Only reached when no debugger or QEMU handles semihosting.
    loop {
        cortex_m::asm::wfi();
    }
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals already taken");
    };
    board::start_tick(core.SYST);

    #[cfg(feature = "bench")]
    {
        host_print(format_args!("firmware-example: bench on {}\n", board::NAME));
        let ok = bench::run(host_print);
        exit(if ok {
            debug::EXIT_SUCCESS
        } else {
            debug::EXIT_FAILURE
        })
    }

    let Some((mut upstream, mut downstream)) = uart::take() else {
        panic!("serial ports already taken");
    };
    let Some(state) = cortex_m::singleton!(BRIDGE: bridge::Bridge = bridge::Bridge::new()) else {
        panic!("bridge state already taken");
    };
    host_print(format_args!(
        "firmware-example: bridge up on {}\n",
        board::NAME
    ));
    log::info!("bridge up");

    match bridge::run(
        state,
        &mut upstream,
        &mut downstream,
        board::now_ms,
        board::sleep_unless,
    ) {
        Ok(stats) => {
            host_print(format_args!(
                "firmware-example: quit at {} ms\nfirmware-example: {:?}\n",
                board::now_ms(),
                stats
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
