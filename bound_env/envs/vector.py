"""Native vector environment for PassiveBound-v0: all robots advance in one compiled call.

``gym.make_vec("PassiveBound-v0", num_envs=N)`` (mode ``"vector_entry_point"``, the default
for this id) builds a `PassiveBoundVectorEnv`. It gives the same observations, rewards,
terminations, truncations and infos as ``gym.make_vec(..., vectorization_mode="sync")`` for
the same seeds (robot i is seeded with seed + i), without a Python loop over robots: one call
of `bound_env.sim.task.step_batch` (or `step_batch_parallel`, one Numba thread per robot) steps
them all. Resets (at the start and after an episode end) run in Python for the robots
concerned.

Autoreset follows Gymnasium 1.x: by default ``AutoresetMode.NEXT_STEP`` (the step after a
robot's episode ended resets it and returns its reset observation with reward 0); also
``SAME_STEP`` (reset within the ending step, ``info["final_obs"]``, ``info["final_info"]``)
and ``DISABLED`` (reset robots yourself with ``reset(options={"reset_mask": mask})``).
"""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .. import MAX_EPISODE_STEPS
from ..sim.task import S_REWARD, S_STEPS, PassiveBoundTask, TaskConfig
from .env import RENDER_MODES, check_action, make_spaces, render_text


