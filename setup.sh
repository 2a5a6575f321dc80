#!/usr/bin/env bash
# Sets up PointsPro in ./.venv on a fresh Debian/Ubuntu machine with Python ≥ 3.11:
#   1. the system libraries the stack needs, when missing (needs root or passwordless sudo):
#        libusb-1.0-0, libgomp1 ........ open3d
#        libgl1, libegl1 ............... VTK (pyvista) rendering
#        libxkbcommon-x11-0, libxcb-* .. Qt's xcb platform (the window)
#        xvfb, xauth ................... a virtual screen for screenshots (xvfb-run)
#   2. a virtual environment .venv with `pip install -e '.[test]'` (skipped when pyproject.toml is
#      unchanged since the last run).
set -euo pipefail
cd "$(dirname "$0")"

PY="${PYTHON:-}"
if [ -z "$PY" ]; then
  for cand in python3.11 python3.12 python3.13 python3; do
    if command -v "$cand" >/dev/null 2>&1; then PY="$cand"; break; fi
  done
fi
if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "setup.sh: PointsPro needs Python >= 3.11 (found: $("$PY" --version 2>&1)); set PYTHON=..." >&2
  exit 2
fi

DEBS="libusb-1.0-0 libgomp1 libgl1 libegl1 libxkbcommon-x11-0 libxcb-cursor0 libxcb-icccm4
libxcb-image0 libxcb-keysyms1 libxcb-randr0 libxcb-render-util0 libxcb-shape0 libxcb-xinerama0
libxcb-xkb1 libdbus-1-3 libfontconfig1 xvfb xauth"
if command -v dpkg >/dev/null 2>&1; then
  missing=""
  for p in $DEBS; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
  if [ -n "$missing" ]; then
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO="sudo -n"
    echo "setup.sh: installing system packages:$missing" >&2
    if ! $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q $missing >/dev/null 2>&1; then
      $SUDO apt-get update -q >/dev/null 2>&1 || true
      $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q $missing >/dev/null \
        || echo "setup.sh: could not install$missing — install them by hand (see the top of setup.sh)" >&2
    fi
  fi
fi

[ -x .venv/bin/python ] || "$PY" -m venv .venv
stamp=.venv/.pointspro-installed
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  .venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip 2>&1 | grep -v '^WARNING: Location' >&2 || true
  .venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test]' 2>&1 | grep -v '^WARNING: Location' >&2 || true
  .venv/bin/python -c 'import pointspro.core, open3d, PySide6, pyvista' \
    || { echo "setup.sh: the installation is incomplete (see the messages above)" >&2; exit 1; }
  echo "$want" > "$stamp"
fi
