#!/usr/bin/env bash
# Set up hexa_mjx on a fresh machine: system libraries for off-screen rendering (Debian/Ubuntu,
# when run as root), then a virtual environment in .venv with the pinned Python packages.
set -euo pipefail
cd "$(dirname "$0")/.."

# Off-screen OpenGL for MuJoCo's renderer: OSMesa (software) and EGL with Mesa.
GL_PACKAGES="libosmesa6 libegl1 libegl-mesa0 libgl1"
if command -v apt-get >/dev/null 2>&1; then
  if ! dpkg -s $GL_PACKAGES >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ]; then
      apt-get update -qq
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $GL_PACKAGES >/dev/null
    else
      echo "note: video rendering needs: sudo apt-get install $GL_PACKAGES" >&2
    fi
  fi
fi

PYTHON=${PYTHON:-$(command -v python3.11 || command -v python3)}
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
  echo "error: hexa_mjx needs Python 3.11 (found $("$PYTHON" --version)); set PYTHON=/path/to/python3.11" >&2
  exit 1
fi
[ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test]"
echo "hexa_mjx is set up in .venv (activate with: . .venv/bin/activate)"
