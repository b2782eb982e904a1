//! embassy on the STM32 boards: the executor ([`executor`]), embassy-time
//! on the board's SysTick ([`time`]), each serial line served by a task
//! over an `embedded-io-async` port ([`mod@line`]), and the bridge's loops
//! awaiting those tasks instead of sleeping ([`serve`]).
//!
//! Why SysTick: QEMU's STM32L475 models no timers, and one tick source for
//! every STM32 board keeps the images alike; the tick is 1 ms, the
//! bridge's own unit.

pub mod executor;
pub mod line;
pub mod serve;
pub mod time;
