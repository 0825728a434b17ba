"""PassiveBoundRescue-v0 and -v1: the rescue task, one step = one stride from a start past the
safe radius.

The task that fine-tuning solves (`agents.experts.finetune`), public: starts beyond the safe radius
of the LQR (where the gate hands over to a learned controller), a stride of the one stride map
(`bound_env.stride_map`) per step, and a return inside the safe radius ends the episode.
v0 (`PassiveBoundRescueEnv`) pays for survival; v1 (`PassiveBoundRescueV1Env`) pays for a
return only, so that standard RL learns to rescue. The start distribution (`sample_direction`,
`sample_starts`) is the distillation's and fine-tuning's; it lives here so that `bound_env`
owns it and `agents` re-exports it.
"""

from __future__ import annotations

import math
import os
from dataclasses import replace

import gymnasium as gym
import numpy as np
from gymnasium import spaces, utils

from .schema import dt_value, real_array
from .stride_env import Z_HIGH, Z_LOW, check_coefficients, refuse_step_after_end
from .stride_map import EVAL_RTOL, StrideMap, interval_weights
from .task import APEX_SCALES, PassiveBoundTask, check_reset_options

DEFAULT_CONTROLLER = "mpc"  # the spec whose LQR (and safe radius) the defaults are
DEFAULT_R_MAX = 0.45  # starts up to this relative size (distillation's and fine-tuning's)
DEFAULT_AXIS_PROB = 0.25  # probability of a start along one axis
DEFAULT_HORIZON = 30  # strides of an episode; a return earns the strides left to it
MAX_START_DRAWS = 10_000  # redraws of a start before `reset` gives up (bounded work)
ACTION_MODES = ("direct", "lqr_residual")
DEFAULT_GAMMA = 0.99  # v1's shaping discount: the learner's gamma (configs/ppo-rescue.yaml)
DEFAULT_RESIDUAL_SCALE = 0.25  # v1 "lqr_residual": coefficients added per unit of action


def sample_direction(rng: np.random.Generator, axis_prob: float) -> np.ndarray:
    """xi: one axis (either sign) with probability ``axis_prob``, else uniform on the 6-sphere
    scaled to max |xi_i| = 1 (`bound_env.analysis.margins.random_directions`)."""
    if rng.random() < axis_prob:
        xi = np.zeros(6)
        xi[rng.integers(6)] = rng.choice((-1.0, 1.0))
        return xi
    u = rng.standard_normal(6)
    return u / np.max(np.abs(u))


def sample_starts(rng, n: int, z_ref, r_max: float, axis_prob: float, r_min=0.0) -> np.ndarray:
    """n starts z* + r |z*| xi, r ~ U(``r_min``, ``r_max``), xi from `sample_direction`
    (n, 6)."""
    r = rng.uniform(r_min, r_max, n)
    xi = np.array([sample_direction(rng, axis_prob) for _ in range(n)])
    return z_ref + r[:, None] * np.abs(z_ref) * xi


def _number(name: str, value, low: float, high: float = np.inf, strict_low=True) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    ok = np.isfinite(v) and (v > low if strict_low else v >= low) and v <= high
    if not ok:
        rng = f"{'(' if strict_low else '['}{low}, {high}]"
        raise ValueError(f"{name} must be in {rng}, got {value!r}")
    return v


def _check_spec_name(controller) -> None:
    if not isinstance(controller, (str, os.PathLike)) or str(controller) == "":
        raise ValueError(
            f"controller must be the name or path of an lqr or mpc spec, got {controller!r}"
        )


def rescue_lqr(controller=DEFAULT_CONTROLLER, gait="default", basis=None, K=None,
               max_torque=None, dt=None, gain=None):  # fmt: skip
    """The LQR of the rescue task: the spec ``controller``'s (an lqr or mpc spec, name or
    path) with ``basis``, ``K``, ``max_torque``, ``dt`` in place of the spec's where given.
    Its stored gain is kept only when none of them changes (else the gain is designed with
    the spec's Q and R); ``gain`` (K x 6, SI) replaces it. Returns (the LQR, the spec).
    A bad argument is a one-line ValueError naming it (``dt``: the range of the spec files,
    `bound_env.schema.dt_value`)."""
    from .control import load_controller, load_spec

    _check_spec_name(controller)
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
        changes["dt"] = dt_value(changes["dt"], "dt")  # a stride holds >= 4 intervals
    same = all(getattr(spec, k) == v for k, v in changes.items())
    lqr_spec = replace(spec, controller="lqr", extra={}, **changes)
    if gain is not None:
        lqr_spec.gain = real_array(gain, "gain", shape=(None, 6), max_size=6 * 64).tolist()
    elif not same:
        lqr_spec.gain = None
    try:
        lqr = load_controller(lqr_spec, str(gait))
    except ValueError as e:  # the spec loader names the spec file; a given gain is ours
        msg = str(e)
        if gain is None or "gain" not in msg:
            raise
        raise ValueError(msg[msg.index("gain") :]) from None
    return lqr, spec


