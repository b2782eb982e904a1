#!/usr/bin/env bash
# Demo: the bridge firmware on QEMU lm3s6965evb writes a 20,000-record x
# 8-axis position table (one 26DH command, 1,640,014 bytes) to the
# controller simulator in controller-sized, confirmed commands, then checks
# the simulator's table. Extra arguments go to the demo binary
# (--records N, --timeout SECS). Exit code 0 only on success.
set -euo pipefail
cd "$(dirname "$0")/.."
./tools/setup.sh
echo "==> building the firmware (release, lm3s6965evb)"
cargo build -q -p firmware-example --release --target thumbv7m-none-eabi
echo "==> building the demo (release)"
cargo build -q -p host-tests --release --bin demo
target=${CARGO_TARGET_DIR:-target}
elf=$target/thumbv7m-none-eabi/release/firmware-example
echo "==> running"
exec "$target/release/demo" --elf "$elf" "$@"
