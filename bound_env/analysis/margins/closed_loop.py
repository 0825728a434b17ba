"""The closed loop: a controller in the loop of one PassiveBound environment, its apex-to-apex
map (`ClosedLoop`), kicks, batched rough-terrain runs (through the one batched loop,
`bound_env.analysis.apex_loop.interval_loop`), and the per-worker `Setup` of a margins
evaluation with its cache of loops (`loop_for`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...model.events import PHASES
from ...sim.stride_map import EVAL_RTOL, RETURN_TOL, StrideMap, Strides, max_intervals
from ...sim.stride_protocol import reset_controller
from ...sim.task import FAIL_FIRST, FAILURE_NAMES
from ..apex_loop import (
    RETURNED,
    apex_loop,
    interval_loop,
    timed_interval_actions,
    timed_on_apex,
)
from .budget import DEFAULT_SEED, Budget

ENV_ID = "PassiveBound-v0"
PROFILE_SEG = 5  # ceiling search: control intervals per piece of a torque profile
PROFILE_SPAN = 1.3  # ceiling search: the profile covers 1.3 x the strides' nominal duration
STRIDES = [0]  # strides advanced in this process (benchmarks/margins.py reads it)
FAILURES_BY_REASON = (None, *FAILURE_NAMES[FAIL_FIRST:])  # apex_loop's reason -> failure name


@dataclass
class StrideOut:
    """One stride of the closed-loop map."""

    z1: np.ndarray | None
    failure: str | None
    effort: float = math.nan  # time-averaged |tau| [N m]
    period: float = math.nan  # [s]
    steps: int = 0  # control intervals started
    phase: str | None = None  # stance condition at the end (at the failure)


class ClosedLoop:
    """A controller in the loop of one PassiveBound environment (no wrappers).

    ``stride(z)`` is the closed-loop apex map (see the package docstring) of a fresh
    controller (a stateful one is reset at every call); ``next_stride(z)`` continues an
    episode; ``kick`` adds ``delta`` to one entry of the simulator state just before control
    interval ``step``.
    """

    def __init__(
        self,
        controller,
        gait: str = "default",
        gait_overrides: dict | None = None,
        env_extra: dict | None = None,
        through_map: bool = True,
    ):
        """``through_map``: advance a stride controller's strides through the one stride map
        (the same strides as the env loop, bit for bit); False steps ``env`` interval by
        interval, for a caller that records it (the demo)."""
        import gymnasium as gym

        import bound_env

        gym.register_envs(bound_env)
        kwargs = dict(getattr(controller, "env_kwargs", None) or {})
        kwargs.update(env_extra or {})
        kwargs["gait"] = gait
        overrides = {**(kwargs.get("gait_overrides") or {}), **(gait_overrides or {})}
        kwargs["gait_overrides"] = overrides or None
        kwargs["rtol"] = EVAL_RTOL
        kwargs["reset_noise_scale"] = 0.0
        self.env = gym.make(ENV_ID, **kwargs).unwrapped
        self.controller = controller
        self.max_torque = float(self.env.task.max_torque)
        self.dt = float(self.env.task.dt)
        self.max_steps = max_intervals(self.dt)
        self.i_since_apex = list(self.env.task.obs_names).index("time_since_apex")
        self.on_apex = getattr(controller, "on_apex", None)
        self.last_phase: str | None = None  # stance condition at the end of the last `run`
        # a stride controller advances whole strides through the one stride map: the same
        # strides as the env's loop below, bit for bit (its `interval_actions` are exactly
        # what it outputs interval by interval), without a Python call per interval
        self.plant = StrideMap(gait, overrides or None, self.dt, self.max_torque, EVAL_RTOL)
        self.stride_map = None  # set for a stride controller on smooth ground
        if (
            through_map
            and callable(getattr(controller, "interval_actions", None))
            and not kwargs.get("slope_noise_deg")
        ):
            self.stride_map = self.plant

    def strides(self, Z, kicks=None) -> Strides:
        """One closed-loop stride from each apex state Z[i] of a stride controller, through
        the one stride map (``kicks[i]``: (interval, state index 4..7, delta) or None)."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        r = self.stride_map.run(Z, timed_interval_actions(self.controller, Z), kicks=kicks)
        STRIDES[0] += len(Z)
        return r

    def stride(self, z, kick: tuple | None = None) -> StrideOut:
        """One closed-loop stride from the apex z with a fresh controller: a stateful one is
        reset first (`reset_controller`), so that a stride on its own (the fixed point's
        iterates and finite-difference probes, the effort on the cycle) is the map of a
        controller that has seen nothing, whatever strides were asked for before it."""
        reset_controller(self.controller)
        return self.next_stride(z, kick)

    def next_stride(self, z, kick: tuple | None = None) -> StrideOut:
        """The next stride of an episode from z: the controller as it is, its memory of the
        strides before kept (`run`'s strides; a caller that continues an episode)."""
        if self.stride_map is not None:
            z = np.asarray(z, dtype=float)
            r = self.strides(z[None], None if kick is None else [kick])  # (checks the kick)
            if r.ok[0]:
                # the apex time as the env loop reads it (the observation's float32 time since
                # the apex, at the end of that interval), and the effort to it, as before
                t_step = float(r.t_step[0])
                t_seen = t_step - float(np.float32(t_step - r.period[0]))
                impulse = r.impulse_before[0] + r.tau_last[0] * max(0.0, t_seen - r.t_prev[0])
                return StrideOut(
                    r.z1[0].copy(), None, float(impulse / t_seen), t_seen, int(r.intervals[0])
                )
            return StrideOut(
                None, r.failure(0), steps=int(r.intervals[0]), phase=PHASES[int(r.phase[0])]
            )
        STRIDES[0] += 1
        env, ctrl = self.env, self.controller
        z = np.asarray(z, dtype=float)
        obs, info = env.reset(options={"apex_state": z})
        if info["failure"] is not None:
            return StrideOut(None, info["failure"], phase="df")
        if self.on_apex is not None:
            timed_on_apex(self.on_apex, z, 0.0)
        t_prev, impulse = 0.0, 0.0
        for k in range(self.max_steps):
            if kick is not None and k == kick[0]:
                apply_kick(env, kick[1], kick[2])
            obs, _, terminated, _, info = env.step(np.array([ctrl(obs)]))
            tau = abs(info["tau"])
            if "apex_z" in info:
                t_apex = info["time"] - float(obs[self.i_since_apex])
                impulse += tau * max(0.0, t_apex - t_prev)
                return StrideOut(
                    np.array(info["apex_z"], dtype=float), None, impulse / t_apex, t_apex, k + 1
                )
            impulse += tau * (info["time"] - t_prev)
            t_prev = info["time"]
            if terminated:
                return StrideOut(None, info["failure"], steps=k + 1, phase=info["phase"])
        return StrideOut(None, "no_apex", steps=self.max_steps, phase=info["phase"])

    def map(self, z) -> np.ndarray | None:
        return self.stride(z).z1

    def run(
        self, z0, z_target, max_strides: int, kick: tuple | None = None, survive_only: bool = False
    ) -> tuple[bool, int, str | None]:
        """Iterate the map from z0 (the first stride kicked if ``kick``). Returns (success,
        strides, failure): success = returned within RETURN_TOL of ``z_target`` within
        ``max_strides`` (or, with ``survive_only``, did not fall in ``max_strides``)."""
        z = np.asarray(z0, dtype=float)
        self.last_phase = None
        reset_controller(self.controller)  # a run is an episode (a stateful controller)
        for n in range(1, max_strides + 1):
            out = self.next_stride(z, kick if n == 1 else None)
            if out.z1 is None:
                self.last_phase = out.phase
                return False, n, out.failure
            z = out.z1
            if not np.all(np.isfinite(z)):
                return False, n, "non_finite"
            if not survive_only and np.max(np.abs(z - z_target)) < RETURN_TOL:
                return True, n, None
        return survive_only, max_strides, None

    def run_many(
        self, Z0, z_target, max_strides: int, kicks=None
    ) -> list[tuple[bool, int, str | None]]:
        """`run` from each row of Z0 (``kicks[i]``: robot i's first-stride kick or None), all
        robots advanced together by the one batched closed loop (`bound_env.analysis.
        apex_loop`): a stride controller through the one stride map, any other through the
        task's batch kernel (the same outcomes as `run` row by row: every robot's strides are
        its own)."""
        Z = np.array(np.atleast_2d(Z0), dtype=float)
        if self.stride_map is not None:
            r = apex_loop(Z, z_target, max_strides, strides=self.strides, kicks=kicks)
        else:
            r = apex_loop(
                Z, z_target, max_strides, task=self.env.task, controller=self.controller,
                kicks=kicks,
            )  # fmt: skip
            STRIDES[0] += r["apexes"]
        return [
            (
                bool(r["outcome"][i] == RETURNED),
                int(r["strides"][i]),
                FAILURES_BY_REASON[int(r["reason"][i])],
            )
            for i in range(len(Z))
        ]

    def episode(self, z0, max_strides: int, seed: int | None = None) -> tuple:
        """One long episode from the apex state z0 (env seed ``seed``: with
        ``slope_noise_deg`` it fixes the terrain). Returns (survived ``max_strides`` strides,
        strides completed, failure)."""
        env, ctrl = self.env, self.controller
        z0 = np.asarray(z0, dtype=float)
        obs, info = env.reset(seed=seed, options={"apex_state": z0})
        if info["failure"] is not None:
            return False, 0, info["failure"]
        reset_controller(ctrl)
        if self.on_apex is not None:
            timed_on_apex(self.on_apex, z0, 0.0)
        while True:
            obs, _, terminated, _, info = env.step(np.array([ctrl(obs)]))
            if terminated:
                self.last_phase = info["phase"]
                STRIDES[0] += info["stride"]
                return False, info["stride"], info["failure"]
            if "apex_z" in info:
                if info["stride"] >= max_strides:
                    STRIDES[0] += info["stride"]
                    return True, info["stride"], None
                if self.on_apex is not None:
                    z1, t_seen = np.array(info["apex_z"]), float(obs[self.i_since_apex])
                    timed_on_apex(self.on_apex, z1, t_seen)

    def profile(
        self, z0, actions, max_strides: int, period: float, seg: int = PROFILE_SEG
    ) -> tuple:
        """Open loop: the normalized torques ``actions[j]`` held over control intervals
        [j seg, (j + 1) seg) from the apex state z0, zero after the last piece. Returns
        (strides completed >= max_strides, progress score, failure, phase, strides) with
        score = strides completed + the fraction of a nominal stride (``period`` [s], an
        argument: the score depends on nothing a worker kept from earlier tasks) survived since."""
        code, n, t_step, t_apex, t, status, phase = self.plant.open_loop(
            z0, actions, seg, max_strides
        )
        STRIDES[0] += n
        if code == 1:
            return True, float(n), None, None, n
        if code == -2:  # the start itself is impossible
            return False, 0.0, FAILURE_NAMES[status], "df", 0
        if code == 0:
            # the apex time as the env's loop read it: the observation's float32 time since it
            t_seen = t_step - float(np.float32(t_step - t_apex)) if t_step > 0.0 else 0.0
            frac = min(0.99, (t - t_seen) / max(period, 1e-3))
            return False, n + frac, FAILURE_NAMES[status], PHASES[phase], n
        return False, float(n), "no_apex", PHASES[phase], n


