"""The main job's comparison (``bound-env demo``): from one perturbed apex start, the passive
robot falls, the stride LQR (``lqr``) falls too, and the shipped learned controller
(``default``) brings the gait back to its cycle: why learning.

**The start** is z* + r |z*| xi with xi = ``random_directions(DEMO_DIRECTIONS,
DEMO_SEED)[DEMO_INDEX]`` (`bound_env.analysis.margins.random_directions`, max |xi_i| = 1) and r =
``DEMO_SIZE``, chosen on the *validation* directions (seed 777), never on the test set's (seed
12345): it is the first of the 16 directions of seed 777 from which, at each of r = 0.15, 0.2
and 0.25, the passive gait falls, ``lqr`` falls and ``default`` returns within
``DEMO_STRIDES`` strides (direction 6; so the choice is not on a knife's edge). At r = 0.2 the
passive gait falls in its first stride (its back hip touches the ground), ``lqr`` in its
second (front hip), and ``default`` returns in 10 strides. (The demo's earlier start,
direction 1, showed passive vs learned only: the LQR alone returns from it as fast as
``default``, which picks the LQR's own plan there.)
``tests/test_demo.py`` checks the three outcomes.

**The runs** are those of the margins (`bound_env.analysis.margins.ClosedLoop.run`, the
closed-loop apex map at the evaluation tolerance): *returned* means within 1e-4 (SI) of z*
within ``DEMO_STRIDES`` strides. ``bound_env`` never imports ``agents`` (tests/test_layers.py):
`agents.cli.register` adds `demo_comparison` to `bound_env.commands.render_cli`'s demo parts when
``bound-env`` builds its parser (the ``bound_env.commands`` entry point).

**The animation** (``compare.gif``) shows the three robots side by side, one frame pair per two
control intervals (50 frames per second of simulated time, played in real time), drawn by
`bound_env.envs.render.render_frame`; a fallen robot holds its last frame. The learned robot is
shown for ``SHOW_AFTER`` more strides once it has returned. The one-stride episodes of the
apex map are drawn as one run: each starts where the last one's apex was.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from bound_env.model.params import Z_SI_UNITS

from ..common.seeds import VALIDATION_SEED

DEMO_POLICY = "default"  # the shipped learned controller (a name for finetuned/s0)
DEMO_BASELINE = "lqr"  # the classical controller that falls from the start
DEMO_SEED = VALIDATION_SEED  # 777: validation directions (the test set's seed is 12345)
DEMO_DIRECTIONS = 16  # xi = random_directions(16, 777)[6] (a row does not depend on n)
DEMO_INDEX = 6
DEMO_SIZE = 0.2  # r, in units of |z*_i|
DEMO_STRIDES = 100  # strides allowed to return (the margins' basin_strides, quick budget)
SHOW_AFTER = 2  # strides the animation shows after the learned robot's return
PANEL = (400, 240)  # width, height of each robot's half of a frame [pixels]
FRAME_STEPS = 2  # control intervals per frame (50 frames per simulated second at dt = 10 ms)


def demo_start(gait="default") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z0, z*, xi): the perturbed start of the comparison (module docstring), SI."""
    from bound_env.analysis.margins import random_directions
    from bound_env.model.params import load_gait

    z_star = np.asarray(load_gait(gait).z0, dtype=float)
    xi = random_directions(DEMO_DIRECTIONS, DEMO_SEED)[DEMO_INDEX]
    return z_star + DEMO_SIZE * np.abs(z_star) * xi, z_star, xi


class _Recorded:
    """The env of a `ClosedLoop`, recording after every reset and step: the state (x shifted
    so that the chained one-stride episodes read as one run), the elapsed time, the strides
    completed and tau; and |tau| of every control interval."""

    def __init__(self, env):
        self._env = env
        self.states: list = []  # (y, aux, time [s], strides, tau [N m])
        self.taus: list[float] = []
        self.last_apex_z = None
        self._since = list(env.task.obs_names).index("time_since_apex")
        self._x0 = self._t0 = 0.0  # offsets of the current one-stride episode
        self._next = (0.0, 0.0)  # ... of the next one: the last apex's position and time
        self._strides = 0
        self._past_apex = False  # the last state is past an apex the next reset restarts at

    def __getattr__(self, name):
        return getattr(self._env, name)

    def reset(self, **kwargs):
        out = self._env.reset(**kwargs)
        if self._past_apex:
            self.states.pop()  # the reset's state is that apex: drop the overshoot
        self._x0, self._t0 = self._next
        self._past_apex = False
        self._snap(0.0, 0.0)
        return out

    def step(self, action):
        out = self._env.step(action)
        obs, info = out[0], out[4]
        tau = float(info["tau"])
        self.taus.append(abs(tau))
        if "apex_z" in info:
            b = self._env._b
            n = min(int(info["apex_count"]), b.apex.shape[1])
            t_apex = float(info["time"]) - float(obs[self._since])
            self._next = (self._x0 + float(b.apex[0, n - 1, 0]), self._t0 + t_apex)
            self.last_apex_z = np.array(info["apex_z"], dtype=float)
            self._strides += 1
            self._past_apex = True
        self._snap(float(info["time"]), tau)
        return out

    def _snap(self, t: float, tau: float) -> None:
        from bound_env.model.params import A_XB, A_XF

        b = self._env._b
        y, aux = b.y[0].copy(), b.aux[0].copy()
        y[0] += self._x0
        aux[A_XB] += self._x0  # the toes' contact points, along the slope
        aux[A_XF] += self._x0
        self.states.append((y, aux, self._t0 + t, self._strides, tau))


