"""Where a margins column's time goes, run by hand:

    python benchmarks/margins.py --policy lqr --budget quick
    python benchmarks/margins.py --policy mpc --budget full --base ../wt-base   # vs a checkout

For one column (``--policy``) it runs every task of one margins evaluation serially in this
process, without the cache (after a warm-up on the test budget, so that compiling is not
timed), and prints each measure's wall time, its share, the strides it
advanced and the strides per second. With ``--base DIR`` (a checkout of another version, e.g.
today's main in a `git worktree`), the same tasks run in a subprocess on that code first, and
a ratio column says how much faster this code is, both timed in this run. The machine's load
average is printed beside each figure: other jobs slow every row, and the ratios are what to
compare (benchmark on a quiet machine: load under 1.5).

``--measures curve,basin`` restricts the run to some measures (the cycle always runs first: the
others start from the closed-loop fixed point it finds).

With ``--base``, the results are compared too, task by task (every number but the timings):
the last columns count the tasks whose results are identical, and the largest relative
difference of a number elsewhere (the contract of a refactor: the same outcomes).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

MEASURES = ("cycle", "basin", "ceiling", "curve", "terrain", "mfpt", "window", "push")


def _api():
    """The margins API of this checkout: the core package, or the old agents/results/margins.py."""
    try:
        from bound_env.analysis.margins import closed_loop as cl
        from bound_env.analysis.margins import run as core

        return (
            core.Setup, core.run_task, core.setup_key, core.as_budget, cl.STRIDES, "core",
            core.MFPT_CHUNK,
        )  # fmt: skip
    except ImportError:  # a checkout from before the move (no stride counter)
        from agents.results import margins as core

        return (
            core.Setup, core.run_task, core.setup_key, core.BUDGETS.get, None, "agents",
            core.MFPT_CHUNK,
        )  # fmt: skip


TIMINGS = ("seconds", "decision_seconds", "decision_hist")  # wall times: not compared


def _untimed(x):
    """A task's result without its wall times (JSON-able)."""
    if isinstance(x, dict):
        return {k: _untimed(v) for k, v in x.items() if k not in TIMINGS}
    if isinstance(x, (list, tuple)):
        return [_untimed(v) for v in x]
    if hasattr(x, "tolist"):
        return x.tolist()
    return x


def _merge_chunks(results: list) -> list:
    """MFPT results per sigma, whatever the checkout's robots per task: the chunks of one
    sigma joined (robots in order); other results as they are."""
    if not results or "chunk" not in results[0]:
        return results
    by_sigma: dict = {}
    for r in results:
        m = by_sigma.setdefault(
            r["sigma_deg"],
            {"sigma_deg": r["sigma_deg"], "robots": 0, "strides": [], "fell": [], "failures": {}},
        )
        m["robots"] += r["robots"]
        m["strides"] += r["strides"]
        m["fell"] += r["fell"]
        for k, n in r["failures"].items():
            m["failures"][k] = m["failures"].get(k, 0) + n
    return list(by_sigma.values())


