#!/usr/bin/env bash
# Set up .venv (if needed) and run the main job: the published gait, one stride from the
# published apex state and one from the model's own fixed point.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
echo "== One stride from the paper's published apex state (reproducing reading of Table II)"
.venv/bin/bound-env stride --gait paper
echo
echo "== One stride from the model's fixed point z* at the published parameters"
.venv/bin/bound-env stride --gait default
