"""Classical spine controllers: stride-to-stride feedback (LQR, deadbeat) and extra damping.

Protocol (what `bound_env.analysis.margins.ClosedLoop` and any other loop over the *unwrapped*
PassiveBound-v0 env use):

- ``__call__(obs) -> float``: the normalized action of the next control interval;
- ``on_apex(z, time_since_apex)`` (optional): called with the apex state z (SI, float64) at
  every apex: after a reset onto an apex with 0.0, and after each step whose info has
  ``"apex_z"``, with the time elapsed since that apex at the end of the step [s];
- ``fingerprint() -> str``, ``name``, ``env_kwargs`` (the env keyword arguments the controller
  was designed for: gait, max_torque, dt).

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

from ..stride_task import TorqueBasis
from ..task import OBS_NAMES

# indices in the default (x_g excluded) PassiveBound-v0 observation
OBS_TIME = OBS_NAMES[1:].index("time_since_apex")
OBS_TH2DOT = OBS_NAMES[1:].index("theta2dot")
OBS_Z = tuple(
    OBS_NAMES[1:].index(n) for n in ("y_g", "theta1", "theta2", "xdot_g", "theta1dot", "theta2dot")
)


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

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self._taus = self.basis.torques(self.coefficients(z), self.max_torque)

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

    def fingerprint(self) -> str:
        return hashlib.sha256(
            repr(("damping", self.c, self.max_torque, self.dt, self.gait)).encode()
        ).hexdigest()[:16]
