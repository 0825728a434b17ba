"""Reference back-end: ``scipy.integrate.solve_ivp`` (DOP853) with one event function per guard.

It integrates and locates the guards' zero crossings; what a crossing means (resets, failures,
the end of a stride) is decided by `bound_env.model.events`, exactly as in the fast back-end
(`bound_env.model.fast`). Slow but independent of the compiled integrator: the tests compare the
two.
"""

from __future__ import annotations

import time

import numpy as np

from .dynamics import rhs, total_energy
from .events import (
    APEX,
    CONTINUE,
    F_INTEGRATION,
    F_NON_FINITE,
    GUARD_DIRECTION,
    GUARD_NAMES,
    N_GUARDS,
    PHASES,
    TIME_UP,
    Event,
    apply_events,
    coincident,
    guard_values,
    phase_index,
    start_status,
)

MAX_TRANSITIONS = 10_000  # bound on the number of solve_ivp restarts (one per transition)

# Bounds of one reference stride, the same as the fast back-end's (`bound_env.model.fast`), so that
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
    y0,
    aux,
    flags,
    t0=0.0,
    t_end=2.0,
    stop_at_apex=True,
    rtol=1e-12,
    atol=1e-12,
    record_dt=None,
    apexes=None,
):
    """Integrate the hybrid system from (t0, y0) until the apex (or t_end) with solve_ivp.

    ``aux`` and ``flags`` are updated in place. With ``stop_at_apex`` false an apex ends a
    stride and the integration goes on to ``t_end``, as in `bound_env.model.fast.advance`; the
    apex states are appended to the list ``apexes`` when one is given. Returns (status, t, y,
    events, samples) where samples is a list of (t, y, phase, energy) when ``record_dt`` is
    given.
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
    for _ in range(MAX_TRANSITIONS):
        evs = _events_for(aux, flags)
        y0_seg = y
        try:
            sol = solve_ivp(
                f,
                (t, t_end),
                y,
                method=method,
                rtol=rtol,
                atol=atol,
                events=evs,
                dense_output=record_dt is not None,
            )
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
        status = apply_events(y, aux, flags, fired)
        ph = PHASES[phase_index(aux)]
        for i in np.flatnonzero(fired):
            events.append(Event(t, GUARD_NAMES[i], ph))
        if record_dt is not None:
            samples.append((t, y.copy(), ph, total_energy(y, aux)))
        if status == APEX and not stop_at_apex:
            if apexes is not None:
                apexes.append(y.copy())
            continue
        if status != CONTINUE:
            return status, t, y, events, samples
    return F_INTEGRATION, t, y, events, samples
