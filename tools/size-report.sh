#!/usr/bin/env bash
# Flash and RAM of the bridge firmware, per board. Static RAM and flash come
# from the ELF sections; the stack is measured: each QEMU board runs a short
# paced demo and a run with controller faults, and the firmware reports the
# deepest its painted stack went (cortex-m-rt's paint-stack). Prints, per
# board (lm3s6965's stack also after a PLC's session on its Modbus port):
#   ram <board> static <bytes> stack <bytes> total <bytes>
#   flash <board> <bytes>
# (lm3s6965's, and the Ethernet build's, also after a configuration
# session: iai bridge config through the bridge's own station, and on the
# Ethernet build the web page read and a form saved)
# and, for the QEMU (Cortex-M3/M4) boards, whether the goal is met:
#   goal <board> ram met|missed flash met|missed
# The lm3s6965 build carries the Modbus gateway beside the bridge (both
# upstreams at once): its RAM goal is 12 KiB; the others run the bridge
# alone (8 KiB).
# then the same ram and flash lines for the Ethernet build (lm3s6965-eth)
# with the network's share of its static RAM.
# The b-l475e-iot01a (STM32L475 under QEMU 10: the STM32 boards' embassy
# tasks with the bridge and the Modbus gateway) is measured like the
# other QEMU boards, with 100-record demos (QEMU's model of its USART
# receives slowly, see README). The stm32g030 (Cortex-M0+, STM32G030x8:
# the bridge alone) and the stm32g070 (the two-UART gateway whose
# upstream the configuration block chooses, protocol B or Modbus RTU) run
# the same tasks on embassy-stm32 and are built and sized only (QEMU has
# no model of them); their stack is the one measured on b-l475e-iot01a
# (the same tasks, compiled for the Cortex-M4): for stm32g030, the bridge
# alone, the peak of its demos (the gateway idle); for stm32g070, the peak
# with its PLC session too:
#   ram <board> static <bytes> stack <bytes> (measured on b-l475e-iot01a) total <bytes>
#   goal <board> on STM32G030x8: ram met|missed flash met|missed
#   goal stm32g070 on STM32G070xB: ram met|missed flash met|missed
set -euo pipefail
cd "$(dirname "$0")/.."
target=${CARGO_TARGET_DIR:-target}
size=arm-none-eabi-size
nm=arm-none-eabi-nm

# board  bin  target  features  qemu(yes/no); the STM32G0 boards after
# b-l475e-iot01a, whose measured stack they take.
boards=(
  "lm3s6965 lm3s6965 thumbv7m-none-eabi board-lm3s6965 yes"
  "mps2-an386 mps2-an386 thumbv7em-none-eabihf board-mps2-an386 yes"
  "b-l475e-iot01a b-l475e-iot01a thumbv7em-none-eabihf board-b-l475e-iot01a yes"
  "stm32g030 stm32g030 thumbv6m-none-eabi board-stm32g030 no"
  "stm32g070 stm32g070 thumbv6m-none-eabi board-stm32g070 no"
)
for b in "${boards[@]}"; do
  read -r _ bin t feat _ <<<"$b"
  cargo build -q -p firmware-example --profile firmware --target "$t" \
    --no-default-features --features "$feat" --bin "$bin"
done
cargo build -q -p host-tests --bin demo --bin gateway
cargo build -q -p iai-cli --bin iai

