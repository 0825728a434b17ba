#!/usr/bin/env bash
# Create or reuse .venv at the repo root and install the project with its dev tools and the
# optional Dask, rl-zoo3 and docs extras (the tests run real Dask clusters, rl-zoo3's own config
# preprocessing and `mkdocs build --strict`).
# Re-running is cheap: the install is skipped while pyproject.toml and the extras are unchanged.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
EXTRAS="dev,dask,zoo,docs"
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv" >&2
  "$PY" -m venv .venv
fi
stamp=.venv/.bound_env_installed
want=$({ cat pyproject.toml; echo "extras: $EXTRAS"; } | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ] || ! .venv/bin/python -c "import bound_env" 2>/dev/null; then
  echo "[setup] installing bound_env and its dependencies into .venv (torch==2.13.0, CPU)" >&2
  .venv/bin/python -m pip install -q --upgrade pip >&2
  .venv/bin/python -m pip install -q -e ".[$EXTRAS]" >&2
  echo "$want" > "$stamp"
fi
