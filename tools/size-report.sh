#!/usr/bin/env bash
# Prints flash and RAM figures: the firmware for both boards against the
# limits of memory.x, and the core's RAM-resident types.
set -euo pipefail
cd "$(dirname "$0")/.."
size=arm-none-eabi-size
cargo build -q -p firmware-example --profile firmware --target thumbv7m-none-eabi
cargo build -q -p firmware-example --profile firmware --target thumbv7em-none-eabihf \
  --no-default-features --features board-mps2-an386
echo "memory.x: FLASH 256 KiB (262144 B), RAM 64 KiB (65536 B)"
for t in thumbv7m-none-eabi thumbv7em-none-eabihf; do
  elf=${CARGO_TARGET_DIR:-target}/$t/firmware/firmware-example
  $size -A "$elf" | awk -v t="$t" '
    $1==".vector_table"||$1==".text"||$1==".rodata" {flash+=$2}
    $1==".data" {flash+=$2; data=$2}
    $1==".bss"||$1==".uninit" {bss+=$2}
    END {printf "%-24s flash %7d B (%5.1f%% of 256 KiB)  data %6d B  bss %6d B  static RAM %6d B (%5.1f%% of 64 KiB)\n",
         t, flash, flash*100/262144, data, bss, data+bss, (data+bss)*100/65536}'
done