# Stack peak of an image after a configuration session
# (host-tests/web/config_session.py): the gateway with --stack-report on a
# fresh page, `iai bridge config set` with a new password, `config get`,
# a change with the password and one refused without it, and with
# --ethernet the web page's pages read, a form saved and one refused; then
# a stop that ends the firmware and logs its peak. Prints the peak, or
# nothing if it could not be measured.
config_stack() {
  local elf=$1 mode=$2 dir pid pb http="" ready=protocol-b flags=()
  [ "$mode" = ethernet ] && ready=http flags=(--ethernet)
  dir=$(mktemp -d)
  : >"$dir/out"
  "$target/debug/gateway" --elf "$elf" --stack-report "${flags[@]}" >"$dir/out" 2>"$dir/err" &
  pid=$!
  for _ in $(seq 1 300); do
    grep -q "^$ready " "$dir/out" && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.2
  done
  pb=$(awk '$1=="protocol-b" || $1=="protocol-b-tcp" {print $2}' "$dir/out")
  [ "$mode" = ethernet ] && http=$(awk '$1=="http" {print $2}' "$dir/out")
  if [ -n "$pb" ] && python3 host-tests/web/config_session.py "$target/debug/iai" "$pb" $http >"$dir/session" 2>&1; then
    kill -TERM "$pid"
    wait "$pid" || true
    sed -n 's/.*firmware stack peak \([0-9]*\) bytes.*/\1/p' "$dir/err"
  else
    echo "size-report: the configuration session on $(basename "$elf") failed:" >&2
    cat "$dir/session" "$dir/err" >&2
    kill -TERM "$pid" 2>/dev/null || true
    wait "$pid" || true
  fi
  rm -rf "$dir"
}

# Stack peak of an image after a PLC's session on its Modbus port
# (pymodbus, from tools/setup.sh's venv; host-tests/plc/): the gateway with
# --stack-report, servo, home, a move and 20 positions through the table
# window, then a stop that ends the firmware and logs its peak. `rtu`: the
# image's RTU port (board $3: lm3s6965 or b-l475e-iot01a); `tcp`: the
# Ethernet image (gateway --ethernet) over Modbus TCP. Prints the peak, or
# nothing if it could not be measured.
modbus_stack() {
  local elf=$1 mode=$2 board=${3:-lm3s6965} py=.venv/bin/python dir pid port ready flags=() plc=()
  "$py" -c 'import pymodbus' 2>/dev/null || {
    echo "size-report: no pymodbus in .venv (tools/setup.sh): Modbus stack not measured" >&2
    return 0
  }
  if [ "$mode" = tcp ]; then
    ready=modbus-tcp flags=(--ethernet) plc=(--tcp)
  else
    ready=modbus-rtu flags=(--board "$board")
  fi
  dir=$(mktemp -d)
  : >"$dir/out"
  "$target/debug/gateway" --elf "$elf" --stack-report "${flags[@]}" >"$dir/out" 2>"$dir/err" &
  pid=$!
  for _ in $(seq 1 300); do
    grep -q "^$ready " "$dir/out" && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.2
  done
  port=$(awk -v r="$ready" '$1==r {sub(/.*:/, "", $2); print $2}' "$dir/out")
  awk 'BEGIN {for (n = 1; n <= 20; n++) {
    printf "%d 255 30 30 100", n
    for (a = 1; a <= 8; a++) printf " 0 %d", n * 100 + a
    printf "\n" }}' >"$dir/table"
  if [ -n "$port" ] && "$py" host-tests/plc/pymodbus_plc.py "${plc[@]}" 127.0.0.1 "$port" "$dir/table" >"$dir/plc" 2>&1; then
    kill -TERM "$pid"
    wait "$pid" || true
    sed -n 's/.*firmware stack peak \([0-9]*\) bytes.*/\1/p' "$dir/err"
  else
    echo "size-report: the PLC session ($ready) on $(basename "$elf") failed:" >&2
    cat "$dir/plc" "$dir/err" >&2
    kill -TERM "$pid" 2>/dev/null || true
    wait "$pid" || true
  fi
  rm -rf "$dir"
}

