"""PassiveBoundRescue-v0 (deprecated: use PassiveBoundRescue-v1, `bound_env.envs.rescue_v1`): the
rescue task paying for survival, one step = one stride from a start past the safe radius.

v0 warns (DeprecationWarning) when made and goes in the next release; until then it stays the
task of `bound-env finetune` (`agents.experts.finetune`), which silences the warning.
"""

from __future__ import annotations

import sys
import warnings

import numpy as np
from gymnasium import spaces, utils

from .rescue_common import (
    DEFAULT_AXIS_PROB,
    DEFAULT_CONTROLLER,
    DEFAULT_HORIZON,
    DEFAULT_R_MAX,
    RescueBase,
)
from .stride_env import Z_HIGH, Z_LOW, check_coefficients, refuse_step_after_end


def _caller_level() -> int:
    """The stacklevel of the first frame outside gymnasium and bound_env: the warning is the
    caller's (shown by Python's default filters when that is ``__main__``, as any
    DeprecationWarning)."""
    frame, level = sys._getframe(2), 2  # the frame that called __init__
    while frame is not None and str(frame.f_globals.get("__name__", "")).startswith(
        ("gymnasium", "bound_env")
    ):
        frame, level = frame.f_back, level + 1
    return level


DEPRECATION = (
    "PassiveBoundRescue-v0 is deprecated and goes in the next release: use "
    "PassiveBoundRescue-v1 (a return is the only reward, an O(1) observation; "
    "docs/envs/passive-bound-rescue-v1.md)"
)


