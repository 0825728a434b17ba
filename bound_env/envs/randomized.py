"""`RandomizedPlant`: an env of the project on a new plant at every reset, with sensor noise and
actuation delay (model error, `bound_env.model.mismatch`).

    import gymnasium as gym
    import bound_env
    from bound_env.envs.wrappers import RandomizedPlant

    gym.register_envs(bound_env)
    env = RandomizedPlant(gym.make("PassiveBound-v1"), mismatch="pm10+noise+delay1")
    obs, info = env.reset(seed=3)  # info["plant"]: this episode's parameters

It wraps every registered env id: the step envs (``PassiveBound-v0/v1``,
``PassiveBoundLiteral-v0/v1``), the stride env (``PassiveBoundStride-v1``) and the rescue envs
(``PassiveBoundRescue-v0/v1``); the native vector env is refused (a one-line ValueError; make
the vector env from wrapped single envs, ``gym.make_vec(id, n, vectorization_mode="sync",
wrappers=[RandomizedPlant])``).

The plant
---------
At every ``reset`` the plant's parameters are drawn from the env's own ``np_random``
(`bound_env.model.mismatch.sample_factors`), after it is seeded and before the start state is
drawn, so ``reset(seed=s)`` gives the same plant and the same start every time. The drawn
parameters go to the one holder of the env's plant, ``env.unwrapped.plant_task``
(`bound_env.sim.task.PassiveBoundTask.set_params`): the step env's task; for the stride and
rescue envs the task of the stride map every stride runs on (`bound_env.sim.stride_map.StrideMap`
keeps no copy). So the robot of every id runs on the drawn plant, slope included (the stride
env's rough terrain draws around the drawn slope). The controller-facing side keeps the
nominal model: z*, the observation's bounds, the rescue env's LQR and (for the stride envs)
the torque basis are the gait's. ``info["plant"]`` (at the reset and at every step) holds
the plant's values of `bound_env.model.mismatch.PLANT_KEYS` in gait-file units, and
``info["plant_factors"]`` the drawn factors.

Sensor noise
------------
``noise`` reaches everything a controller decides on, each in its own units:

- the observation: Gaussian, sigma times `bound_env.model.mismatch.NOISE_SCALES` (SI) on the
  components the spec names. The step envs observe SI, so the noise is added there. The stride
  and rescue envs observe the apex state z: the noise is drawn on z in SI and the observation
  is made from the noisy z (``env.unwrapped.apex_observation``), so in the rescue envs'
  normalized observation (z - z*)/``obs_scale`` it is sigma / ``obs_scale`` (v1's scales,
  not the apex scales). Then clipped to the observation space.
- the apex state that ``info`` carries (``info["apex_z"]``, ``info["start_z"]``, which
  stride controllers and `bound_env.control.plain.PlainPolicy` read): noisy too, sigma in SI on
  z's components (the stride and rescue envs: the same draw as the observation; the step envs:
  a draw of its own, the apex is another instant than the observation's). The true apex
  state stays in ``info["true_apex_z"]`` / ``info["true_start_z"]``, for analysis only.
- the rescue envs' own LQR (the plan of v1's ``action_mode="lqr_residual"`` and of
  `bound_env.envs.wrappers.LibraryActions`' row 0) plans on the observed apex state
  (``env.unwrapped.z_observed``).

The env itself (rewards, termination, ``info["error"]``, ``env.unwrapped.z``) sees the true
state.

Actuation delay
---------------
``delay`` (control intervals): PassiveBound-* only (a stride env's step is a whole stride, so
a delay of whole intervals is not an action of its step; a ValueError says so): the action
given at step k acts at step k + delay, zero torque before. An action is checked when it is
given, as the plain env checks it (any type the plain env accepts; NaN, inf or a wrong
shape: ValueError at once).

Privileged observation
----------------------
``privileged_obs=True`` appends the drawn plant's factors (one per parameter the spec varies,
in the order of `bound_env.model.mismatch.PLANT_KEYS`; ``env.privileged_names``) to the
observation, float32, within [1 - delta, 1 + delta]: what an asymmetric critic reads (as
legged_gym's privileged observations). A robot shows no such thing, so a policy trained on it
is **privileged**, an upper reference and never a policy to score or deploy: the policy
loader refuses to evaluate a run whose ``env_wrapper`` has ``privileged_obs: true``
(`RandomizedPlant.reads_privileged`, which reads the saved ``config.yaml``). The factors are
never noised; a spec that varies no parameter is refused with it. Off by default.

Compositions
------------
- `RandomizedPlant` over `RandomizedPlant`: refused (one line). The robot would run the inner
  draw while ``info["plant"]`` names the outer one; join the specs instead
  (``"pm10+noise"``).
- `bound_env.envs.wrappers.LibraryActions` over or under it: row 0 plans on the observed state.

With a spec without error (``none``, every range 0, no noise, no delay) the wrapped env is
the env, bit for bit (the same observations, rewards and infos from the same seeds), apart
from the added ``info`` keys.
"""