def apply_kick(env, index: int, delta: float) -> None:
    """Add ``delta`` to velocity entry ``index`` (4..7) of the simulator state y between two
    control intervals (`bound_env.envs.env.PassiveBoundEnv.kick`). The controller sees it in the
    next observation (a push is sensed one control interval later, like a sampled sensor)."""
    if not 4 <= index <= 7:
        raise ValueError(f"a kick changes a velocity (state index 4..7), got index {index}")
    d = np.zeros(4)
    d[index - 4] = delta
    env.kick(d)


def rough_episodes(loop: ClosedLoop, z0, seeds, max_strides: int) -> dict:
    """`ClosedLoop.episode` for many robots at once: robot k runs the episode of
    ``loop.episode(z0, max_strides, seed=seeds[k])`` (the same task, hence ``loop``'s rough
    terrain, and the same slope draws from its own env RNG), all advanced together by the one
    batched loop (`bound_env.analysis.apex_loop.interval_loop`, long episodes), each robot
    with a fresh controller state (the outcomes of ``episode``, tested). Returns {"strides":
    completed strides per robot, "fell": 0/1 per robot, "failures": {reason: count}}."""
    from gymnasium.utils import seeding

    task = loop.env.task
    z0 = task.check_apex_state(z0)
    terrain = [seeding.np_random(int(sd))[0] for sd in seeds]
    r = interval_loop(
        task, loop.controller, np.tile(z0, (len(seeds), 1)), max_strides, restart=False,
        terrain=terrain,
    )  # fmt: skip
    failures: dict = {}
    for code in r["status"][r["status"] > 0]:
        name = FAILURE_NAMES[int(code)]
        failures[name] = failures.get(name, 0) + 1
    STRIDES[0] += int(r["strides"].sum())
    return {
        "strides": r["strides"].tolist(),
        "fell": (r["status"] > 0).astype(np.int64).tolist(),
        "failures": failures,
    }


