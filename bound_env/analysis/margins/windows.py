"""Survival windows of a gait parameter around its nominal value (JSON ``slope_window_deg``,
``kc_window``): an outward doubling scan, then bisection."""

from __future__ import annotations

import math

from .budget import WINDOW_SCAN
from .closed_loop import Setup, loop_for


def task_window(setup: Setup, key: str, side: int) -> dict:
    """Edge of the survival window of gait parameter ``key`` on one side of nominal."""
    from bound_env.model.params import load_gait

    nominal = load_gait(setup.gait).params.to_gait_dict()[key]
    overrides0 = dict(setup.controller.env_kwargs.get("gait_overrides") or {})
    nominal = float(overrides0.get(key, nominal))
    first, limit = WINDOW_SCAN[key]
    b = setup.budget

    def survives(offset: float) -> bool:
        value = nominal + side * offset
        if key == "kc" and value <= 0:
            return False
        try:
            loop = loop_for(setup, {key: value})
        except ValueError:  # invalid parameter value
            return False
        return loop.run(setup.z_cl, setup.z_cl, b.window_strides, survive_only=True)[0]

    good, bad, d = 0.0, None, first
    while d <= limit:
        if survives(d):
            good, d = d, 2 * d
        else:
            bad = d
            break
    if bad is None:
        return {"edge": nominal + side * good, "capped": True, "nominal": nominal}
    if good == 0.0 and not survives(0.0):
        return {"edge": math.nan, "capped": False, "nominal": nominal}
    for _ in range(b.window_iters):
        mid = 0.5 * (good + bad)
        if survives(mid):
            good = mid
        else:
            bad = mid
    return {"edge": nominal + side * good, "capped": False, "nominal": nominal}
