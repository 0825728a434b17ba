"""PassiveBoundRescue-v0: the rescue task, one step = one stride from a start past the safe radius.

The task that fine-tuning solves (`agents.finetune`), public: starts beyond the safe radius of
the LQR (where the gate hands over to a learned controller), a stride of the one stride map
(`bound_env.stride_map`) per step, and a return inside the safe radius ends the episode.
The start distribution (`sample_direction`, `sample_starts`) is the distillation's and
fine-tuning's; it lives here so that `bound_env` owns it and `agents` re-exports it.
"""

from __future__ import annotations

from dataclasses import replace

import gymnasium as gym
import numpy as np
from gymnasium import spaces, utils

from .stride_env import Z_HIGH, Z_LOW, check_coefficients
from .stride_map import EVAL_RTOL, StrideMap, interval_weights
from .task import APEX_SCALES

DEFAULT_CONTROLLER = "mpc"  # the spec whose LQR (and safe radius) the defaults are
DEFAULT_R_MAX = 0.45  # starts up to this relative size (distillation's and fine-tuning's)
DEFAULT_AXIS_PROB = 0.25  # probability of a start along one axis
DEFAULT_HORIZON = 30  # strides of an episode; a return earns the strides left to it


def sample_direction(rng: np.random.Generator, axis_prob: float) -> np.ndarray:
    """xi: one axis (either sign) with probability ``axis_prob``, else uniform on the 6-sphere
    scaled to max |xi_i| = 1 (`bound_env.analysis.margins.random_directions`)."""
    if rng.random() < axis_prob:
        xi = np.zeros(6)
        xi[rng.integers(6)] = rng.choice((-1.0, 1.0))
        return xi
    u = rng.standard_normal(6)
    return u / np.max(np.abs(u))


def sample_starts(rng, n: int, z_ref, r_max: float, axis_prob: float) -> np.ndarray:
    """n starts z* + r |z*| xi, r ~ U(0, ``r_max``), xi from `sample_direction` (n, 6)."""
    r = rng.uniform(0.0, r_max, n)
    xi = np.array([sample_direction(rng, axis_prob) for _ in range(n)])
    return z_ref + r[:, None] * np.abs(z_ref) * xi


def _number(name: str, value, low: float, high: float = np.inf, strict_low=True) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    ok = np.isfinite(v) and (v > low if strict_low else v >= low) and v <= high
    if not ok:
        rng = f"{'(' if strict_low else '['}{low}, {high}]"
        raise ValueError(f"{name} must be in {rng}, got {value!r}")
    return v


def rescue_lqr(controller=DEFAULT_CONTROLLER, gait="default", basis=None, K=None,
               max_torque=None, dt=None, gain=None):  # fmt: skip
    """The LQR of the rescue task: the spec ``controller``'s (an lqr or mpc spec, name or
    path) with ``basis``, ``K``, ``max_torque``, ``dt`` in place of the spec's where given.
    Its stored gain is kept only when none of them changes (else the gain is designed with
    the spec's Q and R); ``gain`` (K x 6, SI) replaces it. Returns (the LQR, the spec)."""
    from .control import load_controller, load_spec

    spec = load_spec(controller)
    if spec.controller not in ("lqr", "mpc"):
        raise ValueError(f"controller {controller!r} is a {spec.controller} spec, not lqr or mpc")
    changes = {
        k: v
        for k, v in (("basis", basis), ("K", K), ("max_torque", max_torque), ("dt", dt))
        if v is not None
    }
    if changes.get("max_torque") is not None:
        changes["max_torque"] = _number("max_torque", changes["max_torque"], 0.0)
    if changes.get("dt") is not None:
        changes["dt"] = _number("dt", changes["dt"], 0.0)
    same = all(getattr(spec, k) == v for k, v in changes.items())
    lqr_spec = replace(spec, controller="lqr", extra={}, **changes)
    if gain is not None:
        lqr_spec.gain = np.asarray(gain, dtype=float).tolist()
    elif not same:
        lqr_spec.gain = None
    return load_controller(lqr_spec, str(gait)), spec


