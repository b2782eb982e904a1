#!/usr/bin/env bash
# The bridge firmware under QEMU (lm3s6965evb by default) with the
# controller simulator behind it and its host side on a TCP port: prints
# `protocol-b 127.0.0.1:PORT` once it is ready, then point any client at
# it, for instance `iai send 212 query_axis_pattern=1 --tcp 127.0.0.1:PORT`.
# On lm3s6965 and b-l475e-iot01a it then prints `modbus-rtu
# 127.0.0.1:PORT`: the gateway's Modbus RTU port (unit 1, even parity),
# RTU frames over TCP, for instance
# pymodbus's RTU framer on a TCP client, or mbpoll -m rtu on a pty that
# `socat pty,link=/tmp/plc,raw,echo=0 tcp:127.0.0.1:PORT` makes.
# The port behaves like a serial cable to the bridge: bytes go at the line
# rate and the bridge's XON/XOFF are honoured (QEMU models neither). One
# client at a time. Ctrl-C stops QEMU and the simulator.
# Arguments go to the gateway binary: --port P (default: a free port),
# --baud B (default 115200), --modbus-port P, --modbus-baud B (default
# 115200), --board lm3s6965|mps2-an386|b-l475e-iot01a (the STM32L475
# board needs QEMU 10, which tools/setup.sh installs),
# --reply-delay-ms MS, --faults SPEC (as iai simulate), --seed S.
# --ethernet: protocol B over TCP instead. The Ethernet build
# (lm3s6965-eth: smoltcp on the Stellaris MAC, lm3s6965 only) boots with
# QEMU's user network forwarding 127.0.0.1:PORT to the bridge's port 5020,
# the simulator on the controller UART; prints `protocol-b-tcp
# 127.0.0.1:PORT` once the bridge answers over TCP, then `modbus-tcp
# 127.0.0.1:PORT` (forwarded to the firmware's Modbus TCP port 502; set
# with --modbus-port), then `http 127.0.0.1:PORT` (the web page, forwarded
# to the firmware's port 80; set with --http-port; open it in a browser).
# No relay: clients talk to the firmware's TCP stack, one protocol-B host
# at a time (others get & B0B), four Modbus TCP clients at once.
# --config-image FILE boots with that configuration page (`iai bridge
# config block`), --blank-config with none (every default).
# --ethernet --broker 127.0.0.1:PORT: the firmware's Sparkplug B edge node
# on the MQTT broker at that port of this machine (the guest reaches it as
# 10.0.2.2): group IAI, the node ID made from the MAC address, DCMD
# commands off; prints `sparkplug spBv1.0/IAI/NBIRTH/NODE` once NBIRTH is
# out (after the http line).
# Also builds the iai tool (target/release/iai).
set -euo pipefail
cd "$(dirname "$0")/.."
./tools/setup.sh >&2
board=lm3s6965
ethernet=no
args=("$@")
for ((i = 0; i < ${#args[@]}; i++)); do
  case "${args[i]}" in
    --board) board=${args[i + 1]:-} ;;
    --board=*) echo "gateway.sh: write --board NAME (two words)" >&2; exit 2 ;;
    --ethernet) ethernet=yes ;;
  esac
done
case "$board" in
  lm3s6965 | lm3s6965evb) target=thumbv7m-none-eabi; bin=lm3s6965; features=board-lm3s6965 ;;
  mps2-an386) target=thumbv7em-none-eabihf; bin=mps2-an386; features=board-mps2-an386 ;;
  b-l475e-iot01a) target=thumbv7em-none-eabihf; bin=b-l475e-iot01a; features=board-b-l475e-iot01a ;;
  *) echo "gateway.sh: --board takes lm3s6965, mps2-an386 or b-l475e-iot01a, not '$board'" >&2; exit 2 ;;
esac
if [ "$ethernet" = yes ]; then
  [ "$bin" = lm3s6965 ] || { echo "gateway.sh: --ethernet runs on lm3s6965 only" >&2; exit 2; }
  bin=lm3s6965-eth
  features=board-lm3s6965,ethernet
fi
echo "==> building the firmware ($bin)" >&2
cargo build -q -p firmware-example --profile firmware --target "$target" \
  --no-default-features --features "$features" --bin "$bin"
echo "==> building the gateway and iai (release)" >&2
cargo build -q -p host-tests --release --bin gateway
cargo build -q -p iai-cli --release --bin iai
tdir=${CARGO_TARGET_DIR:-target}
echo "==> starting (iai is $tdir/release/iai)" >&2
exec "$tdir/release/gateway" --elf "$tdir/$target/firmware/$bin" "$@"