from __future__ import annotations

from collections import deque

import gymnasium as gym
import numpy as np

from ..files.schema import boolean
from ..model.mismatch import (
    MismatchSpec,
    as_spec,
    plant_params,
    plant_values,
    sample_factors,
)
from ..model.params import Z_NAMES
from ..sim.task import PassiveBoundTask
from .env import PassiveBoundEnv, check_action


def plant_task(env) -> PassiveBoundTask:
    """The one `PassiveBoundTask` that holds the plant of an env of the project
    (``env.unwrapped.plant_task``); ValueError for any other env."""
    base = env.unwrapped if isinstance(env, gym.Env) else env
    task = getattr(base, "plant_task", None)
    if isinstance(env, gym.vector.VectorEnv):
        raise ValueError(
            f"RandomizedPlant wraps one env, got the vector env {type(env).__name__}: make "
            "the vector env from wrapped envs, gym.make_vec(env_id, n, "
            'vectorization_mode="sync", wrappers=[RandomizedPlant])'
        )
    if not isinstance(task, PassiveBoundTask):
        raise ValueError(
            f"RandomizedPlant wraps PassiveBound-*, PassiveBoundStride-* or PassiveBoundRescue-*, "
            f"got {type(base).__name__}"
        )
    return task


def plant_tasks(env) -> list[PassiveBoundTask]:
    """``[plant_task(env)]``: every env of the project holds its plant in one task (kept for
    the callers of the former several-copies search)."""
    return [plant_task(env)]


def _inner_randomized(env) -> bool:
    while isinstance(env, gym.Wrapper):
        if isinstance(env, RandomizedPlant):
            return True
        env = env.env
    return False


