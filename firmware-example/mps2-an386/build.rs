//! With the `rt` feature, puts `device.x` (one weak alias per interrupt) on
//! the linker search path for cortex-m-rt's `link.x`. No `memory.x`: the
//! firmware brings its own.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    if env::var_os("CARGO_FEATURE_RT").is_some() {
        let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
        fs::copy("device.x", out.join("device.x")).expect("copy device.x");
        println!("cargo:rustc-link-search={}", out.display());
    }
    println!("cargo:rerun-if-changed=device.x");
    println!("cargo:rerun-if-changed=build.rs");
}
