"""Basin stability (JSON ``basin_curve``): the outcome of the closed loop from random directions
at one perturbation size, and the controller's decision times measured on those runs."""

from __future__ import annotations

import numpy as np

from ...sim.stride_protocol import DECISION_KINDS
from .budget import random_directions, sample_seeds
from .closed_loop import Setup, loop_for


def task_curve(setup: Setup, size: float) -> dict:
    """Basin stability at one size: the outcome (1: returned) from each random direction."""
    loop = loop_for(setup)
    zs, zc = setup.z_star, setup.z_cl
    dirs = random_directions(setup.budget.curve_dirs, sample_seeds(setup.seed)["directions"])
    timed = getattr(loop.controller, "decision_seconds", None)  # a controller that times itself
    n0 = len(timed) if timed is not None else 0
    kinds = Decisions(loop.controller)
    runs = loop.run_many(zc + size * np.abs(zs) * dirs, zc, setup.budget.basin_strides)
    outcomes = [int(ok) for ok, _, _ in runs]
    wins = sum(outcomes)
    out = {
        "size": size,
        "success": wins / len(dirs),
        "n": len(dirs),
        "k": int(wins),
        "outcomes": outcomes,
    }
    if timed is not None:  # every decision of these closed loops [s]
        out["decision_seconds"] = [float(t) for t in timed[n0:]]
    return kinds.into(out)


class Decisions:
    """Counts of who made a gated controller's apex decisions during a task (its
    ``decision_kinds``, `bound_env.control.mpc.DECISION_KINDS`); nothing for others."""

    def __init__(self, controller):
        self.kinds = getattr(controller, "decision_kinds", None)
        self.n0 = len(self.kinds) if self.kinds is not None else 0

    def into(self, out: dict) -> dict:
        """``out`` with ``decision_kinds``: {kind: count} of the decisions since __init__."""
        if self.kinds is not None:
            new = self.kinds[self.n0 :]
            out["decision_kinds"] = {k: int(sum(1 for x in new if x == k)) for k in DECISION_KINDS}
        return out


def decision_shares(results: list) -> dict | None:
    """The shares of the decisions in tasks' ``decision_kinds`` (None without any)."""
    counts = [r["decision_kinds"] for r in results if r.get("decision_kinds")]
    if not counts:
        return None
    total = {k: sum(c.get(k, 0) for c in counts) for k in DECISION_KINDS}
    n = sum(total.values())
    shares = {k: (total[k] / n if n else None) for k in DECISION_KINDS}
    return {**shares, "n": n, "counts": total}


def decision_summary(curve: list) -> dict | None:
    """p50, p99, mean and max of a controller's decision times over the random-direction
    curve's closed loops (None for a controller that does not time its decisions)."""
    ts = [t for c in curve for t in c.get("decision_seconds", [])]
    if not any("decision_seconds" in c for c in curve) or not ts:
        return None
    return {
        **time_stats(ts),
        "measured_on": "every decision of the random-direction curve's closed loops",
    }


def time_stats(ts) -> dict:
    """p50, p99, mean, max and count of decision times [s]."""
    a = np.asarray(ts, dtype=float)
    return {
        "p50": float(np.median(a)),
        "p99": float(np.quantile(a, 0.99)),
        "mean": float(a.mean()),
        "max": float(a.max()),
        "n": int(a.size),
    }
