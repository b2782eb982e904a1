#!/usr/bin/env bash
# Installs what a fresh machine lacks: the thumb targets, rustfmt/clippy,
# QEMU for Cortex-M and the ARM binutils used for size reports, the
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
command -v qemu-system-arm >/dev/null || need+=(qemu-system-arm)
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
