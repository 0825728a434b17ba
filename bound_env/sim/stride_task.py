"""The stride-level task: one step = one apex-to-apex stride under a spine-torque profile.

This is the task layer of `bound_env.envs.stride_env.PassiveBoundStrideEnv` and of the stride-level
controllers in `bound_env.control`. It knows nothing of Gymnasium. One stride starts at an
apex state z (eq. 17) and applies the spine torque

    tau(t) = max_torque * sum_i u_i phi_i(t),    u in [-1, 1]^K,  t measured from the apex,

until the next apex (the Poincare map P of eq. 18, now with an input: z1 = P(z, u)).

The basis
---------
Every basis is piecewise constant on a grid of sub-windows of the *nominal* stride (the passive
stride from the reference apex state z*, period T): ``edges`` (n_sub + 1 times, edges[0] = 0,
edges[-1] = T) and a matrix ``phi`` (n_sub x K) whose column i holds the value of phi_i on each
sub-window, so the torque on sub-window j is max_torque * (phi @ u)[j].

- ``"windows"``: K equal windows of [0, T]; phi is the identity.
- ``"phases"``: one window per stance condition of the nominal stride (for the default gait
  df, bs, df, fs, df: K = 5; the middle flight lasts 0.75 ms); phi is the identity.
- ``"hats"``: K piecewise-linear "hat" functions with peaks at K equally spaced knots from 0 to
  T (a partition of unity), realized by their average over each of ``HAT_SUBWINDOWS`` equal
  sub-windows per knot interval. This is the smooth basis, discretized so that the torque
  stays a constant parameter between sub-window edges and every contact is still located
  exactly.

**Past the nominal period** (a perturbed stride can last longer than T) the last sub-window's
torque holds until the apex (or until `NO_APEX_TIME`, when the stride fails with ``no_apex``).
A stride shorter than T simply never reaches the later windows.

The plant: the step env's control grid
--------------------------------------
A profile acts on the robot as the step env (PassiveBound-v0) would apply it: interval k of
the control grid, [k dt, (k + 1) dt] from the apex (dt = 10 ms by default), holds the
profile's average over that interval, so each interval delivers the profile's impulse
exactly. The stride itself is `bound_env.sim.stride_map`, the one stride map of the project
(the step env's own compiled kernel, event-accurate), so the stride env, the classical
designs, the MPC, distillation, fine-tuning and the margins all see the same map. Zero action
is the passive Poincare map up to the integrator tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..model.params import Gait, load_gait
from ..model.stride import DEFAULT_T_MAX, simulate_stride
from .stride_map import EVAL_RTOL, StrideMap, interval_weights
from .task import (
    DEFAULT_DT,
    DEFAULT_RESET_NOISE_SCALE,
    PassiveBoundTask,
    TaskConfig,
    check_number,
)

BASES = ("windows", "phases", "hats")
DEFAULT_BASIS = "windows"
DEFAULT_K = 4  # basis functions of the default "windows" basis
HAT_SUBWINDOWS = 8  # sub-windows per knot interval of the "hats" basis
MAX_K = 64  # more basis functions than this is certainly a mistake
DEFAULT_STRIDE_RTOL = EVAL_RTOL  # integrator tolerance (relative and absolute)
DEFAULT_STRIDE_MAX_TORQUE = 80.0  # [N m], the saturation of the learned policies
NO_APEX_TIME = DEFAULT_T_MAX  # a stride without an apex within this time fails: 2 s
DEFAULT_CTRL_COST_WEIGHT = 0.1  # per stride, times mean(u^2)


@dataclass(frozen=True)
class TorqueBasis:
    """A piecewise-constant torque basis on the nominal stride (see the module docstring)."""

    name: str
    edges: np.ndarray  # (n_sub + 1,) sub-window edges [s] from the apex, edges[-1] = T
    phi: np.ndarray  # (n_sub, K) value of each basis function on each sub-window

    @property
    def K(self) -> int:
        return self.phi.shape[1]

    @property
    def period(self) -> float:
        """Nominal stride period T [s]."""
        return float(self.edges[-1])

    def torques(self, u, max_torque: float) -> np.ndarray:
        """Torque on each sub-window [N m] for the coefficients u (clipped to [-1, 1])."""
        return max_torque * (self.phi @ np.clip(np.asarray(u, dtype=float), -1.0, 1.0))

    def average(self, taus: np.ndarray, t0: float, t1: float) -> float:
        """Time average over [t0, t1] (from the apex) of the profile with sub-window torques
        ``taus``; the last sub-window holds past T."""
        if not t1 > t0:
            return float(
                taus[np.searchsorted(self.edges, t0, side="right") - 1]
                if t0 < self.edges[-1]
                else taus[-1]
            )
        lo = np.clip(self.edges[:-1], t0, t1)
        hi = np.clip(np.append(self.edges[1:-1], math.inf), t0, t1)
        return float(np.dot(taus, hi - lo) / (t1 - t0))

    def describe(self) -> dict:
        return {
            "basis": self.name,
            "K": self.K,
            "period": self.period,
            "edges": self.edges.tolist(),
        }


def nominal_stride(gait: Gait, z_ref=None, rtol: float = DEFAULT_STRIDE_RTOL):
    """The passive stride from z_ref (default the gait's z*) at the gait's parameters."""
    z = gait.z0 if z_ref is None else z_ref
    res = simulate_stride(z, gait.params, rtol=rtol, atol=rtol)
    if res.failure is not None:
        raise ValueError(
            f"the nominal stride of gait {gait.path.stem!r} fails "
            f"({res.failure}); no torque basis can be built on it"
        )
    return res


def make_basis(name: str, K: int | None, period: float, phase_durations=None) -> TorqueBasis:
    """A basis ``name`` (`BASES`) with K functions on a nominal stride of length ``period``
    (``phase_durations``: the nominal stance-condition durations, for ``"phases"``)."""
    if name not in BASES:
        raise ValueError(f"basis must be one of {BASES}, got {name!r}")
    if name == "phases":
        d = np.asarray(phase_durations, dtype=float)
        if K is not None and int(K) != len(d):
            raise ValueError(
                f"K={K} does not match basis 'phases': the nominal stride has "
                f"{len(d)} phases, so K must be {len(d)} (or omitted)"
            )
        edges = np.concatenate([[0.0], np.cumsum(d)])
        edges[-1] = period
        return TorqueBasis(name, edges, np.eye(len(d)))
    K = DEFAULT_K if K is None else K
    if isinstance(K, bool) or not isinstance(K, (int, np.integer)) or not 1 <= K <= MAX_K:
        raise ValueError(f"K must be an integer from 1 to {MAX_K}, got {K!r}")
    K = int(K)
    if name == "windows":
        return TorqueBasis(name, np.linspace(0.0, period, K + 1), np.eye(K))
    if K < 2:
        raise ValueError(f"basis 'hats' needs K >= 2 knots, got K={K}")
    n_sub = (K - 1) * HAT_SUBWINDOWS
    edges = np.linspace(0.0, period, n_sub + 1)
    knots = np.linspace(0.0, period, K)
    width = knots[1] - knots[0]
    # exact sub-window average of each hat: a fine midpoint rule is exact for a linear piece,
    # and sub-window edges coincide with knots, so each sub-window holds one linear piece
    mid = 0.5 * (edges[:-1] + edges[1:])
    phi = np.maximum(0.0, 1.0 - np.abs(mid[:, None] - knots[None, :]) / width)
    return TorqueBasis(name, edges, phi)


@dataclass
class StrideOutcome:
    """One controlled stride."""

    z1: np.ndarray | None  # next apex state (SI), None on a failure
    failure: str | None
    period: float  # [s] (time of the failure if one)
    effort: float  # mean |tau| over the stride [N m]
    y_end: np.ndarray  # full state at the end (the apex, or the last state before a failure)


class StrideSimulator:
    """The controlled stride map z1 = P(z, u) of a torque basis: the profile's interval
    averages on the step env's control grid (`bound_env.sim.stride_map.interval_weights`), through
    the one stride map (`bound_env.sim.stride_map.StrideMap`). No Gymnasium."""

    def __init__(self, stride_map: StrideMap, basis: TorqueBasis):
        self.stride_map = stride_map
        self.basis = basis
        self.max_torque = stride_map.max_torque
        self.rtol = stride_map.rtol
        self.dt = stride_map.dt
        self.W = interval_weights(basis.edges, basis.phi, self.dt)  # a = W u
        self.W_sub = interval_weights(basis.edges, np.eye(len(basis.edges) - 1), self.dt)

    @property
    def params(self):
        """The plant's parameters: its stride map's task's, read now (no copy)."""
        return self.stride_map.params

    def actions(self, U) -> np.ndarray:
        """Interval actions (n, n_intervals) of coefficient rows U (clipped to [-1, 1])."""
        return np.clip(np.atleast_2d(np.asarray(U, dtype=float)), -1.0, 1.0) @ self.W.T

    def run(self, z, u, slope: tuple | None = None) -> StrideOutcome:
        """One stride from apex state z (SI) with coefficients u (clipped to [-1, 1]).

        ``slope`` = (alpha_from, alpha_to) [rad], rough terrain: z is an apex state in the
        frame of a ground at alpha_from, which tilts to alpha_to at that apex
        (`bound_env.model.terrain.change_slope`); the stride runs on alpha_to. None: the
        parameters' slope, unchanged."""
        return self._one(z, self.actions(u)[0], slope)

    def run_torques(self, z, taus, slope: tuple | None = None) -> StrideOutcome:
        """One stride with the sub-window torques ``taus`` [N m] (as `run`)."""
        a = self.W_sub @ np.asarray(taus, dtype=float) / self.max_torque
        return self._one(z, a, slope)

    def _one(self, z, a, slope) -> StrideOutcome:
        z = np.asarray(z, dtype=float).reshape(6)
        r = self.stride_map.run(z[None], a[None], slopes=None if slope is None else [slope])
        return StrideOutcome(
            z1=r.z1[0].copy() if r.ok[0] else None,
            failure=r.failure(0),
            period=float(r.period[0]),
            effort=float(r.effort[0]),
            y_end=r.y_end[0].copy(),
        )

    def map(self, z, u) -> np.ndarray | None:
        return self.run(z, u).z1


@dataclass(frozen=True)
class StrideTaskConfig:
    """The stride task's settings: one field per keyword argument of PassiveBoundStride-v1
    (the env's docstring has their meaning and units). The plant's share of them is the step
    env's `bound_env.sim.task.TaskConfig` (`plant`), checked there; the basis is checked by
    `make_basis`, the reward weights by `StrideTask`."""

    gait: str | Path = "default"
    gait_overrides: dict | None = None
    basis: str = DEFAULT_BASIS
    K: int | None = None
    max_torque: float = DEFAULT_STRIDE_MAX_TORQUE
    reset_noise_scale: float = DEFAULT_RESET_NOISE_SCALE
    alive_reward: float = 1.0
    tracking_cost_weight: float = 1.0
    ctrl_cost_weight: float = DEFAULT_CTRL_COST_WEIGHT
    apex_scales: tuple | None = None
    rtol: float = DEFAULT_STRIDE_RTOL
    slope_noise_deg: float = 0.0
    dt: float = DEFAULT_DT

    def plant(self) -> TaskConfig:
        """The step env's settings of the same robot: the plant a stride advances."""
        return TaskConfig(
            gait=self.gait,
            gait_overrides=self.gait_overrides,
            dt=self.dt,
            max_torque=self.max_torque,
            reset_noise_scale=self.reset_noise_scale,
            alive_reward=self.alive_reward,
            tracking_cost_weight=self.tracking_cost_weight,
            ctrl_cost_weight=self.ctrl_cost_weight,
            apex_scales=self.apex_scales,
            rtol=self.rtol,
            slope_noise_deg=self.slope_noise_deg,
        )


STRIDE_TASK_SETTINGS = tuple(f.name for f in fields(StrideTaskConfig))


class StrideTask:
    """Configuration and logic of `bound_env.envs.stride_env.PassiveBoundStrideEnv`: a
    `StrideTaskConfig`, or its fields as keyword arguments. Reuses
    `bound_env.sim.task.PassiveBoundTask` (on the config's `plant`) for the gait, z*, the apex
    scales and the start state, so both envs start alike from the same seed."""

    def __init__(self, config: StrideTaskConfig | None = None, **settings):
        unknown = sorted(set(settings) - set(STRIDE_TASK_SETTINGS))
        if unknown:
            raise ValueError(
                f"unknown stride task setting(s) {unknown}; known: {STRIDE_TASK_SETTINGS}"
            )
        if config is None:
            config = StrideTaskConfig(**settings)
        elif settings:
            config = replace(config, **settings)
        self.config = config
        # the one holder of the plant: the start check, the slope draws and every stride read
        # its parameters (`set_params` changes them all)
        self.step_task = PassiveBoundTask(config.plant())  # (validates every number)
        self.slope_noise_deg = self.step_task.slope_noise_deg
        self.gait = self.step_task.gait
        self.z_ref = self.step_task.z_ref
        self.apex_scales = self.step_task.apex_scales
        self.max_torque = self.step_task.max_torque
        self.alive_reward = check_number("alive_reward", config.alive_reward, 0.0)
        self.tracking_cost_weight = check_number(
            "tracking_cost_weight", config.tracking_cost_weight, 0.0
        )
        self.ctrl_cost_weight = check_number("ctrl_cost_weight", config.ctrl_cost_weight, 0.0)
        self.rtol = check_number("rtol", config.rtol, 0.0, strict=True)
        # the nominal stride is the gait file's (without overrides), so that the basis, like
        # z*, is the same for every override of the same gait
        nominal = nominal_stride(load_gait(config.gait), rtol=self.rtol)
        self.basis = make_basis(config.basis, config.K, nominal.t_end, nominal.durations)
        self.dt = self.step_task.dt
        # the strides run on the step task itself (its plant, dt, max_torque and rtol; the
        # stride env draws the slopes of rough terrain per stride)
        self.sim = StrideSimulator(StrideMap(task=self.step_task), self.basis)

    @property
    def params(self):
        """The plant's parameters (the step task's, read now: `set_params` reaches them)."""
        return self.step_task.params

    def set_params(self, params) -> None:
        """Run from now on on the plant ``params`` (`bound_env.sim.task.PassiveBoundTask.set_params`
        of the one task that holds it): the next start check, slope draw and stride."""
        self.step_task.set_params(params)

    @property
    def K(self) -> int:
        return self.basis.K

    def start_state(self, rng, options=None) -> np.ndarray:
        return self.step_task.start_state(rng, options)

    def tracking_error(self, z) -> float:
        """sum_i ((z_i - z*_i) / s_i)^2."""
        return float(np.sum(((np.asarray(z) - self.z_ref) / self.apex_scales) ** 2))

    def rewards(self, z1, u, failed: bool) -> tuple[float, float, float]:
        """(alive, tracking, ctrl) of one stride with clipped coefficients u."""
        alive = 0.0 if failed else self.alive_reward
        tracking = 0.0 if z1 is None else -self.tracking_cost_weight * self.tracking_error(z1)
        ctrl = -self.ctrl_cost_weight * float(np.mean(np.square(u)))
        return alive, tracking + 0.0, ctrl + 0.0
