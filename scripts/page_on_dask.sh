#!/usr/bin/env bash
# Regenerate the results page (docs/MARGINS.md, --budget full) through a Dask cluster on this
# machine, reached as a remote one is: `compare --scheduler tcp://127.0.0.1:PORT`.
#   bash scripts/page_on_dask.sh [WORKERS] [OUT] [DOCS]
#   (default: 2 workers, out/margins, docs: the repository's page)
# Starts a scheduler and WORKERS single-threaded workers on 127.0.0.1, runs the page, stops
# them (also on Ctrl-C or an error), and writes the wall time to OUT/page_timing.json.
# A rerun resumes: finished columns and tasks are cached under OUT.
set -euo pipefail
cd "$(dirname "$0")/.."
WORKERS=${1:-2}
OUT=${2:-out/margins}
DOCS=${3:-docs}
PORT=${PORT:-8799}
BIN=.venv/bin
mkdir -p "$OUT"
LOG="$OUT/dask"
mkdir -p "$LOG"
"$BIN/dask" scheduler --host 127.0.0.1 --port "$PORT" --no-dashboard >"$LOG/scheduler.log" 2>&1 &
SCHED=$!
PIDS=("$SCHED")
cleanup() { kill "${PIDS[@]}" 2>/dev/null || true; wait 2>/dev/null || true; }
trap cleanup EXIT
for i in $(seq 1 "$WORKERS"); do
  OMP_NUM_THREADS=1 "$BIN/dask" worker "tcp://127.0.0.1:$PORT" --nthreads 1 --no-dashboard \
    --host 127.0.0.1 >"$LOG/worker$i.log" 2>&1 &
  PIDS+=("$!")
done
sleep 3
start=$(date +%s.%N)
"$BIN/bound-env" compare --budget full --scheduler "tcp://127.0.0.1:$PORT" --workers "$WORKERS" \
  --out "$OUT" --docs "$DOCS"
end=$(date +%s.%N)
python3 - "$OUT/page_timing.json" "$start" "$end" "$WORKERS" <<'EOF'
import json, os, platform, sys, time
path, t0, t1, n = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
info = {"wall_s": t1 - t0, "workers": n, "scheduler": "tcp://127.0.0.1 (dask scheduler + "
        f"{n} single-threaded dask workers)", "machine": f"{platform.machine()}, "
        f"{os.cpu_count()} cores", "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "load_average_after": list(os.getloadavg())}
tmp = path + f".tmp{os.getpid()}"
with open(tmp, "w") as f:
    json.dump(info, f, indent=2)
os.replace(tmp, path)
print(f"page in {info['wall_s'] / 60:.1f} min with {n} Dask workers -> {path}")
EOF
