"""``bound-env animate``: an animated GIF (and optionally one PNG frame) of the passive gait,
``bound.gif`` in the ``--out`` folder (``out/animate``), or the .gif/.mp4 that ``--out`` names.

The robot runs PassiveBound-v0 with zero action from the gait's apex state (no start noise),
so the animation shows exactly the passive model; frames are taken from the environment's
``rgb_array`` rendering.

``bound-env demo`` is the main job: the passive cycle (a zero-action episode, ``bound.gif``),
then every registered *demo part* (`register_demo_part`). The core registers none: a part
that needs more than the core lives above it and registers itself when its commands are
registered (the ``bound_env.commands`` entry point, `bound_env.commands.cli`); ``agents`` adds the
passive-vs-learned comparison from a perturbed start (agents/results/demo.py, ``comparison`` in
``summary.json``, ``compare.gif``). bound_env never imports agents (tests/test_layers.py).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from pathlib import Path

from ..files.values import number
from .cli_args import add_gait_args, add_progress_args, gait_overrides, out_dir, strict_json

# name -> part(gait=..., out=..., progress=...) -> (JSON-able summary, lines to print at the
# end); ``bound-env demo`` runs them in order and stores each summary under its name
DEMO_PARTS: dict[str, Callable] = {}


def register_demo_part(name: str, part: Callable) -> None:
    """Add ``part`` to ``bound-env demo`` (its summary goes to ``summary.json[name]``)."""
    DEMO_PARTS[name] = part


def register(sub) -> None:
    """Add the ``animate`` sub-command to the ``bound-env`` parser's sub-parsers."""
    p = sub.add_parser("animate", help="write a GIF of the passive gait (zero spine torque)")
    add_gait_args(p, default="default")
    p.add_argument(
        "--strides",
        type=number(float, 0, 1000, lo_open=True),
        default=3.0,
        help="length of the animation in passive strides (default: %(default)s)",
    )
    p.add_argument(
        "--out",
        default="out/animate",
        metavar="DIR",
        help="folder for bound.gif, as every command's --out (default: %(default)s); a path "
        "ending in .gif or .mp4 names the file itself (the old spelling)",
    )
    p.add_argument(
        "--fps",
        type=number(float, 0, 1000, lo_open=True),
        default=50.0,
        help="frames per second of the GIF (default: %(default)s)",
    )
    p.add_argument(
        "--slowdown",
        type=number(float, 0, 1000, lo_open=True),
        default=1.0,
        help="play this many times slower than real time (default: %(default)s)",
    )
    p.add_argument("--width", type=number(int, 16, 8192), default=640, help="frame width [pixels]")
    p.add_argument(
        "--height", type=number(int, 16, 8192), default=360, help="frame height [pixels]"
    )
    p.add_argument(
        "--frame",
        metavar="PNG",
        help="also save one frame (mid-stance of the first stride) as a PNG",
    )
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    add_progress_args(p)
    p.set_defaults(func=cmd_animate)

    p = sub.add_parser(
        "demo",
        help="the main job: a zero-action episode of PassiveBound-v0 on the passive cycle, "
        "then passive vs the shipped learned controller from a perturbed start",
    )
    add_gait_args(p, default="default", overrides=False)
    p.add_argument("--out", default="out/demo", help="folder for summary.json and bound.gif")
    p.add_argument(
        "--gif-strides",
        type=number(float, 0, 1000, lo_open=True),
        default=3.0,
        help="strides in the animation",
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    add_progress_args(p)
    p.set_defaults(func=cmd_demo)


def animation_frames(
    gait="default",
    overrides=None,
    strides=3.0,
    fps=50.0,
    slowdown=1.0,
    width=640,
    height=360,
    progress=False,
    desc="frames",
):
    """(frames, stride period [s], simulated time between frames [s]) of the passive gait.

    One frame every ``slowdown / fps`` seconds of simulated time (rounded to whole control
    intervals of the environment); stops early if the gait fails. ``progress``: a progress
    bar (stderr) over the control intervals.
    """
    import numpy as np

    from ..envs.env import PassiveBoundEnv
    from ..model.stride import simulate_stride

    env = PassiveBoundEnv(
        gait=gait,
        gait_overrides=overrides,
        reset_noise_scale=0.0,
        render_mode="rgb_array",
        width=width,
        height=height,
    )
    period = simulate_stride(env.task.z_ref, env.params).t_end
    if not math.isfinite(period):
        period = 0.4
    every = max(1, round(slowdown / (fps * env.dt)))
    n_steps = max(1, math.ceil(strides * period / env.dt))
    env.reset(seed=0)
    frames = [env.render()]
    zero = np.zeros(1, dtype=np.float32)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n_steps, desc=desc, unit="step", file=sys.stderr)
    try:
        for k in range(1, n_steps + 1):
            _, _, terminated, _, info = env.step(zero)
            if k % every == 0 or terminated:
                frames.append(env.render())
            if bar is not None:
                bar.update()
            if terminated:
                print(f"the gait failed after {k * env.dt:.2f} s: {info['failure']}")
                break
    finally:
        if bar is not None:
            bar.close()
        env.close()
    return frames, period, every * env.dt


