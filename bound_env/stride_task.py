"""The stride-level task: one step = one apex-to-apex stride under a spine-torque profile.

This is the task layer of `bound_env.stride_env.PassiveBoundStrideEnv` and of the stride-level
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

Event-accurate application
--------------------------
The compiled simulator (`bound_env.fast.advance`) integrates with the torque as an entry of the
parameter vector (``aux[P_TAU]``). `run_profile` advances it piecewise: to each sub-window edge
with that window's torque, stopping at the apex, so contacts and the apex are located on the
integrator's dense output and a torque change never falls inside an integrator step.
Consecutive sub-windows with equal torque are merged first, so zero action is a single call,
the same one `bound_env.stride.simulate_stride` makes: zero action is exactly the passive map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dynamics import jit, make_aux
from .events import APEX, F_NO_APEX, N_FLAGS, TIME_UP, failure_name
from .fast import EVENT_CAPACITY, Options, advance, event_log, recorder
from .params import P_TAU, Gait, load_gait
from .stride import DEFAULT_T_MAX, simulate_stride, state_from_z, z_from_state
from .task import DEFAULT_RESET_NOISE_SCALE, PassiveBoundTask, check_number
from .terrain import change_slope, set_slope

BASES = ("windows", "phases", "hats")
DEFAULT_BASIS = "windows"
DEFAULT_K = 4  # basis functions of the default "windows" basis
HAT_SUBWINDOWS = 8  # sub-windows per knot interval of the "hats" basis
MAX_K = 64  # more basis functions than this is certainly a mistake
DEFAULT_STRIDE_RTOL = 1e-10  # integrator tolerance (relative and absolute), as simulate_stride
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


@jit
def run_profile(
    y,
    aux,
    flags,
    t_edges,
    taus,
    rtol,
    atol,
    t_max,
    log,
    rec,
):
    """Advance from an apex (t = 0) to the next apex with torque taus[j] on [t_edges[j],
    t_edges[j + 1]) and the last torque held until ``t_max``.

    ``y``, ``aux`` and ``flags`` are updated in place. Returns (status, t, impulse) with
    impulse = integral of |tau| dt [N m s] over the stride.
    """
    t = 0.0
    h = 0.0
    opts = Options(rtol, atol, True)
    impulse = 0.0
    status = TIME_UP
    n = taus.shape[0]
    for j in range(n):
        t_end = t_edges[j + 1] if j < n - 1 else t_max
        aux[P_TAU] = taus[j]
        status, t_new, h = advance(y, aux, flags, t, t_end, h, opts, log, rec)
        impulse += abs(taus[j]) * (t_new - t)
        t = t_new
        if status != TIME_UP:
            break
    if status == TIME_UP:
        status = F_NO_APEX
    return status, t, impulse


def merge_windows(edges: np.ndarray, taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop sub-window edges between equal torques (zero action becomes one window)."""
    keep = np.flatnonzero(np.diff(taus) != 0.0) + 1
    return np.concatenate([[0.0], edges[keep], [edges[-1]]]), taus[np.concatenate([[0], keep])]


@dataclass
class StrideOutcome:
    """One controlled stride."""

    z1: np.ndarray | None  # next apex state (SI), None on a failure
    failure: str | None
    period: float  # [s] (time of the failure if one)
    effort: float  # mean |tau| over the stride [N m]
    y_end: np.ndarray  # full state at the end (the apex, or the last state before a failure)


