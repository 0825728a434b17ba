"""What the rescue envs PassiveBoundRescue-v0 (`bound_env.envs.rescue_v0`) and -v1
(`bound_env.envs.rescue_v1`) share: the start distribution (`sample_direction`, `sample_starts`, the
distillation's and fine-tuning's; it lives here so that `bound_env` owns it and `agents`
re-exports it), the task's LQR (`rescue_lqr`) and its safe radius, the checks of their
arguments, and `RescueBase`, the plant (a stride of the one stride map per step), the starts
and the episode's end. `bound_env.envs.rescue_env` imports all of it from one place.
"""

from __future__ import annotations

import os
from dataclasses import replace

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..files.schema import dt_value, real_array
from ..model.params import Z_NAMES
from ..sim.stride_map import EVAL_RTOL, StrideMap
from ..sim.stride_protocol import ProfileActions
from ..sim.task import APEX_SCALES, PassiveBoundTask, check_reset_options
from .stride_env import Z_HIGH, Z_LOW, refuse_step_after_end

DEFAULT_CONTROLLER = "mpc"  # the spec whose LQR (and safe radius) the defaults are
DEFAULT_R_MAX = 0.45  # starts up to this relative size (distillation's and fine-tuning's)
DEFAULT_AXIS_PROB = 0.25  # probability of a start along one axis
DEFAULT_HORIZON = 30  # strides of an episode; a return earns the strides left to it
MAX_START_DRAWS = 10_000  # redraws of a start before `reset` gives up (bounded work)
ACTION_MODES = ("direct", "lqr_residual")
DEFAULT_GAMMA = 0.99  # v1's shaping discount: the learner's gamma (configs/ppo-rescue.yaml)
DEFAULT_RESIDUAL_SCALE = 0.25  # v1 "lqr_residual": coefficients added per unit of action
MAX_R = 1.0  # largest start radius: at r = 1 a component of the start reaches 0 or 2 z*_i
MAX_SHAPING = 100.0  # v1's shaping c at most (the return pays 1; c = 1e308 made rewards inf)


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


