"""Step-level residual PPO on `PassiveBound-v0` over a stride controller (``ppo-residual``).

Residual policy learning: the env's action on every 10 ms control interval is

    a = clip(a_base(obs) + scale * g * r, -1, 1),

with a_base the base controller's interval torque (by default the shipped `default`: the LQR
inside its safe radius, a library profile chosen by a network outside it), r in [-1, 1] the
learned residual and g the gate: 0 while the last apex state lies within the base's safe
radius (max |z - z*| / s <= safe, where the base's own LQR acts alone), past it 1, or with
``ramp`` > 0 min(1, (max |z - z*| / s - safe) / ramp) (`_Gate`: the shipped recipe ramps over
0.25, so that a residual cannot hold the robot on a cycle just outside the safe radius). So
inside the safe radius, and on the cycle, the controller *is* the base (zero torque on the
cycle), and outside it the residual adds feedback *within* a stride, which a planner that
decides once per apex cannot have. ``agents.runtime.stride.ZeroActionNet`` zeroes the action layer
before the first update, so training starts exactly at the base controller.

The policy's observation (`residual_features`) is the env's observation without the entries
that jump at contact events (`agents.common.wrappers.ObservationFilter.DEFAULT_DROP`), then the
base's action on this interval, the normalized error x = (z - z*) / s of the last apex state and the
gate g.

**Training task** (`ResidualOver`, an rl-zoo3 ``env_wrapper``): episodes start at an apex
z* + r |z*| xi past the safe radius (r ~ U(0, ``r_max``), the distillation's starts,
`agents.experts.distill.sample_starts`); a return inside the safe radius ends the episode with
``alive_reward`` for every step left to ``max_steps``, a fall ends it. With the env's own
alive reward and costs at 0 (the shipped ``configs/ppo-residual.yaml``) that bonus is the only
reward: surviving without returning earns as little as falling (a survival reward taught the
residual to hold the robot on another stable cycle). ``residual_cost`` r^2 per step keeps the
residual off where it does not help; `CriticWarmup` fits the critic before the actor moves.

**Evaluation** (`ResidualController`, loaded by `agents.runtime.policy.load_controller` from a run
or policy folder whose ``config.yaml`` wraps the env in `ResidualOver`): the same computation in
float64 NumPy, with the base re-planning at every apex (``on_apex``).
"""

from __future__ import annotations

import functools
import hashlib
import inspect
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np

from bound_env.files import schema as check
from bound_env.sim.stride_protocol import (
    OBS_TIME,
    OBS_Z,
    notify_apex,
    profile_rows,
    reset_controller,
)

from ..common.wrappers import ObservationFilter, full_observation_names

MAX_START_DRAWS = 10_000  # draws of a start past the safe radius before reset gives up


def _keep_index(obs_names) -> np.ndarray:
    drop = set(ObservationFilter.DEFAULT_DROP)
    return np.array([i for i, n in enumerate(obs_names) if n not in drop])


def residual_features(obs, keep, base_action: float, x_apex, gate: float) -> np.ndarray:
    """The residual policy's observation (module docstring), float64."""
    obs = np.asarray(obs, dtype=np.float64)
    return np.concatenate([obs[keep], [base_action], x_apex, [gate]])


def residual_features_rows(obs, keep, base_actions, x_apex, gates) -> np.ndarray:
    """`residual_features` of n rows at once (n, ...): each row's the same entries, copied."""
    obs = np.asarray(obs, dtype=np.float64)
    return np.concatenate(
        [
            obs[:, keep],
            np.asarray(base_actions, float)[:, None],
            x_apex,
            np.asarray(gates)[:, None],
        ],
        axis=1,
    )


class _Gate:
    """The base's safe radius: x = (z - z*) / s and the gate g: 0 within max |x| <= safe;
    past it 1 (``ramp`` 0), or min(1, (max |x| - safe) / ramp) (a residual that fades
    towards the safe radius cannot hold the robot on a cycle just outside it)."""

    def __init__(self, base, ramp: float = 0.0):
        for attr in ("z_ref", "scales", "safe"):
            if getattr(base, attr, None) is None:
                raise ValueError(
                    f"base controller {getattr(base, 'name', base)!r} has no {attr}: the "
                    "residual needs a gated stride controller (default, distilled/*, mpc)"
                )
        self.z_ref = np.asarray(base.z_ref, dtype=float)
        self.scales = np.asarray(base.scales, dtype=float)
        self.safe = float(base.safe)
        self.ramp = float(ramp)

    def __call__(self, z) -> tuple[np.ndarray, float]:
        x = (np.asarray(z, dtype=float) - self.z_ref) / self.scales
        e = float(np.max(np.abs(x)))
        if e <= self.safe:
            return x, 0.0
        return x, (1.0 if self.ramp <= 0 else min(1.0, (e - self.safe) / self.ramp))


