#!/usr/bin/env bash
# One-time, idempotent set-up: a libLLVM that Dr.Jit accepts (>= 16), a virtual display with software OpenGL
# (for the hardware back-end's projector window and its tests) and the project's virtual environment.
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

# install_missing "DEBS" "why": Debian's packages of DEBS that are not installed yet, with one line saying why.
install_missing() {
  local missing="" p
  for p in $1; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
  done
  if [ -n "$missing" ]; then
    echo "bootstrap: installing Debian's$missing ($2)" >&2
    local SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    # shellcheck disable=SC2086
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
  fi
}

# The hardware back-end's projector window (lftransfer.rig.hardware.projector) and its tests: the glfw wheel
# brings libglfw, which dlopens libX11 & co. and libGL.so.1 at run time; Mesa's software OpenGL (llvmpipe)
# draws under Xvfb, the virtual X server the tests start.
install_missing "xvfb xauth libgl1 libglx-mesa0 libgl1-mesa-dri libegl1 libx11-6 libx11-xcb1 libxext6 libxrandr2
  libxinerama1 libxcursor1 libxi6 libxxf86vm1" "virtual display and software OpenGL for the projector window"

# The browser test of `lft live` (tests/app/test_viewer.py) drives Debian's chromium through its chromedriver:
# browsers that pip packages would download are not reachable here.
install_missing "chromium chromium-driver" "the viewer's browser test"

if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q -e ".[test]"
