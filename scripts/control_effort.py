"""On-cycle and recovery effort of each controller, in the step env (PassiveBound-v0).

    PYTHONPATH=. .venv/bin/python scripts/control_effort.py [--policy lqr ...] [--out DIR]

For each controller: its closed-loop cycle z_cl (as `bound-env margins` finds it), the mean
|tau| over one stride of that cycle (on-cycle effort), and the recovery effort: the
time-averaged |tau| over the first `STRIDES` strides after a perturbation z_cl + r |z*| u,
for `N_DIRS` random directions u (`bound_env.analysis.margins.random_directions`, scaled to
max |u_i| = 1) at each relative size r in `SIZES`, with the fraction of those runs that
returned (max-abs apex error < 1e-4 within 100 strides). Writes ``effort.csv`` and ``effort.json``.

Bad input (an empty or unknown policy, an ``--out`` that cannot be written) is a one-line
error and exit 2 before any policy is measured.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path

import numpy as np

from agents.runtime.policy import load_controller
from bound_env.analysis.margins import RETURN_TOL, ClosedLoop, fd_steps, random_directions
from bound_env.commands.cli_args import check_writable
from bound_env.files.cache import atomic_write
from bound_env.model.numerics import map_fixed_point
from bound_env.model.params import load_gait
from bound_env.sim.stride_protocol import reset_controller

SIZES = (0.02, 0.05)  # relative perturbation sizes (the passive basin_min is ~0.02)
N_DIRS = 12
STRIDES = 10  # strides over which the recovery effort is averaged
DEFAULT_POLICIES = ("passive", "agents/policies/archive/ppo-v1", "lqr", "deadbeat", "damping")


def recovery(loop: ClosedLoop, z0, z_cl) -> tuple[float, bool]:
    """(time-averaged |tau| over the first STRIDES strides, returned within 100 strides)."""
    z, impulse, time_total = np.asarray(z0, dtype=float), 0.0, 0.0
    reset_controller(loop.controller)  # one episode
    for n in range(100):
        out = loop.next_stride(z)
        if out.z1 is None:
            return (impulse / time_total if time_total else float("nan")), False
        if n < STRIDES:
            impulse += out.effort * out.period
            time_total += out.period
        z = out.z1
        if n >= STRIDES - 1 and np.max(np.abs(z - z_cl)) < RETURN_TOL:
            return impulse / time_total, True
    return impulse / time_total, False


def policy_arg(text: str) -> str:
    """An argparse ``type``: a policy's name or path, not empty."""
    if not text.strip():
        raise argparse.ArgumentTypeError("a policy must be a name or a path, got ''")
    return text


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--policy",
        action="append",
        type=policy_arg,
        help=f"a policy, repeatable (default: {', '.join(DEFAULT_POLICIES)})",
    )
    ap.add_argument("--out", default="out/control_effort", help="folder (default: %(default)s)")
    return ap


def main(argv=None) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    try:  # every policy and the folder checked before the first is measured
        check_writable(args.out, "--out")
        ctrls = {p: load_controller(p, gait="default") for p in args.policy or DEFAULT_POLICIES}
    except (OSError, ValueError, TypeError) as e:
        ap.error(" ".join(str(e).split()))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    z_star = load_gait("default").z0
    rows = []
    for policy, ctrl in ctrls.items():
        loop = ClosedLoop(ctrl)
        z_cl, res, _ = map_fixed_point(loop.map, z_star, fd_steps(z_star))
        cyc = loop.stride(z_cl)
        row = {
            "policy": policy,
            "max_torque": loop.max_torque,
            "fixed_point_residual": res,
            "on_cycle_effort": cyc.effort,
        }
        for r in SIZES:
            efforts, wins = [], 0
            for u in random_directions(N_DIRS):
                e, ok = recovery(loop, z_cl + r * np.abs(z_star) * u, z_cl)
                wins += ok
                if ok:
                    efforts.append(e)
            row[f"recovery_effort_r{r:g}"] = float(np.mean(efforts)) if efforts else None
            row[f"returned_r{r:g}"] = wins / N_DIRS
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    buf = io.StringIO()
    w = csv.DictWriter(buf, list(rows[0]))
    w.writeheader()
    w.writerows(rows)
    for name, text in (
        ("effort.csv", buf.getvalue()),
        ("effort.json", json.dumps(rows, indent=2) + "\n"),
    ):
        atomic_write(out / name, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
