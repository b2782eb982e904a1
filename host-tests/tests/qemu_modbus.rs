//! The Modbus RTU gateway end to end, with third-party Modbus masters:
//! the gateway (`tools/gateway.sh`'s binary) runs the lm3s6965 firmware
//! under QEMU with the simulated controller behind it, and its
//! `modbus-rtu 127.0.0.1:PORT` is worked by
//!
//! 1. **pymodbus** (RTU framer on a TCP client, `host-tests/plc/
//!    pymodbus_plc.py`): servo on, home, wait for HEND, a numeric move to
//!    25.500 mm, wait for PEND, read PNOW; then 500 positions of 8 axes
//!    written through the table window (2200H) and read back through it
//!    (21F0H, 2200H), equal;
//! 2. **mbpoll** (RTU through a pty that socat bridges to the TCP port,
//!    one process per request, `plc_gateway::mbpoll`): servo on (off
//!    first if the PLC before left it on), home, wait for HEND, a numeric
//!    move to 12.000 mm, wait for PEND, read PNOW; then 500 other
//!    positions of 8 axes written through the window, a whole window per
//!    call, each write waited for through CMDST, and read back through it,
//!    equal.
//!
//! After each, PNOW is compared with the simulator's 212H, asked by the
//! real `iai` tool on the protocol-B port, and `iai table read --all`
//! gives exactly the 500 positions that PLC wrote. Then
//!
//! 3. **raw RTU frames** on the relay's socket (`plc_gateway::standard`):
//!    functions 15 and 16 whose byte count is not the quantity's (03),
//!    Read Device Identification with the simulator's 201H version,
//!    unsupported functions (01), unit 255 unanswered;
//! 4. the README's **worked example** ("Worked example: Modbus RTU"), run
//!    by bash as written, with mbpoll and socat.
//!
//! pymodbus comes from the venv `tools/setup.sh` makes (`.venv`), mbpoll
//! and socat from Debian packages it installs. A client that is absent is
//! skipped with its reason printed; the test fails if both are.

mod gateway_proc;
mod plc_gateway;

use std::path::PathBuf;

use gateway_proc::{Gateway, SERIAL};
use host_tests::qemu::{build_firmware, Board};
use host_tests::table::table;
use iai_protocol_b::position::PositionRecord;
use plc_gateway::mbpoll::{plc_sequence, Link};
use plc_gateway::standard::{standard_cases, worked_example, Raw};
use plc_gateway::{on_path, pymodbus_python, pymodbus_sequence};

/// Positions each PLC writes and reads back.
const POSITIONS: u32 = 500;

#[test]
fn pymodbus_and_mbpoll_run_a_plcs_sequence_through_the_gateway() {
    let python = pymodbus_python();
    let mbpoll = if !on_path("mbpoll") {
        Err("mbpoll is not installed".to_owned())
    } else if !on_path("socat") {
        Err("socat is not installed".to_owned())
    } else {
        Ok(())
    };
    if let Err(why) = &python {
        println!("SKIPPED the pymodbus part: {why} (tools/setup.sh installs it)");
    }
    if let Err(why) = &mbpoll {
        println!("SKIPPED the mbpoll part: {why} (tools/setup.sh installs it)");
    }
    assert!(
        python.is_ok() || mbpoll.is_ok(),
        "neither pymodbus nor mbpoll: run tools/setup.sh"
    );

    let elf = build_firmware(Board::Lm3s6965).expect("build lm3s6965 firmware");
    let iai = host_tests::qemu::iai_binary().expect("the iai binary");
    let mut gw = Gateway::start(&elf, &[] as &[&str], &SERIAL);
    let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
    let records: Vec<PositionRecord> = table(POSITIONS, 8, 2026).collect();

    if let Ok(py) = &python {
        pymodbus_sequence(&mut gw, py, &iai, &records, false);
    }

    if mbpoll.is_ok() {
        // Another table than pymodbus's: the window and iai must show
        // mbpoll's writes, not what was there.
        let other: Vec<PositionRecord> = table(POSITIONS, 8, 7).collect();
        assert!(other.iter().zip(&records).all(|(a, b)| a != b));
        let link = Link::rtu(&gw.modbus, &tmp);
        plc_sequence(&mut gw, &iai, link, &other);
    }

    // The standard's cases, raw frames as a serial master sends them.
    let revision = standard_cases(&mut Raw::rtu(&gw.modbus));
    println!("raw RTU frames: FC 15/16 byte counts 03, unsupported 01, 43/14 {revision:?}");

    if mbpoll.is_ok() {
        let pty = tmp.join(format!("worked-{}.pty", std::process::id()));
        let pty = pty.to_str().expect("a path");
        let addr = gw.modbus.clone();
        worked_example(
            "### Worked example: Modbus RTU",
            &[("127.0.0.1:PORT", &addr), ("/tmp/plc", pty)],
            &tmp,
        );
    }

    let status = gw.stop();
    let log = gw.log();
    assert!(status.success(), "{status}\n{log}");
    println!("{log}");
}
