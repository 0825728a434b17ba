"""Classical spine controllers: stride-to-stride feedback (LQR, deadbeat) and extra damping.

Protocol (what `bound_env.analysis.margins.ClosedLoop` and any other loop over the *unwrapped*
PassiveBound-v0 env use):

- ``__call__(obs) -> float``: the normalized action of the next control interval;
- ``on_apex(z, time_since_apex)`` (optional): called with the apex state z (SI, float64) at
  every apex: after a reset onto an apex with 0.0, and after each step whose info has
  ``"apex_z"``, with the time elapsed since that apex at the end of the step [s];
- ``stateful`` and ``reset()`` (optional): a controller with memory across strides (e.g.
  `bound_env.control.offset_free.OffsetFree`) forgets its episode in ``reset()``, which the
  loops call at each start (`reset_controller`); it has no stateless ``interval_actions``;
- ``fingerprint() -> str``, ``name``, ``env_kwargs`` (the env keyword arguments the controller
  was designed for: gait, max_torque, dt);
- ``interval_actions(Z) -> A`` (a stride controller): for n apex states at once, the actions
  ``__call__`` outputs on each control interval of the stride from each (after
  ``on_apex(z, 0.0)``), bit for bit, for `bound_env.stride_map.max_intervals` intervals, so
  that a closed loop can advance whole strides through the one stride map
  (`bound_env.stride_map`) instead of one Python call per interval.

A stride-level controller chooses the coefficients u = sat(-G (z - z*)) in ``on_apex`` and then
outputs its torque profile tau(t) = max_torque * sum_i u_i phi_i(t). The step env holds the
torque constant over each control interval [t, t + dt] (t since the apex); the controller
outputs the **interval average** of tau(t) there, so each interval delivers the profile's
impulse exactly and the step-env closed loop stays close to the stride-env one (the torque is
only redistributed within the intervals that straddle a window edge). In the stride env
(`PassiveBoundStride-v1`) the same controller acts through ``stride_action(z)``.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from ..stride_map import max_intervals
from ..stride_task import TorqueBasis
from ..task import OBS_NAMES

# indices in the default (x_g excluded) PassiveBound-v0 observation
OBS_TIME = OBS_NAMES[1:].index("time_since_apex")
OBS_TH2DOT = OBS_NAMES[1:].index("theta2dot")
OBS_Z = tuple(
    OBS_NAMES[1:].index(n) for n in ("y_g", "theta1", "theta2", "xdot_g", "theta1dot", "theta2dot")
)


def observed_times(dt: float) -> np.ndarray:
    """The time since the apex a stride controller reads on control interval k of a stride
    (the observation's, rounded to float32), k < `max_intervals` (dt)."""
    return np.float32(dt * np.arange(max_intervals(dt))).astype(float)


def grid_times(dt: float) -> np.ndarray:
    """The start k dt of control interval k of a stride (the MPC snaps the observed time
    to it), k < `max_intervals` (dt)."""
    return dt * np.arange(max_intervals(dt))


def interval_averages(basis: TorqueBasis, taus, t0, dt: float) -> np.ndarray:
    """basis.average(taus[i], t0[i, j], t0[i, j] + dt) for each row of ``taus`` (n, n_sub)
    and each time of row i of ``t0`` (broadcast to (n, m)), bit for bit as the scalar path
    (elementwise products, and at most two non-zero terms per interval for sub-windows wider
    than dt, so the order of the sums cannot matter)."""
    taus = np.atleast_2d(np.asarray(taus, dtype=float))
    t0 = np.atleast_2d(np.asarray(t0, dtype=float))
    t1 = t0 + dt
    lo = np.clip(basis.edges[:-1], t0[..., None], t1[..., None])
    hi = np.clip(np.append(basis.edges[1:-1], np.inf), t0[..., None], t1[..., None])
    return (taus[:, None, :] * (hi - lo)).sum(axis=-1) / (t1 - t0)


def interval_actions_of(basis: TorqueBasis, max_torque: float, U, times, dt: float) -> np.ndarray:
    """(n, len(times)): clip(basis.average(tau_i, t, t + dt) / max_torque, -1, 1) for the
    profile tau_i = basis.torques(U[i], max_torque) of each row of U and each t of ``times``,
    bit for bit as a stride controller's ``__call__`` computes it (`interval_averages`)."""
    taus = np.array([basis.torques(u, max_torque) for u in np.atleast_2d(U)])
    avg = interval_averages(basis, taus, np.asarray(times, dtype=float)[None, :], dt)
    return np.clip(avg / max_torque, -1.0, 1.0)


class StridePlans:
    """The stride plans of n robots under one stride controller, for loops that step many
    robots through the step env at once (long episodes, `bound_env.stride_map.to_next_apex`):
    each robot's profile, chosen at its last apex (``apex``), and the time since that apex it
    was announced at. The controller provides ``apex_torques(z)`` (the profile it plans at z,
    as ``on_apex`` stores it), ``snaps_time`` (whether it reads its profile at the observed
    time or snaps it to the apex's interval grid), ``basis``, ``max_torque`` and ``dt``."""

    def __init__(self, controller, n: int):
        self.ctrl = controller
        self.taus = np.zeros((n, controller.basis.phi.shape[0]))
        self.t0 = np.zeros(n)

    def apex(self, i: int, z, time_since_apex: float = 0.0) -> None:
        self.taus[i] = self.ctrl.apex_torques(np.asarray(z, dtype=float))
        self.t0[i] = time_since_apex


def reset_controller(controller) -> None:
    """Forget a stateful controller's episode (``reset()``, e.g. `OffsetFree`'s estimate): the
    loops call it at the start of each episode; memoryless controllers are left alone."""
    reset = getattr(controller, "reset", None)
    if getattr(controller, "stateful", False) and callable(reset):
        reset()


def notify_apex(controller, obs, info) -> None:
    """The loop side of the ``on_apex`` protocol, for any rollout of PassiveBound-v0: call it
    after ``reset`` and after every ``step`` with that call's observation and info. It calls
    ``controller.on_apex`` when the info marks an apex (``start_z`` after a reset, ``apex_z``
    after a step); controllers without ``on_apex`` are left alone."""
    on_apex = getattr(controller, "on_apex", None)
    if on_apex is None:
        return
    if "apex_z" in info:
        on_apex(np.asarray(info["apex_z"], dtype=float), float(obs[OBS_TIME]))
    elif "start_z" in info:
        on_apex(np.asarray(info["start_z"], dtype=float), 0.0)


@dataclass
class StrideFeedback:
    """u = sat(-G (z - z*)), chosen once per stride at the apex (LQR, deadbeat)."""

    name: str
    kind: str  # "lqr" or "deadbeat"
    gain: np.ndarray  # G, (K, 6), SI: u per unit apex error
    z_ref: np.ndarray  # z* (SI)
    basis: TorqueBasis
    max_torque: float  # [N m] at |u_i| = 1
    dt: float = 0.01  # control interval of the step env [s]
    gait: str = "default"
    design: dict = field(default_factory=dict)  # A, B, Q, R, spectral radii (for reports)
    _taus: np.ndarray | None = field(default=None, repr=False)

    @property
    def env_kwargs(self) -> dict:
        return {"gait": self.gait, "max_torque": self.max_torque, "dt": self.dt}

    @property
    def stride_env_kwargs(self) -> dict:
        """Keyword arguments of PassiveBoundStride-v1 with the same basis and saturation."""
        return {
            "gait": self.gait,
            "basis": self.basis.name,
            "K": self.basis.K,
            "max_torque": self.max_torque,
        }

    def coefficients(self, z) -> np.ndarray:
        """u = clip(-G (z - z*), -1, 1)."""
        dz = np.asarray(z, dtype=float) - self.z_ref
        return np.clip(-(self.gain @ dz), -1.0, 1.0)

    def stride_action(self, z) -> np.ndarray:
        """The action of PassiveBoundStride-v1 at apex state z."""
        return self.coefficients(z)

    def plan(self, Z) -> np.ndarray:
        """The coefficients for n apex states at once, (n, K) for Z (n, 6) (one matrix
        product: equal to `coefficients` row by row to rounding); (K,) for one state."""
        Z = np.asarray(Z, dtype=float)
        if Z.ndim == 1:
            return self.coefficients(Z)
        return np.clip(-((Z - self.z_ref) @ self.gain.T), -1.0, 1.0)

    def interval_actions(self, Z) -> np.ndarray:
        """The step env's actions of the strides from the apex states Z (module docstring)."""
        U = [self.coefficients(z) for z in np.atleast_2d(Z)]
        return interval_actions_of(self.basis, self.max_torque, U, observed_times(self.dt), self.dt)

    def apex_torques(self, z) -> np.ndarray:
        """The profile planned at apex state z: torque on each sub-window [N m]."""
        return self.basis.torques(self.coefficients(z), self.max_torque)

    snaps_time = False  # the profile is read at the observed (float32) time since the apex

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self._taus = self.apex_torques(z)

    def __call__(self, obs) -> float:
        t = float(obs[OBS_TIME])
        if self._taus is None:  # no apex announced yet: the observation at a reset is one
            z = np.asarray(obs, dtype=float)[list(OBS_Z)]
            self.on_apex(z, t)
        tau = self.basis.average(self._taus, t, t + self.dt)
        return float(np.clip(tau / self.max_torque, -1.0, 1.0))

    def fingerprint(self) -> str:
        h = hashlib.sha256(self.kind.encode())
        for a in (self.gain, self.z_ref, self.basis.edges, self.basis.phi):
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
        h.update(repr((self.max_torque, self.dt, self.gait)).encode())
        return h.hexdigest()[:16]

    def __getstate__(self):  # the per-stride profile is not part of the controller
        state = dict(self.__dict__)
        state["_taus"] = None
        return state


@dataclass
class DampingFeedback:
    """Extra spine damping tau = -c theta2dot, per control interval (saturated)."""

    name: str
    c: float  # [N m s/rad]
    max_torque: float
    dt: float = 0.01
    gait: str = "default"

    @property
    def env_kwargs(self) -> dict:
        return {"gait": self.gait, "max_torque": self.max_torque, "dt": self.dt}

    def __call__(self, obs) -> float:
        return float(np.clip(-self.c * float(obs[OBS_TH2DOT]) / self.max_torque, -1.0, 1.0))

    def batch(self, obs) -> np.ndarray:
        """The actions for a batch of observations (one row each), as ``__call__`` row by
        row (the same elementwise operations)."""
        x = np.asarray(obs)[:, OBS_TH2DOT].astype(float)
        return np.clip(-self.c * x / self.max_torque, -1.0, 1.0)

    def fingerprint(self) -> str:
        return hashlib.sha256(
            repr(("damping", self.c, self.max_torque, self.dt, self.gait)).encode()
        ).hexdigest()[:16]
