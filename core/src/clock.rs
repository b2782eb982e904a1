//! Time for the engines: a wrapping millisecond tick supplied by the caller.
//!
//! The sans-IO engines take `now` as an argument; their blocking, `nb` and
//! async flavours read it from a [`Clock`] (or, with the `async` feature, an
//! `AsyncClock`) so that a
//! timeout always starts when the transmission really ended. Any closure
//! `FnMut() -> u32` is a clock:
//!
//! ```
//! use iai_protocol_b::clock::Clock;
//! let mut t = 0u32;
//! let mut clock = || { t += 1; t };
//! assert_eq!(clock.now_ms(), 1);
//! ```

/// A millisecond clock that wraps around after `u32::MAX`.
pub trait Clock {
    /// The current tick, ms, wrapping.
    fn now_ms(&mut self) -> u32;
    /// Called while waiting for bytes or time (e.g. `cortex_m::asm::wfi`).
    fn idle(&mut self) {}
}

impl<F: FnMut() -> u32> Clock for F {
    fn now_ms(&mut self) -> u32 {
        self()
    }
}

/// A millisecond clock that can sleep, for the async flavours.
#[cfg(feature = "async")]
pub trait AsyncClock {
    /// The current tick, ms, wrapping.
    fn now_ms(&mut self) -> u32;
    /// Sleeps about `ms` milliseconds (or until woken earlier).
    fn sleep_ms(&mut self, ms: u32) -> impl core::future::Future<Output = ()>;
}

/// Whether tick `now` is at or after tick `at` on the wrapping clock
/// (ticks less than 2^31 ms, about 24.8 days, apart).
///
/// ```
/// use iai_protocol_b::clock::reached;
/// assert!(reached(5, 5));
/// assert!(reached(3, u32::MAX - 1)); // after the wrap
/// assert!(!reached(u32::MAX - 1, 3));
/// ```
pub const fn reached(now: u32, at: u32) -> bool {
    now.wrapping_sub(at) < 0x8000_0000
}

/// The later of two ticks on the wrapping clock.
pub const fn later(a: u32, b: u32) -> u32 {
    if reached(a, b) {
        a
    } else {
        b
    }
}
