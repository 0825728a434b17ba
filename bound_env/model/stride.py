"""The apex-to-apex stride: the Poincare map P (eq. 18) and the back-end switch.

`simulate_stride` starts at an apex state z (eq. 17), integrates with the *fast* back-end
(`bound_env.model.fast`, compiled) or the *reference* one (`bound_env.model.reference`,
solve_ivp), and returns a `StrideResult`: the next apex state, or a named failure (see
`bound_env.model.events`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .dynamics import make_aux, total_energy
from .events import APEX, F_NO_APEX, FL_STRICT, N_FLAGS, TIME_UP, failure_name
from .fast import simulate_fast
from .params import Z_IN_Y, Params, z_to_paper
from .reference import simulate_reference

DEFAULT_T_MAX = 2.0  # a stride with no apex within this time [s] fails with "no_apex"
_Z_IDX = np.array(Z_IN_Y)


def state_from_z(z) -> np.ndarray:
    """Full state y = [q, qdot] at an apex z (SI) with x_g = 0, ydot_g = 0 (eq. 17)."""
    y = np.zeros(8)
    y[_Z_IDX] = np.asarray(z, dtype=float).reshape(6)
    return y


def z_from_state(y) -> np.ndarray:
    """Apex coordinates z = [y_g, th1, th2, xdot_g, th1dot, th2dot] of a full state."""
    y = np.asarray(y, dtype=float)
    return y[_Z_IDX].copy()


@dataclass
class Trajectory:
    """A sampled stride: t [s], q, qdot (SI), stance condition name, total energy [J]."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    phase: list
    energy: np.ndarray


@dataclass
class StrideResult:
    """One apex-to-apex stride (the Poincare map P, eq. 18) or how it failed."""

    z0: np.ndarray
    z1: np.ndarray | None
    failure: str | None
    phases: list = field(default_factory=list)
    durations: list = field(default_factory=list)
    events: list = field(default_factory=list)
    energy0: float = math.nan
    energy1: float = math.nan
    t_end: float = math.nan
    y_end: np.ndarray | None = None
    trajectory: Trajectory | None = None

    @property
    def ok(self) -> bool:
        return self.failure is None

    def summary(self) -> dict:
        """Plain-JSON summary (z in paper units), as ``bound-env stride --json`` prints it."""
        return {
            "z0": [float(v) for v in z_to_paper(self.z0)],
            "z1": None if self.z1 is None else [float(v) for v in z_to_paper(self.z1)],
            "phases": list(self.phases),
            "durations": [float(d) for d in self.durations],
            "failure": self.failure,
            "energy": {"start": float(self.energy0), "end": float(self.energy1)},
            "period": float(self.t_end),
            "events": [{"t": e.t, "name": e.name, "phase": e.phase} for e in self.events],
        }


def phases_from_events(events: list, t_end: float) -> tuple[list, list]:
    """Phase names in order and their durations, merging events that did not change phase."""
    phases, starts = ["df"], [0.0]
    for e in events:
        if e.phase != phases[-1]:
            phases.append(e.phase)
            starts.append(e.t)
    durations = [b - a for a, b in zip(starts, starts[1:] + [t_end], strict=True)]
    return phases, durations


def simulate_stride(
    z0,
    params: Params,
    *,
    backend="fast",
    tau=0.0,
    strict=False,
    rtol=None,
    atol=None,
    t_max=DEFAULT_T_MAX,
    record_dt=None,
) -> StrideResult:
    """One stride of the Poincare map P (eq. 18) from the apex state ``z0`` (SI).

    ``backend`` is ``"fast"`` (compiled, default tolerances 1e-10) or ``"reference"``
    (solve_ivp DOP853, default tolerances 1e-12). ``strict=True`` ends the stride at the first
    apex after any touchdown instead of after both legs have been in stance. ``record_dt``
    (s) returns a sampled `Trajectory` plus every event state.
    """
    z0 = np.asarray(z0, dtype=float).reshape(6)
    y0 = state_from_z(z0)
    aux = make_aux(params.to_array(tau))
    flags = np.zeros(N_FLAGS, dtype=np.bool_)
    flags[FL_STRICT] = strict
    e0 = total_energy(y0, aux) if np.all(np.isfinite(y0)) else math.nan
    if backend == "reference":
        status, t, y, events, samples = simulate_reference(
            y0,
            aux,
            flags,
            t_end=t_max,
            rtol=rtol or 1e-12,
            atol=atol or 1e-12,
            record_dt=record_dt,
        )
    elif backend == "fast":
        status, t, y, events, samples = simulate_fast(
            y0,
            aux,
            flags,
            t_end=t_max,
            rtol=rtol or 1e-10,
            atol=atol or 1e-10,
            record_dt=record_dt,
        )
    else:
        raise ValueError(f"backend must be 'fast' or 'reference', got {backend!r}")
    if status == TIME_UP:
        status = F_NO_APEX
    z1 = z_from_state(y) if status == APEX else None
    phases, durations = phases_from_events(events, t)
    traj = None
    if record_dt is not None and samples:
        ts = np.array([s[0] for s in samples])
        ys = np.array([s[1] for s in samples])
        traj = Trajectory(
            ts, ys[:, :4], ys[:, 4:], [s[2] for s in samples], np.array([s[3] for s in samples])
        )
    return StrideResult(
        z0=z0,
        z1=z1,
        failure=failure_name(status),
        phases=phases,
        durations=durations,
        events=events,
        energy0=e0,
        energy1=total_energy(y, aux) if np.all(np.isfinite(y)) else math.nan,
        t_end=t,
        y_end=y,
        trajectory=traj,
    )
