"""PassiveBoundRescue-v1: the rescue task paying for a return only, one step = one stride from a
start past the safe radius (the one standard RL learns; `bound_env.envs.rescue_common` holds what it
shares with v0).
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces, utils

from ..files.schema import boolean
from .rescue_common import (
    ACTION_MODES,
    DEFAULT_AXIS_PROB,
    DEFAULT_CONTROLLER,
    DEFAULT_GAMMA,
    DEFAULT_HORIZON,
    DEFAULT_R_MAX,
    DEFAULT_RESIDUAL_SCALE,
    MAX_SHAPING,
    RescueBase,
    check_start_radius,
    number_in,
)
from .stride_env import Z_HIGH, Z_LOW, check_coefficients, refuse_step_after_end


class PassiveBoundRescueV1Env(RescueBase, utils.EzPickle):
    r"""Rescue the bounding quadruped from a start past the safe radius; only a return pays.

    ## Description

    The rescue task of `PassiveBoundRescue-v0` (the same plant, starts, safe radius and
    episode ends: one step is one stride of the step env through the one stride map
    `bound_env.sim.stride_map` at the evaluation tolerance 1e-10; the episode starts past the
    LQR's safe radius and ends on a return inside it or a fall), posed so that standard RL
    learns it: **a return is the only reward**, so returning is worth more than any survival
    (in v0 a return was worth the strides left, exactly what surviving to the horizon was
    worth, and plain PPO learned to survive without returning); the observation is scaled
    per component to O(1); optional potential-based shaping on the log apex error (which
    cannot change the optimal policy); options for a start-radius curriculum (`r_min`,
    `r_max`, `set_start_radius`) and for an action that is a residual on the LQR's plan
    (`action_mode="lqr_residual"`).

    ## Action Space

    `Box(-1, 1, (K,), float32)`, a (clipped) vector a; NaN or inf raise `ValueError`. The
    stride's torque profile is tau(t) = `max_torque` * sum_i u_i phi_i(t) from the apex in
    the LQR's basis (default: 8 equal windows of the nominal stride, 80 N m), with

    - `action_mode="direct"` (default): u = a, the coefficients themselves (as v0);
    - `action_mode="lqr_residual"`: u = clip(u_lqr(z) + `residual_scale` * a, -1, 1), a
      residual on the LQR's plan u_lqr(z) = clip(-G (z - `z*`), -1, 1) at the current apex
      state z (a = 0 plays the LQR).

    | Num | Action | Min | Max | Unit |
    | --- | --- | --- | --- | --- |
    | i   | a_i: coefficient u_i of basis function phi_i, or its residual | -1 | 1 | see above |

    ## Observation Space

    `Box(low, high, (6,), float32)`: the apex error scaled per component to O(1),
    o_i = (z_i - `z*_i`) / sigma_i, with sigma_i = max(0.45 |`z*_i`|, s_i): the spread of the
    default starts (0.45 |`z*_i`|, the largest start along axis i), floored at the apex scale
    s_i of the tasks (`bound_env.sim.task.APEX_SCALES`; the floor matters for the two angles,
    whose `z*_i` is near 0). sigma does not change with `r_min`/`r_max`, so a curriculum keeps
    the observation. For the default gait:

    | Num | Observation | sigma_i |
    | --- | --- | --- |
    | 0 | (y_g - y_g*) / sigma_0, height of the centre of mass | 0.112 m |
    | 1 | (theta1 - theta1*) / sigma_1, pitch of the back body | 0.1 rad |
    | 2 | (theta2 - theta2*) / sigma_2, spine angle | 0.2 rad |
    | 3 | (xdot_g - xdot_g*) / sigma_3, forward speed | 1.27 m/s |
    | 4 | (theta1dot - theta1dot*) / sigma_4 | 2.31 rad/s |
    | 5 | (theta2dot - theta2dot*) / sigma_5 | 1.15 rad/s |

    Starts then lie within |o_i| <= 1 (0.045 for the angles). The bounds are v0's, scaled
    alike. `env.unwrapped.obs_scale` is sigma (SI); the apex state itself is
    `info["apex_z"]` and `env.unwrapped.z`. After a fall the observation is the last apex's.

    ## Rewards

    reward = return + shaping, each in `info`:

    - *return* (`info["reward_return"]`): 1 on the stride that brings the apex state back
      inside the safe radius (the episode terminates), 0 otherwise (a fall too);
    - *shaping* (`info["reward_shaping"]`, 0 unless `shaping` > 0): F = `gamma` Phi(z') -
      Phi(z) for the stride from apex z to z', with the potential
      Phi(z) = -`shaping` * log(e(z) / `safe`), e(z) = max_i |z_i - `z*_i`| / s_i the
      normalized apex error (the norm that defines the safe radius; Phi = 0 on it), and
      Phi = 0 after a termination (a return or a fall: the absorbing state's potential).
      Potential-based shaping (Ng, Harada and Russell, 1999) adds -Phi(z_0) to every
      episode's discounted return whatever the policy does, so it cannot change the
      optimal policy; it pays each stride for the factor by which it shrinks the error.
      Use the learner's discount as `gamma` (the shipped config: 0.99).

    **Why a return dominates.** Without shaping every reward is 0 except the return's 1, so
    the value of any state is the discounted probability of a later return: returning now
    (1) is worth more than any survival (at most `gamma` < 1), and falling (0) is never
    better than surviving.

    ## Starting State

    `z*` + r |`z*`| xi with r ~ U(`r_min`, `r_max`) and xi one axis (either sign) with
    probability `axis_prob`, else uniform on the 6-sphere scaled to max |xi_i| = 1
    (`bound_env.envs.rescue_env.sample_starts`), redrawn until it lies past the safe radius (at
    most 10,000 draws; radii that give no start past it are refused). With `r_min` = 0
    these are v0's starts from the same seed. A curriculum changes the radii between
    episodes with `env.unwrapped.set_start_radius(r_max, r_min=0.0)` (e.g. from an SB3
    callback: `venv.env_method("set_start_radius", 0.3)`).
    `reset(options={"apex_state": z})` starts at the apex state z (SI, 6 numbers; past the
    safe radius), e.g. a validation set of starts; any other option key is refused.
    `reset` returns `info["start_z"]` and `info["error"]`.

    ## Episode End

    ### Termination

    - a **return**: the new apex state lies inside the safe radius (`info["returned"]`);
    - a **fall** (`info["fell"]`, the reason in `info["failure"]`, the step env's failure
      names; a non-finite apex state counts as a fall, `non_finite`).

    ### Truncation

    After `horizon` strides without either (the env truncates itself: `horizon` is its
    argument, no `max_episode_steps` in the registration). Truncation is not a termination:
    the robot is still running, so a learner should bootstrap there, as Stable-Baselines3
    does (`TimeLimit.truncated`: it adds `gamma` V(z_horizon) to the last reward). This does
    not give survival a value of its own: V is the discounted prospect of a later return,
    so a return within the horizon is still worth more than reaching the horizon.
    `terminate_at_horizon=True` makes the horizon a termination instead (no bootstrap; with
    shaping, Phi = 0 there as after a fall, so every episode without a return then sums to
    -Phi(z_0) whatever it did: only returns tell policies apart).
    `step` after a termination or a truncation raises `ValueError` (call `reset`).

    ## Info

    `stride` (strides completed), `error` (the normalized error e of the new apex state, of
    the last one after a fall), `reward_return`, `reward_shaping`, `returned`, `fell`,
    `failure` (None unless a fall), `apex_z` (after a completed stride), `u` (the
    coefficients played, after clipping).

    ## Arguments

    ```python
    import gymnasium as gym
    import bound_env
    gym.register_envs(bound_env)
    env = gym.make("PassiveBoundRescue-v1")                             # return-only reward
    env = gym.make("PassiveBoundRescue-v1", shaping=0.1, gamma=0.99)    # + log-error shaping
    env = gym.make("PassiveBoundRescue-v1", action_mode="lqr_residual") # a residual on the LQR
    ```

    | Parameter | Type | Default | Description |
    | --- | --- | --- | --- |
    | `gait` | **str, Path** | `"default"` | gait file (path, or name under `configs/gaits/`) |
    | `controller` | **str, Path** | `"mpc"` | lqr or mpc spec of the LQR, its basis and `safe` |
    | `basis` | **str** | the spec's (`"windows"`) | torque basis of the action |
    | `K` | **int** | the spec's (8) | number of basis functions |
    | `max_torque` | **float** | the spec's (80.0) | torque at coefficient 1 [N m], in (0, 1e4] |
    | `dt` | **float** | the spec's (0.01) | control grid of the plant [s], in [1e-4, 0.1] |
    | `gain` | **K x 6 floats** | the spec's | the LQR gain G (SI) (1) |
    | `safe` | **float** | the spec's (0.05) | safe radius: normalized error of a return |
    | `r_min` | **float** | `0.0` | smallest start, relative to abs(`z*`) |
    | `r_max` | **float** | `0.45` | largest start, relative to abs(`z*`), in (0, 1] |
    | `axis_prob` | **float** | `0.25` | probability of a start along one axis |
    | `horizon` | **int** | `30` | strides of an episode (truncation) |
    | `shaping` | **float** | `0.0` | c of the shaping potential, in [0, 100] (0: return only) |
    | `gamma` | **float** | `0.99` | discount of the shaping, the learner's gamma, in (0, 1] |
    | `action_mode` | **str** | `"direct"` | `"direct"` or `"lqr_residual"` |
    | `residual_scale` | **float** | `0.25` | coefficients per unit of action (`"lqr_residual"`) |
    | `terminate_at_horizon` | **bool** | `False` | the horizon a termination, not a truncation |

    (1) As v0: the spec's stored gain is used when `basis`, `K`, `max_torque` and `dt` are
    the spec's; otherwise the LQR is designed with the spec's Q and R (`bound_env.control`).
    An lqr spec has no `safe`: 0.05 then; an offset-free spec (`lqr-of`) is refused (the
    task's LQR is a memoryless plan). A bad argument is a one-line `ValueError` naming it.

    ## Version History

    * v1: A return is the only reward (1; v0 paid 1 per stride survived plus the strides
      left on a return); optional potential-based shaping (`shaping`, `gamma`); the
      observation scaled per component to O(1) by the spread of the starts (v0: by the apex
      scales, up to 12.7); `r_min` and `set_start_radius` for a curriculum; `action_mode`
      and `residual_scale` for a residual on the LQR's plan; `terminate_at_horizon`. Same
      plant, starts (with `r_min` = 0), safe radius and episode ends as v0. Later hardened
      without a change to any valid episode: `shaping` above 100 (1e308 made the first
      reward inf), an offset-free controller spec, `max_torque` above 1e4 N m, `r_max` above
      1 and an `apex_state` outside the apex-state bounds are refused in one line; under
      `bound_env.envs.randomized.RandomizedPlant`'s sensor noise, "lqr_residual" plans on the
      observed apex state (`z_observed`).
    * v0: Initial version: `PassiveBoundRescue-v0`, still registered and unchanged.
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
        r_min: float = 0.0,
        r_max: float = DEFAULT_R_MAX,
        axis_prob: float = DEFAULT_AXIS_PROB,
        horizon: int = DEFAULT_HORIZON,
        shaping: float = 0.0,
        gamma: float = DEFAULT_GAMMA,
        action_mode: str = "direct",
        residual_scale: float = DEFAULT_RESIDUAL_SCALE,
        terminate_at_horizon: bool = False,
    ):
        utils.EzPickle.__init__(
            self, gait, controller, basis, K, max_torque, dt, gain, safe, r_min, r_max,
            axis_prob, horizon, shaping, gamma, action_mode, residual_scale,
            terminate_at_horizon,
        )  # fmt: skip
        self.terminate_at_horizon = boolean(terminate_at_horizon, "terminate_at_horizon")
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode must be one of {', '.join(ACTION_MODES)}, "
                             f"got {action_mode!r}")  # fmt: skip
        self.action_mode = action_mode
        self.residual_scale = number_in("residual_scale", residual_scale, 0.0, 2.0)
        self.shaping = number_in("shaping", shaping, 0.0, MAX_SHAPING, strict_low=False)
        self.gamma = number_in("gamma", gamma, 0.0, 1.0)
        self._setup(gait, controller, basis, K, max_torque, dt, gain, safe, r_min, r_max,
                    axis_prob, horizon)  # fmt: skip
        self.obs_scale = np.maximum(DEFAULT_R_MAX * np.abs(self.z_ref), self.scales)
        low = ((Z_LOW - self.z_ref) / self.obs_scale).astype(np.float32)
        high = ((Z_HIGH - self.z_ref) / self.obs_scale).astype(np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

    def set_start_radius(self, r_max: float, r_min: float = 0.0) -> None:
        """Starts from the next `reset` on: r ~ U(``r_min``, ``r_max``) (a curriculum);
        ValueError (one line) for radii `__init__` would refuse."""
        self.r_min, self.r_max = check_start_radius(r_min, r_max, self.safe, self.z_ref,
                                                    self.scales)  # fmt: skip

    def potential(self, z) -> float:
        """Phi(z) = -shaping * log(e(z) / safe) (0 without shaping)."""
        if self.shaping == 0.0:
            return 0.0
        return -self.shaping * math.log(max(self.error(z), 1e-12) / self.safe)

    def coefficients(self, action) -> np.ndarray:
        """The profile coefficients u that ``action`` plays at the current apex state (with
        ``"lqr_residual"``: on the LQR's plan at the apex state as observed, ``z_observed``:
        with sensor noise under `bound_env.envs.randomized.RandomizedPlant`)."""
        a = np.clip(check_coefficients(action, self.K), -1.0, 1.0)
        if self.action_mode == "direct":
            return a
        plan = self.lqr.coefficients(self.z_observed)
        return np.clip(plan + self.residual_scale * a, -1.0, 1.0)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        z = self._start(options)
        self._begin(z)
        return self._obs(), {"start_z": z.copy(), "error": self.error(z)}

    def step(self, action):
        refuse_step_after_end(self._ended)
        u = self.coefficients(action)
        phi0 = self.potential(self._z)
        z1, info = self._stride(u)
        info["u"] = u
        terminated = z1 is None or info["returned"]
        at_horizon = not terminated and self._k >= self.horizon
        if at_horizon and self.terminate_at_horizon:
            terminated, at_horizon = True, False
        ret = 1.0 if info["returned"] else 0.0
        phi1 = 0.0 if terminated else self.potential(z1)
        shaping = self.gamma * phi1 - phi0 if self.shaping > 0.0 else 0.0
        info.update(reward_return=ret, reward_shaping=shaping)
        return self._obs(), ret + shaping, terminated, at_horizon, info
