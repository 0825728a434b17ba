"""Hold under parameter error: does a stride controller hold random plants from the nominal z*?

    PYTHONPATH=. python scripts/hold_eval.py --policy lqr lqr+of default default+of \
        --delta 0.05 0.1 0.2 --seed 777 [--robots 32] [--strides 100] [--out results.jsonl]

Each robot runs on its own plant: m1, m2, I1, I2, kb, kf, kc and zeta of the controller's gait
each scaled by U(1 - delta, 1 + delta), drawn from ``--seed`` (the same plants for every
controller). Every robot starts on the nominal z* and runs ``--strides`` strides through the
one stride map (`bound_env.stride_map.StrideMap.run` with per-robot parameters); hold = no
fall. Reported: the held count and, over the held robots, the median of the mean |tau| over
the last 10 strides (impulse / time). A stateful controller (`OffsetFree`) keeps one state per
robot (``start`` / ``plan_actions``). Each finished (policy, delta, seed) row is appended to
``--out`` (JSON lines) and skipped when already there, so a killed run resumes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from bound_env.dynamics import make_aux
from bound_env.params import load_gait
from bound_env.stride_map import EVAL_RTOL, StrideMap

VARIED = ("m1", "m2", "I1", "I2", "kb", "kf", "kc", "zeta")
TAIL = 10  # strides of the effort average


def sample_plants(gait: str, delta: float, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(factors (n, 8), aux (n, N_AUX)): the plants of ``n`` robots from ``seed``."""
    base = load_gait(gait).params
    rng = np.random.default_rng(seed)
    F = rng.uniform(1.0 - delta, 1.0 + delta, size=(n, len(VARIED)))
    aux = []
    for f in F:
        values = {k: getattr(base, k) * float(x) for k, x in zip(VARIED, f, strict=True)}
        aux.append(make_aux(base.with_values(**values).to_array()))
    return F, np.array(aux)


def hold(ctrl, aux: np.ndarray, strides: int, gait: str = "default") -> dict:
    """Run every robot ``strides`` strides from z*; per robot: held, strides, tail effort."""
    kw = dict(getattr(ctrl, "env_kwargs", None) or {})
    sm = StrideMap(gait, None, kw.get("dt", 0.01), kw.get("max_torque", 80.0), EVAL_RTOL)
    n = len(aux)
    Z = np.tile(sm.z_ref, (n, 1))
    live = np.arange(n)
    done = np.zeros(n, dtype=np.int64)
    impulse = np.zeros((n, strides))
    period = np.zeros((n, strides))
    state = ctrl.start(n) if getattr(ctrl, "stateful", False) else None
    for k in range(strides):
        if state is not None:
            A = ctrl.plan_actions(state, Z[live], live)
        else:
            A = ctrl.interval_actions(Z[live])
        r = sm.run(Z[live], A, aux=aux[live])
        ok = r.ok & np.all(np.isfinite(r.z1), axis=1)
        impulse[live, k] = r.effort * r.period
        period[live, k] = r.period
        Z[live[ok]] = r.z1[ok]
        done[live[ok]] += 1
        live = live[ok]
        if not len(live):
            break
    held = done >= strides
    tail = impulse[:, -TAIL:].sum(axis=1) / np.maximum(period[:, -TAIL:].sum(axis=1), 1e-12)
    return {"held": held.tolist(), "strides": done.tolist(), "tail_effort": tail.tolist()}


def summary(res: dict) -> tuple[int, float]:
    held = np.array(res["held"])
    eff = np.array(res["tail_effort"])[held]
    return int(held.sum()), float(np.median(eff)) if eff.size else float("nan")


