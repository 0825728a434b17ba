"""Hold under parameter error: does a controller hold random plants from the nominal z*?

    PYTHONPATH=. python scripts/hold_eval.py --policy lqr lqr+of default default+of \
        --delta 0.05 0.1 0.2 --seed 777 [--robots 32] [--strides 100] [--out results.jsonl]

The hold measure of ``bound-env margins --mismatch pmD`` (``mismatch.hold``), alone, for many
controllers, error sizes and seeds. Each robot runs on its own plant: m1, m2, I1, I2, kb, kf,
kc and zeta of the controller's gait each scaled by U(1 - delta, 1 + delta), drawn by the
library's plant sampling (`bound_env.model.mismatch.sample_plant_params`) from the library's plant
seed of ``--seed`` (`bound_env.analysis.margins.model_error.mismatch_tasks.mismatch_seeds`), so that
``--seed 777 --delta 0.05`` names the same plants, in the same order, as
``bound-env margins --mismatch pm5 --seed 777`` (the same plants for every controller).
Every robot starts on the nominal z* and runs ``--strides`` strides through the library's
hold measure (`mismatch_tasks.task_mm_hold`: the step env, each stride restarted at its apex,
every robot with a fresh controller state); hold = no fall. Reported: the held count and,
over the held robots, the median of the mean |tau| over the last 10 strides (impulse / time).
Each finished (policy, delta, seed) row is appended to ``--out`` (JSON lines) with its
``fingerprint`` (`agents.results.provenance.row_fingerprint`: the code, the controller's data
and files, the gait, the spec, the robots, the strides and the settings) and skipped when
already there under the same fingerprint, so a killed run resumes; a row made under another
(an edited spec or policy, another gait or ``--strides``, other code) is recomputed, and the
run says so.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bound_env.analysis.margins.budget import BUDGETS, check_seed
from bound_env.analysis.margins.closed_loop import Setup
from bound_env.analysis.margins.model_error.mismatch_tasks import (
    MISMATCH_BUDGETS,
    mismatch_seeds,
    plants_of,
    task_mm_hold,
)
from bound_env.model.mismatch import EIGHT, from_dict
from bound_env.model.params import load_gait

TAIL = 10  # strides of the effort average
MEASURE = "mm_hold"  # the rows' measure (rows of the earlier stride-map script have none)


def spec_of(delta: float):
    """The model-error spec of ``--delta``: the eight parameters at +-delta (``pm5`` for
    0.05, as `bound_env.model.mismatch.PRESETS`)."""
    return from_dict({"params": dict.fromkeys(EIGHT, delta), "name": f"pm{100 * delta:g}"})


def setup_of(ctrl, key: str, delta: float, robots: int, strides: int, seed: int, gait: str):
    """The margins `Setup` of the hold measure (only its model-error part is used)."""
    mb = replace(
        MISMATCH_BUDGETS["quick"],
        name="hold_eval",
        plants=robots,
        hold_strides=strides,
        effort_strides=TAIL,
    )
    return Setup(
        controller=ctrl,
        gait=gait,
        budget=BUDGETS["test"],
        z_star=np.asarray(load_gait(gait).z0, dtype=float),
        key=f"hold_eval/{key}",
        seed=check_seed(seed),
        mismatch=spec_of(delta),
        mismatch_budget=mb,
    )


def plants(delta: float, robots: int, seed: int, gait: str = "default") -> list:
    """The plants (`bound_env.model.params.Params`) of ``robots`` robots (`plants_of`)."""
    return plants_of(setup_of(None, "", delta, robots, 1, seed, gait), robots)


def hold(setup) -> dict:
    """Per robot: held, strides, tail effort (None unless held), by `task_mm_hold`."""
    r = task_mm_hold(setup)
    return {
        "held": [bool(o) for o in r["outcomes"]],
        "strides": r["strides"],
        "tail_effort": r["effort"],
    }


def summary(res: dict) -> tuple[int, float]:
    held = np.array(res["held"])
    eff = np.array([e for e, h in zip(res["tail_effort"], held, strict=True) if h], dtype=float)
    return int(held.sum()), float(np.median(eff)) if eff.size else float("nan")


def table(path: Path, seeds: list[int]) -> str:
    """A Markdown table of the rows of ``path`` on ``seeds`` (pooled): held / n with its
    Wilson 95 % interval and the median tail |tau| of the held robots, and for each 'NAME+of'
    the paired count against NAME on the same plants (held only by +of / only by NAME,
    exact McNemar p)."""
    from bound_env.analysis.margins.stats import wilson_interval
    from bound_env.analysis.paired import mcnemar_exact

    rows = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    rows = [
        r for r in rows if r["seed"] in seeds and not r.get("set") and r.get("measure") == MEASURE
    ]
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
            eff = np.array(
                [np.nan if e is None else e for s in seeds for e in pooled[(p, d)][1][s]]
            )
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
    ap = parser()  # typed, range-checked options (end of the file)
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
    try:
        check_seed(args.seed)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    overrides = {}
    for item in args.set:
        k, _, v = item.partition("=")
        overrides[k] = v if k == "estimator" else float(v)
    # the settings' tag, on the rows of the policies that take them (the '+of' ones)
    tag = ",".join(
        f"{k}={v}" if isinstance(v, str) else f"{k}={v:g}" for k, v in sorted(overrides.items())
    )
    from agents.results.provenance import reusable, row_fingerprint

    seen: dict = {}  # (policy, delta, seed, set, n) -> its rows, oldest first
    if args.out is not None and args.out.exists():
        for line in args.out.read_text().splitlines():
            row = json.loads(line)
            if row.get("measure") == MEASURE:
                key = (row["policy"], row["delta"], row["seed"], row.get("set", ""), row["n"])
                seen.setdefault(key, []).append(row)
    for name in args.policy:
        ctrl = load(name, args.gait)
        from bound_env.control import OffsetFree

        # an OffsetFree only (mpc-adaptive is stateful too, and has no inner controller)
        takes = bool(overrides) and isinstance(ctrl, OffsetFree)
        row_tag = tag if takes else ""
        if takes:
            ctrl = OffsetFree(ctrl.inner, name=ctrl.name, **{**ctrl.settings(), **overrides})
        elif overrides:
            print(f"note: {name} is not offset-free: --set does not apply to it", file=sys.stderr)
        for delta in args.delta:
            key = (name, delta, args.seed, row_tag, args.robots)
            fp = row_fingerprint(
                name,
                ctrl,
                args.gait,
                spec=spec_of(delta).to_dict(),
                seed=args.seed,
                robots=args.robots,
                strides=args.strides,
                tail=TAIL,
                set=row_tag,
            )
            what = f"{name} delta={delta:g} seed={args.seed} {row_tag}".rstrip()
            if reusable(seen.get(key, []), fp, what) is not None:
                continue
            setup = setup_of(
                ctrl, f"{name}/{row_tag}", delta, args.robots, args.strides, args.seed, args.gait
            )
            t0 = time.time()
            res = hold(setup)
            n_held, eff = summary(res)
            print(
                f"{name:14s} delta={delta:.2f} seed={args.seed} {row_tag:28s} held {n_held:2d}/"
                f"{args.robots}  median tail |tau| {eff:6.2f} N m  ({time.time() - t0:.0f} s)",
                flush=True,
            )
            if args.out is not None:
                row = {
                    "policy": name,
                    "delta": delta,
                    "seed": args.seed,
                    "measure": MEASURE,
                    "plant_seed": mismatch_seeds(args.seed)["plants"],
                    "set": row_tag,
                    "n": args.robots,
                    "strides": args.strides,
                    "held": n_held,
                    "median_tail_effort": eff,
                    **res,
                    "fingerprint": fp,
                }
                with args.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    if args.out is not None and args.out.exists():
        compact(args.out)
    return 0


def compact(path: Path) -> None:
    """Rewrite the rows file ``path`` (atomically) with only the newest row of each (policy,
    delta, seed, set, robots): a row recomputed under a new fingerprint replaces the one before
    it, so that a reader finds one row per key."""
    from bound_env.files.cache import atomic_write

    lines = path.read_text().splitlines()
    last = {}
    for i, line in enumerate(lines):
        row = json.loads(line)
        key = (row.get("measure"), row["policy"], row["delta"], row["seed"], row.get("set", ""),
               row["n"])  # fmt: skip
        last[key] = i
    keep = sorted(last.values())
    if len(keep) < len(lines):
        atomic_write(path, "".join(lines[i] + "\n" for i in keep))


def parser() -> argparse.ArgumentParser:
    """The options, typed and range-checked with the command line's own argparse types
    (`bound_env.files.values.number`): a bad one is a usage error, exit 2."""
    from bound_env.files.values import number

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", nargs="+", type=_policy, default=["lqr", "lqr+of"])
    ap.add_argument("--delta", nargs="+", type=number(float, 0.0, 0.99), default=[0.05, 0.1, 0.2])
    ap.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=777)
    ap.add_argument("--robots", type=number(int, 1, 100_000), default=32)
    ap.add_argument("--strides", type=number(int, TAIL, 100_000), default=100)
    ap.add_argument("--gait", default="default")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument(
        "--set",
        nargs="*",
        type=_of_setting,
        default=[],
        metavar="KEY=VALUE",
        help="OffsetFree settings of the '+of' policies (estimator, gain, deadband, max_shift)",
    )
    ap.add_argument(
        "--table",
        type=number(int, 0, 2**32 - 1),
        nargs="+",
        metavar="SEED",
        help="print the Markdown table of --out on these seeds (pooled) and exit",
    )
    return ap


def _policy(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("a policy must be a name or a path, got ''")
    return text


def _of_setting(text: str) -> str:
    """``KEY=VALUE`` of an `OffsetFree` setting, its value checked (`OF_LIMITS`)."""
    from bound_env.control.offset_free import ESTIMATORS, OF_LIMITS

    key, eq, value = text.partition("=")
    if not eq or key not in ("estimator", *OF_LIMITS):
        raise argparse.ArgumentTypeError(
            f"{text!r}: give KEY=VALUE with KEY one of estimator, {', '.join(OF_LIMITS)}"
        )
    if key == "estimator":
        if value not in ESTIMATORS:
            raise argparse.ArgumentTypeError(
                f"estimator must be one of {ESTIMATORS}, got {value!r}"
            )
        return text
    from bound_env.files.values import number

    lo, hi = OF_LIMITS[key]
    try:
        number(float, lo, hi, lo_open=key == "gain")(value)
    except argparse.ArgumentTypeError as e:
        raise argparse.ArgumentTypeError(f"{key}: {e}") from None  # names the setting
    return text


def run(argv=None) -> int:
    """`main`, with what fails after the options parsed (an unknown policy or gait, an --out
    that is a folder) as one line and exit 2."""
    try:
        return main(argv)
    except (ValueError, OSError, TypeError) as e:
        print(f"hold_eval.py: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(run())
