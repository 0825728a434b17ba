"""Fast back-end: the whole hybrid loop compiled with Numba.

Adaptive DOP853 steps (`bound_env._dop853`), guard sign changes checked after every accepted
step, each crossing located as a root of its guard on the step's 7th-order dense output,
resets applied by the same compiled `bound_env.events.apply_events` the reference back-end
uses. No Python runs between the start and the end of a stride (or of a control interval).
"""

from __future__ import annotations

import math

import numpy as np

from ._dop853 import (
    INTERPOLATOR_POWER,
    N_STAGES_EXTENDED,
    dense_eval,
    make_dop853,
    step_factor,
)
from .dynamics import jit, rhs, total_energy
from .events import (
    APEX,
    CONTINUE,
    F_INTEGRATION,
    F_NON_FINITE,
    FL_TOUCHED_B,
    FL_TOUCHED_F,
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

_ode = make_dop853(rhs)  # DOP853 compiled for the model's right-hand side
rk_step, dense_prepare, initial_step = _ode.rk_step, _ode.dense_prepare, _ode.initial_step

MAX_STEPS = 200_000  # accepted + rejected steps in one call; beyond that: integration_failed
ROOT_ITERATIONS = 60  # bound on the root finder's iterations per guard
EVENT_CAPACITY = 256  # events logged per call
H_MIN = 1e-14  # smallest step [s] before the integration is declared failed


@jit
def _guard_at(t, F, y_old, t_old, h, aux, flags, i, ybuf, gbuf):
    dense_eval(F, y_old, t_old, h, t, ybuf)
    guard_values(ybuf, aux, flags, gbuf)
    return gbuf[i]


@jit
def _locate(i, t_a, g_a, t_b, g_b, F, y_old, t_old, h, aux, flags, ybuf, gbuf):
    """Root of guard i in [t_a, t_b] on the dense output: Illinois false position, with
    bisection when it stalls; returns the end of the final bracket on the firing side."""
    side = 0
    for _ in range(ROOT_ITERATIONS):
        if t_b - t_a <= 4e-16 * max(1.0, abs(t_b)):
            break
        t_c = (t_a * g_b - t_b * g_a) / (g_b - g_a)
        if not (t_a < t_c < t_b):
            t_c = 0.5 * (t_a + t_b)
        g_c = _guard_at(t_c, F, y_old, t_old, h, aux, flags, i, ybuf, gbuf)
        if GUARD_DIRECTION[i] * g_c >= 0.0:  # firing side
            t_b, g_b = t_c, g_c
            if side == 1:
                g_a *= 0.5
            side = 1
        else:
            t_a, g_a = t_c, g_c
            if side == -1:
                g_b *= 0.5
            side = -1
        if g_c == 0.0:
            break
    return t_b


@jit
def _record(t, y, aux, rec_t, rec_y, rec_ph, rec_e, n_rec):
    if n_rec < rec_t.shape[0]:
        rec_t[n_rec] = t
        rec_y[n_rec, :] = y
        rec_ph[n_rec] = phase_index(aux)
        rec_e[n_rec] = total_energy(y, aux)
        return n_rec + 1
    return n_rec


@jit
def advance(
    y, aux, flags, t, t_end, stop_at_apex, rtol, atol, h,
    ev_t, ev_g, ev_ph, apex_y, rec_dt, rec_t, rec_y, rec_ph, rec_e,
):  # fmt: skip
    """Integrate the hybrid system from (t, y) to the apex (if ``stop_at_apex``) or t_end.

    ``y``, ``aux`` (contacts, toes) and ``flags`` are updated in place. Events are logged in
    ``ev_t, ev_g, ev_ph`` (time, guard, phase after); with ``stop_at_apex`` false every apex
    is stored in ``apex_y`` and starts a new stride. With ``rec_dt > 0`` the state is
    sampled every ``rec_dt`` and at every event into the ``rec_*`` buffers.

    Returns (status, t, h_next, n_events, n_apex, n_rec).
    """
    n = y.shape[0]
    K = np.empty((N_STAGES_EXTENDED, n))
    F = np.empty((INTERPOLATOR_POWER, n))
    fy = np.empty(n)
    y_new = np.empty(n)
    f_new = np.empty(n)
    ybuf = np.empty(n)
    g_old = np.empty(N_GUARDS)
    g_new = np.empty(N_GUARDS)
    gbuf = np.empty(N_GUARDS)
    fired = np.zeros(N_GUARDS, dtype=np.bool_)
    n_ev = 0
    n_apex = 0
    n_rec = 0
    recording = rec_dt > 0.0
    t_next_rec = t

    status = start_status(y, aux)
    if status != CONTINUE:
        return status, t, h, n_ev, n_apex, n_rec
    rhs(t, y, aux, fy)
    guard_values(y, aux, flags, g_old)
    if recording:
        n_rec = _record(t, y, aux, rec_t, rec_y, rec_ph, rec_e, n_rec)
        t_next_rec = t + rec_dt
    if not h > 0.0:
        h = initial_step(t, y, fy, aux, rtol, atol, 1.0, t_end - t, y_new, f_new)

    for _ in range(MAX_STEPS):
        if t >= t_end:
            return TIME_UP, t, h, n_ev, n_apex, n_rec
        h_try = min(h, t_end - t)
        if h_try < H_MIN:
            if t_end - t < H_MIN:  # reached t_end up to rounding
                return TIME_UP, t_end, h, n_ev, n_apex, n_rec
            return F_INTEGRATION, t, h, n_ev, n_apex, n_rec
        err = rk_step(t, y, fy, h_try, aux, rtol, atol, K, y_new, f_new)
        if not err <= 1.0:  # rejected (or NaN)
            finite = True
            for i in range(n):
                if not math.isfinite(y_new[i]):
                    finite = False
            if not finite and h_try < 1e-9:
                return F_NON_FINITE, t, h, n_ev, n_apex, n_rec
            h = h_try * step_factor(err)
            continue
        guard_values(y_new, aux, flags, g_new)
        # earliest guard crossing in this step
        t_star = t + h_try
        first = -1
        dense_ready = False
        for i in range(N_GUARDS):
            d = GUARD_DIRECTION[i]
            if d * g_old[i] < 0.0 and d * g_new[i] >= 0.0:
                if not dense_ready:
                    dense_prepare(t, y, y_new, h_try, aux, K, F)
                    dense_ready = True
                ti = _locate(i, t, g_old[i], t + h_try, g_new[i], F, y, t, h_try, aux, flags,
                             ybuf, gbuf)
                if first < 0 or ti < t_star:
                    t_star, first = ti, i
        if recording:
            if not dense_ready:
                dense_prepare(t, y, y_new, h_try, aux, K, F)
                dense_ready = True
            while t_next_rec < t_star:
                dense_eval(F, y, t, h_try, t_next_rec, ybuf)
                n_rec = _record(t_next_rec, ybuf, aux, rec_t, rec_y, rec_ph, rec_e, n_rec)
                t_next_rec += rec_dt
        if first < 0:
            t += h_try
            y[:] = y_new
            fy[:] = f_new
            g_old[:] = g_new
            h = h_try * step_factor(err)
            continue
        # an event: move to it, fire it and everything coincident, reset
        dense_eval(F, y, t, h_try, t_star, ybuf)
        y[:] = ybuf
        t = t_star
        guard_values(y, aux, flags, gbuf)
        fired[:] = False
        fired[first] = True
        coincident(g_old, gbuf, fired)
        status = apply_events(y, aux, flags, fired)
        ph = phase_index(aux)
        for i in range(N_GUARDS):
            if fired[i] and n_ev < ev_t.shape[0]:
                ev_t[n_ev] = t
                ev_g[n_ev] = i
                ev_ph[n_ev] = ph
                n_ev += 1
        if recording:
            n_rec = _record(t, y, aux, rec_t, rec_y, rec_ph, rec_e, n_rec)
        if status == APEX:
            if stop_at_apex:
                return APEX, t, h, n_ev, n_apex, n_rec
            if n_apex < apex_y.shape[0]:
                apex_y[n_apex, :] = y
            n_apex += 1
            flags[FL_TOUCHED_B] = False
            flags[FL_TOUCHED_F] = False
        elif status != CONTINUE:
            return status, t, h, n_ev, n_apex, n_rec
        rhs(t, y, aux, fy)
        guard_values(y, aux, flags, g_old)
        h = max(h_try * step_factor(err), 1e-6)
    return F_INTEGRATION, t, h, n_ev, n_apex, n_rec


def simulate_fast(y0, aux, flags, t0=0.0, t_end=2.0, rtol=1e-10, atol=1e-10, record_dt=None):
    """Python wrapper with the same return as `bound_env.hybrid.simulate_reference`."""
    y = np.array(y0, dtype=float)
    ev_t = np.empty(EVENT_CAPACITY)
    ev_g = np.empty(EVENT_CAPACITY, dtype=np.int64)
    ev_ph = np.empty(EVENT_CAPACITY, dtype=np.int64)
    apex_y = np.empty((1, 8))
    cap = int((t_end - t0) / record_dt) + 2 * EVENT_CAPACITY if record_dt else 1
    rec_t, rec_y = np.empty(cap), np.empty((cap, 8))
    rec_ph, rec_e = np.empty(cap, dtype=np.int64), np.empty(cap)
    status, t, _, n_ev, _, n_rec = advance(
        y, aux, flags, float(t0), float(t_end), True, rtol, atol, 0.0, ev_t, ev_g, ev_ph,
        apex_y, float(record_dt or 0.0), rec_t, rec_y, rec_ph, rec_e,
    )  # fmt: skip
    events = [Event(float(ev_t[k]), GUARD_NAMES[ev_g[k]], PHASES[ev_ph[k]]) for k in range(n_ev)]
    samples = [(float(rec_t[k]), rec_y[k].copy(), PHASES[rec_ph[k]], float(rec_e[k]))
               for k in range(n_rec)]
    return int(status), float(t), y, events, samples
