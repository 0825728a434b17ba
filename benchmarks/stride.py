"""Median time per stride of the fast and the reference back-ends, measured in the same run.

Run by hand: ``.venv/bin/python benchmarks/stride.py [--gait default] [--rtol 1e-10]``.
Both back-ends integrate the same stride (the default gait's fixed point); the reference is
timed at the same tolerance and at its own default (1e-12).
"""

import argparse
import statistics
import time

from bound_env.model.hybrid import simulate_stride
from bound_env.model.params import load_gait


def median_time(fn, repeats, inner):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        times.append((time.perf_counter() - t0) / inner)
    return statistics.median(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--gait", default="default")
    ap.add_argument("--rtol", type=float, default=1e-10)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    gait = load_gait(args.gait)
    z, p, tol = gait.z0, gait.params, args.rtol

    def fast():
        return simulate_stride(z, p, backend="fast", rtol=tol, atol=tol)

    def ref_same():
        return simulate_stride(z, p, backend="reference", rtol=tol, atol=tol)

    def ref_default():
        return simulate_stride(z, p, backend="reference")

    fast()  # compile / load the on-disk cache
    ref_same()
    # alternate the back-ends so that machine load affects both alike
    t_fast, t_ref, t_ref12 = [], [], []
    for _ in range(args.repeats):
        t_fast.append(median_time(fast, 3, 200))
        t_ref.append(median_time(ref_same, 1, 5))
        t_ref12.append(median_time(ref_default, 1, 3))
    tf, tr, tr12 = (statistics.median(x) for x in (t_fast, t_ref, t_ref12))
    print(f"gait {gait.path.name}: one stride, period {fast().t_end:.4f} s")
    print(f"fast      (rtol {tol:g}):  {tf * 1e3:8.4f} ms/stride")
    print(f"reference (rtol {tol:g}):  {tr * 1e3:8.4f} ms/stride   ratio {tr / tf:6.1f}x")
    print(f"reference (rtol 1e-12):    {tr12 * 1e3:8.4f} ms/stride   ratio {tr12 / tf:6.1f}x")


if __name__ == "__main__":
    main()
