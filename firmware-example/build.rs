//! Link setup for the board binaries.
//!
//! * Memory maps live at the repository root: `memory.x` for the QEMU
//!   boards, `memory-stm32g030.x` for the STM32G030. cortex-m-rt's `link.x`
//!   includes `memory.x` from the linker search path. The `lm3s6965` device
//!   crate puts a `memory.x` of its own on that path too, so which one the
//!   linker takes would depend on the order of search paths. The root map
//!   therefore defines `_bridge_config` (the address of the configuration
//!   block), which the boards reference: linking with any other map fails
//!   with an undefined symbol, and `tools/size-report.sh` prints the symbol
//!   from each ELF. There must be no `memory.x` in this crate's folder.
//! * The device crates (`lm3s6965`, `mps2-an386`, `stm32g0`) provide
//!   `device.x` and the interrupt vector table for cortex-m-rt's `device`
//!   feature.
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
    let boards = ["LM3S6965", "MPS2_AN386", "STM32G030"]
        .iter()
        .filter(|b| env::var_os(format!("CARGO_FEATURE_BOARD_{b}")).is_some())
        .count();
    assert!(
        boards <= 1,
        "select one board feature at a time (e.g. --no-default-features --features board-mps2-an386)"
    );

    let map = if env::var_os("CARGO_FEATURE_BOARD_STM32G030").is_some() {
        // link.x includes "memory.x": give the G0 map that name in a folder
        // of our own.
        let src = repo_root.join("memory-stm32g030.x");
        let dir = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR")).join("stm32g030");
        fs::create_dir_all(&dir).expect("create map folder");
        fs::copy(&src, dir.join("memory.x")).expect("copy memory-stm32g030.x");
        println!("cargo:rustc-link-search={}", dir.display());
        src
    } else {
        println!("cargo:rustc-link-search={}", repo_root.display());
        repo_root.join("memory.x")
    };
    assert!(
        map.is_file(),
        "expected the memory map at {}",
        map.display()
    );
    println!("cargo:rerun-if-changed={}", map.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
