"""Run a policy in the environment it was trained for: `load_policy` and ``bound-env rollout``.

A trained policy needs more than its ``model.zip``: the environment kwargs it was trained
with (``max_torque``, ``dt``, the gait), the observation wrappers of its config
(`agents.common.wrappers.ObservationFilter`) and its ``VecNormalize`` statistics. `load_policy`
reads them all (with the checks of `agents.runtime.policy.load_controller`) and returns an
environment factory and an action function that belong together:

```python
from agents.runtime.rollout import load_policy

make_env, act = load_policy("default")        # a shipped name, or a policy/run folder
env = make_env()                               # or gym.make("PassiveBound-v1")
obs, info = env.reset(seed=0)
obs, reward, terminated, truncated, info = env.step(act(obs, info))
```

``act(obs, info)`` is a `bound_env.control.PlainPolicy`: it announces each apex to a stride
controller itself (the info carries the exact apex state), so this loop gives ``bound-env
rollout``'s trajectory bit for bit; a stride controller called without ``info`` raises a
TypeError, and an env whose observation length, ``max_torque`` or ``dt`` is not the policy's
a ValueError (`bound_env.control.plain`). Feedback policies (PPO, damping, passive) also take
``act(obs)``. ``PassiveBound-v1`` has the published task's defaults (80 N m), the settings of
every shipped policy except two families trained at ``rtol`` 1e-8 (``warm-started/*``,
``ppo-v1-final/*``: `make_env` sets it; the tolerance does not show in what the env returns).

Only the wrappers that change what the policy sees or does (observation and action
wrappers) are applied; training-only wrappers such as `agents.common.wrappers.PerturbedStarts`
(the start distribution) are not: the env's own ``reset_noise_scale`` sets the start.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from bound_env.control.plain import FULL_OBS_DIM, PlainPolicy
from bound_env.control.privileged import is_privileged

from ..common.policy_files import find_policy_files, read_policy_section
from .controllers import MLPController, check_gait
from .policy import load_controller, resolve_policy, unwrapped_name

# About how many frames a rollout's video has at most. Frames are streamed to the file
# (`bound_env.envs.render.VideoWriter`), so memory does not grow with them; the cap keeps the
# file's size and the rendering time bounded (a frame is ~0.7 MB raw, ~50-100 kB in a GIF).
MAX_VIDEO_FRAMES = 2000
ENV_ID = "PassiveBound-v0"  # the env class; the policy's env id only adds its registered kwargs


def _policy_wrappers(path) -> list:
    """[(class, kwargs)] of the observation/action wrappers in a saved policy's config (none
    for a distilled choice policy, `agents.experts.distill`, or a learned adaptive controller,
    `agents.runtime.adaptive_policy`: they read the env's own observation)."""
    import gymnasium as gym

    from ..common.config import class_entries, get_class_by_name
    from .adaptive_policy import POLICY_FILE as ADAPTIVE
    from .choice_policy import POLICY_FILE

    if Path(path).is_dir() and any((Path(path) / f).is_file() for f in (POLICY_FILE, ADAPTIVE)):
        return []
    section, _, _ = read_policy_section(find_policy_files(path))
    out = []
    for name, kwargs in class_entries(section.get("env_wrapper")):
        cls = get_class_by_name(name)
        if issubclass(cls, (gym.ObservationWrapper, gym.ActionWrapper)):
            out.append((cls, kwargs))
    return out


