//! Instructions per wire byte of the core's position-stream encoder and
//! decoder on a Cortex-M4F, counted under QEMU `mps2-an386` with
//! `-icount shift=5,sleep=off` (SysTick then advances with executed
//! instructions: instructions = ticks x 1.25; repeated runs agree).
//!
//! Builds `firmware-example` with the `bench` feature into its own target
//! directory (`target/icount`, so the bridge ELF other tests use stays
//! as it is), runs it and prints the firmware's figures. Exit code 0 only
//! if the firmware checked its round trip and exited cleanly.

use std::process::ExitCode;
use std::time::Duration;

use host_tests::qemu::{build_firmware_with, run_to_exit, target_dir, Board};

fn main() -> ExitCode {
    let board = Board::Mps2An386;
    let dir = target_dir().join("icount");
    let elf = match build_firmware_with(board, "release", &["bench"], Some(&dir)) {
        Ok(elf) => elf,
        Err(e) => {
            eprintln!("icount: building the bench firmware: {e}");
            return ExitCode::FAILURE;
        }
    };
    let args = ["-icount", "shift=5,sleep=off"];
    match run_to_exit(board, &elf, &args, Duration::from_secs(120)) {
        Ok(outcome) => {
            print!("{}", outcome.stdout);
            if outcome.success() {
                println!("icount: {board}, -icount shift=5,sleep=off (instructions, not cycles)");
                ExitCode::SUCCESS
            } else {
                eprintln!("icount: firmware failed: {outcome:#?}");
                ExitCode::FAILURE
            }
        }
        Err(e) => {
            eprintln!("icount: {e}");
            ExitCode::FAILURE
        }
    }
}
