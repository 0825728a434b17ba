#!/usr/bin/env bash
# Regenerate the results page (docs/MARGINS.md, --budget full) through a Dask cluster on this
# machine, reached as a remote one is: `compare --scheduler tcp://127.0.0.1:PORT`.
#   bash scripts/page_on_dask.sh [WORKERS] [OUT] [DOCS]
#   (default: 2 workers, out/margins, docs: the repository's page; PORT=8799, BIN=.venv/bin)
# Starts a scheduler and WORKERS single-threaded workers on 127.0.0.1, runs the page, stops
# them (also on Ctrl-C, SIGTERM or an error: nothing is left running), and writes the wall time
# to OUT/page_timing.json. A rerun resumes: finished columns and tasks are cached under OUT.
# Checked before anything starts: WORKERS (1 to 256, compare's --workers limit) and PORT (free
# on 127.0.0.1: a taken port fails at once, naming it); a scheduler or workers that do not come
# up fail within STARTUP_S seconds (default 60), naming their log.
set -euo pipefail
cd "$(dirname "$0")/.."
WORKERS=${1:-2}
OUT=${2:-out/margins}
DOCS=${3:-docs}
PORT=${PORT:-8799}
BIN=${BIN:-.venv/bin}
STARTUP_S=${STARTUP_S:-60}
MAX_WORKERS=256  # bound_env.sim.parallel.MAX_WORKERS
die() { echo "page_on_dask.sh: $*" >&2; exit 2; }
[[ "$WORKERS" =~ ^[0-9]{1,6}$ ]] && ((10#$WORKERS >= 1 && 10#$WORKERS <= MAX_WORKERS)) ||
  die "WORKERS must be an integer from 1 to $MAX_WORKERS, got '$WORKERS'"
WORKERS=$((10#$WORKERS))
[[ "$PORT" =~ ^[0-9]{1,6}$ ]] && ((10#$PORT >= 1024 && 10#$PORT <= 65535)) ||
  die "PORT must be an integer from 1024 to 65535, got '$PORT'"
[[ "$STARTUP_S" =~ ^[0-9]{1,5}$ ]] && ((10#$STARTUP_S >= 1)) ||
  die "STARTUP_S must be a whole number of seconds >= 1, got '$STARTUP_S'"
[[ -x "$BIN/dask" && -x "$BIN/bound-env" ]] ||
  die "BIN=$BIN has no dask or bound-env (install with: pip install -e '.[dask]')"
port_free() {  # exit 0 if nothing listens on 127.0.0.1:$1 and it can be bound
  "$BIN/python" - "$1" <<'EOF'
import socket, sys
s = socket.socket()
try:
    s.bind(("127.0.0.1", int(sys.argv[1])))
except OSError:
    sys.exit(1)
finally:
    s.close()
EOF
}
listening() {  # exit 0 once something accepts connections on 127.0.0.1:$1
  "$BIN/python" -c 'import socket, sys; socket.create_connection(("127.0.0.1", int(sys.argv[1])), 1).close()' "$1" 2>/dev/null
}
port_free "$PORT" || die "port $PORT on 127.0.0.1 is taken (another scheduler or program?); choose another: PORT=NNNN bash $0 ..."

mkdir -p "$OUT"
LOG="$OUT/dask"
mkdir -p "$LOG"
PIDS=()
cleanup() {  # stop the workers and the scheduler, and whatever they started
  local pid kids
  trap - EXIT INT TERM
  for pid in "${PIDS[@]}"; do
    kids=$(pgrep -P "$pid" 2>/dev/null || true)
    kill -TERM "$pid" $kids 2>/dev/null || true
  done
  for _ in $(seq 1 50); do  # up to 10 s to close cleanly
    pid=""
    for p in "${PIDS[@]}"; do kill -0 "$p" 2>/dev/null && pid=$p; done
    [[ -z "$pid" ]] && break
    sleep 0.2
  done
  for pid in "${PIDS[@]}"; do
    kids=$(pgrep -P "$pid" 2>/dev/null || true)
    kill -KILL "$pid" $kids 2>/dev/null || true
  done
  wait 2>/dev/null || true
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
"$BIN/dask" scheduler --host 127.0.0.1 --port "$PORT" --no-dashboard >"$LOG/scheduler.log" 2>&1 &
SCHED=$!
PIDS+=("$SCHED")
for _ in $(seq 1 $((STARTUP_S * 5))); do
  kill -0 "$SCHED" 2>/dev/null ||
    die "the Dask scheduler on port $PORT stopped at start: $(tail -n 1 "$LOG/scheduler.log")"
  listening "$PORT" && break
  sleep 0.2
done
listening "$PORT" || die "the Dask scheduler did not listen on port $PORT within $STARTUP_S s (see $LOG/scheduler.log)"
for i in $(seq 1 "$WORKERS"); do
  OMP_NUM_THREADS=1 "$BIN/dask" worker "tcp://127.0.0.1:$PORT" --nthreads 1 --no-dashboard \
    --host 127.0.0.1 >"$LOG/worker$i.log" 2>&1 &
  PIDS+=("$!")
done
sleep 3
for i in $(seq 1 "$WORKERS"); do
  kill -0 "${PIDS[$i]}" 2>/dev/null ||  # PIDS: the scheduler, then worker 1, 2, ...
    die "Dask worker $i stopped at start: $(tail -n 1 "$LOG/worker$i.log")"
done
start=$(date +%s.%N)
# in the background, so that a signal to this script is handled at once (bash runs its traps
# only between commands) and stops compare with the cluster
"$BIN/bound-env" compare --budget full --scheduler "tcp://127.0.0.1:$PORT" --workers "$WORKERS" \
  --out "$OUT" --docs "$DOCS" &
COMPARE=$!
PIDS=("$COMPARE" "${PIDS[@]}")
rc=0
wait "$COMPARE" || rc=$?
((rc == 0)) || exit "$rc"
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
