#!/usr/bin/env bash
# Create .venv (Python 3.11, needed by bpy) and install calib_masonry with every extra, pinned by
# constraints.txt (torch CPU build, numpy<2, bpy 5.0.x). Safe to run again: it only adds what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), f"calib_masonry needs Python 3.11 (bpy), found {sys.version.split()[0]}"'
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -c constraints.txt -e '.[all]'