def number_in(name: str, value, low: float, high: float = np.inf, strict_low=True) -> float:
    if isinstance(value, (bool, str, bytes)):  # '0.3' is text, not a number (as schema.real)
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
    `bound_env.files.schema.dt_value`)."""
    from ..control import load_controller, load_spec
    from ..control.spec import MAX_TORQUE_LIMIT

    _check_spec_name(controller)
    spec = load_spec(controller)
    if spec.controller not in ("lqr", "mpc"):
        raise ValueError(f"controller {controller!r} is a {spec.controller} spec, not lqr or mpc")
    if spec.offset_free is not None:
        raise ValueError(
            f"controller {controller!r} is held offset-free (it keeps an estimate across "
            "strides); the rescue task's LQR is a memoryless plan: give its base spec "
            "(e.g. 'lqr')"
        )
    changes = {
        k: v
        for k, v in (("basis", basis), ("K", K), ("max_torque", max_torque), ("dt", dt))
        if v is not None
    }
    if changes.get("max_torque") is not None:
        changes["max_torque"] = number_in(
            "max_torque", changes["max_torque"], 0.0, MAX_TORQUE_LIMIT
        )
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
    r_max = number_in("r_max", r_max, 0.0, MAX_R)
    r_min = number_in("r_min", r_min, 0.0, strict_low=False)
    if r_min >= r_max:
        raise ValueError(f"r_min must be below r_max={r_max!r}, got {r_min!r}")
    reach = r_max * float(np.max(np.abs(z_ref) / scales))
    if reach <= safe:
        raise ValueError(
            f"r_max={r_max!r} gives no start past the safe radius safe={safe!r} (the largest "
            f"start error is {reach:.3g}): raise r_max or lower safe"
        )
    return r_min, r_max


class RescueBase(gym.Env):
    """What both versions share: the LQR and its safe radius, the starts, the plant, the
    checks of reset options and of stepping after the end."""

    metadata = {"render_modes": []}

    def _setup(self, gait, controller, basis, K, max_torque, dt, gain, safe, r_min, r_max,
               axis_prob, horizon):  # fmt: skip
        self.lqr, spec = rescue_lqr(controller, gait, basis, K, max_torque, dt, gain)
        if safe is None:
            safe = spec.extra.get("safe", 0.05) if spec.controller == "mpc" else 0.05
        self.safe = number_in("safe", safe, 0.0)
        self.axis_prob = number_in("axis_prob", axis_prob, 0.0, 1.0, strict_low=False)
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
        self._profile = ProfileActions(b, self.lqr.dt)
        self.plant = StrideMap(self.lqr.gait, None, self.lqr.dt, self.lqr.max_torque, EVAL_RTOL)
        self.action_space = spaces.Box(-1.0, 1.0, (self.K,), dtype=np.float32)
        self._z = self.z_ref.copy()
        # the apex state as the controller side sees it (the LQR of LibraryActions' row 0 and
        # of v1's "lqr_residual"): z, or z with sensor noise under RandomizedPlant
        self.z_observed = self._z.copy()
        self._k = 0
        self._ended: str | None = "before the first reset()"  # step() needs a reset() first

    @property
    def z(self) -> np.ndarray:
        """The current apex state (SI, float64), a copy."""
        return self._z.copy()

    @property
    def basis(self):
        return self.lqr.basis

    @property
    def plant_task(self) -> PassiveBoundTask:
        """The one holder of the robot's plant: the task of the stride map every stride runs
        on (``set_params`` changes the next stride; model error,
        `bound_env.envs.randomized.RandomizedPlant`)."""
        return self.plant.task

    def apex_observation(self, z) -> np.ndarray:
        """The observation of the apex state z (SI): (z - z*) / ``obs_scale``, float32,
        clipped to the bounds (sensor noise, `bound_env.envs.randomized.RandomizedPlant`, adds to
        z first, so it is in the observation's units)."""
        x = ((np.asarray(z, dtype=float) - self.z_ref) / self.obs_scale).astype(np.float32)
        return np.clip(x, self.observation_space.low, self.observation_space.high)

    def _obs(self) -> np.ndarray:
        return self.apex_observation(self._z)

    def _begin(self, z) -> None:
        self._z, self._k, self._ended = z, 0, None
        self.z_observed = z.copy()

    def error(self, z) -> float:
        """The normalized apex error max_i |(z_i - z*_i) / s_i|."""
        return float(np.max(np.abs(np.asarray(z) - self.z_ref) / self.scales))

    def past_safe(self, z) -> bool:
        return self.error(z) > self.safe

    def profile_actions(self, u) -> np.ndarray:
        """The interval actions of the coefficients u (the plant's input)."""
        return self._profile(u)[0]

    def _start(self, options) -> np.ndarray:
        """The start apex state: ``options["apex_state"]`` (past the safe radius), or a draw
        of `sample_starts` past it (at most `MAX_START_DRAWS` draws)."""
        options = check_reset_options(options)
        if options.get("apex_state") is not None:
            z = PassiveBoundTask.check_apex_state(options["apex_state"]).copy()
            out = np.flatnonzero((z < Z_LOW) | (z > Z_HIGH))
            if out.size:
                j = int(out[0])
                raise ValueError(
                    f"options['apex_state']: {Z_NAMES[j]}={float(z[j])!r} lies outside "
                    f"[{Z_LOW[j]:g}, {Z_HIGH[j]:g}] (SI), the bounds of the apex state"
                )
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
        self.z_observed = z1.copy()
        info.update(apex_z=z1.copy(), error=self.error(z1))
        if not self.past_safe(z1):
            info["returned"] = True
            self._ended = "the robot returned inside the safe radius"
        elif self._k >= self.horizon:
            self._ended = f"the episode reached its horizon={self.horizon}"
        return z1, info
