"""Speed of the basin atlas (`bound_env.analysis.basin`), run by hand:

    python benchmarks/basin_map.py                 # 64x64 passive and shipped policy
    python benchmarks/basin_map.py --grid 32 --policy-grid 16   # quicker
    python benchmarks/basin_map.py --no-dask --also lqr,default,mpc --json docs/timings.json

Prints starts per second and ratios, all timed in this run on this machine:

- passive, one process (in-process executor) vs a local process pool of 2 workers vs a Dask
  LocalCluster of 2 single-threaded workers (the same chunks);
- the shipped policy with the process pool of 2 workers.

Each executor is opened and warmed up first (one small chunk per worker, so that every worker
has loaded the compiled code), then the whole grid is timed without the chunk cache.
Cluster start-up is timed separately. The machine's load average is printed beside: other
jobs on the machine slow every row, and the ratios between rows are what to compare.
``--json PATH`` records each case's grid time in the ``basin_map`` section of PATH
(`bound_env.files.cache.record_section`: with the load, the commit and the command); the docs quote
``docs/timings.json``'s (`agents.results.numbers`, ``basinmap(NAME)``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from bound_env.analysis.basin import (
    BasinSpec,
    axis_values,
    controller_cycle,
    parse_axes,
    parse_range,
    run_chunk,
    run_grid,
)
from bound_env.model.params import load_gait
from bound_env.sim.parallel import open_pool


def spec_for(grid: int, controller=None, gait: str = "default", chunk: int = 128) -> BasinSpec:
    z_star = np.asarray(load_gait(gait).z0, dtype=float)
    ax = parse_axes("xdot_g,y_g")
    values = axis_values(ax, parse_range(None, ax, z_star), grid)
    target = z_star if controller is None else controller_cycle(controller, z_star, gait)[0]
    return BasinSpec(
        axes=ax,
        values=values,
        z_slice=z_star,
        z_target=target,
        controller=controller,
        gait=gait,
        chunk=chunk,
    )


def timed(spec: BasinSpec, scheduler: str | None, workers: int) -> tuple[float, float]:
    """(seconds to open and warm up, seconds for the grid)."""
    t0 = time.perf_counter()
    with open_pool(scheduler, workers, quiet=True) as pool:
        warm = BasinSpec(
            **{**spec.__dict__, "values": (spec.values[0][:2], spec.values[1][:1]), "chunk": 1}
        )
        futs = [pool.executor.submit(run_chunk, warm, i % 2) for i in range(2 * workers)]
        for f in futs:
            f.result()
        t1 = time.perf_counter()
        res = run_grid(spec, pool.executor)
        t2 = time.perf_counter()
    assert res["outcome"].size == spec.n_starts
    return t1 - t0, t2 - t1


def row(name: str, n: int, setup: float, seconds: float, base: float | None) -> None:
    ratio = f"{base / seconds:5.2f}x" if base else "    1x"
    print(
        f"| {name:38s} | {n:6d} | {setup:6.1f} | {seconds:7.1f} | {n / seconds:8.1f} | {ratio} |"
        f" {os.getloadavg()[0]:4.1f} |",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=64, help="passive grid (default: 64)")
    ap.add_argument("--policy-grid", type=int, default=64, help="policy grid (0: skip)")
    ap.add_argument(
        "--policy",
        default="agents/policies/archive/ppo-v1",
        help="policy name or path (default: the archived ppo-v1, docs/analysis.md's table)",
    )
    ap.add_argument(
        "--also",
        default="lqr,default",
        help="more controllers timed like the policy, comma-separated (default: lqr, the "
        "stride LQR, per robot in Python; default, the fine-tuned stride controller); '' none",
    )
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--repeat", type=int, default=1, help="rounds of the passive cases")
    ap.add_argument("--json", help="record the grid times in this file's basin_map section")
    args = ap.parse_args()
    load0 = [round(v, 2) for v in os.getloadavg()]
    times: dict = {}
    print(f"cores: {os.cpu_count()}, load average at start: {os.getloadavg()}")
    print("| case | starts | open+warm s | grid s | starts/s | vs first row | load |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    spec = spec_for(args.grid)
    g = f"{args.grid}x{args.grid}"
    for _ in range(args.repeat):  # alternating, so that a change of load hits every case
        su, serial = timed(spec, None, 1)
        row(f"passive {g}, 1 process", spec.n_starts, su, serial, None)
        su, pool = timed(spec, None, 2)
        row(f"passive {g}, process pool 2", spec.n_starts, su, pool, serial)
        times["passive-serial"] = min(serial, times.get("passive-serial", serial))
        times["passive"] = min(pool, times.get("passive", pool))
        if not args.no_dask:
            su, dask = timed(spec, "local:2", 2)
            row(f"passive {g}, Dask LocalCluster 2", spec.n_starts, su, dask, serial)
            print(f"Dask vs process pool: {pool / dask:.2f}x the pool's rate")
    if args.policy_grid:
        from agents.runtime.policy import load_controller

        names = [args.policy] + [n for n in args.also.split(",") if n.strip()]
        for name in names:
            ctrl = load_controller(name.strip())
            pspec = spec_for(args.policy_grid, ctrl, ctrl.env_kwargs.get("gait") or "default")
            su, ptime = timed(pspec, None, 2)
            times[Path(name.strip()).name] = ptime
            row(
                f"policy {name} {args.policy_grid}x{args.policy_grid}, pool 2",
                pspec.n_starts,
                su,
                ptime,
                None,
            )
    print(f"load average at end: {os.getloadavg()}")
    if args.json:
        from bound_env.files.cache import record_section

        record_section(
            args.json,
            "basin_map",
            {
                "seconds": times,
                "grid": [args.grid, args.policy_grid],
                "strides": 100,
                "workers": 2,
                "load_average_before": load0,
                "what": "wall seconds of a basin map (xdot_g x y_g through z*), a process pool "
                "of 2 warmed up first; passive also in one process",
            },
            "python benchmarks/basin_map.py " + " ".join(sys.argv[1:]),
        )
        print(f"recorded in {args.json}")


if __name__ == "__main__":
    main()
