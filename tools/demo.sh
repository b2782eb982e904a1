#!/usr/bin/env bash
# Demo: the bridge firmware on QEMU lm3s6965evb writes a 20,000-record x
# 8-axis position table (one 26DH command, 1,640,014 bytes) to the
# controller simulator in controller-sized, confirmed commands, then checks
# the simulator's table. The host writes at 115,200 baud and honours the
# bridge's XON/XOFF (QEMU models neither); the figures at the end are the
# effective rate against the line rate, the XOFF pauses, the overruns the
# bridge counted and its measured stack peak. Extra arguments go to the demo
# binary (--records N, --baud B, --processing-ms MS, --board NAME,
# --faults SEED, --timeout SECS). Exit code 0 only on success.
set -euo pipefail
cd "$(dirname "$0")/.."
./tools/setup.sh
echo "==> building the firmware (lm3s6965evb and mps2-an386)"
cargo build -q -p firmware-example --profile firmware --target thumbv7m-none-eabi \
  --no-default-features --features board-lm3s6965 --bin lm3s6965
cargo build -q -p firmware-example --profile firmware --target thumbv7em-none-eabihf \
  --no-default-features --features board-mps2-an386 --bin mps2-an386
echo "==> building the demo (release)"
cargo build -q -p host-tests --release --bin demo
target=${CARGO_TARGET_DIR:-target}
echo "==> running"
exec "$target/release/demo" "$@"
