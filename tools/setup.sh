#!/usr/bin/env bash
# One-time set-up of a fresh machine: the Debian library open3d needs, then .venv with depthseg.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  echo "setup: installing Debian package libusb-1.0-0 (open3d needs it)"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  if ! { $SUDO apt-get update -qq && $SUDO apt-get install -y -qq libusb-1.0-0; } >/tmp/depthseg-apt.log 2>&1; then
    echo "setup: could not install libusb-1.0-0 (see /tmp/depthseg-apt.log)." >&2
    echo "setup: run 'sudo apt-get install libusb-1.0-0' yourself; without it the simulator (open3d) cannot import." >&2
    exit 1
  fi
fi

PY="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
# torch first and pinned: this takes the CPU wheel; an open range would pull a CUDA build.
.venv/bin/python -m pip install -q "torch==2.13.0"
# -c: the versions the documented numbers were made with (the simulator's frames depend on them)
.venv/bin/python -m pip install -q -c tools/constraints.txt -e ".[sim,train,dev,ros,ray]"
echo "setup: .venv ready"
