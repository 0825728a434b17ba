#!/usr/bin/env bash
# Set up .venv (if needed), lint, and run the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check .
# serial; `-n 2 --dist loadfile` (pytest-xdist, the dev extra) halves the time but is not the
# default yet: docs/developers.md, "Test times"
.venv/bin/python -m pytest tests "$@"