# --------------------------------------------------------------------------------------------
# Tasks (run in worker processes)
# --------------------------------------------------------------------------------------------


@dataclass
class Setup:
    """Everything a worker needs; picklable."""

    controller: object
    gait: str
    budget: Budget
    z_star: np.ndarray
    z_cl: np.ndarray | None = None
    cycle_steps: int = 0
    key: str = ""
    period: float = math.nan  # closed-loop stride period [s]
    seed: int = DEFAULT_SEED  # --seed: the random directions, terrain and push samples
    mismatch: object = (
        None  # model error (`bound_env.model.mismatch.MismatchSpec`) of the mm_ tasks
    )
    mismatch_budget: object = None  # their `mismatch_tasks.MismatchBudget`


_LOOPS: dict = {}


def loop_for(
    setup: Setup, overrides: dict | None = None, env_extra: dict | None = None
) -> ClosedLoop:
    """The `ClosedLoop` of ``setup`` (with gait ``overrides`` and extra env arguments), built
    once per worker process and kept (the store is emptied past 64 loops)."""
    k = (
        setup.key,
        tuple(sorted((overrides or {}).items())),
        tuple(sorted((env_extra or {}).items())),
    )
    if k not in _LOOPS:
        if len(_LOOPS) > 64:
            _LOOPS.clear()
        _LOOPS[k] = ClosedLoop(setup.controller, setup.gait, overrides, env_extra)
    return _LOOPS[k]
