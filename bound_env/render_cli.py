"""``bound-env animate``: an animated GIF (and optionally one PNG frame) of the passive gait.

The robot runs PassiveBound-v0 with zero action from the gait's apex state (no start noise),
so the animation shows exactly the passive model; frames are taken from the environment's
``rgb_array`` rendering.
"""

from __future__ import annotations

import math


def register(sub) -> None:
    """Add the ``animate`` sub-command to the ``bound-env`` parser's sub-parsers."""
    p = sub.add_parser("animate", help="write a GIF of the passive gait (zero spine torque)")
    p.add_argument(
        "--gait",
        default="default",
        help="gait file path or name under configs/gaits/ (default: %(default)s)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="override a gait key, e.g. --set kc=300 --set alpha_deg=2.0",
    )
    p.add_argument(
        "--strides",
        type=float,
        default=3.0,
        help="length of the animation in passive strides (default: %(default)s)",
    )
    p.add_argument("--out", default="bound.gif", help="GIF file to write (default: %(default)s)")
    p.add_argument(
        "--fps",
        type=float,
        default=50.0,
        help="frames per second of the GIF (default: %(default)s)",
    )
    p.add_argument(
        "--slowdown",
        type=float,
        default=1.0,
        help="play this many times slower than real time (default: %(default)s)",
    )
    p.add_argument("--width", type=int, default=640, help="frame width [pixels]")
    p.add_argument("--height", type=int, default=360, help="frame height [pixels]")
    p.add_argument(
        "--frame",
        metavar="PNG",
        help="also save one frame (mid-stance of the first stride) as a PNG",
    )
    p.set_defaults(func=cmd_animate)


def animation_frames(
    gait="default", overrides=None, strides=3.0, fps=50.0, slowdown=1.0, width=640, height=360
):
    """(frames, stride period [s], simulated time between frames [s]) of the passive gait.

    One frame every ``slowdown / fps`` seconds of simulated time (rounded to whole control
    intervals of the environment); stops early if the gait fails.
    """
    import numpy as np

    from .env import PassiveBoundEnv
    from .hybrid import simulate_stride

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
    for k in range(1, n_steps + 1):
        _, _, terminated, _, info = env.step(zero)
        if k % every == 0 or terminated:
            frames.append(env.render())
        if terminated:
            print(f"the gait failed after {k * env.dt:.2f} s: {info['failure']}")
            break
    env.close()
    return frames, period, every * env.dt


def cmd_animate(args) -> int:
    from .params import parse_override
    from .render import save_gif

    if not args.strides > 0:
        raise ValueError("--strides must be positive")
    if not (args.fps > 0 and args.slowdown > 0):
        raise ValueError("--fps and --slowdown must be positive")
    overrides = dict(parse_override(s) for s in (args.set or []))
    frames, period, frame_dt = animation_frames(
        args.gait, overrides, args.strides, args.fps, args.slowdown, args.width, args.height
    )
    path = save_gif(frames, args.out, fps=args.slowdown / frame_dt)
    print(f"wrote {path}: {len(frames)} frames, {args.strides:g} strides of {period:.4f} s")
    if args.frame:
        from PIL import Image

        # mid-stance of the back leg in the first stride: ~30 % into it
        k = min(len(frames) - 1, round(0.3 * period / frame_dt))
        Image.fromarray(frames[k]).save(args.frame)
        print(f"wrote {args.frame}")
    return 0
