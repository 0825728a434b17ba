#!/usr/bin/env bash
# Set up .venv (if needed), lint, and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check .
# two processes (pytest-xdist, the dev extra), one test file each: docs/developers.md, "Test times"
.venv/bin/python -m pytest tests -n 2 --dist loadfile "$@"