def table(path: Path, seeds: list[int]) -> str:
    """A Markdown table of the rows of ``path`` on ``seeds`` (pooled): held / n with its
    Wilson 95 % interval and the median tail |tau| of the held robots, and for each 'NAME+of'
    the paired count against NAME on the same plants (held only by +of / only by NAME,
    exact McNemar p)."""
    from bound_env.analysis.margins.stats import wilson_interval
    from bound_env.analysis.paired import mcnemar_exact

    rows = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    rows = [r for r in rows if r["seed"] in seeds and not r.get("set")]
    pols = list(dict.fromkeys(r["policy"] for r in rows))
    deltas = sorted({r["delta"] for r in rows})
    pooled: dict = {}
    for r in rows:
        key = (r["policy"], r["delta"])
        h, e = pooled.setdefault(key, ({}, {}))
        h[r["seed"]], e[r["seed"]] = r["held"], r["tail_effort"]
    head = "| policy | " + " | ".join(f"±{d:.0%}" for d in deltas) + " |"
    out = [head, "| --- |" + " --- |" * len(deltas)]
    for p in pols:
        cells = []
        for d in deltas:
            if (p, d) not in pooled or set(pooled[(p, d)][0]) != set(seeds):
                cells.append("")
                continue
            held = np.concatenate([pooled[(p, d)][0][s] for s in seeds]).astype(bool)
            eff = np.concatenate([pooled[(p, d)][1][s] for s in seeds])
            lo, hi = wilson_interval(int(held.sum()), held.size)
            med = f", {np.median(eff[held]):.2g} N·m" if held.any() else ""
            cell = f"{held.sum()}/{held.size} [{lo:.2f}, {hi:.2f}]{med}"
            base = p[: -len("+of")] if p.endswith("+of") else None
            if base is not None and (base, d) in pooled and set(pooled[(base, d)][0]) == set(seeds):
                b = np.concatenate([pooled[(base, d)][0][s] for s in seeds]).astype(bool)
                m = mcnemar_exact(held, b)
                cell += f"; +{int((held & ~b).sum())}/−{int((b & ~held).sum())} p {m['p']:.2g}"
            cells.append(cell)
        out.append(f"| {p} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def load(name: str, gait: str):
    from agents.runtime.policy import load_controller

    return load_controller(name, gait=gait)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", nargs="+", default=["lqr", "lqr+of"])
    ap.add_argument("--delta", nargs="+", type=float, default=[0.05, 0.1, 0.2])
    ap.add_argument("--seed", type=int, default=777)
    ap.add_argument("--robots", type=int, default=32)
    ap.add_argument("--strides", type=int, default=100)
    ap.add_argument("--gait", default="default")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="OffsetFree settings of the '+of' policies (estimator, gain, deadband, max_shift)",
    )
    ap.add_argument(
        "--table",
        type=int,
        nargs="+",
        metavar="SEED",
        help="print the Markdown table of --out on these seeds (pooled) and exit",
    )
    args = ap.parse_args(argv)
    if args.table:
        if args.out is None or not args.out.is_file():
            print("error: --table reads the rows of --out FILE", file=sys.stderr)
            return 2
        print(table(args.out, args.table))
        return 0
    if not (0.0 <= min(args.delta) and max(args.delta) < 1.0):
        print("error: --delta must lie in [0, 1)", file=sys.stderr)
        return 2
    overrides = {}
    for item in args.set:
        k, _, v = item.partition("=")
        overrides[k] = v if k == "estimator" else float(v)
    tag = ",".join(f"{k}={v:g}" for k, v in sorted(overrides.items()))
    seen = set()
    if args.out is not None and args.out.exists():
        for line in args.out.read_text().splitlines():
            row = json.loads(line)
            seen.add((row["policy"], row["delta"], row["seed"], row.get("set", ""), row["n"]))
    for name in args.policy:
        ctrl = None
        for delta in args.delta:
            key = (name, delta, args.seed, tag, args.robots)
            if key in seen:
                continue
            if ctrl is None:
                ctrl = load(name, args.gait)
                if overrides and getattr(ctrl, "stateful", False):
                    from bound_env.control import OffsetFree

                    ctrl = OffsetFree(
                        ctrl.inner, name=ctrl.name, **{**ctrl.settings(), **overrides}
                    )
            _, aux = sample_plants(args.gait, delta, args.robots, args.seed)
            t0 = time.time()
            res = hold(ctrl, aux, args.strides, args.gait)
            n_held, eff = summary(res)
            print(
                f"{name:14s} delta={delta:.2f} seed={args.seed} {tag:28s} held {n_held:2d}/"
                f"{args.robots}  median tail |tau| {eff:6.2f} N m  ({time.time() - t0:.0f} s)",
                flush=True,
            )
            if args.out is not None:
                row = {
                    "policy": name,
                    "delta": delta,
                    "seed": args.seed,
                    "set": tag,
                    "n": args.robots,
                    "strides": args.strides,
                    "held": n_held,
                    "median_tail_effort": eff,
                    **res,
                }
                with args.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