def load_policy(path, gait=None, force: bool = False, env_id: str | None = None):
    """``(env_factory, act)`` for a policy name (`agents.runtime.policy.policy_names`) or folder.

    ``env_factory(**kwargs)`` makes the environment the policy was trained for (its env kwargs
    and observation wrappers; ``kwargs`` add to or override them, e.g. ``render_mode``,
    ``reset_noise_scale``, ``max_episode_steps``). ``act(obs, info)`` is the deterministic
    action (float32, shape (1,)) for an observation of that environment (or of
    ``PassiveBound-v1``: the full observation is filtered as the policy was trained) and the
    info returned with it, a `bound_env.control.PlainPolicy` (module docstring; ``act(obs)``
    for feedback policies); ``act.controller`` is the controller. ``gait`` evaluates on another
    gait (refused for a trained policy unless ``force``); built-in controllers (``passive``,
    ...) run on ``gait`` or the default one. ``env_id``: the env a plain SB3 ``model.zip``
    without ``config.yaml`` was trained on (`agents.runtime.policy.load_controller`).
    """
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    ctrl = load_controller(path, gait=gait, force=force, env_id=env_id)
    resolved = resolve_policy(unwrapped_name(path))  # NAME+of: NAME's env and wrappers
    wrappers = [] if isinstance(resolved, str) else _policy_wrappers(resolved)
    env_kwargs = dict(ctrl.env_kwargs)
    if gait is not None:
        env_kwargs["gait"] = str(gait)
    obs_index, full_dim = None, FULL_OBS_DIM
    if isinstance(ctrl, MLPController) and ctrl.obs_index is not None:
        # act takes the full observation and the one of the ObservationFilter (make_env's)
        obs_index = ctrl.obs_index
        full_dim += 0 if env_kwargs.get("exclude_current_positions_from_observation", True) else 1
        inner = replace(ctrl, obs_index=None)
    elif isinstance(ctrl, MLPController):
        inner, full_dim = ctrl, int(ctrl.obs_shape[0])
    else:
        inner = ctrl
    act = PlainPolicy(inner, obs_index=obs_index, full_dim=full_dim, name=str(path))

    def env_factory(**kwargs):
        env = gym.make(ENV_ID, **{**env_kwargs, **kwargs})
        for cls, kw in wrappers:
            env = cls(env, **kw)
        return env

    env_factory.env_kwargs = env_kwargs
    act.controller = ctrl
    return env_factory, act


def rollout(
    policy="default",
    gait=None,
    strides: int = 50,
    seed: int = 0,
    noise: float = 0.0,
    video: str | Path | None = None,
    force: bool = False,
) -> dict:
    """One episode of ``strides`` strides (or until a fall); a JSON-able summary.

    Keys: ``policy``, ``privileged`` (true: the controller reads the robot's true plant,
    `bound_env.control.privileged`: a reference, never deployable), ``gait``, ``env_kwargs``,
    ``seed``, ``noise`` (the env's
    ``reset_noise_scale``), ``strides`` (completed), ``requested_strides``, ``fell`` and
    ``failure`` (the simulator's reason, or null), ``apex_error`` (per stride: the largest
    |z - z*| / apex_scales component, where z* is the gait's fixed point), ``mean_abs_tau``
    (N m, average over control intervals of equal length), ``max_torque`` (N m), ``steps``,
    ``time`` (s), ``video`` (path or null), ``video_every`` (a frame of every that many
    control intervals: 1 unless the run would give more than about `MAX_VIDEO_FRAMES` frames,
    `video_every`). The frames are streamed to the file (`bound_env.envs.render.VideoWriter`), so
    memory does not grow with ``strides``.
    """
    from bound_env.sim.task import NO_APEX_TIME

    if not (isinstance(strides, int) and 1 <= strides <= 100_000):
        raise ValueError(f"--strides must be an integer from 1 to 100000, got {strides!r}")
    if isinstance(seed, bool) or not (isinstance(seed, int) and 0 <= seed < 2**32):
        raise ValueError(f"--seed must be an integer from 0 to 2**32 - 1, got {seed!r}")
    if not (math.isfinite(noise) and 0.0 <= noise <= 10.0):
        raise ValueError(f"--noise must be a number from 0 to 10, got {noise!r}")
    if video is not None and Path(video).suffix.lower() not in (".gif", ".mp4"):
        raise ValueError(f"--video must end in .gif or .mp4, got {str(video)!r}")
    if video is not None:  # before the run, not after it
        from bound_env.commands.cli_args import check_writable

        check_writable(video, "--video", folder=False)
    make_env, act = load_policy(policy, gait=gait, force=force)
    dt = float(make_env.env_kwargs.get("dt", 0.01))
    max_steps = strides * (int(math.ceil(NO_APEX_TIME / dt)) + 2)
    env = make_env(
        reset_noise_scale=float(noise),
        max_episode_steps=max_steps,
        render_mode="rgb_array" if video else None,
    )
    task = env.unwrapped.task
    z_ref, scales = np.asarray(task.z_ref), np.asarray(task.apex_scales)
    every = video_every(task, strides, dt) if video else 1
    fps = max(1, round(1 / dt / every))
    if video and Path(video).suffix.lower() == ".gif":
        fps = min(fps, 50)  # players honour at most 50 frames per second in a GIF
    with contextlib.ExitStack() as stack:
        writer = stack.enter_context(_video_writer(video, fps)) if video else None
        obs, info = env.reset(seed=seed)
        failure, errors, taus, steps = info.get("failure"), [], [], 0
        if writer is not None:
            writer.append(env.render())
        while failure is None and len(errors) < strides:
            # act announces every apex to a stride controller (bound_env.control.plain)
            obs, _, terminated, truncated, info = env.step(act(obs, info))
            steps += 1
            taus.append(abs(float(info["tau"])))
            if writer is not None and steps % every == 0:
                writer.append(env.render())  # encoded and let go: nothing accumulates
            if "apex_z" in info:
                z = np.asarray(info["apex_z"])
                errors.append(float(np.max(np.abs((z - z_ref) / scales))))
            if terminated:
                failure = info.get("failure") or "terminated"
            elif truncated:
                break
        env.close()
    if video and every > 1:
        print(
            f"[rollout] --video: {steps} control intervals, a frame of every {every}th "
            f"(about {MAX_VIDEO_FRAMES} frames at most; it plays in real time)",
            file=sys.stderr,
        )
    return {
        "policy": str(policy),
        "privileged": is_privileged(act.controller),
        "gait": str(make_env.env_kwargs.get("gait", "default")),
        "env_kwargs": _jsonable(make_env.env_kwargs),
        "seed": seed,
        "noise": noise,
        "requested_strides": strides,
        "strides": len(errors),
        "fell": failure is not None,
        "failure": failure,
        "apex_error": errors,
        "mean_abs_tau": float(np.mean(taus)) if taus else 0.0,
        "max_torque": float(task.max_torque),
        "steps": steps,
        "time": steps * dt,
        "video": str(video) if video else None,
        "video_every": every if video else None,
    }


