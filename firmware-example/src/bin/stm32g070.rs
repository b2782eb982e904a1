//! The two-UART gateway on an STM32G070 (Cortex-M0+, 128 KiB flash,
//! 36 KiB RAM; e.g. STM32G070KB), on embassy-stm32: one upstream port,
//! which speaks what the configuration block chooses (byte 19, bit 2):
//! protocol B through the bridge, or Modbus RTU through the PLC gateway
//! (8E1, 8O1 or 8N2 as the block's parity says), the bridge then keeping
//! the controller line with no protocol-B host.
//!
//! Why not the STM32G030x8 of the bridge alone: the image with both
//! engines takes more flash than its 64 KiB (and its two engines' state
//! more than its 8 KiB of RAM); `tools/size-report.sh` prints both figures
//! against it. The same pins as `stm32g030.rs`. See
//! `firmware_example::board::stm32g0`.
//!
//! Built and linked for its size figures only: QEMU has no model of it,
//! and it has not run on silicon.
#![no_std]
#![no_main]

use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
use embassy_stm32::usart::{BufferedInterruptHandler, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, peripherals};
use firmware_example::board::config_page;
use firmware_example::board::stm32g0::{self, GpioModem, Parts};

bind_interrupts!(struct Irqs {
    USART1 => BufferedInterruptHandler<peripherals::USART1>;
    USART2 => BufferedInterruptHandler<peripherals::USART2>;
});

#[cortex_m_rt::entry]
fn main() -> ! {
    let p = embassy_stm32::init(stm32g0::clocks());
    let (cfg, source) = config_page::load_config();
    let Some(b) = stm32g0::buffers() else {
        stm32g0::halt()
    };
    // The upstream port on USART2: PA3 RX, PA2 TX; RTS on PA1, CTS on PA0.
    let up = stm32g0::upstream_uart(&cfg, cfg.upstream);
    let upstream = BufferedUart::new(p.USART2, p.PA3, p.PA2, b.up_tx, b.up_rx, Irqs, up);
    let modem = GpioModem {
        rts: Output::new(p.PA1, Level::High, Speed::Low),
        cts: Input::new(p.PA0, Pull::None),
    };
    // The controller on USART1: PA10 RX, PA9 TX.
    let down = stm32g0::controller_uart(&cfg);
    let controller = BufferedUart::new(p.USART1, p.PA10, p.PA9, b.down_tx, b.down_rx, Irqs, down);
    let (Ok(upstream), Ok(controller)) = (upstream, controller) else {
        stm32g0::halt()
    };
    stm32g0::run_one_upstream(Parts {
        config: (cfg, source),
        upstream,
        controller,
        modem,
        watchdog: IndependentWatchdog::new(p.IWDG, stm32g0::WATCHDOG_US),
    })
}
