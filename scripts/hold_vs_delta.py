"""Hold against model error: each controller's hold at delta = 2.5, 5, 7.5, 10 and 15 %.

    PYTHONPATH=. python scripts/hold_vs_delta.py --policy lqr lqr-of mpc mpc-adaptive \
        mpc-privileged --seed 12345 --out docs/data/hold_vs_delta.json \
        --figure docs/figures/hold_vs_delta.png [--delta 2.5 5 7.5 10 15] [--table]

Each (policy, delta) is `bound_env.analysis.margins.hold_delta.hold_row`: the hold of
``bound-env margins --mismatch pmD --budget quick --seed SEED`` (32 plants, 100 strides from
the nominal z*), with the median effort of the held plants and every apex decision's wall
time. Finished rows are appended to ``OUT.jsonl`` (beside ``--out``), each with its
``fingerprint`` (`agents.results.provenance.row_fingerprint`: the code, the controller's data
and files, the gait, the spec and the seed), and reused when already there under the same
fingerprint, so a killed run resumes; a row made under another fingerprint (an edited spec or
policy, another gait, other code) is recomputed, and the run says so. The JSON (every row of
the requested policies, deltas and seed) and the figure are written atomically at the end.
A privileged controller (it reads the robot's true plant, `bound_env.control.privileged`) is
marked so in the JSON, the figure and the table. Design and tuning read the validation seed
777; the test seed 12345 is run once, for the report.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from agents.results.provenance import reusable, row_fingerprint
from bound_env.analysis.margins.hold_delta import (
    DELTAS,
    hold_delta_figure,
    hold_delta_table,
    hold_row,
    spec_name,
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
        help="model error in percent (presets pmD; default: 2.5 5 7.5 10 15)",
    )
    ap.add_argument(
        "--seed", type=number(int, 0, 2**32 - 1), default=777, help="plant seed (777: validation)"
    )
    ap.add_argument("--gait", default="default")
    ap.add_argument("--out", type=Path, required=True, help="the JSON to write")
    ap.add_argument("--figure", type=Path, default=None, help="the PNG to write")
    ap.add_argument("--table", action="store_true", help="print a Markdown table")
    args = ap.parse_args(argv)
    try:
        deltas = [d / 100.0 for d in args.delta]
        for d in deltas:
            spec_name(d)
    except ValueError as e:
        ap.error(f"--delta: {e}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    log = args.out.with_suffix(".jsonl")
    done: dict = {}  # (policy, delta, seed) -> its rows, oldest first
    for i, line in enumerate(read_lines(log) if log.exists() else [], 1):
        try:
            r = json.loads(line)
            key = (r["policy"], r["delta"], r["seed"])
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
        for d in deltas:
            key = (name, d, args.seed)
            fp = row_fingerprint(
                name,
                ctrl,
                args.gait,
                spec=as_spec(spec_name(d)).to_dict(),
                seed=args.seed,
                budget="quick",
            )
            r = reusable(done.get(key, []), fp, f"{name} ±{100 * d:g} % (seed {args.seed})")
            if r is None:
                t0 = time.perf_counter()
                r = hold_row(ctrl, d, args.seed, args.gait)
                r.update(policy=name, privileged=privileged, seconds=time.perf_counter() - t0)
                r["fingerprint"] = fp
                append_line(log, json.dumps(r))
                done.setdefault(key, []).append(r)
                print(
                    f"{name} ±{100 * d:g} %: {r['k']}/{r['n']} held, effort "
                    f"{r['effort_median']} N m ({r['seconds']:.0f} s)",
                    flush=True,
                )
            rows.append(r)
        columns[name] = {"privileged": privileged, "rows": rows}
    data = {
        "what": "hold against model error (bound_env.analysis.margins.hold_delta)",
        "made_with": "python scripts/hold_vs_delta.py " + " ".join(argv or sys.argv[1:]),
        "seed": args.seed,
        "seed_role": "test" if args.seed == 12345 else "validation",
        "gait": args.gait,
        "deltas": deltas,
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