def check_start_radius(r_min, r_max, safe: float, z_ref, scales) -> tuple[float, float]:
    """(r_min, r_max) checked: 0 <= r_min < r_max (finite), and some start out to ``r_max``
    lies past the safe radius ``safe`` (the largest normalized error of a start is
    r_max max_i |z*_i| / s_i); ValueError naming the argument otherwise."""
    r_max = _number("r_max", r_max, 0.0)
    r_min = _number("r_min", r_min, 0.0, strict_low=False)
    if r_min >= r_max:
        raise ValueError(f"r_min must be below r_max={r_max!r}, got {r_min!r}")
    reach = r_max * float(np.max(np.abs(z_ref) / scales))
    if reach <= safe:
        raise ValueError(
            f"r_max={r_max!r} gives no start past the safe radius safe={safe!r} (the largest "
            f"start error is {reach:.3g}): raise r_max or lower safe"
        )
    return r_min, r_max


class _RescueBase(gym.Env):
    """What both versions share: the LQR and its safe radius, the starts, the plant, the
    checks of reset options and of stepping after the end."""

    metadata = {"render_modes": []}

    def _setup(self, gait, controller, basis, K, max_torque, dt, gain, safe, r_min, r_max,
               axis_prob, horizon):  # fmt: skip
        self.lqr, spec = rescue_lqr(controller, gait, basis, K, max_torque, dt, gain)
        if safe is None:
            safe = spec.extra.get("safe", 0.05) if spec.controller == "mpc" else 0.05
        self.safe = _number("safe", safe, 0.0)
        self.axis_prob = _number("axis_prob", axis_prob, 0.0, 1.0, strict_low=False)
        if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
            raise ValueError(f"horizon must be an integer >= 1, got {horizon!r}")
        self.horizon = int(horizon)
        self.z_ref = np.asarray(self.lqr.z_ref, dtype=float)
        self.scales = np.asarray(APEX_SCALES, dtype=float)
        self.r_min, self.r_max = check_start_radius(r_min, r_max, self.safe, self.z_ref,
                                                    self.scales)  # fmt: skip
        b = self.lqr.basis
        self.K = b.K
        # the profile's interval averages a = W u (as the MPC's planning model applies it)
        self._W = interval_weights(b.edges, b.phi, self.lqr.dt)
        self.plant = StrideMap(self.lqr.gait, None, self.lqr.dt, self.lqr.max_torque, EVAL_RTOL)
        self.action_space = spaces.Box(-1.0, 1.0, (self.K,), dtype=np.float32)
        self._z = self.z_ref.copy()
        self._k = 0
        self._ended: str | None = "before the first reset()"  # step() needs a reset() first

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

    def _start(self, options) -> np.ndarray:
        """The start apex state: ``options["apex_state"]`` (past the safe radius), or a draw
        of `sample_starts` past it (at most `MAX_START_DRAWS` draws)."""
        options = check_reset_options(options)
        if options.get("apex_state") is not None:
            z = PassiveBoundTask.check_apex_state(options["apex_state"]).copy()
            if not self.past_safe(z):
                raise ValueError(
                    f"options['apex_state'] lies inside the safe radius (error "
                    f"{self.error(z):.4g} <= safe={self.safe:g}): a rescue starts past it"
                )
            return z
        for _ in range(MAX_START_DRAWS):
            z = sample_starts(self.np_random, 1, self.z_ref, self.r_max, self.axis_prob,
                              self.r_min)[0]  # fmt: skip
            if self.past_safe(z):
                return z
        raise ValueError(
            f"no start past the safe radius safe={self.safe:g} in {MAX_START_DRAWS} draws with "
            f"r_min={self.r_min:g}, r_max={self.r_max:g}: raise r_max or lower safe"
        )

    def _stride(self, u):
        """One stride from the current apex under the coefficients u (clipped): the new apex
        state, or None on a fall, and the info's common keys."""
        refuse_step_after_end(self._ended)
        r = self.plant.run(self._z[None], self.profile_actions(u)[None])
        self._k += 1
        info = {"stride": self._k, "returned": False, "fell": False, "failure": r.failure(0)}
        z1 = r.z1[0]
        if not r.ok[0] or not np.all(np.isfinite(z1)):
            info.update(fell=True, failure=info["failure"] or "non_finite")
            info["error"] = self.error(self._z)
            self._ended = "the robot fell"
            return None, info
        self._z = z1.copy()
        info.update(apex_z=z1.copy(), error=self.error(z1))
        if not self.past_safe(z1):
            info["returned"] = True
            self._ended = "the robot returned inside the safe radius"
        elif self._k >= self.horizon:
            self._ended = f"the episode reached its horizon={self.horizon}"
        return z1, info