def _run(controller, gait, z0, z_star, show_after: int = 0) -> dict:
    """`ClosedLoop.run` of ``controller`` from z0, its env recorded; then, if it returned,
    ``show_after`` more strides on the cycle (recorded, not counted)."""
    from bound_env.analysis.margins import ClosedLoop

    loop = ClosedLoop(controller, gait, through_map=False)  # its env recorded, step by step
    rec = _Recorded(loop.env)
    loop.env = rec
    returned, strides, failure = loop.run(z0, z_star, DEMO_STRIDES)
    taus = list(rec.taus)  # the run itself, up to the return or the fall
    if returned and show_after > 0:
        z = rec.last_apex_z
        for _ in range(show_after):
            out = loop.next_stride(z)  # the same episode, continued
            if out.z1 is None:
                break
            z = out.z1
    loop.env = rec._env
    return {
        "returned": bool(returned),
        "strides": int(strides),
        "failure": failure,
        "mean_abs_tau": float(np.mean(taus)) if taus else 0.0,
        "max_torque": loop.max_torque,
        "dt": loop.dt,
        "states": rec.states,
    }


def compare_from_start(policy: str = DEMO_POLICY, gait="default", show_after: int = 0) -> dict:
    """The passive gait and ``policy`` from the demo's start (`demo_start`) on ``gait``.

    Returns the summary's ``comparison`` object: ``start`` (``z`` and ``z_star`` in SI, their
    units in ``z_units``,
    ``seed``, ``index``, ``n_directions``, ``r``, ``direction``), ``passive`` (``fell``,
    ``failure``, ``strides``: strides completed before the fall, or before it returned,
    ``mean_abs_tau``), ``lqr`` (the same, and ``returned``, ``policy``, ``max_torque``),
    ``learned`` (``policy``, ``returned``, ``strides``: strides to return (or completed before
    a fall), ``failure``, ``mean_abs_tau``: mean |tau| [N m] over the control intervals up to
    the return, ``max_torque`` [N m]); and, under the private keys ``_states`` and ``_dt``,
    the recorded runs (passive, lqr, learned) and the control interval, for the animation."""
    from bound_env.control.privileged import refuse_privileged

    from ..runtime.controllers import ZeroController
    from ..runtime.policy import load_controller

    z0, z_star, xi = demo_start(gait)
    ctrl = load_controller(policy, gait=gait)
    refuse_privileged(ctrl, "be shown as the demo's controller", policy)
    p = _run(ZeroController(), gait, z0, z_star)
    lq = _run(load_controller(DEMO_BASELINE, gait=gait), gait, z0, z_star)
    q = _run(ctrl, gait, z0, z_star, show_after=show_after)
    return {
        "start": {
            "z": z0.tolist(),
            "z_star": z_star.tolist(),
            "z_units": list(Z_SI_UNITS),  # z, z_star (SI; the summary's top-level z_star: deg)
            "seed": DEMO_SEED,
            "index": DEMO_INDEX,
            "n_directions": DEMO_DIRECTIONS,
            "r": DEMO_SIZE,
            "direction": xi.tolist(),
            "gait": str(gait),
        },
        "passive": {
            "fell": not p["returned"] and p["failure"] is not None,
            "failure": p["failure"],
            "strides": p["strides"] - (0 if p["returned"] else 1),
            "mean_abs_tau": p["mean_abs_tau"],
        },
        "lqr": {
            "policy": DEMO_BASELINE,
            "fell": not lq["returned"] and lq["failure"] is not None,
            "returned": lq["returned"],
            "failure": lq["failure"],
            "strides": lq["strides"] - (0 if lq["returned"] else 1),
            "mean_abs_tau": lq["mean_abs_tau"],
            "max_torque": lq["max_torque"],
        },
        "learned": {
            "policy": str(policy),
            "returned": q["returned"],
            "strides": q["strides"] - (0 if q["returned"] else 1),
            "failure": q["failure"],
            "mean_abs_tau": q["mean_abs_tau"],
            "max_torque": q["max_torque"],
        },
        "_states": (p["states"], lq["states"], q["states"]),
        "_dt": q["dt"],
    }


