#!/usr/bin/env bash
# Installs what a fresh machine lacks: the thumb targets, rustfmt/clippy,
# QEMU for Cortex-M (9 or later, for the b-l475e-iot01a machine: on
# Debian 12, whose own is 7.2, QEMU 10 from bookworm-backports) and the
# ARM binutils used for size reports, the
# Windows target with mingw-w64 for the iai tool's cross-build, and the
# Modbus clients the gateway's end-to-end test runs: mbpoll and socat
# (Debian) and pymodbus (PyPI, pinned) in the venv .venv of the checkout;
# for the Sparkplug B test, the Mosquitto broker and its clients and
# protoc (Debian), paho-mqtt and protobuf (PyPI, pinned: protobuf 4.21
# reads what Debian's protoc 3.21 generates) in the same venv;
# for the web page's browser test, Chromium and its WebDriver (Debian's
# chromium and chromium-driver) and Selenium (PyPI, pinned, in .venv).
# Idempotent: does nothing that is already done.
set -euo pipefail

targets=(thumbv6m-none-eabi thumbv7m-none-eabi thumbv7em-none-eabihf x86_64-pc-windows-gnu)
installed=$(rustup target list --installed)
for t in "${targets[@]}"; do
  grep -qx "$t" <<<"$installed" || rustup target add "$t"
done
for c in rustfmt clippy; do
  rustup component list --installed | grep -q "^$c" || rustup component add "$c"
done

need=()
command -v arm-none-eabi-size >/dev/null || need+=(binutils-arm-none-eabi)
command -v x86_64-w64-mingw32-gcc >/dev/null || need+=(gcc-mingw-w64-x86-64)
command -v mbpoll >/dev/null || need+=(mbpoll)
command -v socat >/dev/null || need+=(socat)
command -v mosquitto >/dev/null || [ -x /usr/sbin/mosquitto ] || need+=(mosquitto)
command -v mosquitto_sub >/dev/null || need+=(mosquitto-clients)
command -v protoc >/dev/null || need+=(protobuf-compiler)
command -v python3 >/dev/null || need+=(python3)
command -v chromium >/dev/null || need+=(chromium)
command -v chromedriver >/dev/null || need+=(chromium-driver)
# Debian's python3 makes venvs only with python3-venv (ensurepip).
python3 -c 'import ensurepip, venv' 2>/dev/null || need+=(python3-venv)
SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO=sudo
if ((${#need[@]})); then
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
fi
# The STM32L475 board (host-tests/tests/qemu_stm32.rs) needs QEMU's
# b-l475e-iot01a machine (QEMU 9.0 and later). Debian 12 ships 7.2;
# bookworm-backports has 10.0 (its qemu-system-gui and qemu-block-extra,
# if installed, are upgraded with it: QEMU loads only its own modules).
if ! qemu-system-arm -machine help 2>/dev/null | grep -q '^b-l475e-iot01a '; then
  if grep -q '^VERSION_CODENAME=bookworm$' /etc/os-release; then
    list=/etc/apt/sources.list.d/bookworm-backports.list
    grep -qs bookworm-backports "$list" ||
      echo 'deb http://deb.debian.org/debian bookworm-backports main' | $SUDO tee "$list" >/dev/null
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq -t bookworm-backports qemu-system-arm >/dev/null
  else
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq qemu-system-arm >/dev/null
  fi
  qemu-system-arm -machine help | grep -q '^b-l475e-iot01a ' || {
    echo "setup.sh: $(qemu-system-arm --version | head -1) has no b-l475e-iot01a machine (QEMU 9 or later has it)" >&2
    exit 1
  }
fi
# pymodbus for the gateway's end-to-end test (host-tests/tests/qemu_modbus.rs).
PYMODBUS=3.16.1
venv="$(cd "$(dirname "$0")/.." && pwd)/.venv"
if ! "$venv/bin/python" -c "import pymodbus, sys; sys.exit(pymodbus.__version__ != '$PYMODBUS')" 2>/dev/null; then
  if ! python3 -m venv --clear "$venv"; then
    # A python3 whose ensurepip is split off (Debian without python3-venv).
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq python3-venv >/dev/null
    python3 -m venv --clear "$venv"
  fi
  "$venv/bin/python" -m pip install -q --disable-pip-version-check "pymodbus==$PYMODBUS"
fi
# paho-mqtt and protobuf for the Sparkplug host (host-tests/sparkplug/).
PAHO=2.1.0
PROTOBUF=4.21.12
if ! "$venv/bin/python" -c "
import sys, paho.mqtt, google.protobuf as p
sys.exit(paho.mqtt.__version__ != '$PAHO' or p.__version__ != '$PROTOBUF')" 2>/dev/null; then
  "$venv/bin/python" -m pip install -q --disable-pip-version-check "paho-mqtt==$PAHO" "protobuf==$PROTOBUF"
fi
# Selenium for the web page's browser test (host-tests/tests/qemu_web.rs).
SELENIUM=4.51.0
if ! "$venv/bin/python" -c "import selenium, sys; sys.exit(selenium.__version__ != '$SELENIUM')" 2>/dev/null; then
  "$venv/bin/python" -m pip install -q --disable-pip-version-check "selenium==$SELENIUM"
fi
if ! command -v cargo-nextest >/dev/null; then
  cargo install --locked cargo-nextest
fi
