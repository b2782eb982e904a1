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

/// Whether the hold `until` is over at `now`, for a hold that was set at
/// most `horizon` ms (less than 2^31) ahead of the tick it was set at.
///
/// Unlike [`reached`], a hold set long ago (more than 2^31 ms, about 24.8
/// days: an engine idle that long, or a fresh engine's hold of 0 seen
/// from a clock past 2^31) counts as over: it would otherwise seem to lie
/// up to 24.8 days ahead.
///
/// ```
/// use iai_protocol_b::clock::passed;
/// assert!(!passed(100, 3_100, 6_000));
/// assert!(passed(3_100, 3_100, 6_000));
/// assert!(passed(3_200, 3_100, 6_000));
/// // A fresh engine's hold of 0, on a clock 25 days after boot:
/// assert!(passed(0x8000_0001, 0, 6_000));
/// ```
pub const fn passed(now: u32, until: u32, horizon: u32) -> bool {
    let ahead = until.wrapping_sub(now);
    ahead == 0 || ahead > horizon
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hold_is_over_at_its_tick_and_after_whatever_the_wrap() {
        for set_at in [0u32, 1_000, 0x7FFF_FFFF, 0x8000_0000, u32::MAX - 10] {
            let until = set_at.wrapping_add(500);
            assert!(!passed(set_at, until, 500));
            assert!(!passed(until.wrapping_sub(1), until, 500));
            assert!(passed(until, until, 500));
            assert!(passed(until.wrapping_add(1), until, 500));
            // Long after: half the clock's range later, and just before
            // the clock comes round to the hold again.
            assert!(passed(until.wrapping_add(0x8000_0000), until, 500));
            assert!(passed(until.wrapping_sub(501), until, 500));
        }
    }
}
