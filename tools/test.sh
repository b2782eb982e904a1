#!/usr/bin/env bash
# All the checks, as CI runs them: set-up, formatting, lints, no_std builds
# for three Cortex-M targets, the bridge firmware for its boards, docs,
# doctests, size figures (which build the firmware the QEMU tests run), then
# every test (unit, recorded frames, host model, end-to-end, QEMU).
# Ends with the test runner's summary.
set -euo pipefail
cd "$(dirname "$0")/.."
./tools/setup.sh

step() { printf '\n==> %s\n' "$*"; }

step "formatting"
cargo fmt --all --check

step "clippy (core, host tests, iai, simulator, test support) -D warnings"
cargo clippy -p iai-protocol-b -p host-tests -p iai-cli -p iai-simulator -p test-support --all-targets -- -D warnings
cargo clippy -p iai-protocol-b --features defmt -- -D warnings

step "core builds for thumbv6m / thumbv7m / thumbv7em (no std, no alloc)"
for t in thumbv6m-none-eabi thumbv7m-none-eabi thumbv7em-none-eabihf; do
  cargo build -q -p iai-protocol-b --target "$t"
done
cargo build -q -p iai-protocol-b --target thumbv7em-none-eabihf --features defmt

step "minimum supported Rust version of the core (1.87, declared in core/Cargo.toml)"
rustup toolchain install 1.87 --profile minimal --target thumbv7em-none-eabihf
cargo +1.87 build -q -p iai-protocol-b --all-features
cargo +1.87 build -q -p iai-protocol-b --target thumbv7em-none-eabihf
echo "ok: core builds with Rust 1.87"

step "firmware: the bridge library (host), five boards, the Ethernet board, the embassy example, defmt feature, the icount bench, clippy -D warnings"
cargo clippy -q -p firmware-example --no-default-features --lib --tests -- -D warnings
cargo clippy -q -p firmware-example --no-default-features --features ethernet --lib --tests -- -D warnings
cargo clippy -q -p firmware-example --target thumbv7m-none-eabi \
  --no-default-features --features board-lm3s6965,ethernet --bin lm3s6965-eth -- -D warnings
cargo clippy -q -p firmware-example --target thumbv7m-none-eabi -- -D warnings
cargo clippy -q -p firmware-example --target thumbv7em-none-eabihf \
  --no-default-features --features board-mps2-an386 -- -D warnings
cargo clippy -q -p firmware-example --target thumbv6m-none-eabi \
  --no-default-features --features board-stm32g030 -- -D warnings
cargo clippy -q -p firmware-example --target thumbv6m-none-eabi \
  --no-default-features --features board-stm32g070 -- -D warnings
cargo clippy -q -p firmware-example --target thumbv7em-none-eabihf \
  --no-default-features --features board-b-l475e-iot01a --bins --examples -- -D warnings
cargo clippy -q -p mps2-an386 --target thumbv7em-none-eabihf --features rt -- -D warnings
cargo clippy -q -p firmware-example --target thumbv7m-none-eabi --features defmt -- -D warnings
cargo clippy -q -p firmware-example --target thumbv7em-none-eabihf \
  --no-default-features --features icount-bench --bin icount_bench -- -D warnings
echo "debug build (what a new user types first):"
cargo build -q -p firmware-example --target thumbv7m-none-eabi
echo "ok: cargo build -p firmware-example --target thumbv7m-none-eabi"

step "no-panic proof: the decode paths and the bridge library link without a panic handler symbol"
for t in thumbv7m-none-eabi thumbv7em-none-eabihf; do
  cargo build -q -p firmware-example --release --features no-panic-proof --bin no_panic_proof --target "$t"
done
cargo build -q -p firmware-example --release --features no-panic-proof,ethernet --bin no_panic_proof \
  --target thumbv7m-none-eabi
echo "ok: no panic path survives in the decoders, the bridge or the Ethernet driver (see firmware-example/src/bin/no_panic_proof.rs)"

step "panic audit: the Ethernet build with smoltcp's interface and sockets, every panic call by where it comes from"
cargo rustc -q -p firmware-example --release --no-default-features --features no-panic-audit \
  --bin no_panic_proof --target thumbv7m-none-eabi -- -C llvm-args=-enable-tail-merge=false
python3 tools/panic-audit.py target/thumbv7m-none-eabi/release/no_panic_proof \
  firmware-example/no-panic-smoltcp.txt

step "iai builds for Windows (x86_64-pc-windows-gnu, mingw-w64)"
cargo build -q -p iai-cli --target x86_64-pc-windows-gnu
echo "ok: iai.exe builds"

step "docs (no warnings) and doctests"
RUSTDOCFLAGS="-D warnings" cargo doc -q -p iai-protocol-b --no-deps
RUSTDOCFLAGS="-D warnings" cargo doc -q -p firmware-example --no-deps --no-default-features
RUSTDOCFLAGS="-D warnings" cargo doc -q -p firmware-example --no-deps --no-default-features --features ethernet
RUSTDOCFLAGS="-D warnings" cargo doc -q -p iai-cli --no-deps
RUSTDOCFLAGS="-D warnings" cargo doc -q -p iai-simulator --no-deps
cargo test -q -p iai-protocol-b -p iai-simulator --doc

step "size report (flash, static RAM, stack measured under QEMU) and instruction counts (figures, not assertions)"
./tools/size-report.sh
cargo run -q -p host-tests --bin icount

step "fuzzing smoke run: 30 s per cargo-fuzz target (installs nightly and cargo-fuzz if missing)"
./fuzz/smoke.sh 30

step "tests"
cargo nextest run -p iai-protocol-b -p host-tests -p firmware-example -p iai-cli -p iai-simulator -p test-support --no-default-features --no-fail-fast
