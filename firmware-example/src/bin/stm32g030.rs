//! The bridge on an STM32G030x8 (Cortex-M0+, 8 KiB RAM, 64 KiB flash; e.g.
//! STM32G030C8), on embassy-stm32: the small part the size goal aims at.
//! Its flash is the x8's, as the Cortex-M0 image does not fit the x6's
//! 32 KiB (see `memory-stm32g030.x`). Its upstream port speaks protocol B
//! only: the image that lets the configuration block choose Modbus RTU as
//! well does not fit this part (see `stm32g070.rs`). See
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
use firmware_example::config::UpstreamProtocol;

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
    // The host on USART2: PA3 RX, PA2 TX; RTS on PA1, CTS on PA0.
    let up = stm32g0::upstream_uart(&cfg, UpstreamProtocol::ProtocolB);
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
    stm32g0::run_bridge(Parts {
        config: (cfg, source),
        upstream,
        controller,
        modem,
        watchdog: IndependentWatchdog::new(p.IWDG, stm32g0::WATCHDOG_US),
    })
}
