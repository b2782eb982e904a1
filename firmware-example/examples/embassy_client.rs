//! The core inside an embassy application, as a firmware engineer would
//! write it: one task asks a controller for its axis status with
//! `Client::call_async`, then writes a position table with
//! `Transfer::run_async` (every record read back and compared), both over
//! an `embedded-io-async` UART, with no blocking loop; it prints what it
//! got through semihosting (a failure with `core::fmt`: an example, not
//! sized) and ends the QEMU run.
//!
//! Runs on QEMU 10's `b-l475e-iot01a`: the controller on UART4 (`-serial`
//! 3), a simulated one in the test (`host-tests/tests/qemu_stm32.rs`),
//! which checks the printed lines and that the controller holds exactly
//! [`table`]'s records. Build: `cargo build --release --example
//! embassy_client --no-default-features --features board-b-l475e-iot01a
//! --target thumbv7em-none-eabihf`.
#![no_std]
#![no_main]

use cortex_m_semihosting::{debug, hprintln};
use firmware_example::board::clock::start_tick;
use firmware_example::board::embassy::executor;
use firmware_example::board::embassy::time::Clock;
use firmware_example::board::image::boot_seed;
use firmware_example::board::report::{exit, Out};
use firmware_example::board::stm32l4::usart::{Format, Port};
use firmware_example::board::stm32l4::{Usart, CORE_CLOCK_HZ};
use iai_protocol_b::axis::{AxisPattern, PerAxis};
use iai_protocol_b::client::Client;
use iai_protocol_b::frame::Station;
use iai_protocol_b::line::{Line, LineConfig};
use iai_protocol_b::message::AxisStatusQuery;
use iai_protocol_b::position::PositionRecord;
use iai_protocol_b::profile::Profile;
use iai_protocol_b::transfer::{Guarantee, Transfer, TransferConfig};

/// The controller's station.
const STATION: Station = Station(0x99);
/// Records the table holds.
const RECORDS: u16 = 100;
/// Longest sleep while waiting for a reply, ms: the UART's 256-byte
/// receive buffer holds 22 ms of a 115,200-baud line.
const POLL_MS: u32 = 5;

/// Record `n` of the table (1..=100): two axes at `n` mm and `-n / 2` mm,
/// 0.30 G, 100 mm/s.
fn record(n: u16) -> PositionRecord {
    let mut positions = PerAxis::new();
    let _ = positions.push(i32::from(n) * 1_000);
    let _ = positions.push(-i32::from(n) * 500);
    PositionRecord {
        number: n,
        axes: AxisPattern::first(2),
        acceleration: 30,
        deceleration: 30,
        speed: 100,
        positions,
        extended: 0,
    }
}

/// The table the example writes.
fn table() -> impl Iterator<Item = PositionRecord> {
    (1..=RECORDS).map(record)
}

#[embassy_executor::task]
async fn controller(mut uart: Port) -> ! {
    let mut line = Line::new(LineConfig::new(STATION), boot_seed());
    let mut clock = Clock;
    let mut out = Out::new();

    let mut client: Client = Client::new();
    let query = AxisStatusQuery {
        query_axis_pattern: AxisPattern::first(2),
    };
    match client
        .call_async(&mut line, &mut uart, &mut clock, POLL_MS, &query)
        .await
    {
        Ok(reply) => {
            out.str("embassy client: 212H axes ")
                .dec(reply.axes.len() as u64);
            for axis in reply.axes.iter() {
                out.str(" position ")
                    .str(if axis.current_position < 0 { "-" } else { "" })
                    .dec(u64::from(axis.current_position.unsigned_abs()));
            }
            out.str("\n");
        }
        Err(e) => {
            hprintln!("embassy client: 212H failed: {:?}", e);
            exit(debug::EXIT_FAILURE)
        }
    }

    let mut transfer: Transfer<_> = Transfer::new(TransferConfig::new(Profile::TTA), table());
    match transfer
        .run_async(&mut line, &mut uart, &mut clock, POLL_MS)
        .await
    {
        Ok(guarantee) => {
            let s = transfer.stats();
            out.str("embassy client: table ")
                .str(match guarantee {
                    Guarantee::Verified => "verified",
                    Guarantee::FaultsVerified => "faults verified",
                    Guarantee::Unverified => "unverified",
                })
                .str(", records ")
                .dec(u64::from(s.records_confirmed))
                .str(", frames ")
                .dec(u64::from(s.frames_confirmed))
                .str(", retries ")
                .dec(u64::from(s.retries))
                .str("\n");
            exit(debug::EXIT_SUCCESS)
        }
        Err(e) => {
            hprintln!(
                "embassy client: table failed: {:?} {:?}",
                e,
                transfer.stats()
            );
            exit(debug::EXIT_FAILURE)
        }
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    // SAFETY: called once, before anything else uses the core peripherals.
    let core = unsafe { cortex_m::Peripherals::steal() };
    start_tick(core.SYST, CORE_CLOCK_HZ);
    let uart = Usart::Uart4.init(115_200, Format::Plain);
    Out::new().str("embassy client: up\n");
    executor::run(|spawner| {
        if let Ok(t) = controller(uart) {
            spawner.spawn(t);
        }
    })
}
