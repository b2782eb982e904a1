//! Link setup for the board binaries.
//!
//! * Memory maps live at the repository root. cortex-m-rt's `link.x`
//!   includes `memory.x`; the linker finds the root one first (it runs in
//!   the repository root), ahead of the `memory.x` that the `lm3s6965`
//!   device crate puts on the search path. The root `memory.x` includes
//!   `board-memory.x`, which this script copies from the board's
//!   `memory-<board>.x` into its output folder and puts on the search
//!   path. The root map defines `_bridge_config`, which the boards
//!   reference: a link with any other `memory.x` fails (undefined symbol),
//!   and `tools/size-report.sh` prints the symbol from each ELF. There must
//!   be no `memory.x` in this crate's folder.
//! * The device crates (`lm3s6965`, `mps2-an386`, and `stm32-metapac` for
//!   the STM32 boards, through embassy-stm32 or directly) provide
//!   `device.x` and the interrupt vector table for cortex-m-rt's `device`
//!   feature; without a board (`icount_bench`) an empty `device.x` is
//!   written here.
//! * `-Tlink.x` selects cortex-m-rt's linker script; `-Tdefmt.x` is added
//!   with the `defmt` feature only.
//! * Nothing is linked for host builds of the library.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let target = env::var("TARGET").unwrap_or_default();
    if !target.starts_with("thumb") {
        return;
    }
    let manifest_dir =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let repo_root = manifest_dir
        .parent()
        .expect("firmware-example lives inside the workspace")
        .to_path_buf();
    assert!(
        !manifest_dir.join("memory.x").exists(),
        "firmware-example/memory.x would shadow the shared ../memory.x; remove it"
    );
    let boards = [
        "LM3S6965",
        "MPS2_AN386",
        "STM32G030",
        "STM32G070",
        "B_L475E_IOT01A",
    ]
    .iter()
    .filter(|b| env::var_os(format!("CARGO_FEATURE_BOARD_{b}")).is_some())
    .count();
    assert!(
        boards <= 1,
        "select one board feature at a time (e.g. --no-default-features --features board-mps2-an386)"
    );

    let map = if env::var_os("CARGO_FEATURE_BOARD_STM32G030").is_some() {
        "memory-stm32g030.x"
    } else if env::var_os("CARGO_FEATURE_BOARD_STM32G070").is_some() {
        "memory-stm32g070.x"
    } else if env::var_os("CARGO_FEATURE_BOARD_B_L475E_IOT01A").is_some() {
        "memory-stm32l475.x"
    } else {
        "memory-qemu.x"
    };
    let map = repo_root.join(map);
    assert!(
        map.is_file(),
        "expected the memory map at {}",
        map.display()
    );
    assert!(
        repo_root.join("memory.x").is_file(),
        "expected the root memory.x"
    );
    let dir = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR")).join("map");
    fs::create_dir_all(&dir).expect("create the map folder");
    if env::var_os("CARGO_FEATURE_NO_PANIC_PROOF").is_some() {
        // The no-panic proof only links, never runs: its optimised image
        // (the bridge and the gateway, everything inlined) may be larger
        // than a board's flash, so it gets the 4 MiB of mps2-an386.
        fs::write(
            dir.join("board-memory.x"),
            "CONFIG_PAGE = 2K;\nMEMORY\n{\n  FLASH : ORIGIN = 0x00000000, LENGTH = 4096K - 2K\n  \
             RAM   : ORIGIN = 0x20000000, LENGTH = 64K\n}\n",
        )
        .expect("write the proof's memory map");
    } else {
        fs::copy(&map, dir.join("board-memory.x")).expect("copy the board's memory map");
    }
    if boards == 0 {
        // No device crate (the board-less `icount_bench`): cortex-m-rt's
        // `device` feature still includes a `device.x`; the program brings
        // its own (empty) interrupt table.
        fs::write(dir.join("device.x"), "/* no device interrupts */\n")
            .expect("write an empty device.x");
    }
    println!("cargo:rustc-link-search={}", dir.display());
    // Also on the search path, ahead of the device crates' folders, for a
    // linker that does not run in the repository root.
    println!("cargo:rustc-link-search={}", repo_root.display());
    println!("cargo:rerun-if-changed={}", map.display());
    println!(
        "cargo:rerun-if-changed={}",
        repo_root.join("memory.x").display()
    );
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-examples=-Tlink.x");
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
