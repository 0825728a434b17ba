"""Decision time of mpc-adaptive-bounded (identification and design within a budget) vs mpc's.

Run by hand: ``PYTHONPATH=. python benchmarks/adaptive_budget.py [--spec pm10] [--seed 777]
[--plants 8] [--strides 100] [--policy mpc-adaptive-bounded] [--budget N]``. Robot i runs
on plant i of the seed's plants (`bound_env.model.mismatch.sample_plant_params`, the margins' plant
seed) from the nominal z*,
through the stride map on its plant; at every apex mpc-adaptive decides (``stride_action``:
its observation, its slice of identification and design, its plan) and the shipped mpc plans
from the same apex (``plan``), each timed alone with ``time.perf_counter`` in the same run, so
the ratio is load-independent. Prints p50, p99 and max of both, the ratio of the p99s, the
largest slice of work (stride evaluations) and the machine's load (``uptime``); nothing is
asserted. ``--out FILE`` also writes the row (its policy and budget replace an earlier row of
the same pair) into FILE's ``rows``, atomically, with its ``fingerprint``
(`agents.results.provenance.row_fingerprint`: the code, the controller's data, the spec, the
seed, the plants and strides), so the docs can quote it (`docs/data/adaptive_budget.json`).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import time

import numpy as np


def stats(ts) -> str:
    a = np.asarray(ts) * 1e3
    p50, p99 = np.percentile(a, 50), np.percentile(a, 99)
    return f"p50 {p50:.2f} ms, p99 {p99:.2f} ms, max {a.max():.2f} ms"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--spec", default="pm10")
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--plants", type=int, default=8)
    ap.add_argument("--strides", type=int, default=100)
    ap.add_argument("--budget", type=int, default=None, help="default: the spec's")
    ap.add_argument("--policy", default="mpc-adaptive-bounded", help="an mpc-adaptive spec")
    ap.add_argument("--out", default=None, help="a JSON file to write the row into")
    args = ap.parse_args(argv)
    from bound_env.analysis.margins.model_error.mismatch_tasks import mismatch_seeds
    from bound_env.control import load_controller
    from bound_env.control.adaptive import AdaptiveMPC
    from bound_env.model.dynamics import make_aux
    from bound_env.model.mismatch import as_spec, sample_plant_params
    from bound_env.sim.stride_map import EVAL_RTOL, StrideMap

    mpc = load_controller("mpc")
    extra = dict(a.split("=") for a in os.environ.get("ADAPTIVE_SET", "").split() if a)
    extra = {k: float(v) if "." in v else int(v) for k, v in extra.items()}
    if args.budget is not None:
        extra["budget"] = args.budget
    ada = AdaptiveMPC(spec=args.policy, **extra)
    spec = as_spec(args.spec)
    plants = sample_plant_params(spec, args.plants, mismatch_seeds(args.seed)["plants"], mpc.params)
    sm = StrideMap(mpc.gait, None, mpc.dt, mpc.max_torque, EVAL_RTOL)
    t_ada, t_mpc, fell = [], [], 0
    load_before = os.getloadavg()[0]
    print("load before:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    for p in plants:  # (the largest slice: over the whole run)
        aux = make_aux(p.to_array())[None]
        ada.reset()
        z = np.array(mpc.z_ref, dtype=float)
        for k in range(args.strides):
            t0 = time.perf_counter()
            mpc.plan(z)
            t1 = time.perf_counter()
            ada.stride_action(z)
            t2 = time.perf_counter()
            t_mpc.append(t1 - t0)
            t_ada.append(t2 - t1)
            r = sm.run(z[None], ada.last_actions[None], aux=aux)
            if not r.ok[0]:
                fell += 1
                print(f"  fell at stride {k} (trusted {ada.trusted})")
                break
            z = r.z1[0]
    print("load after:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    work = max(ada.decision_work)
    print(f"{args.spec} seed {args.seed}: {len(plants)} plants, {fell} fell, "
          f"{len(t_ada)} decisions, budget {ada.config['budget']} strides, "
          f"largest slice {work}")  # fmt: skip
    print(f"{args.policy}: {stats(t_ada)}")
    print(f"mpc:          {stats(t_mpc)}")
    print(f"p99 ratio {np.percentile(t_ada, 99) / np.percentile(t_mpc, 99):.2f}x "
          f"(OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')})")  # fmt: skip
    if args.out:
        write_row(args, ada, spec, len(plants), fell, t_ada, t_mpc, work, load_before)
    return 0


def write_row(args, ada, spec, plants, fell, t_ada, t_mpc, work, load_before) -> None:
    """The run's row, with its fingerprint, into ``args.out``'s ``rows`` (module docstring)."""
    import json
    from pathlib import Path

    from agents.results.provenance import row_fingerprint
    from bound_env.files.cache import atomic_write

    def ms(ts, q):
        return round(float(np.percentile(np.asarray(ts) * 1e3, q)), 2)

    budget = int(ada.config["budget"])
    row = {
        "policy": args.policy,
        "budget": budget,
        "made_with": "PYTHONPATH=. python benchmarks/adaptive_budget.py "
        f"--plants {plants} --policy {args.policy}"
        + (f" --budget {args.budget}" if args.budget is not None else "")
        + f" --out {args.out}",
        "load_1min": round(load_before, 2),
        "held": plants - fell,
        "n": plants,
        "decisions": len(t_ada),
        "largest_slice": int(work),
        "p50_ms": ms(t_ada, 50),
        "p99_ms": ms(t_ada, 99),
        "max_ms": ms(t_ada, 100),
        "mpc_p50_ms": ms(t_mpc, 50),
        "mpc_p99_ms": ms(t_mpc, 99),
        "mpc_max_ms": ms(t_mpc, 100),
        "p99_ratio": round(float(np.percentile(t_ada, 99) / np.percentile(t_mpc, 99)), 2),
        "fingerprint": row_fingerprint(
            args.policy,
            ada,
            spec=spec.to_dict(),
            seed=args.seed,
            plants=plants,
            strides=args.strides,
            budget=budget,
        ),
    }
    out = Path(args.out)
    data = json.loads(out.read_text()) if out.is_file() else {"rows": []}
    keep = [r for r in data.get("rows", []) if (r["policy"], r["budget"]) != (args.policy, budget)]
    data["rows"] = keep + [row]
    atomic_write(out, json.dumps(data, indent=1, ensure_ascii=False) + "\n")


if __name__ == "__main__":
    raise SystemExit(main())
