//! The instruction-count bench as a program of its own: no UART, no board
//! module, only the core peripherals and semihosting, so one source runs on
//! every Cortex-M machine QEMU has (`lm3s6965evb`, `mps2-an386`,
//! `microbit`). See `firmware_example::bench` for what it counts and how;
//! `host-tests/src/bin/icount.rs` builds it, runs it under `-icount` and
//! prints the figures.
#![no_std]
#![no_main]

use core::fmt::Write as _;

use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hio};
use firmware_example::{bench, bench_line};

/// No device interrupt is enabled; cortex-m-rt (with its `device` feature,
/// as the firmware builds it) still wants the table.
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
static __INTERRUPTS: [usize; 1] = [0];

/// Print to the host through semihosting, ignoring failures.
fn host_print(args: core::fmt::Arguments<'_>) {
    if let Ok(mut stdout) = hio::hstdout() {
        let _ = stdout.write_fmt(args);
    }
}

/// End the QEMU run with the given status.
fn exit(status: debug::ExitStatus) -> ! {
    debug::exit(status);
    // Only reached when nothing handles semihosting.
    loop {
        cortex_m::asm::wfi();
    }
}

#[entry]
fn main() -> ! {
    let ok = bench::start(host_print)
        .is_some_and(|empty| bench::run(host_print, empty) && bench_line::run(host_print, empty));
    if ok {
        host_print(format_args!("bench ok\n"));
    }
    exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    })
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    host_print(format_args!("bench failed panic: {info}\n"));
    exit(debug::EXIT_FAILURE)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    host_print(format_args!(
        "bench failed HardFault at pc={:#010x}\n",
        frame.pc()
    ));
    exit(debug::EXIT_FAILURE)
}