class PassiveBoundRescueEnv(gym.Env, utils.EzPickle):
    r"""Rescue the bounding quadruped from a start past the safe radius, a stride at a time.

    ## Description

    The stride-level task of `PassiveBoundStride-v1` (same plant: one step is one stride of
    the step env `PassiveBound-v0` through the one stride map `bound_env.stride_map`, at the
    evaluation tolerance 1e-10, as `margins` measures it), posed as the task that the learned
    stride controllers solve: the robot starts **past the safe radius** of the LQR (the
    normalized apex error max_i |(z_i - z*_i) / s_i| above `safe`, where a gated controller
    such as `mpc` or `default` hands over from the LQR) and must bring the apex state back
    inside it without falling. Inside the safe radius the LQR takes over for good, so a
    return ends the episode. This is the task of `bound-env finetune`
    (`agents.finetune`), which plays it through the `bound_env.wrappers.LibraryActions`
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

    `bound_env.wrappers.LibraryActions(env, rows)` gives `Discrete(len(rows))` instead: row 0
    is the LQR's plan u_lqr(z) = clip(-G (z - z*), -1, 1) at the current apex state, row j > 0
    the fixed profile ``rows[j]`` (default: the library of `bound_env.control.mpc.library`
    that the distilled controllers choose from).

    ## Observation Space

    `Box(low, high, (6,), float32)`: the normalized apex error x = (z - z*) / s, with z the
    apex state, z* the gait's fixed point and s the apex scales of the tasks
    (`bound_env.task.APEX_SCALES`); the bounds are `PassiveBoundStride-v1`'s bounds of z,
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
    (`bound_env.rescue_env.sample_starts`), redrawn until it lies past the safe radius.
    `reset(options={"apex_state": z})` starts at the apex state z (SI, 6 numbers) instead
    (e.g. a validation set of starts). `reset` returns `info["start_z"]`.

    ## Episode End

    ### Termination

    - a **return**: the new apex state lies inside the safe radius (`info["returned"]`);
    - a **fall** (`info["fell"]`, the reason in `info["failure"]`, the step env's failure
      names; a non-finite apex state counts as a fall, `non_finite`).

    ### Truncation

    After `horizon` strides without either. The env truncates itself (no
    `max_episode_steps` in the registration) because `horizon` is part of the reward.

    ## Info

    `stride` (strides completed), `error` (the normalized error max_i |x_i| of the new apex
    state, of the last one after a fall), `reward_alive`, `reward_bonus`, `returned`,
    `fell`, `failure` (None unless a fall), `apex_z` (after a completed stride).

    ## Arguments

    ```python
    import gymnasium as gym
    import bound_env
    from bound_env.wrappers import LibraryActions
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
    | `max_torque` | **float** | the spec's (80.0) | torque at coefficient 1 [N m] |
    | `dt` | **float** | the spec's (0.01) | control grid of the plant [s] |
    | `gain` | **K x 6 floats** | the spec's | the LQR gain G (SI) (1) |
    | `safe` | **float** | the spec's (0.05) | safe radius: normalized error of a return |
    | `r_max` | **float** | `0.45` | largest start, relative to abs(z*) |
    | `axis_prob` | **float** | `0.25` | probability of a start along one axis |
    | `horizon` | **int** | `30` | strides of an episode (truncation and bonus) |

    (1) The spec's stored gain is used when `basis`, `K`, `max_torque` and `dt` are the
    spec's; otherwise the LQR is designed with the spec's Q and R (`bound_env.control`).
    The LQR only matters to the `LibraryActions` wrapper (row 0) and to `env.unwrapped.lqr`.
    An lqr spec has no `safe`: 0.05 then.

    ## Version History

    * v0: Initial version (the task of `bound-env finetune`'s former private env, bit for
      bit: the same starts from the same seed and the same strides).
    """

    metadata = {"render_modes": []}

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
        utils.EzPickle.__init__(
            self, gait, controller, basis, K, max_torque, dt, gain, safe, r_max, axis_prob,
            horizon,
        )  # fmt: skip
        self.lqr, spec = rescue_lqr(controller, gait, basis, K, max_torque, dt, gain)
        if safe is None:
            safe = spec.extra.get("safe", 0.05) if spec.controller == "mpc" else 0.05
        self.safe = _number("safe", safe, 0.0)
        self.r_max = _number("r_max", r_max, 0.0)
        self.axis_prob = _number("axis_prob", axis_prob, 0.0, 1.0, strict_low=False)
        if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
            raise ValueError(f"horizon must be an integer >= 1, got {horizon!r}")
        self.horizon = int(horizon)
        self.z_ref = np.asarray(self.lqr.z_ref, dtype=float)
        self.scales = np.asarray(APEX_SCALES, dtype=float)
        b = self.lqr.basis
        self.K = b.K
        # the profile's interval averages a = W u (as the MPC's planning model applies it)
        self._W = interval_weights(b.edges, b.phi, self.lqr.dt)
        self.plant = StrideMap(self.lqr.gait, None, self.lqr.dt, self.lqr.max_torque, EVAL_RTOL)
        # the stride env's apex-state bounds, far outside anything a running robot reaches
        low = ((Z_LOW - self.z_ref) / self.scales).astype(np.float32)
        high = ((Z_HIGH - self.z_ref) / self.scales).astype(np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (self.K,), dtype=np.float32)
        self._z = self.z_ref.copy()
        self._k = 0

    @property
    def z(self) -> np.ndarray:
        """The current apex state (SI, float64), a copy."""
        return self._z.copy()

    @property
    def basis(self):
        return self.lqr.basis

    def error(self, z) -> float:
        """The normalized apex error max_i |(z_i - z*_i) / s_i|."""
        return float(np.max(np.abs(np.asarray(z) - self.z_ref) / self.scales))

    def past_safe(self, z) -> bool:
        return self.error(z) > self.safe

    def profile_actions(self, u) -> np.ndarray:
        """The interval actions of the coefficients u (the plant's input)."""
        return (np.atleast_2d(u) @ self._W.T)[0]

    def _obs(self) -> np.ndarray:
        x = ((self._z - self.z_ref) / self.scales).astype(np.float32)
        return np.clip(x, self.observation_space.low, self.observation_space.high)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        z = (options or {}).get("apex_state")
        if z is not None:
            z = np.asarray(z, dtype=float)
            if z.shape != (6,) or not np.isfinite(z).all():
                raise ValueError(f"options['apex_state'] must be 6 finite numbers, got {z!r}")
            z = z.copy()
        else:
            while True:
                z = sample_starts(self.np_random, 1, self.z_ref, self.r_max, self.axis_prob)[0]
                if self.past_safe(z):
                    break
        self._z, self._k = z, 0
        return self._obs(), {"start_z": z.copy(), "error": self.error(z)}

    def step(self, action):
        u = np.clip(check_coefficients(action, self.K), -1.0, 1.0)
        r = self.plant.run(self._z[None], self.profile_actions(u)[None])
        self._k += 1
        info = {"stride": self._k, "returned": False, "fell": False, "failure": r.failure(0)}
        z1 = r.z1[0]
        if not r.ok[0] or not np.all(np.isfinite(z1)):
            info.update(fell=True, failure=info["failure"] or "non_finite")
            info.update(reward_alive=0.0, reward_bonus=0.0, error=self.error(self._z))
            return self._obs(), 0.0, True, False, info
        self._z = z1.copy()
        info.update(apex_z=z1.copy(), error=self.error(z1), reward_alive=1.0, reward_bonus=0.0)
        if not self.past_safe(z1):
            bonus = float(self.horizon - self._k)
            info.update(returned=True, reward_bonus=bonus)
            return self._obs(), 1.0 + bonus, True, False, info
        return self._obs(), 1.0, False, self._k >= self.horizon, info