def max_difference(a, b) -> float:
    """The largest relative difference between two results' numbers (inf: other keys,
    lengths, strings or outcomes)."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return math.inf
        return max((max_difference(a[k], b[k]) for k in a), default=0.0)
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return math.inf
        return max((max_difference(x, y) for x, y in zip(a, b, strict=True)), default=0.0)
    if isinstance(a, bool) or isinstance(b, bool) or not isinstance(a, (int, float)):
        return 0.0 if a == b else math.inf
    if not isinstance(b, (int, float)):
        return math.inf
    if a == b or (math.isnan(a) and math.isnan(b)):
        return 0.0
    return abs(a - b) / max(abs(a), abs(b))


def jobs_of(budget, measures, chunk: int) -> list:
    """The (measure, args) tasks of one evaluation (as compute_margins lists them)."""
    jobs = []
    for m in measures:
        if m == "basin" and _basin_groups() is not None:  # bisections in lockstep
            jobs += [("basins", g) for g in _basin_groups()]
        elif m == "basin" or m == "ceiling":
            jobs += [(m, (i, s)) for i in range(6) for s in (1, -1)]
        elif m == "curve":
            jobs += [(m, (r,)) for r in budget.curve_sizes]
        elif m == "terrain":
            jobs += [(m, (v,)) for v in budget.terrain_sigmas]
        elif m == "mfpt":
            chunks = range(math.ceil(budget.mfpt_robots / chunk))
            jobs += [(m, (v, c)) for v in budget.mfpt_sigmas for c in chunks]
        elif m == "window":
            jobs += [(m, (k, s)) for k in ("alpha_deg", "kc") for s in (-1, 1)]
        elif m == "push":
            jobs += [(m, ("xdot", v, j)) for j, v in enumerate(budget.push_xdot)]
            jobs += [(m, ("th1dot", v, j)) for j, v in enumerate(budget.push_th1dot)]
    return jobs


def _basin_groups():
    """The checkout's lockstep basin tasks' directions, None before they existed."""
    try:
        from bound_env.analysis.margins.basin import BASIN_GROUPS
    except ImportError:
        return None
    return BASIN_GROUPS


def _per_direction(jobs: list, results: list) -> list:
    """The basin results per direction in the order (0, +), (0, -), (1, +), ..., whether the
    checkout ran them one task per direction or in lockstep groups (``basins``)."""
    by_dir = {}
    for (name, args), r in zip(jobs, results, strict=True):
        if name == "basins":
            by_dir.update(
                {(int(i), int(s)): b for (i, s), b in zip(args, r["basins"], strict=True)}
            )
        else:
            by_dir[tuple(args)] = r
    return [by_dir[(i, s)] for i in range(6) for s in (1, -1)]


def measure(policy: str, budget_name: str, measures: list[str], gait: str) -> dict:
    """{measure: {"seconds", "strides", "tasks", "load"}} for this checkout, serially."""
    from dataclasses import replace

    import numpy as np

    from agents.runtime.policy import load_controller
    from bound_env.model.params import load_gait

    Setup, run_task, setup_key, as_budget, strides, where, chunk = _api()
    budget = as_budget(budget_name)
    ctrl = load_controller(policy, gait=gait)
    z_star = np.asarray(load_gait(gait).z0, dtype=float)
    setup = Setup(ctrl, gait, budget, z_star, key=setup_key(ctrl, gait, budget))
    out = {}

    def timed(name, jobs):
        n0 = strides[0] if strides is not None else 0
        t0 = time.perf_counter()
        results = [run_task(setup, task, args) for task, args in jobs]
        dt = time.perf_counter() - t0
        if name == "basin":
            results = _per_direction(jobs, results)
        out[name] = {
            "seconds": dt,
            "strides": (strides[0] - n0) if strides is not None else None,
            "tasks": len(jobs),
            "load": os.getloadavg()[0],
            "results": _merge_chunks([_untimed(r) for r in results]),
        }
        print(f"  {where}: {name:8s} {dt:8.1f} s", file=sys.stderr, flush=True)
        return results

    cyc = timed("cycle", [("cycle", ())])[0]
    setup = replace(
        setup,
        z_cl=np.array(cyc["z_cl"]),
        cycle_steps=int(cyc["cycle_steps"]),
        period=float(cyc["period"]),
    )
    for m in measures:
        if m != "cycle":
            timed(m, jobs_of(budget, [m], chunk))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policy", default="lqr")
    ap.add_argument("--budget", default="quick")
    ap.add_argument("--gait", default="default")
    ap.add_argument("--measures", default=",".join(MEASURES))
    ap.add_argument("--base", default=None, help="a checkout to compare with (same tasks)")
    ap.add_argument("--json", default=None, help="write the figures to this JSON file")
    ap.add_argument("--raw", action="store_true", help=argparse.SUPPRESS)  # one checkout
    a = ap.parse_args(argv)
    measures = [m for m in a.measures.split(",") if m]
    bad = sorted(set(measures) - set(MEASURES))
    if bad:
        ap.error(f"--measures: unknown {bad}; known: {', '.join(MEASURES)}")
    if a.raw:
        measure(a.policy, "test", measures, a.gait)  # compile (or load) every kernel first
        print(json.dumps(measure(a.policy, a.budget, measures, a.gait)))
        return 0
    base = None
    if a.base:
        root = Path(a.base).resolve()
        if not (root / "bound_env").is_dir():
            ap.error(f"--base: {root} is not a bound_env checkout")
        cmd = [sys.executable, str(Path(__file__).resolve()), "--raw", "--policy", a.policy]
        cmd += ["--budget", a.budget, "--gait", a.gait, "--measures", ",".join(measures)]
        env = dict(os.environ, PYTHONPATH=str(root))
        print(f"base: {root}", file=sys.stderr)
        r = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
        if r.returncode != 0:
            print(r.stderr, file=sys.stderr)
            return 1
        base = json.loads(r.stdout.strip().splitlines()[-1])
    print("this checkout", file=sys.stderr)
    measure(a.policy, "test", measures, a.gait)  # compile (or load) every kernel first
    new = measure(a.policy, a.budget, measures, a.gait)
    total = sum(v["seconds"] for v in new.values())
    print(f"\n{a.policy}, budget {a.budget}, one process, no cache")
    head = "| measure | tasks | seconds | share | strides | strides/s | load |"
    sep = "| --- | --- | --- | --- | --- | --- | --- |"
    if base:
        head += " base seconds | base load | speed-up | identical tasks | max rel. difference |"
        sep += " --- | --- | --- | --- | --- |"
    print(head)
    print(sep)
    rows = list(new) + ["total"]
    for m in rows:
        v = new.get(m) or {
            "seconds": total,
            "tasks": sum(x["tasks"] for x in new.values()),
            "strides": sum(x["strides"] or 0 for x in new.values()),
            "load": os.getloadavg()[0],
        }
        n = v["strides"]
        line = (
            f"| {m} | {v['tasks']} | {v['seconds']:.1f} | {v['seconds'] / total:.0%} | "
            f"{n if n is not None else '-'} | "
            f"{(n / v['seconds']) if n else 0:.0f} | {v['load']:.2f} |"
        )
        if base:
            b = base.get(m) or {
                "seconds": sum(x["seconds"] for x in base.values()),
                "load": float("nan"),
            }
            line += f" {b['seconds']:.1f} | {b['load']:.2f} | {b['seconds'] / v['seconds']:.2f}x |"
            if m != "total":
                d = [max_difference(x, y) for x, y in zip(v["results"], b["results"], strict=True)]
                worst = max(d, default=0.0)
                line += f" {sum(x == 0.0 for x in d)}/{len(d)} | {worst:.1e} |"
            else:
                line += " | |"
        print(line)
    if a.json:
        Path(a.json).write_text(json.dumps({"new": new, "base": base}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