class StrideSimulator:
    """The controlled stride map z1 = P(z, u) for one parameter set (no Gymnasium)."""

    def __init__(
        self,
        params,
        basis: TorqueBasis,
        max_torque: float,
        rtol: float = DEFAULT_STRIDE_RTOL,
        t_max: float = NO_APEX_TIME,
    ):
        self.params = params
        self.basis = basis
        self.max_torque = float(max_torque)
        self.rtol = float(rtol)
        self.t_max = float(t_max)
        self._aux0 = make_aux(params.to_array())
        self._log = event_log(EVENT_CAPACITY, np.empty((1, 8)))
        self._rec = recorder(0, 0.0)

    def run(self, z, u) -> StrideOutcome:
        """One stride from apex state z (SI) with coefficients u (clipped to [-1, 1])."""
        return self.run_torques(z, self.basis.torques(u, self.max_torque))

    def run_torques(self, z, taus, slope: tuple | None = None) -> StrideOutcome:
        """One stride with the sub-window torques ``taus`` [N m] (any values).

        ``slope`` = (alpha_from, alpha_to) [rad], rough terrain: z is an apex state in the
        frame of a ground at alpha_from, which tilts to alpha_to at that apex
        (`bound_env.terrain.change_slope`); the stride runs on alpha_to. None: the
        parameters' slope, unchanged."""
        y = state_from_z(np.asarray(z, dtype=float).reshape(6))
        aux = self._aux0.copy()
        if slope is not None:
            set_slope(aux, slope[0])
            change_slope(y, aux, slope[1] - slope[0])
        flags = np.zeros(N_FLAGS, dtype=np.bool_)
        edges, taus = merge_windows(self.basis.edges, np.asarray(taus, dtype=float))
        status, t, impulse = run_profile(
            y,
            aux,
            flags,
            edges,
            taus,
            self.rtol,
            self.rtol,
            self.t_max,
            self._log,
            self._rec,
        )
        ok = status == APEX
        return StrideOutcome(
            z1=z_from_state(y) if ok else None,
            failure=None if ok else failure_name(status),
            period=float(t),
            effort=float(impulse / t) if t > 0.0 else 0.0,
            y_end=y,
        )

    def map(self, z, u) -> np.ndarray | None:
        return self.run(z, u).z1


class StrideTask:
    """Configuration and logic of `bound_env.stride_env.PassiveBoundStrideEnv` (its docstring
    lists the arguments). Reuses `bound_env.task.PassiveBoundTask` for the gait, z*, the
    apex scales and the start state, so both envs start alike from the same seed."""

    def __init__(
        self,
        gait: str = "default",
        gait_overrides: dict | None = None,
        basis: str = DEFAULT_BASIS,
        K: int | None = None,
        max_torque: float = DEFAULT_STRIDE_MAX_TORQUE,
        reset_noise_scale: float = DEFAULT_RESET_NOISE_SCALE,
        alive_reward: float = 1.0,
        tracking_cost_weight: float = 1.0,
        ctrl_cost_weight: float = DEFAULT_CTRL_COST_WEIGHT,
        apex_scales=None,
        rtol: float = DEFAULT_STRIDE_RTOL,
        slope_noise_deg: float = 0.0,
    ):
        self.step_task = PassiveBoundTask(
            gait=gait,
            gait_overrides=gait_overrides,
            max_torque=max_torque,
            reset_noise_scale=reset_noise_scale,
            alive_reward=alive_reward,
            tracking_cost_weight=tracking_cost_weight,
            ctrl_cost_weight=ctrl_cost_weight,
            apex_scales=apex_scales,
            rtol=rtol,
            slope_noise_deg=slope_noise_deg,
        )  # (validates every number)
        self.slope_noise_deg = self.step_task.slope_noise_deg
        self.gait = self.step_task.gait
        self.params = self.step_task.params
        self.z_ref = self.step_task.z_ref
        self.apex_scales = self.step_task.apex_scales
        self.max_torque = self.step_task.max_torque
        self.alive_reward = check_number("alive_reward", alive_reward, 0.0)
        self.tracking_cost_weight = check_number("tracking_cost_weight", tracking_cost_weight, 0.0)
        self.ctrl_cost_weight = check_number("ctrl_cost_weight", ctrl_cost_weight, 0.0)
        self.rtol = check_number("rtol", rtol, 0.0, strict=True)
        # the nominal stride is the gait file's (without overrides), so that the basis, like
        # z*, is the same for every override of the same gait
        nominal = nominal_stride(load_gait(gait), rtol=self.rtol)
        self.basis = make_basis(basis, K, nominal.t_end, nominal.durations)
        self.sim = StrideSimulator(self.params, self.basis, self.max_torque, self.rtol)

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
