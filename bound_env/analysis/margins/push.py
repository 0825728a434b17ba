"""Push recovery (JSON ``push``): the success rate against the size of a kick in forward speed
or pitch rate at a random control instant of a stride."""

from __future__ import annotations

import numpy as np

from .budget import sample_seeds
from .closed_loop import Setup, loop_for

Y_XDOT, Y_TH1DOT = 4, 6  # indices in the full state y = [x, y, th1, th2, xd, yd, th1d, th2d]


def task_push(setup: Setup, kind: str, size: float, index: int) -> dict:
    loop = loop_for(setup)
    y_index = {"xdot": Y_XDOT, "th1dot": Y_TH1DOT}[kind]
    rng = np.random.default_rng(
        [index, 0 if kind == "xdot" else 1, *sample_seeds(setup.seed)["push"]]
    )
    n = setup.budget.push_samples
    steps = max(1, setup.cycle_steps - 1)
    kicks = []
    for _ in range(n):
        k = int(rng.integers(0, steps))
        sign = 1.0 if rng.random() < 0.5 else -1.0
        kicks.append((k, y_index, sign * size))
    runs = loop.run_many([setup.z_cl] * n, setup.z_cl, setup.budget.basin_strides, kicks=kicks)
    wins = sum(ok for ok, _, _ in runs)
    return {"kind": kind, "size": size, "success": wins / n, "n": n}
