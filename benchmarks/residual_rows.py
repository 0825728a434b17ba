"""The step-level residual policy in the batched closed loop: all robots' actions in one call
(`ResidualController.act_rows`, batched end to end: the bases' interval torques in one array,
`bound_env.sim.stride_protocol.profile_rows`, the features and the network's forward pass) against
one call per robot (the loop before it), and against act_rows with each base called row by row
(the network alone batched: the loop of the last page).

Run by hand: ``PYTHONPATH=. python benchmarks/residual_rows.py [--policy step-ppo/s0]
[--robots 64] [--strides 20] [--repeats 3]``. The robots start at z* + 0.2 |z*| d (directions of
seed 3, past the safe radius, so the network acts) and run ``--strides`` strides through
`ClosedLoop.run_many` (the margins' loop); the three ways alternate ``--repeats`` times in one
process, so their ratios are taken under the same load. The machine's load (1-minute average)
is printed beside the figures; nothing is asserted. The outcomes of the ways are compared.
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
    import agents.runtime.residual as residual_mod

    rows, batched_bases = ResidualController.act_rows, residual_mod.profile_rows
    ways = {
        "one call per robot": (None, batched_bases),
        "act_rows, bases row by row": (rows, lambda copies, obs: None),
        "act_rows end to end": (rows, batched_bases),
    }

    def run(way: str):
        ResidualController.act_rows, residual_mod.profile_rows = ways[way]
        try:
            t0 = time.perf_counter()
            out = ClosedLoop(ctrl).run_many(Z, zs, args.strides)
            return time.perf_counter() - t0, out
        finally:
            ResidualController.act_rows, residual_mod.profile_rows = rows, batched_bases

    run("act_rows end to end")  # compile and warm
    times = {w: [] for w in ways}
    outs = {}
    load = os.getloadavg()[0]
    for _ in range(args.repeats):
        for way in ways:
            dt, outs[way] = run(way)
            times[way].append(dt)
    med = {w: float(np.median(t)) for w, t in times.items()}
    print(f"load: {load:.2f} before, {os.getloadavg()[0]:.2f} after (1 min)")
    print(f"{args.policy}: {args.robots} robots, {args.strides} strides, median of {args.repeats}:")
    base = med["one call per robot"]
    for way, t in med.items():
        print(f"  {way}: {t:.2f} s, {base / t:.2f}x the per-robot loop")
    ref = outs["one call per robot"]
    for way in list(ways)[1:]:
        same = sum(repr(x) == repr(y) for x, y in zip(ref, outs[way], strict=True))
        print(f"outcomes of {way} equal to the per-robot loop's: {same} of {args.robots}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