class PassiveBoundVectorEnv(VectorEnv):
    """``num_envs`` PassiveBound-v0 robots stepped together (`bound_env.envs.env.PassiveBoundEnv`).

    Arguments are those of `bound_env.envs.env.PassiveBoundEnv` plus:

    | Parameter | Type | Default | Description |
    | --- | --- | --- | --- |
    | `num_envs` | **int** | `1` | number of robots |
    | `max_episode_steps` | **int** | `3000` | truncation after this many steps (None: never) |
    | `autoreset_mode` | **AutoresetMode** | `NEXT_STEP` | Gymnasium's autoreset mode (or value) |
    | `parallel` | **bool** | `False` | step the robots on Numba's threads (see below) |
    | `config` | **TaskConfig** | `None` | the task settings at once; keyword arguments change it |

    ``reset(options={"apex_state": z})`` starts every robot at z (6 numbers) or robot i at
    ``z[i]`` (shape (num_envs, 6)); ``options={"reset_mask": mask}`` resets only some robots.
    ``parallel=True`` spreads the robots over Numba's threads: about 1.9x faster for 64 robots
    on an idle two-core machine, but much slower when the cores are busy (e.g. beside a
    PyTorch learner), hence off by default. Results are bit-identical either way.
    In ``"human"`` render mode only robot 0 is shown; ``"rgb_array"`` returns one frame per
    robot.
    """

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = MAX_EPISODE_STEPS,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        parallel: bool = False,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 360,
        config: TaskConfig | None = None,
        **task_kwargs,
    ):
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be one of {RENDER_MODES} or None, got {render_mode!r}"
            )
        config = TaskConfig.resolve(config, task_kwargs)
        if config.slope_noise_deg != 0.0:
            raise ValueError(
                "slope_noise_deg (rough terrain) is supported by the single env "
                "PassiveBound-v0 only, not by the native vector env"
            )
        self.task = PassiveBoundTask(config)
        self.num_envs = int(num_envs)
        self.max_episode_steps = (
            int(max_episode_steps) if max_episode_steps and max_episode_steps > 0 else None
        )
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.parallel = bool(parallel)
        self.dt = self.task.dt
        self.metadata = {
            "render_modes": list(RENDER_MODES),
            "render_fps": round(1 / self.dt),
            "autoreset_mode": self.autoreset_mode,
        }
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)
        self.single_observation_space, self.single_action_space = make_spaces(self.task)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        self._b = self.task.new_batch(self.num_envs)
        self._rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._all = np.ones(self.num_envs, dtype=np.bool_)
        self._none = np.zeros(self.num_envs, dtype=np.bool_)
        self._renderers = None

    # -- resets ----------------------------------------------------------------------------------
    def _reset_robot(self, i: int, seed: int | None = None, options: dict | None = None):
        if seed is not None or self._rngs[i] is None:
            self._rngs[i], _ = seeding.np_random(seed)
        if options and options.get("apex_state") is not None:
            z = np.asarray(options["apex_state"], dtype=float)
            if z.shape == (self.num_envs, 6):
                options = {**options, "apex_state": z[i]}
        z = self.task.start_state(self._rngs[i], options)
        self.task.reset_robot(self._b, i, z)

    def reset(self, *, seed: int | list | None = None, options: dict | None = None):
        """Reset all robots (or those in ``options["reset_mask"]``); robot i gets seed + i."""
        n = self.num_envs
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(
                    f"a list of seeds must have num_envs={n} entries, got {len(seeds)}"
                )
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = self._all
        else:
            mask = np.asarray(mask)
            if mask.shape != (n,) or mask.dtype != np.bool_ or not mask.any():
                raise ValueError(
                    f"options['reset_mask'] must be a bool array of shape ({n},) "
                    f"with at least one True, got {mask!r}"
                )
        for i in np.flatnonzero(mask):
            self._reset_robot(int(i), seeds[i], options)
        self._autoreset[mask] = False
        info = self.task.vector_info(self._b, None if mask is self._all else mask, mask)
        if self.render_mode == "human":
            self.render()
        return self._b.obs.copy(), info

    # -- steps -----------------------------------------------------------------------------------
    def step(self, actions):
        b = self._b
        b.actions[:] = check_action(actions, self.num_envs)
        mode = self.autoreset_mode
        if mode == AutoresetMode.DISABLED and self._autoreset.any():
            raise RuntimeError(
                "autoreset_mode DISABLED: reset the ended robots with reset(options="
                f"{{'reset_mask': mask}}) first: {np.flatnonzero(self._autoreset)}"
            )
        stepping_all = mode != AutoresetMode.NEXT_STEP or not self._autoreset.any()
        if stepping_all:
            reset_rows = self._none
            b.active[:] = True
        else:  # NEXT_STEP: the robots whose episode ended in the last step are reset instead
            reset_rows = self._autoreset
            np.logical_not(reset_rows, out=b.active)
        self.task.step(b, self.parallel)
        if not stepping_all:
            for i in np.flatnonzero(reset_rows):
                self._reset_robot(int(i))
        s = b.s.T
        terminated = self.task.failed(b)
        truncated = (
            s[S_STEPS] >= self.max_episode_steps
            if self.max_episode_steps is not None
            else np.zeros(self.num_envs, dtype=np.bool_)
        )
        rewards = s[S_REWARD].copy()
        if not stepping_all:
            terminated &= b.active
            truncated &= b.active
            rewards[reset_rows] = 0.0
        done = terminated | truncated
        if mode == AutoresetMode.SAME_STEP and done.any():
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):
                final_obs[i] = b.obs[i].copy()
            final_info = self.task.vector_info(b, done)
            for i in np.flatnonzero(done):
                self._reset_robot(int(i))
            info = self.task.vector_info(b, None, done)
            info["final_obs"], info["_final_obs"] = final_obs, done.copy()
            info["final_info"], info["_final_info"] = final_info, done.copy()
        else:
            info = self.task.vector_info(b, None, None if stepping_all else reset_rows)
        self._autoreset = done
        if self.render_mode == "human":
            self.render()
        return b.obs.copy(), rewards, terminated, truncated, info

    # -- rendering -------------------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            return None
        from .render import Renderer

        b = self._b
        if self.render_mode == "human":
            if self._renderers is None:
                self._renderers = Renderer("human", self.width, self.height)
            return self._renderers.render(b.y[0], b.aux[0], text=render_text(b.s[0]))
        if self._renderers is None:
            self._renderers = Renderer("rgb_array", self.width, self.height)
        r = self._renderers
        return tuple(r.render(b.y[i], b.aux[i], text=render_text(b.s[i])) for i in range(b.n))

    def close_extras(self, **kwargs):
        if self._renderers is not None:
            self._renderers.close()
            self._renderers = None
