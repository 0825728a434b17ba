#!/usr/bin/env bash
# Set up .venv (if needed) and run the main job: the published gait stride by stride, a
# zero-action episode of PassiveBound-v0 on the passive limit cycle (bound.gif), then, from one
# perturbed start, the passive robot (it falls), the stride LQR (it falls too) and the shipped
# learned controller (it returns to the cycle) side by side (compare.gif, and a table).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
echo "== One stride from the paper's published apex state (reproducing reading of Table II)"
.venv/bin/bound-env stride --gait paper
echo
echo "== One stride from the model's fixed point z* at the published parameters"
.venv/bin/bound-env stride --gait default
echo
echo "== PassiveBound-v0: zero action on the cycle, then passive vs lqr vs learned from a perturbed start"
.venv/bin/bound-env demo --out out/demo
