"""A cheap validation curve of a stride-level controller on the stride map (not the yardstick).

``python -m agents.experts.stride_validation POLICY [POLICY ...]`` prints `stride_curve` of each
policy (a name or folder for `agents.runtime.policy.load_controller`) as JSON lines. This module
sits above `agents.runtime.policy` (it imports it); nothing below imports it.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from ..runtime.policy import load_controller

VALIDATION_SEED = 2024  # margins' random directions use 12345; these are other directions


def stride_curve(
    ctrl,
    sizes=(0.05, 0.1, 0.15, 0.2, 0.25, 0.3),
    n_dirs: int = 64,
    seed: int = VALIDATION_SEED,
    strides: int = 60,
    tol: float = 1e-4,
    gait: str = "default",
    settle: int = 200,
) -> dict:
    """Return probability of a stride-level controller (``stride_action(z)``; a controller
    without it is passive) against the relative start size r, on the *stride* map of
    PassiveBoundStride-v1 (the one stride map, rtol 1e-10), from z* + r |z*| xi with ``n_dirs``
    directions of seed ``seed`` (disjoint from margins' seed-12345 directions), around the
    closed loop's own cycle z_cl (``settle`` strides from z*; as margins, starts at
    z_cl + r |z*| xi). Returned: within ``tol`` (SI, max-abs) of z_cl in ``strides`` strides
    without a fall. ``effort``: mean |tau| over a stride of the cycle [N m].
    A validation curve, cheaper than `bound_env.analysis.margins` and no substitute for it."""
    from bound_env.sim.stride_task import StrideTask

    task = StrideTask(gait=gait, basis="windows", K=getattr(getattr(ctrl, "basis", None), "K", 4))
    act = getattr(ctrl, "stride_action", None)
    z_ref = task.z_ref
    u = np.random.default_rng(seed).standard_normal((n_dirs, 6))
    dirs = u / np.max(np.abs(u), axis=1, keepdims=True)
    taus_of = (
        (lambda z: task.basis.torques(act(z), task.max_torque))
        if act is not None
        else (lambda z: np.zeros(task.basis.phi.shape[0]))
    )
    z_cl, effort = z_ref.copy(), 0.0  # the closed loop's own cycle, by iteration from z*
    for _ in range(settle):
        o = task.sim.run_torques(z_cl, taus_of(z_cl))
        if o.z1 is None:
            return {
                "sizes": list(sizes),
                "p_return": [0.0] * len(sizes),
                "n_dirs": n_dirs,
                "seed": seed,
                "r50": 0.0,
                "failure_on_cycle": o.failure,
            }
        z_cl, effort = o.z1, o.effort
    out = []
    for r in sizes:
        ok = 0
        for xi in dirs:
            z = z_cl + r * np.abs(z_ref) * xi
            for _ in range(strides):
                o = task.sim.run_torques(z, taus_of(z))
                if o.z1 is None:
                    break
                z = o.z1
                if np.max(np.abs(z - z_cl)) < tol:
                    ok += 1
                    break
        out.append(ok / n_dirs)
    return {
        "sizes": list(sizes),
        "p_return": out,
        "n_dirs": n_dirs,
        "seed": seed,
        "r50": r50_of(sizes, out),
        "effort": effort,
        "fixed_point_shift": (z_cl - z_ref).tolist(),
    }


def r50_of(sizes, p) -> float:
    """Largest size up to which the return rate stays >= 0.5, linearly interpolated at the
    first crossing (0 if the first size is already below 0.5)."""
    if not p or p[0] < 0.5:
        return 0.0
    for i in range(1, len(p)):
        if p[i] < 0.5:
            f = (p[i - 1] - 0.5) / (p[i - 1] - p[i])
            return float(sizes[i - 1] + f * (sizes[i] - sizes[i - 1]))
    return float(sizes[-1])


def main(argv=None) -> int:
    """``python -m agents.experts.stride_validation POLICY [POLICY ...]``: the validation curve as
    JSON lines."""
    import argparse

    p = argparse.ArgumentParser(
        prog="python -m agents.experts.stride_validation", description=main.__doc__
    )
    p.add_argument("policies", nargs="+", help="passive, lqr, a spec .yaml or a policy dir")
    p.add_argument("--n-dirs", type=int, default=64)
    p.add_argument("--seed", type=int, default=VALIDATION_SEED)
    args = p.parse_args(argv)
    for path in args.policies:
        try:
            ctrl = load_controller(path)
        except (FileNotFoundError, ValueError) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        r = stride_curve(ctrl, n_dirs=args.n_dirs, seed=args.seed)
        print(json.dumps({"policy": str(path), **r}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
