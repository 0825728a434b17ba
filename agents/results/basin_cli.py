"""``bound-env basin-map`` (registered with `agents.cli`): the basin atlas of
`bound_env.analysis.basin` for the passive gait or a trained policy."""

from __future__ import annotations

import sys
from pathlib import Path

from ..runtime.policy_args import POLICY_HELP, policy_label


def register(sub) -> None:
    from bound_env.analysis.basin_defaults import (
        DEFAULT_CHUNK,
        DEFAULT_GRID,
        DEFAULT_STRIDES,
        MAX_GRID,
        MAX_STRIDES,
    )
    from bound_env.commands.cli_args import POLICY_GAIT_HELP, add_gait_args, add_progress_args
    from bound_env.files.values import number
    from bound_env.sim.parallel import add_scheduler_args

    p = sub.add_parser(
        "basin-map", help="2-D basin map (basin.npz, basin.png) of the passive gait or a policy"
    )
    p.add_argument("--policy", default="passive", help=POLICY_HELP + " (default: %(default)s)")
    p.add_argument(
        "--axes",
        default="xdot_g,y_g",
        help="two apex components: y_g, theta1, theta2, xdot_g, theta1dot, "
        "theta2dot (default: %(default)s)",
    )
    p.add_argument(
        "--grid",
        type=number(int, 2, MAX_GRID),
        default=DEFAULT_GRID,
        help=f"points per axis, 2 to {MAX_GRID} (default: %(default)s)",
    )
    p.add_argument(
        "--range",
        dest="ranges",
        metavar="LO,HI,LO,HI",
        help="ranges of the two axes in the paper's units [m, deg, deg, m/s, deg/s, "
        "deg/s] (default: z* plus or minus a fixed half-width per component)",
    )
    add_gait_args(p, default=None, overrides=False, help=POLICY_GAIT_HELP)
    p.add_argument(
        "--strides",
        type=number(int, 1, MAX_STRIDES),
        default=DEFAULT_STRIDES,
        help=f"strides allowed to return, at most {MAX_STRIDES} (default: %(default)s)",
    )
    p.add_argument(
        "--chunk",
        type=number(int, 1, MAX_GRID**2),
        default=DEFAULT_CHUNK,
        help="starts per task (default: %(default)s)",
    )
    p.add_argument(
        "--no-overlay",
        action="store_true",
        help="do not compute the passive map to overlay its boundary",
    )
    add_scheduler_args(p, workers_default=2)
    p.add_argument(
        "--out", required=True, help="directory for basin.npz, basin.png and the chunk cache"
    )
    p.add_argument(
        "--png",
        metavar="PATH",
        help="also write the figure to PATH (e.g. docs/basin_passive_xdot_y.png); "
        "nothing outside --out is written without it",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="map a policy on a gait or with files it was not trained for",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    add_progress_args(p)
    p.set_defaults(func=cmd_basin_map)


def resolve(policy: str, gait: str | None, force: bool = False):
    """(controller, or None for the compiled passive path; label; gait)."""
    if policy == "passive":
        return None, "passive", gait or "default"
    from ..runtime.policy import load_controller

    ctrl = load_controller(policy, gait=gait, force=force)
    if not callable(ctrl) or not hasattr(ctrl, "env_kwargs"):
        raise ValueError(
            f"--policy {policy}: basin-map needs 'passive' or a controller "
            "with env_kwargs and __call__(obs) or batch(obs)"
        )
    return ctrl, policy_label(policy), gait or ctrl.env_kwargs.get("gait") or "default"


def cmd_basin_map(args) -> int:
    from bound_env.analysis.basin import basin_map, summary_text
    from bound_env.commands.cli_args import strict_json

    controller, label, gait = resolve(args.policy, args.gait, args.force)
    s = basin_map(
        controller,
        label,
        axes=args.axes,
        grid=args.grid,
        ranges=args.ranges,
        gait=gait,
        max_strides=args.strides,
        chunk=args.chunk,
        scheduler=args.scheduler,
        workers=args.workers,
        out=args.out,
        progress=sys.stderr.isatty() and not args.no_progress,
        overlay_passive=not args.no_overlay,
    )
    if args.png:
        from bound_env.files.cache import atomic_write

        atomic_write(args.png, (Path(args.out) / "basin.png").read_bytes())
        s["png"] = str(args.png)
    if args.json:
        print(strict_json(s))
    else:
        print(summary_text(s))
        print(f"wrote {Path(args.out) / 'basin.npz'} and {Path(args.out) / 'basin.png'}")
    return 0