class RandomizedPlant(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """An env on a plant drawn at every reset, with sensor noise and actuation delay (module
    docstring). ``mismatch``: a `bound_env.model.mismatch.MismatchSpec`, a preset name (``pm10``,
    ``pm5+noise+delay1``) or a YAML file. ``privileged_obs``: append the plant's factors to
    the observation (an asymmetric critic's input; a policy that reads it is privileged and
    not scored)."""

    def __init__(self, env: gym.Env, mismatch="pm5", privileged_obs: bool = False):
        gym.utils.RecordConstructorArgs.__init__(
            self, mismatch=mismatch, privileged_obs=privileged_obs
        )
        boolean(privileged_obs, "privileged_obs")
        if _inner_randomized(env):
            raise ValueError(
                "RandomizedPlant: env is already a RandomizedPlant (the robot would run the "
                "inner draw); wrap once with the specs joined, e.g. mismatch='pm10+noise'"
            )
        task = plant_task(env)
        gym.Wrapper.__init__(self, env)
        self.spec_error: MismatchSpec = as_spec(mismatch)
        self.task = task
        self.tasks = [task]  # (the former several copies: one now)
        base = env.unwrapped
        self.step_env = isinstance(base, PassiveBoundEnv)
        if self.spec_error.delay and not self.step_env:
            raise ValueError(
                f"mismatch delay: {type(base).__name__} steps whole strides; an actuation delay "
                "of control intervals applies to PassiveBound-* only"
            )
        self.nominal = task.params
        # noise standard deviations [SI]: of the observation (step envs, which observe SI) and
        # of the apex state z (every env: the info's apex, the apex envs' observation)
        self._sigma_obs = self.spec_error.obs_sigma(base.task.obs_names) if self.step_env else None
        self._sigma_z = self.spec_error.obs_sigma(Z_NAMES)
        self._noisy_env = bool(np.any(self._sigma_z > 0)) or (
            self._sigma_obs is not None and bool(np.any(self._sigma_obs > 0))
        )
        self._queue: deque = deque()
        self._plant: dict = {}
        self._factors: dict = {}
        self.privileged_obs = bool(privileged_obs)
        self.privileged_names: tuple = ()
        if self.privileged_obs:
            self._privileged_space()

    @staticmethod
    def reads_privileged(kwargs) -> bool:
        """Whether a wrapper made with ``kwargs`` (a saved run's ``env_wrapper`` entry) hands
        the policy the privileged observation: such a policy is never scored."""
        return bool((kwargs or {}).get("privileged_obs", False))

    def _privileged_space(self) -> None:
        space = self.env.observation_space
        ranges = [(k, d) for k, d in self.spec_error.ranges if d > 0]
        if not ranges:
            raise ValueError(
                f"privileged_obs: mismatch {self.spec_error.name!r} varies no plant parameter, "
                "so there is no factor to observe"
            )
        if not (isinstance(space, gym.spaces.Box) and len(space.shape) == 1):
            raise ValueError(f"privileged_obs needs a 1-D Box observation, got {space}")
        self.privileged_names = tuple(k for k, _ in ranges)
        d = np.array([d for _, d in ranges], dtype=np.float32)
        low = np.concatenate([space.low, 1.0 - d]).astype(np.float32)
        high = np.concatenate([space.high, 1.0 + d]).astype(np.float32)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)

    def _with_factors(self, obs):
        if not self.privileged_obs:
            return obs
        f = np.array([self._factors[k] for k in self.privileged_names], dtype=np.float32)
        return np.concatenate([np.asarray(obs, dtype=np.float32), f])

    @property
    def plant(self) -> dict:
        """The current plant's `PLANT_KEYS` values (gait-file units)."""
        return dict(self._plant)

    # -- what the controller sees ---------------------------------------------------------------
    def _z_noise(self, rng) -> np.ndarray:
        return self._sigma_z * rng.standard_normal(6)

    def _observe(self, obs, info: dict):
        """The noisy observation, and ``info`` with its apex state noised (the true one under
        ``true_*``)."""
        true = {k: info[k] for k in ("apex_z", "start_z") if k in info}
        for k, z in true.items():
            info["true_" + k] = np.array(z, dtype=float)
        if not self._noisy_env:
            return obs
        base = self.env.unwrapped
        rng = base.np_random
        if self.step_env:
            sigma = self._sigma_obs
            if np.any(sigma > 0):
                noisy = obs + (sigma * rng.standard_normal(sigma.shape)).astype(obs.dtype)
                space = self.env.observation_space  # (without privileged factors)
                obs = np.clip(noisy, space.low, space.high).astype(obs.dtype)
            if np.any(self._sigma_z > 0):  # the apex: another instant, a draw of its own
                for k, z in true.items():
                    info[k] = np.asarray(z, dtype=float) + self._z_noise(rng)
            return obs
        # the apex envs observe z: one draw on z (SI), the observation made from it
        n = self._z_noise(rng)
        if true:
            z_seen = next(iter(true.values()))
        elif hasattr(base, "z_observed"):  # the rescue envs show the last apex after a fall
            z_seen = base.z
        else:  # the stride env after a fall: the last state's z, as observed
            z_seen = np.asarray(obs, dtype=float)
        z_noisy = np.asarray(z_seen, dtype=float) + n
        for k in true:
            info[k] = z_noisy.copy()
        if hasattr(base, "z_observed"):
            base.z_observed = z_noisy.copy()  # the env's own LQR plans on it
        return base.apex_observation(z_noisy)

    def _info(self, info: dict) -> dict:
        info["plant"] = dict(self._plant)
        info["plant_factors"] = dict(self._factors)
        return info

    # -- Gymnasium API --------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        base = self.env.unwrapped
        if seed is not None:
            gym.Env.reset(base, seed=seed)  # seed np_random; the env's reset below keeps it
        self._factors = sample_factors(self.spec_error, base.np_random)
        params = plant_params(self.nominal, self._factors)
        self.task.set_params(params)
        self._plant = plant_values(params)
        obs, info = self.env.reset(seed=None, options=options)
        self._queue = deque([None] * self.spec_error.delay)
        obs = self._observe(obs, info)
        return self._with_factors(obs), self._info(info)

    def step(self, action):
        if self.spec_error.delay:
            check_action(action)  # refused now, as the plain env would refuse it
            self._queue.append(np.array(action))  # a copy: the caller may reuse its array
            action = self._queue.popleft()
            if action is None:  # nothing decided yet: zero torque
                action = np.zeros(self.action_space.shape, dtype=self.action_space.dtype)
        obs, reward, terminated, truncated, info = self.env.step(action)
        obs = self._observe(obs, info)
        return self._with_factors(obs), reward, terminated, truncated, self._info(info)
