//! The boards: what runs the library on a chip. Compiled only for a
//! Cortex-M target with a `board-*` feature, so that the library stays
//! host-testable; it sits on top (nothing else in the crate imports it).
//!
//! - [`clock`]: the millisecond and microsecond clock on SysTick, WFI
//!   sleep;
//! - [`lines`]: a serial line's interrupt end handed to its UART's
//!   handler, the bridge and its lines built in their statics;
//! - [`run`]: the library's loops on the board's clock, the end-of-run
//!   report;
//! - [`report`]: text to the host through semihosting (the start-up banner
//!   the QEMU tests wait for), exit, the panic and fault handlers;
//! - [`config_page`]: the configuration page's two slots, the blocks read
//!   from the page in force, and where the board writes it, its store and
//!   editor;
//! - [`image`]: the stack's peak, a seed that differs at each boot;
//! - [`memory`]: small `memcpy`, `memset` and `memcmp`;
//! - one module per board family, with its UART driver:
//!   `lm3s6965` (on `pl011`), `mps2_an386`, `stm32g0` (on embassy-stm32),
//!   `stm32l4`; the STM32 families run [`embassy`] tasks.
//!
//! A board binary (`src/bin/<board>.rs`) says which UART is which, its
//! pins and clock, and calls its family's `run`.

pub mod clock;
pub mod config_page;
pub mod image;
pub mod lines;
pub mod memory;
pub mod report;
pub mod run;

#[cfg(feature = "embassy")]
pub mod embassy;
#[cfg(feature = "board-lm3s6965")]
pub mod lm3s6965;
#[cfg(feature = "board-mps2-an386")]
pub mod mps2_an386;
#[cfg(feature = "board-lm3s6965")]
pub mod pl011;
#[cfg(any(feature = "board-stm32g030", feature = "board-stm32g070"))]
pub mod stm32g0;
#[cfg(feature = "board-b-l475e-iot01a")]
pub mod stm32l4;
