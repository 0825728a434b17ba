"""`RandomizedPlant`: an env of the project on a new plant at every reset, with sensor noise and
actuation delay (model error, `bound_env.mismatch`).

    import gymnasium as gym
    import bound_env
    from bound_env.wrappers import RandomizedPlant

    gym.register_envs(bound_env)
    env = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="pm10+noise+delay1")
    obs, info = env.reset(seed=3)  # info["plant"]: this episode's parameters

At every ``reset`` the plant's parameters are drawn from the env's own ``np_random``
(`bound_env.mismatch.sample_factors`), after it is seeded and before the start state is
drawn, so ``reset(seed=s)`` gives the same plant and the same start every time. The
controller-facing side keeps the nominal model: z*, the observation's bounds and (for the
stride envs) the torque basis are the gait's. ``info["plant"]`` (at the reset and at every
step) holds the plant's values of `bound_env.mismatch.PLANT_KEYS` in gait-file units, and
``info["plant_factors"]`` the drawn factors.

- Sensor noise (``noise``): Gaussian, drawn from ``np_random`` after each observation is
  made, added to the components it names (in SI: sigma times `bound_env.mismatch.NOISE_SCALES`;
  in the rescue env's normalized observation, divided by its scales), then clipped to the
  observation space. The env itself (rewards, termination, ``info["apex_z"]``) sees the true
  state.
- Actuation delay (``delay``, control intervals): PassiveBound-* only (a stride env's step is
  a whole stride, so a delay of whole intervals is not an action of its step; a ValueError
  says so): the action given at step k acts at step k + delay, zero torque before.

With a spec without error (``none``, every range 0, no noise, no delay) the wrapped env is
the env, bit for bit (the same observations, rewards and infos from the same seeds), apart
from the added ``info`` keys.
"""

from __future__ import annotations

from collections import deque

import gymnasium as gym
import numpy as np

from .env import PassiveBoundEnv
from .mismatch import (
    MismatchSpec,
    as_spec,
    plant_params,
    plant_values,
    sample_factors,
)
from .params import Z_NAMES
from .task import PassiveBoundTask


def plant_tasks(env) -> list[PassiveBoundTask]:
    """Every `PassiveBoundTask` an env of the project advances or checks its robot with (the
    step env's task; the stride env's step task and its stride map's; the rescue env's
    plant's), found through their public attributes."""
    base = env.unwrapped
    found = []
    for obj in (
        getattr(base, "task", None),
        getattr(getattr(base, "task", None), "step_task", None),
        getattr(
            getattr(getattr(getattr(base, "task", None), "sim", None), "stride_map", None),
            "task",
            None,
        ),
        getattr(getattr(base, "plant", None), "task", None),
    ):
        if isinstance(obj, PassiveBoundTask) and all(obj is not t for t in found):
            found.append(obj)
    if not found:
        raise ValueError(
            f"RandomizedPlant wraps PassiveBound-*, PassiveBoundStride-* or PassiveBoundRescue-*, "
            f"got {type(base).__name__}"
        )
    return found


class RandomizedPlant(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """An env on a plant drawn at every reset, with sensor noise and actuation delay (module
    docstring). ``mismatch``: a `bound_env.mismatch.MismatchSpec`, a preset name (``pm10``,
    ``pm5+noise+delay1``) or a YAML file."""

    def __init__(self, env: gym.Env, mismatch="pm5"):
        gym.utils.RecordConstructorArgs.__init__(self, mismatch=mismatch)
        gym.Wrapper.__init__(self, env)
        self.spec_error: MismatchSpec = as_spec(mismatch)
        self.tasks = plant_tasks(env)
        base = env.unwrapped
        self.step_env = isinstance(base, PassiveBoundEnv)
        if self.spec_error.delay and not self.step_env:
            raise ValueError(
                f"mismatch delay: {type(base).__name__} steps whole strides; an actuation delay "
                "of control intervals applies to PassiveBound-* only"
            )
        self.nominal = self.tasks[0].params
        self._sigma = self._obs_sigma(base)
        self._queue: deque = deque()
        self._plant: dict = {}
        self._factors: dict = {}

    def _obs_sigma(self, base) -> np.ndarray:
        """Noise standard deviation of each observation component, in the observation's
        units."""
        if self.step_env:
            return self.spec_error.obs_sigma(base.task.obs_names)
        sigma = self.spec_error.obs_sigma(Z_NAMES)
        scales = getattr(base, "scales", None)  # the rescue env observes (z - z*) / scales
        if scales is not None and not hasattr(base, "task"):
            sigma = sigma / np.asarray(scales, dtype=float)
        return sigma

    @property
    def plant(self) -> dict:
        """The current plant's `PLANT_KEYS` values (gait-file units)."""
        return dict(self._plant)

    def _noisy(self, obs):
        if not np.any(self._sigma > 0):
            return obs
        rng = self.env.unwrapped.np_random
        noisy = obs + (self._sigma * rng.standard_normal(self._sigma.shape)).astype(obs.dtype)
        space = self.observation_space
        return np.clip(noisy, space.low, space.high).astype(obs.dtype)

    def _info(self, info: dict) -> dict:
        info["plant"] = dict(self._plant)
        info["plant_factors"] = dict(self._factors)
        return info

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        base = self.env.unwrapped
        if seed is not None:
            gym.Env.reset(base, seed=seed)  # seed np_random; the env's reset below keeps it
        self._factors = sample_factors(self.spec_error, base.np_random)
        params = plant_params(self.nominal, self._factors)
        for t in self.tasks:
            t.set_params(params)
        self._plant = plant_values(params)
        if hasattr(base, "task") and hasattr(base.task, "params") and not self.step_env:
            base.task.params = params  # the stride env's slope draws read it
        obs, info = self.env.reset(seed=None, options=options)
        self._queue = deque([0.0] * self.spec_error.delay)
        return self._noisy(obs), self._info(info)

    def step(self, action):
        if self.spec_error.delay:
            self._queue.append(action)
            action = self._queue.popleft()
            if isinstance(action, float):
                action = np.zeros(self.action_space.shape, dtype=self.action_space.dtype)
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._noisy(obs), reward, terminated, truncated, self._info(info)