class PassiveBoundRescueEnv(_RescueBase, utils.EzPickle):
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
    (`agents.experts.finetune`), which plays it through the `bound_env.wrappers.LibraryActions`
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
    (`bound_env.rescue_env.sample_starts`), redrawn until it lies past the safe radius (at
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
      bit: the same starts from the same seed and the same strides). Later hardened without
      a change to any valid episode: `dt` in [1e-4, 0.1] s, a start option inside the safe
      radius or an unknown option key refused, `step` after the episode's end refused.
      v1 (`PassiveBoundRescue-v1`) pays for returns only.
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
        utils.EzPickle.__init__(
            self, gait, controller, basis, K, max_torque, dt, gain, safe, r_max, axis_prob,
            horizon,
        )  # fmt: skip
        self._setup(gait, controller, basis, K, max_torque, dt, gain, safe, 0.0, r_max,
                    axis_prob, horizon)  # fmt: skip
        # the stride env's apex-state bounds, far outside anything a running robot reaches
        low = ((Z_LOW - self.z_ref) / self.scales).astype(np.float32)
        high = ((Z_HIGH - self.z_ref) / self.scales).astype(np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

    def _obs(self) -> np.ndarray:
        x = ((self._z - self.z_ref) / self.scales).astype(np.float32)
        return np.clip(x, self.observation_space.low, self.observation_space.high)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        z = self._start(options)
        self._z, self._k, self._ended = z, 0, None
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


class PassiveBoundRescueV1Env(_RescueBase, utils.EzPickle):
    r"""Rescue the bounding quadruped from a start past the safe radius; only a return pays.

    ## Description

    The rescue task of `PassiveBoundRescue-v0` (the same plant, starts, safe radius and
    episode ends: one step is one stride of the step env through the one stride map
    `bound_env.stride_map` at the evaluation tolerance 1e-10; the episode starts past the
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
    s_i of the tasks (`bound_env.task.APEX_SCALES`; the floor matters for the two angles,
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
    (`bound_env.rescue_env.sample_starts`), redrawn until it lies past the safe radius (at
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
    | `max_torque` | **float** | the spec's (80.0) | torque at coefficient 1 [N m] |
    | `dt` | **float** | the spec's (0.01) | control grid of the plant [s], in [1e-4, 0.1] |
    | `gain` | **K x 6 floats** | the spec's | the LQR gain G (SI) (1) |
    | `safe` | **float** | the spec's (0.05) | safe radius: normalized error of a return |
    | `r_min` | **float** | `0.0` | smallest start, relative to abs(`z*`) |
    | `r_max` | **float** | `0.45` | largest start, relative to abs(`z*`) |
    | `axis_prob` | **float** | `0.25` | probability of a start along one axis |
    | `horizon` | **int** | `30` | strides of an episode (truncation) |
    | `shaping` | **float** | `0.0` | c of the shaping potential (0: return-only reward) |
    | `gamma` | **float** | `0.99` | discount of the shaping, the learner's gamma, in (0, 1] |
    | `action_mode` | **str** | `"direct"` | `"direct"` or `"lqr_residual"` |
    | `residual_scale` | **float** | `0.25` | coefficients per unit of action (`"lqr_residual"`) |
    | `terminate_at_horizon` | **bool** | `False` | the horizon a termination, not a truncation |

    (1) As v0: the spec's stored gain is used when `basis`, `K`, `max_torque` and `dt` are
    the spec's; otherwise the LQR is designed with the spec's Q and R (`bound_env.control`).
    An lqr spec has no `safe`: 0.05 then. A bad argument is a one-line `ValueError` naming it.

    ## Version History

    * v1: A return is the only reward (1; v0 paid 1 per stride survived plus the strides
      left on a return); optional potential-based shaping (`shaping`, `gamma`); the
      observation scaled per component to O(1) by the spread of the starts (v0: by the apex
      scales, up to 12.7); `r_min` and `set_start_radius` for a curriculum; `action_mode`
      and `residual_scale` for a residual on the LQR's plan; `terminate_at_horizon`. Same
      plant, starts (with `r_min` = 0), safe radius and episode ends as v0.
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
        if not isinstance(terminate_at_horizon, (bool, np.bool_)):
            raise ValueError(
                f"terminate_at_horizon must be true or false, got {terminate_at_horizon!r}"
            )
        self.terminate_at_horizon = bool(terminate_at_horizon)
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode must be one of {', '.join(ACTION_MODES)}, "
                             f"got {action_mode!r}")  # fmt: skip
        self.action_mode = action_mode
        self.residual_scale = _number("residual_scale", residual_scale, 0.0, 2.0)
        self.shaping = _number("shaping", shaping, 0.0, strict_low=False)
        self.gamma = _number("gamma", gamma, 0.0, 1.0)
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

    def _obs(self) -> np.ndarray:
        x = ((self._z - self.z_ref) / self.obs_scale).astype(np.float32)
        return np.clip(x, self.observation_space.low, self.observation_space.high)

    def coefficients(self, action) -> np.ndarray:
        """The profile coefficients u that ``action`` plays at the current apex state."""
        a = np.clip(check_coefficients(action, self.K), -1.0, 1.0)
        if self.action_mode == "direct":
            return a
        return np.clip(self.lqr.coefficients(self._z) + self.residual_scale * a, -1.0, 1.0)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        z = self._start(options)
        self._z, self._k, self._ended = z, 0, None
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
