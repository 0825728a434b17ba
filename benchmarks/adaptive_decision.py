"""Decision time of the learned adaptive controller, history update included, against the LQR's.

Run by hand: ``PYTHONPATH=. python benchmarks/adaptive_decision.py [--policy adaptive]
[--strides 2000]``. One episode per ±10 % plant (validation seed 777's plants) from the
nominal z*, through the one stride map; each decision is ``on_apex(z)`` (features from the
history, the network, the history update), timed alone with ``time.perf_counter``; the LQR's
``on_apex`` is timed on the same apexes in the same run, so the ratio is load-independent.
The machine's load (``uptime``) is printed beside the figures; nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--policy", default="adaptive")
    ap.add_argument("--strides", type=int, default=2000)
    args = ap.parse_args(argv)
    from agents.experts.adaptive import true_map, validation_plants
    from agents.runtime.policy import load_controller
    from bound_env.control import load_controller as classical

    torch_threads = os.environ.get("OMP_NUM_THREADS")
    ctrl = load_controller(args.policy)
    mpc = classical("mpc")
    lqr = mpc.lqr
    plants = validation_plants(mpc, "pm10", 32)
    t_ctrl, t_lqr = [], []
    done, p = 0, 0
    while done < args.strides:
        plant = true_map(mpc, plants[p % len(plants)])
        p += 1
        ctrl.reset()
        z = mpc.z_ref.copy()
        for _ in range(100):
            t0 = time.perf_counter()
            lqr.on_apex(z, 0.0)
            t1 = time.perf_counter()
            ctrl.on_apex(z, 0.0)
            t2 = time.perf_counter()
            t_lqr.append(t1 - t0)
            t_ctrl.append(t2 - t1)
            done += 1
            z = plant.map(z, mpc.profile_actions(ctrl._u)[0])
            if z is None or done >= args.strides:
                break
    a, b = np.array(t_ctrl) * 1e3, np.array(t_lqr) * 1e3
    print(f"load: {os.getloadavg()[0]:.2f} (1 min), OMP_NUM_THREADS={torch_threads}")
    print(
        f"{args.policy}: {len(a)} decisions, p50 {np.percentile(a, 50):.4f} ms, "
        f"p99 {np.percentile(a, 99):.4f} ms, max {a.max():.4f} ms"
    )
    print(
        f"lqr:  p50 {np.percentile(b, 50):.4f} ms, p99 {np.percentile(b, 99):.4f} ms; "
        f"ratio p50 {np.percentile(a, 50) / np.percentile(b, 50):.1f}x"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
