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
  ``on_apex(z, 0.0)``), bit for bit, for `bound_env.sim.stride_map.max_intervals` intervals, so
  that a closed loop can advance whole strides through the one stride map
  (`bound_env.sim.stride_map`) instead of one Python call per interval;
- ``planned_profile() -> (taus, t0) | None`` (a stride controller, optional): the torques of
  the profile planned at the last apex and the time since the apex it was announced at, as
  ``__call__`` reads them (None before the first apex), so that the copies of n robots act in
  one array (`bound_env.sim.stride_protocol.profile_rows`, bit for bit their calls; a step-level
  residual's bases).

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

# The loop side of the protocol lives beside the stride map (`bound_env.sim.stride_protocol`), so
# that `bound_env.analysis` needs nothing from here; re-exported for the controllers' users.
from ..sim.stride_protocol import (  # noqa: F401
    OBS_TH2DOT,
    OBS_TIME,
    OBS_Z,
    StridePlans,
    grid_times,
    interval_actions_of,
    interval_averages,
    notify_apex,
    observed_times,
    reset_controller,
)
from ..sim.stride_task import TorqueBasis


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

    def planned_profile(self):
        """(taus [N m], t0) of the last apex's profile, as ``__call__`` reads it (None before
        the first apex; `bound_env.sim.stride_protocol.profile_rows`)."""
        return None if self._taus is None else (self._taus, 0.0)

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