def _jsonable(d: dict) -> dict:
    return json.loads(json.dumps(d, default=lambda v: np.asarray(v).tolist()))


def video_every(task, strides: int, dt: float) -> int:
    """Frames are taken of every ``video_every``-th control interval: 1 unless ``strides``
    strides of the gait's own period (one passive stride from z*) would give more than
    `MAX_VIDEO_FRAMES` frames. Chosen before the run, so frames can be streamed."""
    from bound_env.model.stride import simulate_stride
    from bound_env.sim.task import NO_APEX_TIME

    period = simulate_stride(task.z_ref, task.params).t_end
    if not (math.isfinite(period) and period > 0):  # a gait that fails: its longest stride
        period = NO_APEX_TIME
    return max(1, math.ceil(strides * period / dt / MAX_VIDEO_FRAMES))


def _video_writer(path, fps):
    """A `bound_env.envs.render.VideoWriter` (a GIF, or an MP4 through imageio-ffmpeg) that streams
    the frames to ``path`` and writes it atomically."""
    from bound_env.envs.render import VideoWriter

    return VideoWriter(path, fps)


def summary_text(r: dict) -> str:
    err = r["apex_error"]
    fell = f"fell: {r['failure']}" if r["fell"] else "no fall"
    if err:
        apex = f"apex error (apex_scales units) last {err[-1]:.3g}, max {max(err):.3g}"
    else:  # no apex reached: there is no apex error to report (not "max nan")
        apex = "no apex reached, so no apex error"
    mark = " (privileged: reads the robot's true plant, never deployable)" * bool(
        r.get("privileged")
    )
    return (
        f"{r['policy']}{mark} on gait {r['gait']}: {r['strides']}/{r['requested_strides']} "
        f"strides, {fell}; {apex}; mean |tau| {r['mean_abs_tau']:.3g} N m "
        f"of {r['max_torque']:g}"
    )


__all__ = ["check_gait", "load_policy", "rollout"]
