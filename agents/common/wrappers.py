"""The training distribution: starts beyond the passive basin, with a curriculum on their size.

`PerturbedStarts` replaces the environment's own start noise. Every episode starts at an apex
state z = z* + s * apex_scales * xi (``reset(options={"apex_state": z})``), where

- ``apex_scales`` are the environment's units of apex deviation (about the half-width of the
  *passive* basin along each axis, `bound_env.sim.task.APEX_SCALES`), so s = 1 is the passive edge;
- the size s is drawn uniformly from [0, ``noise_scale``] for each episode, so that easy
  and hard starts stay mixed however far the curriculum has gone;
- the direction xi is, with probability ``axis_prob``, one axis (a single component, either
  sign: the directions in which the basin is measured) and otherwise U(-1, 1) in every component.

``noise_scale`` is the curriculum's knob: `agents.training.train_callbacks.NoiseCurriculumCallback`
raises it during training through ``VecEnv.env_method("set_noise_scale", value)`` (SB3 finds the
method through ``get_wrapper_attr``, so it works under `Monitor`, `TimeLimit` and
`SubprocVecEnv`).

The wrapper is rl-zoo3 compatible: ``env_wrapper: [{agents.common.wrappers.PerturbedStarts:
{...}}]``.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np


class PerturbedStarts(gym.Wrapper):
    """Start every episode at z* plus a perturbation of curriculum-controlled size.

    :param env: a PassiveBound environment (possibly wrapped).
    :param noise_scale: largest perturbation, in units of the env's ``apex_scales`` (1 = about
        the edge of the passive basin along each axis).
    :param axis_prob: probability that a start perturbs one component only.
    :param weights: optional 6 factors on the perturbation of each component (default all 1),
        e.g. to emphasise forward speed and height, the directions the passive gait is weakest in.
    """

    def __init__(
        self, env: gym.Env, noise_scale: float = 1.0, axis_prob: float = 0.5, weights=None
    ):
        super().__init__(env)
        task = getattr(env.unwrapped, "task", None)
        if task is None or not hasattr(task, "apex_scales"):
            raise ValueError("PerturbedStarts needs a PassiveBound env (env.unwrapped.task)")
        if not 0.0 <= axis_prob <= 1.0:
            raise ValueError(f"axis_prob must lie in [0, 1], got {axis_prob}")
        self.z_ref = np.array(task.z_ref, dtype=float)
        self.apex_scales = np.array(task.apex_scales, dtype=float)
        self.axis_prob = float(axis_prob)
        w = np.ones(6) if weights is None else np.asarray(weights, dtype=float).reshape(6)
        if np.any(w < 0) or not np.all(np.isfinite(w)):
            raise ValueError(f"weights must be 6 non-negative numbers, got {weights!r}")
        self.weights = w
        self.noise_scale = 0.0
        self.set_noise_scale(noise_scale)

    def set_noise_scale(self, value: float) -> float:
        """Set the largest start perturbation (apex_scales units); returns it."""
        value = float(value)
        if not np.isfinite(value) or value < 0:
            raise ValueError(f"noise_scale must be a non-negative number, got {value!r}")
        self.noise_scale = value
        return value

    def sample_start(self, rng: np.random.Generator) -> np.ndarray:
        """One start apex state (SI)."""
        size = rng.uniform(0.0, self.noise_scale)
        if rng.random() < self.axis_prob:
            xi = np.zeros(6)
            xi[rng.integers(6)] = rng.choice((-1.0, 1.0))
        else:
            xi = rng.uniform(-1.0, 1.0, size=6)
        return self.z_ref + size * self.apex_scales * self.weights * xi

    def reset(self, *, seed=None, options=None):
        if options and options.get("apex_state") is not None:
            return self.env.reset(seed=seed, options=options)
        if seed is not None:  # seed the env's generator first, then draw from it
            self.env.reset(seed=seed)
        z = self.sample_start(self.env.unwrapped.np_random)
        return self.env.reset(options={**(options or {}), "apex_state": z})


def full_observation_names(env: gym.Env, who: str) -> list[str]:
    """The names of the full observation of the PassiveBound step env that ``env`` gives
    (``env.unwrapped.task.obs_names``); a one-line ValueError naming ``who`` when ``env`` is
    not a step env (the stride and rescue envs observe an apex state) or a wrapper below
    already changed its observation (an `ObservationFilter`, a `ResidualOver`): ``who``
    indexes the observation by those names."""
    names = getattr(getattr(env.unwrapped, "task", None), "obs_names", None)
    if names is None:
        kind = env.unwrapped.spec.id if env.unwrapped.spec else type(env.unwrapped).__name__
        raise ValueError(
            f"{who} needs a PassiveBound step env (PassiveBound-v0/-v1, Literal), not {kind}"
        )
    shape = getattr(env.observation_space, "shape", None)
    if shape != (len(names),):
        raise ValueError(
            f"{who} needs the env's full observation ({len(names)} entries), got shape {shape}: "
            f"the wrapper below it ({type(env).__name__}) changed it; wrap {who} first"
        )
    return list(names)


class ObservationFilter(gym.ObservationWrapper):
    """Keep only some observation entries, by name (``env.unwrapped.task.obs_names``).

    The default drops the entries that jump at a contact event: the 0/1 contact and
    touched-down flags (at touchdown) and the leg angles (at liftoff, where a leg snaps back
    from its stance angle to its touchdown angle). A policy reading them makes the sampled-data
    closed loop jump whenever such an event crosses a control instant: its apex map is then
    discontinuous, can lack an exact fixed point and can chatter in a small set instead of
    converging. What is left is continuous along every trajectory (the leg lengths equal the
    rest lengths at both touchdown and liftoff) and still carries the phase (leg lengths,
    time since the apex).

    :param drop: observation names to remove.
    """

    DEFAULT_DROP = (
        "contact_back",
        "contact_front",
        "touched_back",
        "touched_front",
        "leg_angle_back",
        "leg_angle_front",
    )

    def __init__(self, env: gym.Env, drop=DEFAULT_DROP):
        super().__init__(env)
        names = full_observation_names(env, "ObservationFilter")
        unknown = set(drop) - set(names)
        if unknown:
            raise ValueError(f"unknown observation names {sorted(unknown)}; known: {names}")
        self.index = np.array([i for i, n in enumerate(names) if n not in set(drop)])
        self.names = tuple(names[i] for i in self.index)
        space = env.observation_space
        self.observation_space = gym.spaces.Box(
            space.low[self.index], space.high[self.index], dtype=space.dtype
        )

    def observation(self, observation):
        return observation[self.index]


def observation_index(env_wrappers, obs_names) -> np.ndarray | None:
    """Indices of the observation an ``env_wrapper`` list (rl-zoo3 syntax) keeps through its
    `ObservationFilter`, or None when it has none."""
    from .config import class_entries

    filters = [
        kw
        for name, kw in class_entries(env_wrappers)
        if name.rsplit(".", 1)[-1] == "ObservationFilter"
    ]
    if not filters:
        return None
    if len(filters) > 1:
        raise ValueError("more than one ObservationFilter in env_wrapper")
    drop = set(filters[0].get("drop", ObservationFilter.DEFAULT_DROP))
    return np.array([i for i, n in enumerate(obs_names) if n not in drop])
