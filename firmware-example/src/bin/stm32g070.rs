//! The two-UART gateway on an STM32G070 (Cortex-M0+, 128 KiB flash,
//! 36 KiB RAM; e.g. STM32G070KB): one upstream port, which speaks what
//! the configuration block chooses (byte 19, bit 2): protocol B through
//! the bridge, or Modbus RTU through the PLC gateway, the bridge then
//! keeping the controller line with no protocol-B host
//! ([`firmware_example::modbus::run_one_upstream`]).
//!
//! Why not the STM32G030x8 of the bridge alone: the image with both
//! engines takes more flash than its 64 KiB (and its two engines' state
//! more than its 8 KiB of RAM); `tools/size-report.sh` prints both
//! figures against it. The G070 is the G0 line's part with the same
//! USARTs and pins (`src/stm32g0.rs`) and the room.
//!
//! On the Modbus line the USART frames 8E1, 8O1 or 8N2 as the block's
//! parity says. Built and linked for its size figures only: QEMU has no
//! model of it, and it has not run on silicon.
#![no_std]
#![no_main]
// The PAC's `bits` writers are safe on some registers and not on others.
#![allow(unused_unsafe)]

#[path = "../runtime.rs"]
mod runtime;
#[path = "../stm32g0.rs"]
mod stm32g0_board;

use core::convert::Infallible;
use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;

use cortex_m_rt::entry;
use firmware_example::bridge::Error;
use firmware_example::config::UpstreamProtocol;
use firmware_example::modbus::{self, Gateway};
use firmware_example::serial::FlowControl;
use stm32g0_board as board;

/// The gateway's state, written once at start.
static mut GATEWAY: MaybeUninit<Gateway> = MaybeUninit::uninit();

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals already taken");
    };
    runtime::start_tick(core.SYST, board::CORE_CLOCK_HZ);
    let (mut cfg, source) = runtime::load_config();
    let speaks = cfg.upstream;
    let modbus = speaks == UpstreamProtocol::ModbusRtu;
    if modbus {
        // No flow control on a Modbus line (its bytes are binary).
        cfg.flow = FlowControl::None;
        board::stamp_upstream();
    }
    let rts_cts = cfg.flow == FlowControl::RtsCts;
    board::init_pins(rts_cts);
    let (baud, format) = if modbus {
        (cfg.modbus.baud, board::Format::Modbus(cfg.modbus.parity))
    } else {
        (cfg.upstream_baud, board::Format::Plain)
    };
    board::init_usart(board::up_regs(), baud, format, rts_cts);
    board::init_usart(
        board::down_regs(),
        cfg.downstream_baud,
        board::Format::Plain,
        false,
    );

    // SAFETY: `main` runs once; these are the only references to these
    // statics, and the interrupts that use the ends are unmasked only
    // after `setup` handed them over.
    let (statics, gateway) = unsafe {
        (
            board::statics(),
            (*addr_of_mut!(GATEWAY)).write(Gateway::new(cfg.modbus, cfg.policy)),
        )
    };
    // With no flow control the line's marks pause nothing.
    let (bridge, mut up, mut down) = runtime::setup(statics, cfg, source);
    board::unmask_usarts();
    board::start_watchdog();
    let result = modbus::run_one_upstream(
        speaks,
        bridge,
        gateway,
        &mut up,
        &mut down,
        runtime::now_ms,
        runtime::now_us,
        runtime::sleep_unless,
        board::feed_watchdog,
    );
    let result: Result<_, Error<Infallible, Infallible>> = result;
    runtime::finish(result, up.pauses())
}
