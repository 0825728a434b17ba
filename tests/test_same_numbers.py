"""Same commit, same numbers: a margins job gives bit-identical JSON from a cold and a warm
Numba cache and from 1 or 2 workers (docs/developers.md, "Same commit, same numbers").

With fast-math (``reassoc``, ``contract``) in the kernels the cold and the warm run differed in
the last bits of z_cl, the basin shares and ``rel_cycle``, and in one basin's failure phase
(measured on ebefa3c); without it they agree bit for bit.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# The timing parts of a margins result (wall and CPU): the only keys that may differ between two
# runs.
WALL_CLOCK = ("seconds", "cpu_seconds", "decision_seconds", "decision_times", "decision_hist")

JOB = """
import json, sys
from bound_env.analysis.margins.run import compute_margins
from bound_env.control import load_controller
res = compute_margins(load_controller("mpc"), budget="test", workers=int(sys.argv[2]),
                      use_cache=False)
with open(sys.argv[1], "w") as f:
    json.dump(res, f, sort_keys=True)
"""


def without_wall_clock(x):
    if isinstance(x, dict):
        return {k: without_wall_clock(v) for k, v in x.items() if k not in WALL_CLOCK}
    if isinstance(x, list):
        return [without_wall_clock(v) for v in x]
    return x


def run_job(tmp_path, cache_dir, workers: int) -> dict:
    out = tmp_path / f"margins-{len(list(tmp_path.glob('margins-*')))}.json"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(ROOT))
    subprocess.run(
        [sys.executable, "-c", JOB, str(out), str(workers)], check=True, cwd=ROOT, env=env
    )
    return json.loads(out.read_text())


@pytest.mark.slow
def test_mpc_margins_are_bit_identical_from_a_cold_and_a_warm_cache_and_two_workers(tmp_path):
    """mpc's basins (bisections that end on the MPC's search thresholds), its fixed point,
    curve, terrain and MFPT noise runs, windows and pushes at the test budget: once compiled
    into an empty cache, once loaded from it with two workers."""
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    cold = run_job(tmp_path, cache, workers=1)
    assert any(cache.rglob("*.nbi")), "the first run compiled into the empty cache"
    warm = run_job(tmp_path, cache, workers=2)
    assert "z_cl" in cold and "terrain" in cold and "basin" in cold
    a, b = without_wall_clock(cold), without_wall_clock(warm)
    # json text of floats is their repr: equal text is equal bits
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)
