//! embassy-time's driver on the board's 1 kHz SysTick
//! ([`crate::board::clock`]): `now` is the millisecond count (the
//! `tick-hz-1_000` feature), and each tick wakes the timers that are due
//! from embassy's timer queue. A timer fires on the first tick at or after
//! its time.

use core::cell::RefCell;
use core::task::Waker;

use cortex_m::interrupt::Mutex;
use embassy_time_queue_utils::Queue;

use crate::board::clock::now_ms_64;

/// The timer queue and its next expiry.
struct SysTickDriver {
    queue: Mutex<RefCell<(Queue, u64)>>,
}

impl embassy_time_driver::Driver for SysTickDriver {
    fn now(&self) -> u64 {
        now_ms_64()
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        cortex_m::interrupt::free(|cs| {
            let mut q = self.queue.borrow(cs).borrow_mut();
            if q.0.schedule_wake(at, waker) {
                q.1 = q.1.min(at);
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    queue: Mutex::new(RefCell::new((Queue::new(), u64::MAX))),
});

/// Called by the SysTick handler at every tick: wakes the timers that are
/// due.
pub fn on_tick() {
    let now = now_ms_64();
    cortex_m::interrupt::free(|cs| {
        let mut q = DRIVER.queue.borrow(cs).borrow_mut();
        if now >= q.1 {
            q.1 = q.0.next_expiration(now);
        }
    });
}

/// The board's clock as the core's async engines use it
/// ([`iai_protocol_b::clock::AsyncClock`]): the millisecond tick, and
/// embassy-time's timers to sleep.
pub struct Clock;

impl iai_protocol_b::clock::AsyncClock for Clock {
    fn now_ms(&mut self) -> u32 {
        crate::board::clock::now_ms()
    }

    async fn sleep_ms(&mut self, ms: u32) {
        embassy_time::Timer::after_millis(u64::from(ms)).await;
    }
}
