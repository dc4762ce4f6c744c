#!/usr/bin/env bash
# Install (scripts/setup.sh) and run the whole test suite, slow tests included.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check src tests experiments examples
.venv/bin/ruff format --check src tests experiments examples
# one test file per worker, a worker per core (pytest-xdist; `-n 0` among the arguments: one process)
.venv/bin/python -m pytest -q --durations=5 -n auto --dist loadfile "$@"