class PassiveBoundRescueEnv(RescueBase, utils.EzPickle):
    r"""Rescue the bounding quadruped from a start past the safe radius, a stride at a time.

    ## Description

    The stride-level task of `PassiveBoundStride-v1` (same plant: one step is one stride of
    the step env `PassiveBound-v0` through the one stride map `bound_env.sim.stride_map`, at the
    evaluation tolerance 1e-10, as `margins` measures it), posed as the task that the learned
    stride controllers solve: the robot starts **past the safe radius** of the LQR (the
    normalized apex error max_i |(z_i - z*_i) / s_i| above `safe`, where a gated controller
    such as `mpc` or `default` hands over from the LQR) and must bring the apex state back
    inside it without falling. Inside the safe radius the LQR takes over for good, so a
    return ends the episode. This is the task of `bound-env finetune`
    (`agents.experts.finetune`), which plays it through the `bound_env.envs.wrappers.LibraryActions`
    wrapper (discrete actions: the rows of the MPC's profile library).

    ## Action Space

    `Box(-1, 1, (K,), float32)`: the coefficients u of the stride's torque profile in the
    LQR's basis, tau(t) = `max_torque` * sum_i u_i phi_i(t) from the apex (as
    `PassiveBoundStride-v1`'s action; default: 8 equal windows of the nominal stride,
    80 N m). Out-of-range values are clipped; NaN or inf raise `ValueError`. The profile acts
    through its averages over the step env's control intervals of `dt`.

    | Num | Action | Min | Max | Unit |
    | --- | --- | --- | --- | --- |
    | i   | coefficient u_i of basis function phi_i | -1 | 1 | N m / `max_torque` |

    `bound_env.envs.wrappers.LibraryActions(env, rows)` gives `Discrete(len(rows))` instead: row 0
    is the LQR's plan u_lqr(z) = clip(-G (z - z*), -1, 1) at the current apex state, row j > 0
    the fixed profile ``rows[j]`` (default: the library of `bound_env.control.mpc.library`
    that the distilled controllers choose from).

    ## Observation Space

    `Box(low, high, (6,), float32)`: the normalized apex error x = (z - z*) / s, with z the
    apex state, z* the gait's fixed point and s the apex scales of the tasks
    (`bound_env.sim.task.APEX_SCALES`); the bounds are `PassiveBoundStride-v1`'s bounds of z,
    normalized alike (far outside anything a running robot reaches).

    | Num | Observation | Scale s_i |
    | --- | --- | --- |
    | 0 | (y_g - y_g*) / s_0, height of the centre of mass | 0.02 m |
    | 1 | (theta1 - theta1*) / s_1, pitch of the back body | 0.1 rad |
    | 2 | (theta2 - theta2*) / s_2, spine angle | 0.2 rad |
    | 3 | (xdot_g - xdot_g*) / s_3, forward speed | 0.1 m/s |
    | 4 | (theta1dot - theta1dot*) / s_4 | 1 rad/s |
    | 5 | (theta2dot - theta2dot*) / s_5 | 1 rad/s |

    The apex state itself is `info["apex_z"]` (SI, float64) and `env.unwrapped.z`. After a
    fall the observation is the last apex's.

    ## Rewards

    - *alive* (`info["reward_alive"]`): 1 for each stride that ends at an apex, 0 for a fall;
    - *bonus* (`info["reward_bonus"]`): on a return inside the safe radius after k strides,
      `horizon` - k, the strides left.

    So the return of an episode is the number of strides survived out of `horizon`, and a
    rescue is worth surviving them all (`horizon`).

    ## Starting State

    z* + r |z*| xi with r ~ U(0, `r_max`) and xi one axis (either sign) with probability
    `axis_prob`, else uniform on the 6-sphere scaled to max |xi_i| = 1
    (`bound_env.envs.rescue_env.sample_starts`), redrawn until it lies past the safe radius (at
    most 10,000 draws; a `safe` that no start out to `r_max` can pass is refused when the
    env is made). `reset(options={"apex_state": z})` starts at the apex state z (SI, 6
    numbers) instead (e.g. a validation set of starts); it must lie past the safe radius.
    Any other option key is refused. `reset` returns `info["start_z"]`.

    ## Episode End

    ### Termination

    - a **return**: the new apex state lies inside the safe radius (`info["returned"]`);
    - a **fall** (`info["fell"]`, the reason in `info["failure"]`, the step env's failure
      names; a non-finite apex state counts as a fall, `non_finite`).

    ### Truncation

    After `horizon` strides without either. The env truncates itself (no
    `max_episode_steps` in the registration) because `horizon` is part of the reward.

    `step` after a termination or a truncation raises `ValueError` (call `reset`).

    ## Info

    `stride` (strides completed), `error` (the normalized error max_i |x_i| of the new apex
    state, of the last one after a fall), `reward_alive`, `reward_bonus`, `returned`,
    `fell`, `failure` (None unless a fall), `apex_z` (after a completed stride).

    ## Arguments

    ```python
    import gymnasium as gym
    import bound_env
    from bound_env.envs.wrappers import LibraryActions
    gym.register_envs(bound_env)
    env = gym.make("PassiveBoundRescue-v0")                   # continuous profiles
    env = LibraryActions(gym.make("PassiveBoundRescue-v0"))   # the library's 66 rows
    ```

    | Parameter | Type | Default | Description |
    | --- | --- | --- | --- |
    | `gait` | **str, Path** | `"default"` | gait file (path, or name under `configs/gaits/`) |
    | `controller` | **str, Path** | `"mpc"` | lqr or mpc spec of the LQR (row 0) and defaults |
    | `basis` | **str** | the spec's (`"windows"`) | torque basis of the action |
    | `K` | **int** | the spec's (8) | number of basis functions |
    | `max_torque` | **float** | the spec's (80.0) | torque at coefficient 1 [N m], in (0, 1e4] |
    | `dt` | **float** | the spec's (0.01) | control grid of the plant [s] |
    | `gain` | **K x 6 floats** | the spec's | the LQR gain G (SI) (1) |
    | `safe` | **float** | the spec's (0.05) | safe radius: normalized error of a return |
    | `r_max` | **float** | `0.45` | largest start, relative to abs(z*), in (0, 1] |
    | `axis_prob` | **float** | `0.25` | probability of a start along one axis |
    | `horizon` | **int** | `30` | strides of an episode (truncation and bonus) |

    (1) The spec's stored gain is used when `basis`, `K`, `max_torque` and `dt` are the
    spec's; otherwise the LQR is designed with the spec's Q and R (`bound_env.control`).
    The LQR only matters to the `LibraryActions` wrapper (row 0) and to `env.unwrapped.lqr`.
    An lqr spec has no `safe`: 0.05 then; an offset-free spec (`lqr-of`) is refused (the
    task's LQR is a memoryless plan).

    ## Version History

    * v0: Initial version (the task of `bound-env finetune`'s former private env, bit for
      bit: the same starts from the same seed and the same strides). Later hardened without
      a change to any valid episode: `dt` in [1e-4, 0.1] s, a start option inside the safe
      radius or an unknown option key refused, `step` after the episode's end refused.
      v1 (`PassiveBoundRescue-v1`) pays for returns only. Deprecated: it warns
      (`DeprecationWarning`) when made and goes in the next release; use v1. An offset-free
      controller spec, `max_torque` above 1e4 N m, `r_max` above 1 and an `apex_state`
      outside the apex-state bounds are refused (one line each).
    """

    def __init__(
        self,
        gait: str = "default",
        controller: str = DEFAULT_CONTROLLER,
        basis: str | None = None,
        K: int | None = None,
        max_torque: float | None = None,
        dt: float | None = None,
        gain=None,
        safe: float | None = None,
        r_max: float = DEFAULT_R_MAX,
        axis_prob: float = DEFAULT_AXIS_PROB,
        horizon: int = DEFAULT_HORIZON,
    ):
        warnings.warn(DEPRECATION, DeprecationWarning, stacklevel=_caller_level())
        utils.EzPickle.__init__(
            self, gait, controller, basis, K, max_torque, dt, gain, safe, r_max, axis_prob,
            horizon,
        )  # fmt: skip
        self._setup(gait, controller, basis, K, max_torque, dt, gain, safe, 0.0, r_max,
                    axis_prob, horizon)  # fmt: skip
        # the stride env's apex-state bounds, far outside anything a running robot reaches
        self.obs_scale = self.scales  # v0 observes (z - z*) / the apex scales
        low = ((Z_LOW - self.z_ref) / self.obs_scale).astype(np.float32)
        high = ((Z_HIGH - self.z_ref) / self.obs_scale).astype(np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        z = self._start(options)
        self._begin(z)
        return self._obs(), {"start_z": z.copy(), "error": self.error(z)}

    def step(self, action):
        refuse_step_after_end(self._ended)
        u = np.clip(check_coefficients(action, self.K), -1.0, 1.0)
        z1, info = self._stride(u)
        if z1 is None:
            info.update(reward_alive=0.0, reward_bonus=0.0)
            return self._obs(), 0.0, True, False, info
        info.update(reward_alive=1.0, reward_bonus=0.0)
        if info["returned"]:
            bonus = float(self.horizon - self._k)
            info["reward_bonus"] = bonus
            return self._obs(), 1.0 + bonus, True, False, info
        return self._obs(), 1.0, False, self._k >= self.horizon, info
