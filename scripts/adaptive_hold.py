"""The hold of ``bound-env margins --mismatch`` alone, for several controllers and specs.

    PYTHONPATH=. python scripts/adaptive_hold.py --policy lqr mpc default adaptive/s0 \
        --mismatch pm10 pm15 --seed 12345 --out results.json

Each (policy, spec) runs the margins' own model-error task ``mm_hold``
(`bound_env.analysis.margins.model_error.mismatch_tasks.task_mm_hold`: the step env, robot i on
plant i of the seed's plants, 32 plants, 100 strides from the nominal z*, the quick budget's), so
the plants, the noise streams and the outcomes are exactly those of ``margins --mismatch SPEC --seed
SEED``'s ``hold`` block, without its other measures. Each finished entry is written to ``--out``
(atomically) with its ``fingerprint`` (`agents.results.provenance.row_fingerprint`: the code, the
controller's data and files, the spec's contents and the seed) and skipped when already there under
the same fingerprint, so a killed run resumes; an entry made under another (an edited spec or
policy, other code) is recomputed in its place, and the run says so. Besides the held count: the
outcomes per plant (for paired tests), the strides reached, the median effort of the held plants,
and the controller's decision times (p50, p99) where it keeps them.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from bound_env.files.values import number


def hold_entry(policy: str, spec_text: str, seed: int, ctrl=None) -> dict:
    """The ``mm_hold`` of ``policy`` (``ctrl``: it loaded) on ``spec_text`` (module docstring)."""
    from agents.runtime.policy import load_controller
    from bound_env.analysis.margins import as_budget
    from bound_env.analysis.margins.closed_loop import Setup
    from bound_env.analysis.margins.model_error.mismatch_tasks import MISMATCH_BUDGETS, task_mm_hold
    from bound_env.model.mismatch import as_spec
    from bound_env.model.params import load_gait

    spec = as_spec(spec_text)
    ctrl = load_controller(policy) if ctrl is None else ctrl
    setup = Setup(
        controller=ctrl,
        gait="default",
        budget=as_budget("quick"),
        z_star=np.asarray(load_gait("default").z0, dtype=float),
        key=f"adaptive_hold:{policy}:{ctrl.fingerprint()}",
        seed=seed,
        mismatch=spec,
        mismatch_budget=MISMATCH_BUDGETS["quick"],
    )
    t0 = time.perf_counter()
    r = task_mm_hold(setup)
    held = [e for e, o in zip(r["effort"], r["outcomes"], strict=True) if o and e is not None]
    from bound_env.control.privileged import is_privileged

    return {
        "policy": policy,
        "privileged": is_privileged(ctrl),  # reads the robot's true plant: marked
        "spec": spec.to_dict(),
        "spec_name": spec.name,
        "seed": seed,
        "held": int(sum(r["outcomes"])),
        "n": len(r["outcomes"]),
        "outcomes": r["outcomes"],
        "strides_reached": r["strides"],
        "failures": [f for f in r["failure"]],
        "effort_median": float(np.median(held)) if held else None,
        "seconds": time.perf_counter() - t0,
    }


PRIVILEGED = ("cycle-teacher", "mpc-true-plant", "cycle-teacher-blind1", "cycle-teacher-blind2")


class Blind:
    """A privileged reference that plays the nominal LQR for its first ``n`` strides (as a
    controller that must first see its robot), then the reference."""

    def __init__(self, ref, lqr, n: int):
        self.ref, self.lqr, self.n, self.k = ref, lqr, n, 0

    def reset(self):
        self.k = 0

    def plan(self, z):
        self.k += 1
        return self.lqr.coefficients(z) if self.k <= self.n else self.ref.plan(z)


def privileged_entry(name: str, spec_text: str, seed: int) -> dict:
    """A privileged reference on the same plants (it reads each robot's true plant, so it
    runs outside the margins' controller protocol): robot i on plant i of the seed's plants
    from the nominal z*, ``hold_strides`` strides through the one stride map (the step env's
    strides to rounding). ``cycle-teacher``: the adaptive controller's DAgger teacher
    (`agents.experts.adaptive.CycleTeacher`); ``mpc-true-plant``: the shipped mpc planning on
    the true plant (its planning map built on it); ``cycle-teacher-blindN``: the teacher
    after N strides of the nominal LQR (what knowing the plant is worth once N strides were
    played without knowing it). Privileged: never deployable."""
    from agents.experts.adaptive import CycleTeacher, hold_on, privileged_teacher
    from bound_env.analysis.margins.model_error.mismatch_tasks import (
        MISMATCH_BUDGETS,
        mismatch_seeds,
    )
    from bound_env.control import load_controller as classical
    from bound_env.model.mismatch import as_spec, sample_plant_params

    spec = as_spec(spec_text)
    mb = MISMATCH_BUDGETS["quick"]
    mpc = classical("mpc")
    plants = sample_plant_params(spec, mb.plants, mismatch_seeds(seed)["plants"], mpc.params)
    t0 = time.perf_counter()
    reached = []
    for p in plants:
        if name.startswith("cycle-teacher"):
            ref = CycleTeacher(mpc, p)
        else:
            ref = privileged_teacher(mpc, p)
        if "-blind" in name:
            ref = Blind(ref, mpc.lqr, int(name.rsplit("blind", 1)[1]))
        reached += hold_on(ref, mpc, [p], mb.hold_strides)
    outcomes = [int(n == mb.hold_strides) for n in reached]
    return {
        "policy": name,
        "privileged": True,
        "loop": "stride map",
        "spec": spec.to_dict(),
        "spec_name": spec.name,
        "seed": seed,
        "held": int(sum(outcomes)),
        "n": len(outcomes),
        "outcomes": outcomes,
        "strides_reached": reached,
        "effort_median": None,
        "seconds": time.perf_counter() - t0,
    }


# the code a privileged reference runs besides the mpc (`privileged_entry`)
PRIVILEGED_ROOTS = (
    "agents.experts.adaptive:CycleTeacher",
    "agents.experts.adaptive:hold_on",
    "agents.experts.adaptive:privileged_teacher",
)


def entry_fingerprint(policy: str, spec, seed: int):
    """(the loaded controller or None, the fingerprint an entry of ``policy`` records)."""
    from agents.results.provenance import row_fingerprint

    inputs = {"spec": spec.to_dict(), "seed": seed, "budget": "quick"}
    if policy in PRIVILEGED:
        from bound_env.control import load_controller as classical

        mpc = classical("mpc")
        fp = row_fingerprint("mpc", mpc, roots=PRIVILEGED_ROOTS, reference=policy, **inputs)
        return None, fp
    from agents.runtime.policy import load_controller

    ctrl = load_controller(policy)
    return ctrl, row_fingerprint(policy, ctrl, **inputs)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--policy", nargs="+", required=True, help=f"policies, or privileged {PRIVILEGED}"
    )
    ap.add_argument("--mismatch", nargs="+", required=True, help="specs (presets or .yaml)")
    ap.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=12345)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    from agents.runtime.policy_args import check_run_arguments

    check_run_arguments(ap, args.policy, args.mismatch, skip=PRIVILEGED)
    from bound_env.files.cache import atomic_write

    out = Path(args.out)
    from agents.results.provenance import reusable
    from bound_env.model.mismatch import as_spec

    data = json.loads(out.read_text()) if out.is_file() else {"entries": []}

    def key(e):
        return (e["policy"], e["spec_name"], e["seed"])

    for spec in args.mismatch:
        for policy in args.policy:
            k = (policy, as_spec(spec).name, args.seed)
            ctrl, fp = entry_fingerprint(policy, as_spec(spec), args.seed)
            old = [e for e in data["entries"] if key(e) == k]
            if reusable(old, fp, f"{policy} {k[1]} seed {args.seed}") is not None:
                continue
            if policy in PRIVILEGED:
                e = privileged_entry(policy, spec, args.seed)
            else:
                e = hold_entry(policy, spec, args.seed, ctrl)
            e["fingerprint"] = fp
            data["entries"] = [x for x in data["entries"] if key(x) != k] + [e]
            atomic_write(out, json.dumps(data, indent=1) + "\n")
            print(
                f"{policy:28s} {e['spec_name']:8s} seed {args.seed}: "
                f"held {e['held']}/{e['n']} "
                f"effort {e['effort_median']} ({e['seconds']:.0f} s)",
                file=sys.stderr,
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
