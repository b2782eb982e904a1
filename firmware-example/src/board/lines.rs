//! A serial line's two ends in place: the interrupt end handed from `main`
//! to the UART's handler, the thread end kept by the loop; the bridge
//! built in its static beside them.

use core::cell::Cell;
use core::mem::MaybeUninit;

use cortex_m::interrupt::Mutex;

use super::image::boot_seed;
use crate::bridge::Bridge;
use crate::config::{Config, Source};
use crate::modbus::Gateway;
use crate::serial::{
    DownstreamRings, FlowControl, IsrEnd, ThreadEnd, UpstreamRings, Watermarks, DOWNSTREAM_MARKS,
    UPSTREAM_MARKS,
};

/// Where `main` hands a line's interrupt end to its handler.
pub type Handoff = Mutex<Cell<Option<IsrEnd<'static>>>>;

/// An empty [`Handoff`].
pub const fn handoff() -> Handoff {
    Mutex::new(Cell::new(None))
}

/// Runs `f` on a line's interrupt end where `handoff` keeps it, in a
/// critical section (the end is not copied into a static of the handler's
/// own, which saves its 36 bytes per line). Does nothing before the end
/// was handed over.
pub fn in_handoff(handoff: &Handoff, f: impl FnOnce(&mut IsrEnd<'static>)) {
    cortex_m::interrupt::free(|cs| {
        // SAFETY: the cell is only reached inside critical sections: here,
        // and in `hand_over`, which sets it before the interrupt is
        // unmasked; the reference does not outlive this one.
        if let Some(end) = unsafe { &mut *handoff.borrow(cs).as_ptr() } {
            f(end);
        }
    });
}

/// Splits `rings` and hands the interrupt end to `handoff`; the thread
/// end is returned. `pend` sets the UART's interrupt pending.
pub fn hand_over<const RX: usize, const TX: usize>(
    rings: &'static mut crate::serial::UartRings<RX, TX>,
    flow: FlowControl,
    marks: Watermarks,
    pend: &'static dyn Fn(),
    handoff: &Handoff,
) -> ThreadEnd<'static> {
    let (isr, thread) = rings.split(flow, marks, pend);
    cortex_m::interrupt::free(|cs| handoff.borrow(cs).set(Some(isr)));
    thread
}

/// Builds the bridge from `cfg` in `room`, its static. Not inlined: the
/// optimiser may build parts of it in the caller's stack frame on the way
/// in, and that frame must not stay below the rest of start-up.
#[inline(never)]
pub fn build_bridge(
    room: &'static mut MaybeUninit<Bridge>,
    cfg: Config,
    source: Source,
) -> &'static mut Bridge {
    room.write(Bridge::new(cfg, source, boot_seed()))
}

/// Builds the Modbus gateway from `cfg` in `room`, its static (not
/// inlined, as [`build_bridge`]).
#[inline(never)]
pub fn build_gateway(
    room: &'static mut MaybeUninit<Gateway>,
    cfg: &Config,
) -> &'static mut Gateway {
    room.write(Gateway::new(cfg.modbus, cfg.policy))
}

/// The statics a board gives [`setup`].
pub struct Statics {
    /// Room for the bridge.
    pub bridge: &'static mut MaybeUninit<Bridge>,
    /// The host line.
    pub up: &'static mut UpstreamRings,
    /// The controller line.
    pub down: &'static mut DownstreamRings,
    /// Pends the host UART's interrupt.
    pub pend_up: &'static dyn Fn(),
    /// Pends the controller UART's interrupt.
    pub pend_down: &'static dyn Fn(),
    /// Hand-off to the host UART's handler.
    pub up_end: &'static Handoff,
    /// Hand-off to the controller UART's handler.
    pub down_end: &'static Handoff,
}

/// Builds the bridge from `cfg` (with the configuration page's editor
/// where the board writes the page), splits both lines and hands their
/// interrupt ends over; the caller unmasks the interrupts afterwards.
/// Not inlined, so that its stack frame (the bridge is built on the way
/// into its static) is gone before the loop runs.
#[inline(never)]
pub fn setup(
    s: Statics,
    cfg: Config,
    source: Source,
) -> (&'static mut Bridge, ThreadEnd<'static>, ThreadEnd<'static>) {
    let bridge = build_bridge(s.bridge, cfg, source);
    #[cfg(any(feature = "board-lm3s6965", feature = "board-mps2-an386"))]
    super::config_page::attach_editor(bridge);
    let up = hand_over(s.up, cfg.flow, UPSTREAM_MARKS, s.pend_up, s.up_end);
    let down = hand_over(
        s.down,
        FlowControl::None,
        DOWNSTREAM_MARKS,
        s.pend_down,
        s.down_end,
    );
    (bridge, up, down)
}
