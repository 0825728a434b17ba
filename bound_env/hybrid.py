"""The apex-to-apex stride and the reference back-end (``scipy.integrate.solve_ivp``, DOP853).

Guards, resets, status codes and stride flags live in `bound_env.events` (re-exported here);
the fast back-end is `bound_env.fast`. `simulate_stride` switches between the two.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .dynamics import make_aux, rhs, total_energy
from .events import (  # noqa: F401  (re-exported: the documented names of this module)
    APEX,
    CONTINUE,
    EVENT_COINCIDENCE,
    F_BACKWARD,
    F_EXT_B,
    F_EXT_F,
    F_GROUND_B,
    F_GROUND_F,
    F_GROUND_J,
    F_INTEGRATION,
    F_NO_APEX,
    F_NON_FINITE,
    F_SHORT_B,
    F_SHORT_F,
    FAIL_FIRST,
    FAILURES,
    FL_STRICT,
    FL_TOUCHED_B,
    FL_TOUCHED_F,
    G_APEX,
    G_BACKWARD,
    G_GROUND_B,
    G_GROUND_F,
    G_GROUND_J,
    G_LO_B,
    G_LO_F,
    G_SHORT_B,
    G_SHORT_F,
    G_TD_B,
    G_TD_F,
    GUARD_DIRECTION,
    GUARD_NAMES,
    N_FLAGS,
    N_GUARDS,
    PHASES,
    TIME_UP,
    Event,
    apex_armed,
    apply_events,
    coincident,
    failure_name,
    guard_values,
    phase_index,
    start_status,
)
from .fast import simulate_fast
from .params import Params

DEFAULT_T_MAX = 2.0  # a stride with no apex within this time [s] fails with "no_apex"


def state_from_z(z) -> np.ndarray:
    """Full state y = [q, qdot] at an apex z (SI) with x_g = 0, ydot_g = 0 (eq. 17)."""
    z = np.asarray(z, dtype=float)
    return np.array([0.0, z[0], z[1], z[2], z[3], 0.0, z[4], z[5]])


def z_from_state(y) -> np.ndarray:
    """Apex coordinates z = [y_g, th1, th2, xdot_g, th1dot, th2dot] of a full state."""
    y = np.asarray(y, dtype=float)
    return y[[1, 2, 3, 4, 6, 7]].copy()


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
        from .params import z_to_paper

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


# --------------------------------------------------------------------------------------------
# Reference back-end: scipy.integrate.solve_ivp (DOP853) with event functions.
# --------------------------------------------------------------------------------------------


# Bounds of one reference stride, the same as the fast back-end's (`bound_env.fast`), so that
# neither back-end can hang: a stiff or degenerate model ends as "integration_failed".
REFERENCE_MAX_STEPS = 200_000  # accepted steps over the whole stride
REFERENCE_H_MIN = 1e-14  # smallest step [s]
REFERENCE_WALL_S = 10.0  # wall-clock guard [s] per stride (a normal stride takes ~6 ms)


class _OverBudget(Exception):
    """Raised inside the right-hand side when a reference stride passes its wall-clock guard."""


def _bounded_dop853(budget: dict):
    """scipy's DOP853 that fails (``integration_failed``) past the bounds above."""
    from scipy.integrate import DOP853

    class BoundedDOP853(DOP853):
        def _step_impl(self):
            ok, message = super()._step_impl()
            budget["steps"] += 1
            if not ok:
                return ok, message
            if budget["steps"] > REFERENCE_MAX_STEPS:
                return False, f"more than {REFERENCE_MAX_STEPS} steps"
            if self.h_abs < REFERENCE_H_MIN:
                return False, f"step below {REFERENCE_H_MIN:g} s"
            return True, None

    return BoundedDOP853


def _warm_up(y, aux, flags) -> None:
    """Call every compiled function of the reference loop once on copies (compiling or loading
    them), so that the wall-clock guard measures integration only."""
    y, aux, flags = y.copy(), aux.copy(), flags.copy()
    g, fired = np.zeros(N_GUARDS), np.zeros(N_GUARDS, dtype=np.bool_)
    rhs(0.0, y, aux, np.empty(8))
    guard_values(y, aux, flags, g)
    coincident(g, g, fired)
    apply_events(y, aux, flags, fired)
    total_energy(y, aux)
    phase_index(aux)


def _events_for(aux, flags):
    """solve_ivp event functions for the guards of the current condition (all terminal)."""
    buf = np.empty(N_GUARDS)
    evs = []
    for i in range(N_GUARDS):

        def ev(t, y, i=i):
            guard_values(y, aux, flags, buf)
            return buf[i]

        ev.terminal = True
        ev.direction = float(GUARD_DIRECTION[i])
        evs.append(ev)
    return evs