def _panel(state, label: str, note: str, size=PANEL) -> np.ndarray:
    from bound_env.envs.render import render_frame

    y, aux, t, strides, tau = state
    text = f"{label}{note}\nt {t:5.2f} s   stride {strides}   tau {tau:+5.1f} N m"
    return render_frame(y, aux, size[0], size[1], text=text)


def comparison_frames(comparison: dict, progress: bool = False) -> tuple[list, float]:
    """(side-by-side frames, simulated seconds per frame) of `compare_from_start`'s runs:
    passive on the left, lqr in the middle, learned on the right; a fallen robot holds its
    last frame."""
    states = comparison["_states"]
    labels = (
        "passive",
        comparison["lqr"]["policy"],
        f"learned ({comparison['learned']['policy']})",
    )
    outcome = (comparison["passive"], comparison["lqr"], comparison["learned"])
    runs = [list(s[::FRAME_STEPS]) for s in states]
    for k, st in enumerate(states):  # always show the last state
        if (len(st) - 1) % FRAME_STEPS:
            runs[k].append(st[-1])
    n = max(len(r) for r in runs)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, desc="compare.gif", unit="frame", file=sys.stderr)
    frames, held = [], [None] * len(runs)
    gap = np.full((PANEL[1], 4, 3), 255, dtype=np.uint8)
    for i in range(n):
        halves = []
        for k in range(len(runs)):
            if i < len(runs[k]):
                note, o = "", outcome[k]
                if i == len(runs[k]) - 1 and o["failure"] is not None:
                    note = f": fell ({o['failure']})"
                elif o.get("returned") and runs[k][i][3] >= o["strides"]:
                    note = ": back on the cycle"
                held[k] = _panel(runs[k][i], labels[k], note)
            halves.append(held[k])
        parts = [halves[0]]
        for h in halves[1:]:
            parts += [gap, h]
        frames.append(np.concatenate(parts, axis=1))
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.close()
    return frames, FRAME_STEPS * float(comparison["_dt"])


def table_lines(comparison: dict) -> list[str]:
    """The table: header, passive, lqr, learned, with the torque each used."""
    p, lq, q = comparison["passive"], comparison["lqr"], comparison["learned"]

    def outcome(r) -> str:
        if r.get("returned"):
            return "returned to the cycle"
        return f"fell: {r['failure']}" if r.get("fell") else f"did not return: {r['failure']}"

    rows = [
        ("passive", outcome(p), p["strides"], p.get("mean_abs_tau", 0.0)),
        (lq["policy"], outcome(lq), lq["strides"], lq["mean_abs_tau"]),
        (f"learned ({q['policy']})", outcome(q), q["strides"], q["mean_abs_tau"]),
    ]
    w = max(len(r[0]) for r in rows)
    v = max(len(r[1]) for r in rows)
    lines = [f"{'controller':<{w}}  {'outcome':<{v}}  strides  mean |tau| [N m]"]
    lines += [f"{a:<{w}}  {b:<{v}}  {c:7d}  {d:16.2f}" for a, b, c, d in rows]
    return lines


def demo_comparison(gait="default", out=None, progress: bool = False):
    """The demo part `bound_env.commands.render_cli.cmd_demo` runs (registered by `agents.cli`):
    ``(comparison, lines to print)``; writes ``compare.gif`` into ``out``. On a gait the
    ``default`` controller was not made for, the comparison is skipped (and says why)."""
    from bound_env.envs.render import write_video

    from ..runtime.controllers import same_gait
    from ..runtime.policy import load_controller

    own = load_controller(DEMO_POLICY).env_kwargs.get("gait")
    if own is not None and not same_gait(own, gait):
        why = f"the {DEMO_POLICY} controller was made for gait {own!r}, not {str(gait)!r}"
        return {"skipped": why}, [f"passive vs learned: skipped ({why})"]
    c = compare_from_start(DEMO_POLICY, gait, show_after=SHOW_AFTER)
    frames, frame_dt = comparison_frames(c, progress=progress)
    del c["_states"], c["_dt"]
    lines = [
        f"Passive vs {DEMO_BASELINE} vs the shipped {DEMO_POLICY!r} controller from z* + "
        f"{DEMO_SIZE:g} |z*| xi "
        f"(xi: validation direction {DEMO_INDEX} of seed {DEMO_SEED})"
    ]
    if out is not None and frames:
        gif = write_video(frames, Path(out) / "compare.gif", fps=1.0 / frame_dt)
        c["gif"] = str(gif)
        lines[0] += f"; wrote {gif} ({len(frames)} frames)"
    return c, [lines[0] + ":"] + table_lines(c)
