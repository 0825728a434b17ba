"""The MPC's decision time against another version's, timed side by side in one run:

    python benchmarks/mpc_decisions.py                     # this code against 852f480
    python benchmarks/mpc_decisions.py --base ../wt-base   # against a checkout
    python benchmarks/mpc_decisions.py --spec my-mpc.yaml --rounds 5

The states are the results page's (`agents.results.decisions.timing_states`: the test directions'
starts z* + r |z*| d past the safe radius, the states every planner of the page is timed on).
Each version runs in its own worker process (its own checkout on ``PYTHONPATH``, its own
``mpc`` spec, warmed up on one decision), and the two decide the same state one after the
other, state by state, so that a change of the machine's load hits both alike; the order of
the two alternates from round to round. Each decision is timed around ``coefficients(z)``
as the page times it (`agents.results.decisions.time_decisions`).

Printed: per round, each version's p50 and p99 over the states and the ratios base / this
(larger: this code is faster), and the same over each state's fastest of the rounds (the
least disturbed by other jobs); the load average (``uptime``) beside every round; and how
many of the plans are the same coefficients, bit for bit, and who decided (the gate, the
LQR's plan, an override) in each version. Ratios, not seconds, are the figures to compare on
a shared machine.

Without ``--base``, the base is the commit ``--commit`` (default 852f480, the code the issue
measured against), unpacked once with ``git archive`` into the temporary directory and kept
there (its compiled code is cached beside it).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BASE_COMMIT = "852f480"

WORKER = r"""
import sys, time
import numpy as np
from bound_env.control import load_controller
ctrl = load_controller(sys.argv[1])
def decide(z):
    t0 = time.perf_counter()
    u = ctrl.coefficients(z)
    t = time.perf_counter() - t0
    return t, u
print("ready", flush=True)
for line in sys.stdin:
    z = np.array([float.fromhex(x) for x in line.split()])
    t, u = decide(z)
    print(t.hex(), getattr(ctrl, "_kind", "-"), *[float(x).hex() for x in u], flush=True)
"""


class Worker:
    """One version's MPC in its own process: ``decide(z)`` -> (seconds, kind, coefficients)."""

    def __init__(self, checkout: Path, spec: str):
        env = dict(os.environ, PYTHONPATH=str(checkout), OMP_NUM_THREADS="1")
        env.update(OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
        self.p = subprocess.Popen(
            [sys.executable, "-c", WORKER, spec],
            cwd=checkout,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        line = self.p.stdout.readline()
        if line.strip() != "ready":
            raise SystemExit(f"the worker on {checkout} did not start (spec {spec!r})")

    def decide(self, z) -> tuple[float, str, np.ndarray]:
        self.p.stdin.write(" ".join(float(x).hex() for x in z) + "\n")
        self.p.stdin.flush()
        t, kind, *u = self.p.stdout.readline().split()
        return float.fromhex(t), kind, np.array([float.fromhex(x) for x in u])

    def close(self) -> None:
        self.p.stdin.close()
        self.p.wait(timeout=60)


def base_checkout(commit: str) -> Path:
    """The commit's tree, unpacked once into the temporary directory (kept: its compiled
    code is cached there)."""
    out = Path(tempfile.gettempdir()) / f"bound-env-bench-{commit}"
    if not (out / "bound_env").is_dir():
        tmp = out.with_name(out.name + f".part{os.getpid()}")
        tmp.mkdir(parents=True, exist_ok=True)
        tar = subprocess.run(
            ["git", "-C", str(ROOT), "archive", commit], capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(tmp)], input=tar, check=True)
        tmp.rename(out)
    return out


def stats(ts) -> tuple[float, float]:
    return float(np.percentile(ts, 50)), float(np.percentile(ts, 99))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path, help="a checkout of the base version")
    ap.add_argument("--commit", default=BASE_COMMIT, help="the base commit (without --base)")
    ap.add_argument("--spec", default="mpc", help="this code's mpc spec (name or .yaml)")
    ap.add_argument("--base-spec", default="mpc", help="the base's mpc spec")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seed", type=int, default=12345, help="the directions (the page's)")
    args = ap.parse_args(argv)
    if args.rounds < 1:
        raise SystemExit("--rounds must be at least 1")

    from agents.results.decisions import timing_states
    from bound_env.model.params import load_gait

    Z = timing_states(load_gait("default").z0, args.seed)
    base = args.base.resolve() if args.base else base_checkout(args.commit)
    print(f"cores: {os.cpu_count()}, load average at start: {os.getloadavg()}")
    print(f"{len(Z)} apex states (seed {args.seed}); base {base}; this {ROOT}")
    workers = {"base": Worker(base, args.base_spec), "this": Worker(ROOT, args.spec)}
    for w in workers.values():
        w.decide(Z[0])  # compiled and warm
    times = {k: np.zeros((args.rounds, len(Z))) for k in workers}
    plans, kinds = {}, {}
    print("| round | base p50 ms | this p50 ms | p50 ratio | base p99 ms | this p99 ms "
          "| p99 ratio | load |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in range(args.rounds):
        order = list(workers) if r % 2 == 0 else list(workers)[::-1]
        t0 = time.perf_counter()
        for i, z in enumerate(Z):
            for k in order:
                times[k][r, i], kind, u = workers[k].decide(z)
                plans.setdefault(k, {})[i], kinds.setdefault(k, {})[i] = u, kind
        row(f"{r + 1} ({time.perf_counter() - t0:.0f} s)", times["base"][r], times["this"][r])
    row("fastest of each state", times["base"].min(axis=0), times["this"].min(axis=0))
    for w in workers.values():
        w.close()
    same = sum(np.array_equal(plans["base"][i], plans["this"][i]) for i in range(len(Z)))
    print(f"\nthe same plan (bit for bit) in {same} of {len(Z)} states")
    for k in workers:
        counts = {c: list(kinds[k].values()).count(c) for c in ("gate", "lqr", "override")}
        print(f"{k}: decided by {counts}")


def row(name: str, base, this) -> None:
    (b50, b99), (t50, t99) = stats(base), stats(this)
    print(
        f"| {name} | {1e3 * b50:.2f} | {1e3 * t50:.2f} | {b50 / t50:.2f}x | {1e3 * b99:.1f} "
        f"| {1e3 * t99:.1f} | {b99 / t99:.2f}x | {os.getloadavg()[0]:.2f} |",
        flush=True,
    )


if __name__ == "__main__":
    main()
