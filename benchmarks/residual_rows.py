"""The step-level residual policy in the batched closed loop: all robots' actions in one call
(`ResidualController.act_rows`) against one call per robot (the loop before it).

Run by hand: ``PYTHONPATH=. python benchmarks/residual_rows.py [--policy step-ppo/s0]
[--robots 64] [--strides 20] [--repeats 3]``. The robots start at z* + 0.2 |z*| d (directions of
seed 3, past the safe radius, so the network acts) and run ``--strides`` strides through
`ClosedLoop.run_many` (the margins' loop); the two ways alternate ``--repeats`` times in one
process, so their ratio is taken under the same load. The machine's load (1-minute average) is
printed beside the figures; nothing is asserted. The outcomes of the two ways are compared.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policy", default="step-ppo/s0")
    ap.add_argument("--robots", type=int, default=64)
    ap.add_argument("--strides", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    from agents.runtime.policy import load_controller
    from agents.runtime.residual import ResidualController
    from bound_env.analysis.margins import random_directions
    from bound_env.analysis.margins.closed_loop import ClosedLoop

    ctrl = load_controller(args.policy)
    zs = np.asarray(ctrl.base.z_ref, dtype=float)
    Z = zs + 0.2 * np.abs(zs) * random_directions(args.robots, 3)
    rows = ResidualController.act_rows

    def run(batched: bool):
        ResidualController.act_rows = rows if batched else None
        try:
            t0 = time.perf_counter()
            out = ClosedLoop(ctrl).run_many(Z, zs, args.strides)
            return time.perf_counter() - t0, out
        finally:
            ResidualController.act_rows = rows

    run(True)  # compile and warm
    times = {True: [], False: []}
    outs = {}
    for _ in range(args.repeats):
        for batched in (False, True):
            dt, outs[batched] = run(batched)
            times[batched].append(dt)
    a, b = np.median(times[False]), np.median(times[True])
    same = sum(x == y for x, y in zip(outs[False], outs[True], strict=True))
    print(f"load: {os.getloadavg()[0]:.2f} (1 min)")
    print(
        f"{args.policy}: {args.robots} robots, {args.strides} strides, median of "
        f"{args.repeats}: one call per robot {a:.2f} s, act_rows {b:.2f} s, ratio {a / b:.2f}x"
    )
    print(f"outcomes equal: {same} of {args.robots}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
