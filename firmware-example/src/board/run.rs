//! The loop a board runs once its lines are up: the library's own loops
//! ([`crate::bridge::run`], [`crate::modbus::run`]) on the board's clock
//! and sleep (the STM32 boards await instead: `super::embassy::serve`),
//! then the end-of-run report. With the `stall` feature the loop never
//! starts, so that the watchdog must reset the board.

use core::convert::Infallible;

use cortex_m_semihosting::debug;

use super::clock::{now_ms, now_us, sleep_unless};
use super::image::stack_peak;
use super::report::{exit, Out};
use crate::bridge::{Bridge, Error};
use crate::modbus::Gateway;
use crate::serial::{Port, ThreadEnd};
use crate::status::Stats;

/// With the `stall` feature: says so and never returns (the watchdog is
/// never fed again). Without it: returns at once.
pub fn stall_if_asked() {
    if cfg!(feature = "stall") {
        Out::new().str("firmware-example: stalling the loop\n");
        #[allow(clippy::empty_loop)]
        loop {}
    }
}

/// Runs the bridge over the board's two lines until the host's quit
/// sequence, calling `idle` on every pass (feed the watchdog there), then
/// reports ([`finish`]).
pub fn serve(
    bridge: &mut Bridge,
    up: &mut ThreadEnd<'static>,
    down: &mut ThreadEnd<'static>,
    idle: impl FnMut(),
) -> ! {
    stall_if_asked();
    let result = crate::bridge::run(bridge, up, down, now_ms, sleep_unless, idle);
    finish(result, up.pauses())
}

/// [`serve`] with the Modbus gateway on its own port beside the bridge
/// (see [`crate::modbus::run`]).
pub fn serve_gateway<M: Port<Error = Infallible>>(
    bridge: &mut Bridge,
    gateway: &mut Gateway,
    up: &mut ThreadEnd<'static>,
    down: &mut ThreadEnd<'static>,
    modbus: &mut M,
    idle: impl FnMut(),
) -> ! {
    stall_if_asked();
    let result = crate::modbus::run(
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

/// The end of a bridge run: prints the counters (in `Stats`'s `Debug`
/// layout), the host line's pauses and the stack peak, and exits.
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
