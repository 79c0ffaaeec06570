#!/usr/bin/env bash
# One-time, idempotent set-up: a libLLVM that Dr.Jit accepts (>= 16) and the project's virtual environment.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}

have_llvm() {
  for d in /usr/lib/x86_64-linux-gnu /usr/lib/aarch64-linux-gnu /usr/lib64 /usr/lib /usr/local/lib; do
    for f in "$d"/libLLVM.so.* "$d"/libLLVM-*.so*; do
      [ -e "$f" ] || continue
      v=$(basename "$f" | sed -E 's/^libLLVM[.-](so\.)?([0-9]+).*/\2/')
      [[ "$v" =~ ^[0-9]+$ ]] && [ "$v" -ge 16 ] && return 0
    done
  done
  return 1
}

if ! have_llvm; then
  echo "bootstrap: no libLLVM >= 16 found; installing Debian's libllvm19" >&2
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 >/dev/null
fi

if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q -e ".[test]"
