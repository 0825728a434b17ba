"""``bound-env fixed-point``, ``continue``, ``sweep`` and ``reproduce``.

Registered by `bound_env.commands.cli` through `register`. Everything here is at the package's edge:
states are read and printed in the paper's units [m, deg, deg, m/s, deg/s, deg/s] and
parameters as gait-file keys (degrees for ``*_deg``).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from ..files.values import number
from ..model.params import (
    GAIT_KEYS,
    Z_NAMES,
    Z_PAPER_UNITS,
    parse_z,
    save_gait,
    z_to_paper,
    z_to_si,
)
from ..sim.parallel import add_scheduler_args
from .cli_args import add_gait_args, add_json_arg, gait_from_args, out_dir, say, strict_json


def register(sub) -> None:
    p = sub.add_parser("fixed-point", help="find a fixed point of the Poincare map (Newton)")
    _gait_args(p)
    p.add_argument(
        "--free",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME",
        help="gait keys to solve for, e.g. alpha_deg (needs as many --pin; one "
        "freed key without --pin pins the start's apex energy)",
    )
    p.add_argument(
        "--method",
        choices=("newton", "paper"),
        default="newton",
        help="newton: Newton-Raphson (with --free/--pin); paper: the paper's "
        "search (slope secant, Newton updates, touchdown angles, leg stiffness)",
    )
    p.add_argument(
        "--jacobian",
        choices=("fd", "variational"),
        default="fd",
        help="how nabla P is computed for the eigenvalues (default: %(default)s)",
    )
    p.add_argument(
        "--tol",
        type=number(float, 0, 1, lo_open=True),
        default=1e-10,
        help="Newton tolerance on |P(z) - z|",
    )
    p.add_argument("--max-iter", type=number(int, 1, 10_000), default=50, help="Newton iterations")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument(
        "--out",
        metavar="DIR",
        help="write the fixed point as a gait file, DIR/gait.yaml (use it as --gait DIR/gait.yaml)",
    )
    p.add_argument(
        "--save",
        metavar="PATH",
        help="write the gait file to PATH itself (the old spelling of --out)",
    )
    p.set_defaults(func=cmd_fixed_point)

    p = sub.add_parser("continue", help="continue a fixed point in kc or alpha_deg")
    _gait_args(p)
    p.add_argument(
        "--param",
        required=True,
        choices=GAIT_KEYS,
        metavar="NAME",
        help="continuation parameter, usually kc or alpha_deg",
    )
    p.add_argument("--to", type=number(float), required=True, help="target value (gait units)")
    p.add_argument(
        "--step",
        type=number(float, allow_zero=False),
        help="size of the parameter step towards --to (default: 1/10 of the range); a "
        "negative step that points away from --to is an error",
    )
    p.add_argument("--method", choices=("natural", "arclength"), default="natural")
    p.add_argument(
        "--free",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME",
        help="gait keys solved for along the branch (e.g. alpha_deg, as in Fig. 4)",
    )
    p.add_argument("--max-points", type=number(int, 1, 100_000), default=400)
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output directory: branch.csv, branch.json, branch.png",
    )
    p.add_argument(
        "--quiet",
        "--no-progress",
        dest="quiet",
        action="store_true",
        help="no progress lines on stderr (alias: --no-progress)",
    )
    add_json_arg(p)
    p.set_defaults(func=cmd_continue)

    p = sub.add_parser(
        "sweep",
        help="e_max against alpha_deg or kc, the paper's way "
        "(Figs. 7-8), and the stability windows",
        description="e_max against a gait parameter, the paper's way (Figs. 7-8). The sweep "
        "starts at the gait's own value of --param (its fixed point, always evaluated, even "
        "outside --from..--to) and steps outwards to --to and down to --from, each value "
        "from the previous value's fixed point; a direction stops after 3 values outside "
        "both windows. The windows (100-stride convergence, e_max < 1) are the contiguous "
        "ranges around the gait's own value. Every value must be a valid gait parameter.",
    )
    _gait_args(p, z_and_pins=False)
    p.add_argument(
        "--param",
        required=True,
        choices=GAIT_KEYS,
        metavar="NAME",
        help="the gait key to sweep, usually kc or alpha_deg (gait units: degrees for *_deg)",
    )
    p.add_argument(
        "--from", dest="lo", type=number(float), required=True, help="lowest value (gait units)"
    )
    p.add_argument(
        "--to", dest="hi", type=number(float), required=True, help="highest value (gait units)"
    )
    p.add_argument(
        "--step",
        type=number(float, 0, lo_open=True),
        required=True,
        help="spacing of the values (> 0; at most 100000 values)",
    )
    p.add_argument(
        "--refine", type=number(int, 0, 60), default=6, help="bisections of each window edge"
    )
    p.add_argument("--out", required=True, metavar="DIR", help="sweep.csv and sweep.png")
    p.add_argument(
        "--quiet",
        "--no-progress",
        dest="quiet",
        action="store_true",
        help="no progress lines on stderr (alias: --no-progress)",
    )
    add_scheduler_args(p, workers_default=1)  # the two directions as two tasks
    add_json_arg(p)
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser(
        "reproduce",
        help="measure every published number again: Figs. 3-8 (PNG + CSV) and REPRODUCTION.md",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output directory (report, figures/, cache/, results.json)",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="small budgets (coarse sweeps, kc_stiff = 2000): a smoke test",
    )
    p.add_argument("--force", action="store_true", help="recompute every stage (ignore cache)")
    p.add_argument(
        "--write-gaits",
        action="store_true",
        help="also write configs/gaits/default.yaml and literal-cycle.yaml",
    )
    p.add_argument(
        "--docs", metavar="DIR", help="copy REPRODUCTION.md and the PNG figures to DIR (e.g. docs)"
    )
    p.add_argument(
        "--quiet",
        "--no-progress",
        dest="quiet",
        action="store_true",
        help="no progress lines on stderr (alias: --no-progress)",
    )
    add_json_arg(p)
    p.set_defaults(func=cmd_reproduce)


def _gait_args(p, z_and_pins=True):
    add_gait_args(p, default="default")
    p.add_argument(
        "--z0",
        help="start apex state v1,...,v6 in [m, deg, deg, m/s, deg/s, "
        "deg/s] (default: the gait's z_star, else z_published); --z0=-1,...",
    )
    if z_and_pins:
        p.add_argument(
            "--pin",
            action="append",
            metavar="NAME[=VALUE]",
            help=f"condition for a freed key: energy [J] or one of {Z_NAMES} "
            "(paper units); without a value, the start's value",
        )


def parse_pins(texts, z0, params) -> list[tuple[str, float]]:
    """``NAME[=VALUE]`` -> (name, SI value); z components given in paper units."""
    from ..analysis.poincare import apex_energy

    pins = []
    for t in texts or []:
        name, _, val = t.partition("=")
        name = name.strip()
        if name == "energy":
            v = float(val) if val else apex_energy(z0, params)
        elif name in Z_NAMES:
            i = Z_NAMES.index(name)
            if val:
                zp = z_to_paper(z0)
                zp[i] = float(val)
                v = float(z_to_si(zp)[i])
            else:
                v = float(z0[i])
        else:
            raise ValueError(f"unknown pin {name!r}; use energy or one of {Z_NAMES}")
        pins.append((name, v))
    return pins


def _setup(args):
    gait = gait_from_args(args)
    z = parse_z(args.z0, "--z0")
    return gait, (z if z is not None else gait.z0)


def _default_pins(args, z0, params):
    pins = parse_pins(getattr(args, "pin", None), z0, params)
    if args.free and not pins and len(args.free) == 1:
        pins = parse_pins(["energy"], z0, params)
    return pins


def cmd_fixed_point(args) -> int:
    from ..analysis.fixed_point import find_fixed_point, paper_search

    if args.out and args.save:
        raise ValueError("give --out DIR or --save PATH (its old spelling), not both")
    save = Path(args.save) if args.save else None
    if args.out:
        save = out_dir(args.out) / "gait.yaml"
    elif save is not None and save.is_dir():
        raise ValueError(f"--save {save} is a folder; give a file name, or --out {save}")
    gait, z0 = _setup(args)
    if args.method == "paper":
        if args.free or args.pin:
            raise ValueError("--method paper frees alpha itself; drop --free/--pin")
        res = paper_search(gait.params, z0)
    else:
        pins = _default_pins(args, z0, gait.params)
        res = find_fixed_point(
            gait.params,
            z0,
            free=args.free,
            pin=pins or None,
            tol=args.tol,
            max_iter=args.max_iter,
            jacobian_method=args.jacobian,
        )
    out = res.summary()
    out["gait"] = str(gait.path)
    if save is not None:
        if not res.converged:
            print(
                f"bound-env fixed-point: not saving, no fixed point ({res.reason})", file=sys.stderr
            )
        else:
            out["saved"] = str(_save(save, gait, res, z0))
    if args.json:
        print(strict_json(out))
    else:
        _print_fixed_point(out, res)
    return 0 if res.converged else 1


def _save(path, gait, res, z0) -> Path:
    meta = {
        k: v
        for k, v in (gait.meta or {}).items()
        if k not in ("z_star", "z_published", "fixed_point")
    }
    meta["fixed_point"] = {
        "found_by": f"bound-env fixed-point ({res.method}) from {gait.path}",
        "start_z": [float(v) for v in z_to_paper(z0)],
        "residual": float(res.residual),
        "iterations": int(res.iterations),
        "free": {k: float(v) for k, v in res.free.items()},
        "eigenvalues": [[float(v.real), float(v.imag)] for v in res.eigenvalues]
        if res.eigenvalues is not None
        else None,
        "emax": float(res.emax) if math.isfinite(res.emax) else None,
        "phases": list(res.phases),
        "durations": [float(d) for d in res.durations],
        "strides_to_converge": res.strides_to_converge,
    }
    return save_gait(path, res.params, z_star=res.z, z_published=gait.z_published, **meta)


def _print_fixed_point(out, res):
    print(
        f"gait {out['gait']}  method {out['method']}: {out['reason']} "
        f"after {out['iterations']} iteration(s)"
    )
    for name, unit, v in zip(Z_NAMES, Z_PAPER_UNITS, out["z"], strict=True):
        print(f"  {name:10s} = {v: .10g} {unit}")
    for k, v in res.free.items():
        print(f"  {k:10s} = {v: .10g} (freed)")
    print(f"residual max|P(z) - z| = {out['residual']:.3e}")
    if res.eigenvalues is not None:
        print("eigenvalues: " + ", ".join(f"{v.real:.6f}{v.imag:+.6f}j" for v in res.eigenvalues))
        print(f"e_max = {res.emax:.6f}  ({'stable' if res.emax < 1 else 'unstable'})")
    print(
        "phases "
        + " -> ".join(out["phases"])
        + "  durations "
        + ", ".join(f"{d * 1e3:.2f} ms" for d in out["durations"])
    )
    print(f"strides to recover from +1 % on y_g: {out['strides_to_converge']}")
    if "saved" in out:
        print(f"saved {out['saved']}")


def cmd_continue(args) -> int:
    from ..analysis.continuation import continue_branch, plot_branch

    gait, z0 = _setup(args)
    start = float(gait.params.to_gait_dict()[args.param])
    # --step is a size (unsigned, as in docs/analysis.md); a negative one must point to --to
    if args.step is not None and args.step < 0 and args.to > start:
        raise ValueError(
            f"--step {args.step:g} points away from --to {args.to:g} (the gait's "
            f"{args.param} is {start:g}); give --step {-args.step:g}"
        )
    out = out_dir(args.out)
    pins = _default_pins(args, z0, gait.params)
    branch = continue_branch(
        gait.params,
        z0,
        args.param,
        args.to,
        step=args.step,
        method=args.method,
        free=args.free,
        pin=pins or None,
        max_points=args.max_points,
        out_dir=out,
        progress=not args.quiet,
    )
    if branch.points:
        plot_branch(branch, out / "branch.png")
    flags = [(p.value, n) for p in branch.points for n in ("fold", "pd", "ns") if getattr(p, n)]
    say(
        args,
        f"{len(branch.points)} points, {branch.reason}; wrote {out / 'branch.csv'}"
        + (f" and {out / 'branch.png'}" if branch.points else ""),
    )
    for v, n in flags:
        say(args, f"  {n} between the previous point and {args.param} = {v:.6g}")
    if args.json:
        print(
            strict_json(
                {
                    "param": args.param,
                    "points": len(branch.points),
                    "reason": branch.reason,
                    "reached": bool(branch.reached),
                    "flags": [{"kind": n, "value": v} for v, n in flags],
                    "csv": str(out / "branch.csv"),
                }
            )
        )
    # a fold or any other end of the branch is a result (reported above), not an error;
    # only a branch that could not start is one
    return 0 if branch.points else 1


def cmd_sweep(args) -> int:
    from ..analysis.sweeps import plot_sweep, sweep, write_sweep_csv
    from ..sim.parallel import open_pool

    gait, z0 = _setup(args)
    if args.hi < args.lo:
        raise ValueError(f"--to ({args.hi}) must not be below --from ({args.lo})")
    n_points = math.floor((args.hi - args.lo) / args.step) + 1
    if n_points > 100_000:
        raise ValueError(f"--from/--to/--step ask for {n_points} points; at most 100000")
    values = np.round(np.arange(args.lo, args.hi + 0.5 * args.step, args.step), 12)
    for v in values:  # a value the model refuses (kc < 0, m1 <= 0, ...) is the user's error
        try:
            gait.params.with_values(**{args.param: float(v)})
        except ValueError as e:
            raise ValueError(f"--from/--to: {args.param} = {v:g} is not valid ({e})") from None
    out = out_dir(args.out)
    with open_pool(args.scheduler, args.workers) as pool:
        res = sweep(
            gait.params,
            z0,
            args.param,
            values,
            refine=args.refine,
            progress=not args.quiet,
            executor=pool.executor if pool.kind != "serial" else None,
        )
    write_sweep_csv(res, out / "sweep.csv")
    plot_sweep(res, out / "sweep.png")
    windows = {}
    for kind in ("converged", "stable"):
        w = res.window(kind)
        windows[kind] = [float(w[0]), float(w[1])] if w else None
        label = "100-stride convergence" if kind == "converged" else "e_max < 1"
        say(
            args,
            f"{label} window in {args.param}: " + (f"{w[0]:.6g} .. {w[1]:.6g}" if w else "none"),
        )
    say(args, f"wrote {out / 'sweep.csv'} and {out / 'sweep.png'}")
    if args.json:
        print(
            strict_json(
                {
                    "param": args.param,
                    "points": len(values),
                    "windows": windows,
                    "csv": str(out / "sweep.csv"),
                    "png": str(out / "sweep.png"),
                }
            )
        )
    return 0


def cmd_reproduce(args) -> int:
    from ..analysis.reproduce import run

    res = run(
        args.out,
        quick=args.quick,
        force=args.force,
        progress=not args.quiet,
        write_gaits=args.write_gaits,
        docs_dir=args.docs,
    )
    hits = ", ".join(res["cache"]["hits"]) or "none"
    say(
        args,
        f"wrote {res['report']} ({len(res['figures'])} figure files) in "
        f"{res['wall_seconds']:.1f} s; cached stages: {hits}",
    )
    if args.json:
        print(strict_json(res))
    return 0
