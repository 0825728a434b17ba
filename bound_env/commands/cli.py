"""The ``bound-env`` command line. Each sub-command imports its module only when it runs.

Sub-commands come from three places, in this order: ``stride`` (here), the core modules
`bound_env.commands.analysis_cli` and `bound_env.commands.render_cli`, and plug-ins outside
the package, which declare a ``register(subparsers)`` function in the ``bound_env.commands``
entry-point group (``agents`` does, in ``pyproject.toml``). The core never names a plug-in and
works without it.
"""

from __future__ import annotations

import argparse
import sys
import time
from importlib.metadata import entry_points

from ..files.values import number
from .cli_args import add_gait_args, gait_from_args, strict_json

PLUGIN_GROUP = "bound_env.commands"  # entry points: name = "module:register"


def cmd_stride(args) -> int:
    from ..model.params import parse_z
    from ..model.stride import simulate_stride

    gait = gait_from_args(args)
    z0 = parse_z(args.z, "--z")
    if z0 is None:
        z0 = gait.z0
    if not 1 <= args.repeat <= 10_000_000:
        raise ValueError(f"--repeat must be from 1 to 10000000, got {args.repeat}")
    t0 = time.perf_counter()
    res = simulate_stride(z0, gait.params, backend=args.backend, strict=args.strict)
    first = time.perf_counter() - t0  # includes loading (or compiling) the compiled code
    t0 = time.perf_counter()
    for _ in range(args.repeat - 1):
        res = simulate_stride(z0, gait.params, backend=args.backend, strict=args.strict)
    elapsed = time.perf_counter() - t0
    out = res.summary()
    out["backend"] = args.backend
    out["repeat"] = args.repeat
    # timed after a warm-up stride (the first one loads the compiled code); with --repeat 1
    # only the first stride exists, and it is reported as it is
    out["seconds_per_stride"] = elapsed / (args.repeat - 1) if args.repeat > 1 else first
    out["seconds_first_stride"] = first
    if args.json:
        print(strict_json(out))
        return 0
    print(f"gait {gait.path}  backend {args.backend}")
    print("z0 [m, deg, deg, m/s, deg/s, deg/s] =", _fmt(out["z0"]))
    print("z1 [m, deg, deg, m/s, deg/s, deg/s] =", _fmt(out["z1"]) if out["z1"] else None)
    print("phases    ", " -> ".join(out["phases"]))
    print("durations ", ", ".join(f"{d * 1e3:.2f} ms" for d in out["durations"]))
    print(
        f"period     {out['period']:.4f} s   energy {out['energy']['start']:.4f} -> "
        f"{out['energy']['end']:.4f} J   failure: {out['failure']}"
    )
    return 0


def _fmt(v):
    return "[" + ", ".join(f"{x:.4f}" for x in v) + "]"


def build_parser(registrars=None) -> argparse.ArgumentParser:
    """The whole parser; ``registrars`` defaults to `command_registrars()`."""
    parser = argparse.ArgumentParser(
        prog="bound-env",
        description="Passive quadrupedal bounding with a spring-damper spine (Yamasaki et al.)",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("stride", help="simulate one apex-to-apex stride")
    add_gait_args(p, default="paper")
    p.add_argument(
        "--z",
        help="start apex state v1,...,v6 in [m, deg, deg, m/s, deg/s, deg/s] "
        "(default: the gait's z_star, else z_published); use --z=-0.1,... for negatives",
    )
    p.add_argument(
        "--repeat",
        type=number(int, 1, 10_000_000),
        default=1,
        help="evaluate the stride N times (timing after a warm-up stride)",
    )
    p.add_argument("--backend", choices=("fast", "reference"), default="fast")
    p.add_argument(
        "--strict", action="store_true", help="end the stride at the first apex after any touchdown"
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_stride)

    for register in command_registrars() if registrars is None else registrars:
        register(sub)
    return parser


def command_registrars() -> list:
    """``register`` functions of the core sub-command modules and of the installed plug-ins.

    A plug-in whose module is not installed (an entry point left behind) is skipped; an import
    error inside one (a broken dependency) is raised.
    """
    from . import analysis_cli, render_cli

    regs = [analysis_cli.register, render_cli.register]
    for ep in sorted(entry_points(group=PLUGIN_GROUP), key=lambda ep: ep.name):
        try:
            regs.append(ep.load())
        except ModuleNotFoundError as e:
            missing = e.name and (ep.module == e.name or ep.module.startswith(e.name + "."))
            if not missing:
                raise
    return regs


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("bound_env")
    except PackageNotFoundError:
        return "unknown (not installed)"


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # named by the sub-command's parser: "bound-env margins: error: ..."
            sub = parser._subparsers._group_actions[0].choices.get(args.command, parser)
            sub.error(f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as e:  # usage errors (2), --help and --version (0), as a return code
        return e.code if isinstance(e.code, int) else 2
    args.argv = list(sys.argv[1:] if argv is None else argv)  # what a run records it ran
    from ..sim.parallel import TasksFailed, Terminated, on_sigterm

    restore = on_sigterm()  # SIGTERM unwinds like Ctrl-C: pools shut down, caches are kept
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: one line, not a traceback
        how = "SIGTERM" if isinstance(e, Terminated) else "Ctrl-C"
        hint = _resume_hint(args)
        print(f"bound-env {args.command}: interrupted ({how}); {hint}", file=sys.stderr)
        return 143 if isinstance(e, Terminated) else 130
    except (ValueError, FileNotFoundError, TasksFailed) as e:
        print(f"bound-env {args.command}: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # a file in the way of a folder, a folder given for a file, ...
        where = f": {e.filename}" if getattr(e, "filename", None) else ""
        print(f"bound-env {args.command}: error: {e.strerror or e}{where}", file=sys.stderr)
        return 2
    finally:
        restore()


# commands whose finished work is cached (bound_env.files.cache) and resumed by the same command
RESUMABLE = {"margins", "compare", "reproduce", "continue", "sweep", "basin-map", "distill"}


def _resume_hint(args) -> str:
    if args.command in RESUMABLE:
        return "finished work is cached: run the same command again to resume"
    if args.command == "train":
        return "continue from the last checkpoint with the same command and --resume"
    if args.command == "finetune":
        return "run the same command again to resume from its last checkpoint"
    return "nothing to resume"


if __name__ == "__main__":
    sys.exit(main())
