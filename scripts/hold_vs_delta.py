"""Hold against model error: each controller's hold at delta = 2.5, 5, 7.5, 10 and 15 %.

    PYTHONPATH=. python scripts/hold_vs_delta.py --policy lqr lqr-of mpc mpc-adaptive \
        mpc-privileged --seed 12345 --out docs/data/hold_vs_delta.json \
        --figure docs/figures/hold_vs_delta.png [--delta 2.5 5 7.5 10 15 20] [--table] \
        [--mismatch pm10 pm10+noise pm10+delay1 all10]

Each (policy, family, delta) is `bound_env.analysis.margins.model_error.hold_delta.hold_row`: the
hold of ``bound-env margins --mismatch SPEC --budget quick --seed SEED`` (32 plants, 100 strides
from the nominal z*), with the median effort of the held plants and every apex decision's wall time.
``--mismatch`` gives the families (default ``pm10``: the eight factors alone): each spec's
parameters are set to each delta, its sensor noise and delay kept (`hold_delta.spec_at`:
``pm10+noise`` → pmD+noise, ``all10`` → allD), so the parameter-only, noise, delay and ``all``
families are drawn side by side, one panel each. Finished rows are appended to ``OUT.jsonl`` (beside
``--out``), each with its ``fingerprint`` (`agents.results.provenance.row_fingerprint`: the code,
the controller's data and files, the gait, the spec and the seed), and reused when already there
under the same fingerprint, so a killed run resumes; a row made under another fingerprint (an edited
spec or policy, another gait, other code) is recomputed, and the run says so. The JSON (every row of
the requested policies, deltas and seed) and the figure are written atomically at the end. A
privileged controller (it reads the robot's true plant, `bound_env.control.privileged`) is marked so
in the JSON, the figure and the table. Design and tuning read the validation seed 777; the test seed
12345 is run once, for the report.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from agents.results.provenance import reusable, row_fingerprint
from bound_env.analysis.margins.model_error.hold_delta import (
    DELTAS,
    family,
    hold_delta_figure,
    hold_delta_table,
    hold_row,
    row_family,
    spec_at,
)
from bound_env.files.cache import append_line, atomic_write, read_lines
from bound_env.files.values import number
from bound_env.model.mismatch import as_spec


def load(name: str, gait: str):
    from agents.policy import load_controller

    return load_controller(name, gait=gait)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", nargs="+", required=True, help="controller names or paths")
    ap.add_argument(
        "--delta",
        nargs="+",
        type=float,
        default=[100 * d for d in DELTAS],
        help="model error in percent, in (0, 100) (default: 2.5 5 7.5 10 15)",
    )
    ap.add_argument(
        "--mismatch",
        nargs="+",
        default=["pm10"],
        help="a spec per family (presets joined by +, or a .yaml): its parameters are set to "
        "each delta, its noise and delay kept (default: pm10, the eight factors alone)",
    )
    ap.add_argument(
        "--seed", type=number(int, 0, 2**32 - 1), default=777, help="plant seed (777: validation)"
    )
    ap.add_argument("--gait", default="default")
    ap.add_argument("--out", type=Path, required=True, help="the JSON to write")
    ap.add_argument("--figure", type=Path, default=None, help="the PNG to write")
    ap.add_argument("--table", action="store_true", help="print a Markdown table")
    args = ap.parse_args(argv)
    deltas = [d / 100.0 for d in args.delta]
    for d in args.delta:
        if not 0.0 < d < 100.0:  # (NaN too)
            ap.error(f"--delta: {d:g} is not a percentage in (0, 100)")
    families = {}  # family -> the spec it was given as
    for text in args.mismatch:
        try:
            fam = family(as_spec(text))
        except (ValueError, OSError) as e:
            ap.error(f"--mismatch: {e}")
        if fam in families:
            ap.error(f"--mismatch: {families[fam]!r} and {text!r} are the same family {fam!r}")
        families[fam] = text
    args.out.parent.mkdir(parents=True, exist_ok=True)
    log = args.out.with_suffix(".jsonl")
    done: dict = {}  # (policy, family, delta, seed) -> its rows, oldest first
    for i, line in enumerate(read_lines(log) if log.exists() else [], 1):
        try:
            r = json.loads(line)
            key = (r["policy"], row_family(r), r["delta"], r["seed"])
        except (json.JSONDecodeError, KeyError, TypeError):
            print(f"error: {log}:{i}: not a row of this script ({line[:40]!r})", file=sys.stderr)
            return 2
        done.setdefault(key, []).append(r)
    columns = {}
    for name in args.policy:
        try:
            ctrl = load(name, args.gait)
        except (OSError, ValueError, TypeError) as e:
            print(f"error: --policy {name}: {e}", file=sys.stderr)
            return 2
        privileged = getattr(ctrl, "privileged", False) is True
        rows = []
        for fam, text in families.items():
            for d in deltas:
                key = (name, fam, d, args.seed)
                spec = spec_at(text, d)
                fp = row_fingerprint(
                    name, ctrl, args.gait, spec=spec.to_dict(), seed=args.seed, budget="quick"
                )
                what = f"{name} {spec.name} (seed {args.seed})"
                r = reusable(done.get(key, []), fp, what)
                if r is None:
                    t0 = time.perf_counter()
                    r = hold_row(ctrl, d, args.seed, args.gait, spec=text)
                    r.update(policy=name, privileged=privileged, seconds=time.perf_counter() - t0)
                    r["fingerprint"] = fp
                    append_line(log, json.dumps(r))
                    done.setdefault(key, []).append(r)
                    print(
                        f"{name} {spec.name}: {r['k']}/{r['n']} held, effort "
                        f"{r['effort_median']} N m ({r['seconds']:.0f} s)",
                        flush=True,
                    )
                rows.append(r)
        columns[name] = {"privileged": privileged, "rows": rows}
    data = {
        "what": "hold against model error (bound_env.analysis.margins.model_error.hold_delta)",
        "made_with": "python scripts/hold_vs_delta.py " + " ".join(argv or sys.argv[1:]),
        "seed": args.seed,
        "seed_role": "test" if args.seed == 12345 else "validation",
        "gait": args.gait,
        "deltas": deltas,
        "families": list(families),
        "columns": columns,
    }
    atomic_write(args.out, json.dumps(data, indent=1) + "\n")
    if args.figure is not None:
        args.figure.parent.mkdir(parents=True, exist_ok=True)
        hold_delta_figure(data, args.figure)
    if args.table:
        print(hold_delta_table(data))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