def simulate_reference(
    y0, aux, flags, t0=0.0, t_end=DEFAULT_T_MAX, stop_at_apex=True,
    rtol=1e-12, atol=1e-12, record_dt=None,
):  # fmt: skip
    """Integrate the hybrid system from (t0, y0) until the apex (or t_end) with solve_ivp.

    ``aux`` and ``flags`` are updated in place. Returns (status, t, y, events, samples) where
    samples is a list of (t, y, phase) when ``record_dt`` is given.
    """
    from scipy.integrate import solve_ivp

    y = np.array(y0, dtype=float)
    t = float(t0)
    events, samples = [], []
    g, g_before = np.empty(N_GUARDS), np.empty(N_GUARDS)
    status = start_status(y, aux)
    if status != CONTINUE:
        return status, t, y, events, samples
    if record_dt is not None:
        samples.append((t, y.copy(), PHASES[phase_index(aux)], total_energy(y, aux)))
    out = np.empty(8)

    _warm_up(y, aux, flags)  # compiled code is loaded before the wall-clock guard starts
    budget = {"steps": 0, "evals": 0, "deadline": time.perf_counter() + REFERENCE_WALL_S}

    def f(t, y):
        budget["evals"] += 1
        if budget["evals"] % 128 == 0 and time.perf_counter() > budget["deadline"]:
            raise _OverBudget
        rhs(t, y, aux, out)
        return out.copy()

    method = _bounded_dop853(budget)
    for _ in range(10_000):  # bound on the number of transitions
        evs = _events_for(aux, flags)
        y0_seg = y
        try:
            sol = solve_ivp(
                f, (t, t_end), y, method=method, rtol=rtol, atol=atol, events=evs,
                dense_output=record_dt is not None,
            )  # fmt: skip
        except _OverBudget:
            return F_INTEGRATION, t, y, events, samples
        if sol.status < 0:
            return F_INTEGRATION, t, y, events, samples
        t_new, y_new = float(sol.t[-1]), sol.y[:, -1].copy()
        if record_dt is not None:
            ts = np.arange(t + record_dt, t_new, record_dt)
            ph = PHASES[phase_index(aux)]
            for ti in ts:
                yi = sol.sol(ti)
                samples.append((float(ti), yi, ph, total_energy(yi, aux)))
        t, y = t_new, y_new
        if not np.all(np.isfinite(y)):
            return F_NON_FINITE, t, y, events, samples
        if sol.status == 0:  # reached t_end
            return TIME_UP, t, y, events, samples
        fired = np.zeros(N_GUARDS, dtype=np.bool_)
        for i, te in enumerate(sol.t_events):
            if len(te):
                fired[i] = True
        guard_values(sol.y[:, -2] if sol.y.shape[1] > 1 else y0_seg, aux, flags, g_before)
        guard_values(y, aux, flags, g)
        coincident(g_before, g, fired)
        if not stop_at_apex:
            fired[G_APEX] = False
        status = apply_events(y, aux, flags, fired)
        ph = PHASES[phase_index(aux)]
        for i in np.flatnonzero(fired):
            events.append(Event(t, GUARD_NAMES[i], ph))
        if record_dt is not None:
            samples.append((t, y.copy(), ph, total_energy(y, aux)))
        if status != CONTINUE:
            return status, t, y, events, samples
    return F_INTEGRATION, t, y, events, samples


def simulate_stride(
    z0, params: Params, *, backend="fast", tau=0.0, strict=False, rtol=None, atol=None,
    t_max=DEFAULT_T_MAX, record_dt=None,
) -> StrideResult:  # fmt: skip
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
            y0, aux, flags, t_end=t_max, rtol=rtol or 1e-12, atol=atol or 1e-12,
            record_dt=record_dt,
        )  # fmt: skip
    elif backend == "fast":
        status, t, y, events, samples = simulate_fast(
            y0, aux, flags, t_end=t_max, rtol=rtol or 1e-10, atol=atol or 1e-10,
            record_dt=record_dt,
        )  # fmt: skip
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
        traj = Trajectory(ts, ys[:, :4], ys[:, 4:], [s[2] for s in samples],
                          np.array([s[3] for s in samples]))
    return StrideResult(
        z0=z0, z1=z1, failure=failure_name(status), phases=phases, durations=durations,
        events=events, energy0=e0,
        energy1=total_energy(y, aux) if np.all(np.isfinite(y)) else math.nan,
        t_end=t, y_end=y, trajectory=traj,
    )  # fmt: skip
