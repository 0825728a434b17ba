"""Basin stability (JSON ``basin_curve``): the outcome of the closed loop from random directions
at one perturbation size, and the controller's decision times measured on those runs."""

from __future__ import annotations

import numpy as np

from .budget import random_directions, sample_seeds
from .closed_loop import Setup, loop_for


def task_curve(setup: Setup, size: float) -> dict:
    """Basin stability at one size: the outcome (1: returned) from each random direction."""
    loop = loop_for(setup)
    zs, zc = setup.z_star, setup.z_cl
    dirs = random_directions(setup.budget.curve_dirs, sample_seeds(setup.seed)["directions"])
    timed = getattr(loop.controller, "decision_seconds", None)  # a controller that times itself
    n0 = len(timed) if timed is not None else 0
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
    return out


def decision_summary(curve: list) -> dict | None:
    """p50, p99, mean and max of a controller's decision times over the random-direction
    curve's closed loops (None for a controller that does not time its decisions)."""
    ts = [t for c in curve for t in c.get("decision_seconds", [])]
    if not any("decision_seconds" in c for c in curve) or not ts:
        return None
    a = np.asarray(ts)
    return {
        "p50": float(np.median(a)),
        "p99": float(np.quantile(a, 0.99)),
        "mean": float(a.mean()),
        "max": float(a.max()),
        "n": int(a.size),
        "measured_on": "every decision of the random-direction curve's closed loops",
    }
