#!/usr/bin/env bash
# Install (scripts/setup.sh) and run the whole test suite, slow tests included.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check src tests experiments examples
.venv/bin/ruff format --check src tests experiments examples
.venv/bin/python -m pytest -q --durations=5 "$@"