def cmd_animate(args) -> int:
    from ..envs.render import write_video

    if not args.strides > 0:
        raise ValueError("--strides must be positive")
    if not (args.fps > 0 and args.slowdown > 0):
        raise ValueError("--fps and --slowdown must be positive")
    target = Path(args.out)
    if target.suffix.lower() in (".gif", ".mp4") and not target.is_dir():
        out_dir(target.parent, "--out")  # the old spelling: the animation file itself
    else:
        target = out_dir(target, "--out") / "bound.gif"
    if args.frame is not None:
        if Path(args.frame).is_dir():
            raise ValueError(f"--frame {args.frame} is a folder; give a file name")
        out_dir(Path(args.frame).parent, "--frame")
    overrides = gait_overrides(args)
    frames, period, frame_dt = animation_frames(
        args.gait,
        overrides,
        args.strides,
        args.fps,
        args.slowdown,
        args.width,
        args.height,
        progress=not args.no_progress,
        desc=target.name,
    )
    if not frames:
        raise ValueError(f"gait {args.gait!r} gives no frames to animate")
    path = write_video(frames, target, fps=args.slowdown / frame_dt)
    msg = f"wrote {path}: {len(frames)} frames, {args.strides:g} strides of {period:.4f} s"
    print(msg, file=sys.stderr if args.json else sys.stdout)
    if args.frame:
        from PIL import Image

        # mid-stance of the back leg in the first stride: ~30 % into it
        k = min(len(frames) - 1, round(0.3 * period / frame_dt))
        Image.fromarray(frames[k]).save(args.frame)
        if not args.json:
            print(f"wrote {args.frame}")
    if args.json:
        print(
            strict_json(
                {
                    "gif": str(path),
                    "frames": len(frames),
                    "strides": args.strides,
                    "period": period,
                    "frame": args.frame,
                }
            )
        )
    return 0


def cmd_demo(args) -> int:
    """Zero action from z* for a whole episode, then the registered demo parts (`DEMO_PARTS`:
    with agents installed, passive vs the shipped learned controller from a perturbed start);
    print a summary, write ``summary.json`` and the GIFs."""
    import gymnasium as gym
    import numpy as np

    from ..envs.render import write_video
    from ..files.cache import atomic_write
    from ..model.params import Z_PAPER_UNITS, z_to_paper

    out = out_dir(args.out)
    env = gym.make("PassiveBound-v0", gait=args.gait, reset_noise_scale=0.0)
    _, info = env.reset(seed=0)
    z_ref = env.unwrapped.task.z_ref
    zero = np.zeros(1, dtype=np.float32)
    apex_err, ret, steps, x0 = [], 0.0, 0, info["x_position"]
    terminated = truncated = False
    while not (terminated or truncated):
        _, reward, terminated, truncated, info = env.step(zero)
        ret += float(reward)
        steps += 1
        if "apex_z" in info:
            apex_err.append(float(np.max(np.abs(np.asarray(info["apex_z"]) - z_ref))))
    env.close()
    summary = {
        "gait": args.gait,
        "z_star": [float(v) for v in z_to_paper(z_ref)],
        "z_star_units": list(Z_PAPER_UNITS),  # the paper's units (degrees); SI under parts
        "steps": steps,
        "sim_time_s": steps * env.unwrapped.dt,
        "strides": len(apex_err),
        "distance_m": float(info["x_position"] - x0),
        "max_apex_error_si": max(apex_err) if apex_err else None,
        "return": ret,
        "terminated": bool(terminated),
        "truncated": bool(truncated),
        "failure": info.get("failure"),
    }
    progress = not args.no_progress
    frames, period, frame_dt = animation_frames(
        args.gait, None, args.gif_strides, progress=progress, desc="bound.gif"
    )
    gif = write_video(frames, out / "bound.gif", fps=1.0 / frame_dt) if frames else None
    later = []  # the parts' lines, printed at the end
    for name, part in DEMO_PARTS.items():
        summary[name], lines = part(gait=args.gait, out=out, progress=progress)
        later += lines
    atomic_write(out / "summary.json", strict_json(summary))
    if args.json:
        print(
            strict_json(
                {**summary, "summary": str(out / "summary.json"), "gif": str(gif) if gif else None}
            )
        )
        return 0
    print(f"PassiveBound-v0, zero action from z* of gait {args.gait!r}:")
    print(
        f"  {summary['strides']} strides in {summary['sim_time_s']:.2f} s, "
        f"{summary['distance_m']:.2f} m down the slope, return {ret:.1f}"
    )
    err = summary["max_apex_error_si"]
    print(f"  largest apex deviation from z*: {'-' if err is None else f'{err:.2e}'} (SI)")
    print(f"  ended by {'truncation' if truncated else 'termination: ' + str(summary['failure'])}")
    print(
        f"wrote {out / 'summary.json'} and {gif} ({len(frames)} frames, period {period:.4f} s)"
        if gif
        else f"wrote {out / 'summary.json'} (no frames: the gait fails at once)"
    )
    for line in later:
        print(line)
    return 0
