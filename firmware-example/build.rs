//! Link setup for the firmware example.
//!
//! * The memory map lives in the repository root (`../memory.x`), shared by
//!   every board; put that folder on the linker search path. There must be
//!   no `memory.x` in this crate's folder, or the linker would pick it first.
//! * cortex-m-rt's `device` feature makes `link.x` `INCLUDE device.x`. Each
//!   board module defines its own `__INTERRUPTS` table in Rust, so the
//!   generated `device.x` only carries a comment.
//! * `-Tlink.x` selects cortex-m-rt's linker script; `-Tdefmt.x` is added
//!   with the `defmt` feature only.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest_dir =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR"));
    let repo_root = manifest_dir
        .parent()
        .expect("firmware-example lives inside the workspace")
        .to_path_buf();
    let memory_x = repo_root.join("memory.x");
    assert!(
        memory_x.is_file(),
        "expected the shared memory map at {}",
        memory_x.display()
    );
    assert!(
        !manifest_dir.join("memory.x").exists(),
        "firmware-example/memory.x would shadow the shared ../memory.x; remove it"
    );

    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    fs::write(
        out_dir.join("device.x"),
        "/* Interrupt vectors come from the board module's __INTERRUPTS table. */\n",
    )
    .expect("write device.x");

    println!("cargo:rustc-link-search={}", out_dir.display());
    println!("cargo:rustc-link-search={}", repo_root.display());
    println!("cargo:rustc-link-arg=-Tlink.x");
    // defmt's linker script, only when the `defmt` feature is on.
    if env::var_os("CARGO_FEATURE_DEFMT").is_some() {
        println!("cargo:rustc-link-arg=-Tdefmt.x");
    }
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
}