def load_base(base: str):
    """The base controller: a controller that decides at the apex (`agents.runtime.names`: a
    classical controller, a choice policy or a stride-level policy), never a step-level PPO
    policy."""
    from .kinds.apex import load_apex_controller

    ctrl = load_apex_controller(base)
    if ctrl is None:
        raise ValueError(f"base {base!r}: not a stride controller (a step-level PPO policy)")
    if not hasattr(ctrl, "on_apex"):
        raise ValueError(f"base {base!r}: not a stride controller (no on_apex)")
    from bound_env.control.privileged import refuse_privileged

    # a residual policy over a privileged base would read the true plant: never deployable
    refuse_privileged(ctrl, "be the base of a residual policy", f"base {base}")
    return ctrl


class ResidualOver(gym.Wrapper):
    """A residual on a stride controller's interval torques (see the module docstring).

    :param env: a PassiveBound-v0 env (``gymnasium.make``, possibly with Monitor/TimeLimit).
    :param base: the base controller (a name or folder for `agents.runtime.policy.load_controller`).
    :param scale: the residual's bound (action units; 1 = max_torque).
    :param r_max: starts z* + r |z*| xi with r ~ U(0, r_max), past the safe radius; None keeps
        the env's own starts.
    :param axis_prob: probability that xi is one axis (else uniform on the 6-sphere).
    :param end_on_return: end an episode at the first apex inside the safe radius, with
        ``alive_reward`` for each step left to ``max_steps`` as a bonus.
    :param residual_cost: cost per step of r^2.
    :param ramp: the gate's ramp past the safe radius (0: a step from 0 to 1; `_Gate`).
    """

    def __init__(
        self,
        env: gym.Env,
        base: str = "default",
        scale: float = 0.5,
        r_max: float | None = 0.45,
        axis_prob: float = 0.25,
        end_on_return: bool = True,
        max_steps: int = 800,
        alive_reward: float = 1.0,
        residual_cost: float = 0.05,
        ramp: float = 0.0,
    ):
        super().__init__(env)
        w = "ResidualOver"
        scale = check.real(scale, f"{w} scale", 0.0, 2.0, lo_open=True)
        if r_max is not None:
            r_max = check.real(r_max, f"{w} r_max", 0.0, 10.0, lo_open=True)
        axis_prob = check.real(axis_prob, f"{w} axis_prob", 0.0, 1.0)
        end_on_return = check.boolean(end_on_return, f"{w} end_on_return")
        max_steps = check.integer(max_steps, f"{w} max_steps", 1, 10**7)
        alive_reward = check.real(alive_reward, f"{w} alive_reward", -1e6, 1e6)
        residual_cost = check.real(residual_cost, f"{w} residual_cost", 0.0, 1e6)
        ramp = check.real(ramp, f"{w} ramp", 0.0, 10.0)
        if not isinstance(base, (str, Path)) or not str(base):
            raise ValueError(f"{w} base must be a policy name or folder, got {base!r}")
        full_observation_names(env, w)  # a step env, its observation as the env gives it
        task = env.unwrapped.task
        self.base_name = str(base)
        self.base_ctrl = load_base(self.base_name)
        kw = getattr(self.base_ctrl, "env_kwargs", {}) or {}
        for key, have in (("max_torque", task.max_torque), ("dt", task.dt)):
            if key in kw and not np.isclose(float(kw[key]), float(have)):
                raise ValueError(
                    f"ResidualOver base {base!r} acts with {key} {kw[key]}, the env has {have}"
                )
        self.gate_of = _Gate(self.base_ctrl, ramp)
        if r_max is not None:  # the largest start error: r_max along the widest axis
            widest = float(np.max(np.abs(self.gate_of.z_ref) / self.gate_of.scales))
            if r_max * widest <= self.gate_of.safe:
                raise ValueError(
                    f"ResidualOver r_max {r_max:g} cannot start past the base's safe radius "
                    f"{self.gate_of.safe:g} (its largest start error is r_max x "
                    f"{widest:.4g}); use r_max > {self.gate_of.safe / widest:.4g} or null"
                )
        self.keep = _keep_index(task.obs_names)
        self.scale, self.r_max, self.axis_prob = float(scale), r_max, float(axis_prob)
        self.end_on_return, self.max_steps = bool(end_on_return), int(max_steps)
        self.alive_reward, self.residual_cost = float(alive_reward), float(residual_cost)
        n = len(self.keep) + 8
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (n,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.x, self.gate, self.base_action, self.k = np.zeros(6), 0.0, 0.0, 0

    @classmethod
    def policy_controller(cls, net, settings: dict, model, model_path) -> ResidualController:
        """The evaluation controller of a PPO actor trained through this wrapper
        (`agents.runtime.policy.load_controller` calls it; `residual_controller`)."""
        return residual_controller(net, settings, model, model_path)

    def _apex(self, obs, info) -> bool:
        """Tell the base about an apex; returns whether this step (or reset) had one."""
        z = info.get("apex_z", info.get("start_z"))
        if z is None:
            return False
        notify_apex(self.base_ctrl, obs, info)
        self.x, self.gate = self.gate_of(z)
        return True

    def _observe(self, obs) -> np.ndarray:
        self.base_action = float(self.base_ctrl(obs))
        f = residual_features(obs, self.keep, self.base_action, self.x, self.gate)
        return f.astype(np.float32)

    def reset(self, *, seed=None, options=None):
        from bound_env.sim.task import check_reset_options

        options = check_reset_options(options) or None  # a list or a typo: one line
        if self.r_max is not None and not (options and options.get("apex_state") is not None):
            from bound_env.envs.rescue_env import sample_starts

            if seed is not None:  # seed the env's generator first, then draw from it
                self.env.reset(seed=seed)
                seed = None
            rng = self.env.unwrapped.np_random
            for _ in range(MAX_START_DRAWS):
                z = sample_starts(rng, 1, self.gate_of.z_ref, self.r_max, self.axis_prob)[0]
                if self.gate_of(z)[1]:
                    break
            else:
                raise ValueError(
                    f"ResidualOver r_max {self.r_max:g}: no start past the base's safe radius "
                    f"{self.gate_of.safe:g} in {MAX_START_DRAWS} draws; use a larger r_max"
                )
            options = {**(options or {}), "apex_state": z}
        obs, info = self.env.reset(seed=seed, options=options)
        self.k = 0
        reset_controller(self.base_ctrl)  # a base with memory starts each episode afresh
        if not self._apex(obs, info):  # a reset off an apex: the base reads the observation
            self.x, self.gate = self.gate_of(np.asarray(obs, dtype=float)[list(OBS_Z)])
        return self._observe(obs), info

    def step(self, action):
        r = float(np.clip(np.asarray(action, dtype=float).reshape(-1)[0], -1.0, 1.0))
        a = float(np.clip(self.base_action + self.scale * self.gate * r, -1.0, 1.0))
        obs, reward, terminated, truncated, info = self.env.step(np.array([a], np.float32))
        self.k += 1
        reward = float(reward) - self.residual_cost * r * r
        if self._apex(obs, info) and self.end_on_return and not terminated and not self.gate:
            info["returned"] = True
            reward += self.alive_reward * max(0, self.max_steps - self.k)
            terminated = True
        return self._observe(obs), reward, terminated, truncated, info


@dataclass
class ResidualController:
    """The residual policy for evaluation: the base, plus ``scale * g * net(features)``."""

    name: str
    base: object
    net: object  # agents.runtime.controllers.MLPController on `residual_features`
    scale: float
    keep: np.ndarray
    env_kwargs: dict = field(default_factory=dict)
    seed: int | None = None
    ramp: float = 0.0  # the gate's ramp (`_Gate`)
    _x: np.ndarray | None = field(default=None, repr=False)
    _gate: float = field(default=0.0, repr=False)

    def __post_init__(self):
        self.gate_of = _Gate(self.base, self.ramp)

    # stateful as its base: a base with memory (``adaptive/s0``) is reset with each episode;
    # over a memoryless base the residual stays batched in the margins' loop
    stateful = property(lambda self: getattr(self.base, "stateful", False) is True)

    def reset(self) -> None:
        """Forget the episode: the base's memory (`reset_controller`) and the last apex."""
        reset_controller(self.base)
        self._x, self._gate = None, 0.0

    # the base's record of who made each apex decision (margins' decision shares)
    decision_kinds = property(lambda self: getattr(self.base, "decision_kinds", None))

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self.base.on_apex(z, time_since_apex)
        self._x, self._gate = self.gate_of(z)

    def residual(self, obs, base_action: float) -> float:
        return self.net(residual_features(obs, self.keep, base_action, self._x, self._gate))

    def __call__(self, obs) -> float:
        if self._x is None:  # no apex announced yet: the observation at a reset is one
            self.on_apex(np.asarray(obs, dtype=float)[list(OBS_Z)], float(obs[OBS_TIME]))
        a0 = float(self.base(obs))
        if not self._gate:
            return a0
        r = self.residual(obs, a0)
        return float(np.clip(a0 + self.scale * self._gate * r, -1.0, 1.0))

    def act_rows(self, copies, obs) -> np.ndarray:
        """The actions of ``copies`` (copies of this controller, one per robot, each told its
        own apexes) on their observations ``obs`` (one row each): each copy's ``__call__``,
        end to end for all rows at once. The bases' interval torques in one array
        (`bound_env.sim.stride_protocol.profile_rows`: bit for bit each base's call; a base that
        does not offer it is called row by row), the features of every gated row in one array
        (`residual_features`' entries, copied), and one forward pass of the network for them
        (`MLPController.batch`, each row computed alone; equal to the row-by-row actions to
        rounding)."""
        n = len(copies)
        obs = np.asarray(obs)
        for k, c in enumerate(copies):
            if c._x is None:  # as `__call__`: the observation at a reset is an apex
                c.on_apex(obs[k][list(OBS_Z)], float(obs[k][OBS_TIME]))
        a0 = profile_rows([c.base for c in copies], obs)
        if a0 is None:
            a0 = np.array([float(c.base(obs[k])) for k, c in enumerate(copies)], dtype=float)
        gates = np.fromiter((c._gate for c in copies), dtype=float, count=n)
        out = a0.copy()
        on = np.flatnonzero(gates)
        if on.size:
            feats = residual_features_rows(
                obs[on], self.keep, a0[on], np.stack([copies[k]._x for k in on]), gates[on]
            )
            r = self.net.batch(feats)
            out[on] = np.clip(a0[on] + self.scale * gates[on] * r, -1.0, 1.0)
        return out

    def fingerprint(self) -> str:
        h = hashlib.sha256(b"residual")
        h.update(self.base.fingerprint().encode())
        h.update(self.net.fingerprint().encode())
        h.update(repr((self.scale, self.keep.tolist())).encode())
        if self.ramp:
            h.update(repr(("ramp", self.ramp)).encode())
        return h.hexdigest()[:16]

    def __getstate__(self):  # the per-stride state is not part of the controller
        state = dict(self.__dict__)
        state["_x"], state["_gate"] = None, 0.0
        return state


def check_settings(settings, where: str) -> dict:
    """``settings`` as `ResidualOver`'s keyword arguments: a mapping of its parameters' names
    (an unknown key, e.g. a typo, is a one-line ValueError naming it and ``where``)."""
    allowed = [p for p in inspect.signature(ResidualOver.__init__).parameters][2:]
    return check.mapping(settings, where, allowed=allowed)


def residual_controller(net, settings: dict, model, model_path) -> ResidualController:
    """A `ResidualController` from a loaded PPO actor ``net`` (an MLPController on
    `residual_features`) and its run's `ResidualOver` settings; checks the spaces."""
    import gymnasium as gym

    import bound_env

    gym.register_envs(bound_env)
    where = f"{Path(model_path).parent / 'config.yaml'}: env_wrapper ResidualOver"
    check_settings(settings, where)
    env = gym.make("PassiveBound-v0", **net.env_kwargs)
    try:
        wrapped = ResidualOver(env, **settings)
        want, keep = wrapped.observation_space.shape, wrapped.keep
        base, scale, ramp = wrapped.base_ctrl, wrapped.scale, wrapped.gate_of.ramp
    except ValueError as e:  # a value of the run's config: name the file
        raise ValueError(f"{Path(model_path).parent / 'config.yaml'}: {e}") from None
    finally:
        env.close()
    if tuple(model.observation_space.shape) != want or tuple(model.action_space.shape) != (1,):
        raise ValueError(
            f"policy {model_path}: a residual over {settings.get('base', 'default')!r} observes "
            f"{want} and acts in (1,), the model has {model.observation_space.shape} and "
            f"{model.action_space.shape}"
        )
    return ResidualController(
        name=net.name,
        base=base,
        net=net,
        scale=scale,
        keep=keep,
        env_kwargs=dict(net.env_kwargs),
        seed=net.seed,
        ramp=ramp,
    )


VALIDATION_SIZES = (0.2, 0.25, 0.3, 0.35, 0.4)


def validation_curve(
    ctrl, sizes=VALIDATION_SIZES, n_dirs: int = 64, seed: int | None = None, strides: int = 60
) -> dict:
    """The return rate of ``ctrl`` from z* + r |z*| d for ``n_dirs`` random directions d of
    the VALIDATION seed (`agents.common.seeds.VALIDATION_SEED`, 777; the margins' test directions
    use 12345) at each size r, on the margins' closed loop (returned: within RETURN_TOL of z*
    within ``strides`` strides), and the size where it crosses 1/2 (``r50``, by the margins'
    own interpolation, `crossing_on_grid`). What every choice of the residual recipe was made on."""
    from bound_env.analysis.margins.budget import random_directions
    from bound_env.analysis.margins.closed_loop import ClosedLoop
    from bound_env.analysis.margins.stats import crossing_on_grid

    from ..common.seeds import VALIDATION_SEED

    seed = VALIDATION_SEED if seed is None else int(seed)
    loop = ClosedLoop(ctrl, gait=getattr(ctrl, "env_kwargs", {}).get("gait", "default"))
    zs = np.asarray(loop.env.task.z_ref, dtype=float)
    dirs = random_directions(n_dirs, seed)
    rates = []
    for r in sizes:
        runs = loop.run_many(zs + r * np.abs(zs) * dirs, zs, strides)
        rates.append(sum(ok for ok, _, _ in runs) / n_dirs)
    return {
        "sizes": list(sizes),
        "rates": rates,
        "r50": crossing_on_grid(list(sizes), rates),
        "n_dirs": n_dirs,
        "seed": seed,
        "strides": strides,
    }


def _actor_parameters(model) -> list:
    p = model.policy
    params = list(p.mlp_extractor.policy_net.parameters()) + list(p.action_net.parameters())
    if getattr(p, "log_std", None) is not None:
        params.append(p.log_std)
    return params


@functools.cache
def critic_warmup_class():
    """`CriticWarmup` (built lazily: SB3's callbacks import torch)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class CriticWarmup(BaseCallback):
        """Freeze the actor (hidden layers, action layer, log std) for the first ``rollouts``
        rollouts of a run, so that the critic, which starts from random weights, is fitted
        to the base controller's returns before its advantages move the actor (otherwise
        the first updates push a residual that starts at zero in random directions). A
        function of the timestep count, so a resumed run continues it."""

        def __init__(self, rollouts: int = 10, verbose: int = 0):
            super().__init__(verbose)
            if int(rollouts) < 0:
                raise ValueError(f"CriticWarmup rollouts must be >= 0, got {rollouts!r}")
            self.rollouts = int(rollouts)

        def _warm_steps(self) -> int:
            return self.rollouts * self.model.n_steps * self.model.n_envs

        def _set(self, trainable: bool) -> None:
            for p in _actor_parameters(self.model):
                p.requires_grad_(trainable)

        def _on_training_start(self) -> None:
            self._set(self.num_timesteps >= self._warm_steps())

        def _on_rollout_end(self) -> None:
            self._set(self.num_timesteps >= self._warm_steps())

        def _on_step(self) -> bool:
            return True

    return CriticWarmup


def __getattr__(name):  # agents.runtime.residual.CriticWarmup, importable by its dotted path
    if name == "CriticWarmup":
        return critic_warmup_class()
    raise AttributeError(name)
