"""The ``bound-env`` command line. Each sub-command imports its module only when it runs."""

from __future__ import annotations

import argparse
import json
import sys
import time


def _load(args):
    from .params import load_gait, parse_override

    overrides = dict(parse_override(s) for s in (args.set or []))
    return load_gait(args.gait, overrides)


def _add_gait_args(p, default="paper"):
    p.add_argument("--gait", default=default,
                   help="gait file path or name under configs/gaits/ (default: %(default)s)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a gait key, e.g. --set kc=300 --set alpha_deg=2.0")


def cmd_stride(args) -> int:
    from .hybrid import simulate_stride
    from .params import parse_z

    gait = _load(args)
    z0 = parse_z(args.z, "--z")
    if z0 is None:
        z0 = gait.z0
    if args.repeat < 1:
        raise ValueError("--repeat must be at least 1")
    t0 = time.perf_counter()
    for _ in range(args.repeat):
        res = simulate_stride(z0, gait.params, backend=args.backend, strict=args.strict)
    elapsed = time.perf_counter() - t0
    out = res.summary()
    out["backend"] = args.backend
    out["repeat"] = args.repeat
    out["seconds_per_stride"] = elapsed / args.repeat
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"gait {gait.path}  backend {args.backend}")
    print("z0 [m, deg, deg, m/s, deg/s, deg/s] =", _fmt(out["z0"]))
    print("z1 [m, deg, deg, m/s, deg/s, deg/s] =", _fmt(out["z1"]) if out["z1"] else None)
    print("phases    ", " -> ".join(out["phases"]))
    print("durations ", ", ".join(f"{d * 1e3:.2f} ms" for d in out["durations"]))
    print(f"period     {out['period']:.4f} s   energy {out['energy']['start']:.4f} -> "
          f"{out['energy']['end']:.4f} J   failure: {out['failure']}")
    return 0


def _fmt(v):
    return "[" + ", ".join(f"{x:.4f}" for x in v) + "]"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bound-env",
        description="Passive quadrupedal bounding with a spring-damper spine (Yamasaki et al.)",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("stride", help="simulate one apex-to-apex stride")
    _add_gait_args(p)
    p.add_argument("--z", help="start apex state v1,...,v6 in [m, deg, deg, m/s, deg/s, deg/s] "
                   "(default: the gait's z_star, else z_published); use --z=-0.1,... for negatives")
    p.add_argument("--repeat", type=int, default=1, help="evaluate the stride N times (timing)")
    p.add_argument("--backend", choices=("fast", "reference"), default="fast")
    p.add_argument("--strict", action="store_true",
                   help="end the stride at the first apex after any touchdown")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_stride)

    for register in _EXTRA_COMMANDS:
        register(sub)
    return parser


def _register_optional():
    """Sub-commands that live beside their modules (analysis, environment, agents)."""
    regs = []
    for mod, attr in (
        ("bound_env.analysis.cli", "register"),
        ("bound_env.render_cli", "register"),
        ("agents.cli", "register"),
    ):
        try:
            module = __import__(mod, fromlist=[attr])
        except ModuleNotFoundError as e:
            if e.name and mod.startswith(e.name):
                continue
            raise
        regs.append(getattr(module, attr))
    return regs


_EXTRA_COMMANDS: list = []


def main(argv=None) -> int:
    _EXTRA_COMMANDS[:] = _register_optional()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError) as e:
        print(f"bound-env {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