verdict() { [ "$1" -le "$2" ] && echo met || echo missed; }
l475_stack= l475_demo_stack=
for b in "${boards[@]}"; do
  read -r board bin t feat qemu <<<"$b"
  elf=$target/$t/firmware/$bin
  read -r flash static < <($size -A "$elf" | awk '
    $1==".vector_table"||$1==".text"||$1==".rodata" {flash+=$2}
    $1==".data" {flash+=$2; ram+=$2}
    $1==".bss"||$1==".uninit" {ram+=$2}
    END {print flash, ram}')
  config=$($nm "$elf" | awk '$3=="_bridge_config" {print "0x" $1}')
  vectors=$($size -A "$elf" | awk '$1==".vector_table" {printf "0x%08x", $3}')
  echo "map $board: root memory.x (_bridge_config at $config), vector table at $vectors"
  if [ "$qemu" = yes ]; then
    stack=0
    records=300
    [ "$board" = b-l475e-iot01a ] && records=100
    for run in "--records $records" "--records $records --faults 11"; do
      # shellcheck disable=SC2086
      out=$("$target/debug/demo" --board "$bin" --elf "$elf" $run 2>/dev/null) || {
        echo "size-report: demo $run on $board failed" >&2; exit 1; }
      peak=$(awk -v b="$bin" '$1=="stack" && $2==b {print $3}' <<<"$out")
      echo "stack $board after demo $run: $peak bytes"
      [ "$peak" -gt "$stack" ] && stack=$peak
    done
    demo_stack=$stack
    if [ "$board" = lm3s6965 ] || [ "$board" = b-l475e-iot01a ]; then
      peak=$(modbus_stack "$elf" rtu "$board")
      if [ -n "$peak" ]; then
        echo "stack $board after a PLC's Modbus session (pymodbus): $peak bytes"
        [ "$peak" -gt "$stack" ] && stack=$peak
      fi
    fi
    # The configuration editor: the boards that write their page (the
    # STM32s read theirs).
    if [ "$board" = lm3s6965 ]; then
      peak=$(config_stack "$elf" serial)
      if [ -n "$peak" ]; then
        echo "stack $board after a configuration session (iai bridge config): $peak bytes"
        [ "$peak" -gt "$stack" ] && stack=$peak
      fi
    fi
    echo "ram $board static $static stack $stack total $((static + stack))"
    echo "flash $board $flash"
    ram_goal=8192
    [ "$board" != mps2-an386 ] && ram_goal=12288
    echo "goal $board ram $(verdict $((static + stack)) $ram_goal) (<= $ram_goal) flash $(verdict "$flash" 32768)"
    [ "$board" = b-l475e-iot01a ] && l475_stack=$stack l475_demo_stack=$demo_stack
  else
    stack=${l475_stack:-0}
    [ "$board" = stm32g030 ] && stack=${l475_demo_stack:-0}
    total=$((static + stack))
    echo "ram $board static $static stack $stack (measured on b-l475e-iot01a) total $total"
    echo "flash $board $flash"
    # Both G0 images against the STM32G030x8 (62 KiB of flash below its
    # configuration page, 8 KiB of RAM): the bridge alone is meant for it,
    # the two-UART gateway that lets the block choose its upstream is
    # not; and the gateway against its STM32G070xB (126 KiB, 36 KiB).
    echo "goal $board on STM32G030x8: ram $(verdict "$total" 8192) (<= 8192) flash $(verdict "$flash" 63488) (<= 63488)"
    if [ "$board" = stm32g070 ]; then
      echo "goal $board on STM32G070xB: ram $(verdict "$total" 36864) (<= 36864) flash $(verdict "$flash" 129024) (<= 129024)"
    fi
  fi
done
echo "goal (Cortex-M3/M4 boards): total RAM <= 12288 with the gateway (lm3s6965, b-l475e-iot01a), <= 8192 without; flash <= 32768"

# The Ethernet build (lm3s6965-eth: the bridge with its host on TCP,
# smoltcp on the Stellaris MAC, and the Modbus gateway on Modbus TCP).
# Static RAM and flash as above, the network's share of the static RAM by
# symbol (smoltcp's socket buffers, protocol B's and Modbus TCP's, the
# driver's two frame buffers, the socket slots with smoltcp's socket
# state, the interface with the protocol-B hosts and the Modbus clients,
# the driver), the Modbus gateway's state, and the stack peak: the deeper
# of the QEMU test that streams a 26DH over TCP and ends the run with the
# quit sequence (it prints `stack lm3s6965-eth N`), a PLC's session
# over Modbus TCP (modbus_stack ... tcp) and a Sparkplug session.
# Not held to the 8 KiB goal: the LM3S6965 has 64 KiB of RAM.
eth_elf=$target/thumbv7m-none-eabi/firmware/lm3s6965-eth
cargo build -q -p firmware-example --profile firmware --target thumbv7m-none-eabi \
  --no-default-features --features board-lm3s6965,ethernet --bin lm3s6965-eth
read -r flash static < <($size -A "$eth_elf" | awk '
  $1==".vector_table"||$1==".text"||$1==".rodata" {flash+=$2}
  $1==".data" {flash+=$2; ram+=$2}
  $1==".bss"||$1==".uninit" {ram+=$2}
  END {print flash, ram}')
sym() { # size in bytes of the Ethernet board's static NAME (decimal)
  local hex
  hex=$($nm -S "$eth_elf" | awk -v n="$1" '$4 ~ ("^_ZN16firmware_example5board8lm3s69658ethernet" length(n) n "17h") {print $2}')
  echo $((16#${hex:-0}))
}
buffers=$(( $(sym BUFFERS) + $(sym MODBUS_BUFFERS) )); frames=$(( $(sym RX_FRAME) + $(sym TX_FRAME) ))
gateway=$(sym GATEWAY)
# The Sparkplug edge node: its buffers (socket, packets, table window) and
# its state inside the interface's static (NET).
sparkplug=$(sym SPARKPLUG_BUFFERS)
slots=$(sym SLOTS); iface=$(sym NET); driver=$(sym ETH)
eth_stack=$(cargo test -q -p host-tests --test qemu_ethernet a_26dh_over_tcp -- --nocapture 2>/dev/null |
  awk '$1=="stack" && $2=="lm3s6965-eth" {print $3}')
[ -n "$eth_stack" ] || { echo "size-report: the Ethernet stack run failed" >&2; exit 1; }
echo "stack lm3s6965-eth after a 26DH over TCP: $eth_stack bytes"
peak=$(modbus_stack "$eth_elf" tcp)
if [ -n "$peak" ]; then
  echo "stack lm3s6965-eth after a PLC's Modbus TCP session (pymodbus): $peak bytes"
  [ "$peak" -gt "$eth_stack" ] && eth_stack=$peak
fi
peak=$(config_stack "$eth_elf" ethernet)
if [ -n "$peak" ]; then
  echo "stack lm3s6965-eth after a configuration session (iai bridge config, the web page): $peak bytes"
  [ "$peak" -gt "$eth_stack" ] && eth_stack=$peak
fi
# The stack after a session of the Sparkplug edge node on Mosquitto (its
# end-to-end test ends its second boot with the quit sequence).
sp_stack=$(cargo test -q -p host-tests --test qemu_sparkplug -- --nocapture 2>/dev/null |
  awk '$1=="stack" && $2=="lm3s6965-eth" {print $3}')
if [ -n "$sp_stack" ]; then
  echo "stack lm3s6965-eth after a Sparkplug session (qemu_sparkplug): $sp_stack bytes"
  [ "$sp_stack" -gt "$eth_stack" ] && eth_stack=$sp_stack
else
  echo "size-report: the Sparkplug run failed (mosquitto, tools/setup.sh): its stack not measured" >&2
fi
echo "ram lm3s6965-eth static $static stack $eth_stack total $((static + eth_stack))"
echo "ram lm3s6965-eth network $((buffers + frames + slots + iface + driver)): socket buffers $buffers, frame buffers $frames, socket slots $slots, interface and hosts $iface, driver $driver; modbus gateway $gateway"
echo "ram lm3s6965-eth sparkplug buffers $sparkplug (socket, packets, table window; its state is in the interface's)"
# The web page's share of that: its socket buffers and its 3 of the 12
# slots of the socket set (its connections' state and the form being read
# are in the interface's figure, the frame history it downloads in the
# bridge's static; README, "The web page").
web_buffers=$(sym HTTP_BUFFERS)
echo "ram lm3s6965-eth web page: socket buffers $web_buffers, socket slots $((3 * slots / 12))"
echo "flash lm3s6965-eth $flash"
# The web page's code and tables by symbol (its functions, httparse's):
# less than its whole cost, as the loop inlines part of it.
web_flash=$($nm -S -C "$eth_elf" | python3 -c '
import sys
n = 0
for l in sys.stdin:
    p = l.split(None, 3)
    if len(p) == 4 and p[2] in "tTrR" and ("net::http" in p[3] or "httparse" in p[3]):
        n += int(p[1], 16)
print(n)')
echo "flash lm3s6965-eth web page (its symbols) $web_flash"
