"""Fast back-end: the whole hybrid loop compiled with Numba.

Adaptive DOP853 steps (`bound_env.model._dop853`), guard sign changes checked after every accepted
step, each crossing located as a root of its guard on the step's 7th-order dense output,
resets applied by the same compiled `bound_env.model.events.apply_events` the reference back-end
uses. No Python runs between the start and the end of a stride (or of a control interval).

Like scipy's ``OdeSolver``, `advance` keeps its state in a few named buffers rather than a long
argument list: the hybrid state (``y``, ``aux``, ``flags``, updated in place), the solver
`Options`, an `EventLog` (events and apex states passed) and a `Recorder` (sampled states).
"""

from __future__ import annotations

import math
from collections import namedtuple

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

# Solver options: tolerances and whether an apex ends the call (else it starts a new stride).
Options = namedtuple("Options", ("rtol", "atol", "stop_at_apex"))
# Events of one call: time [s], guard index, phase index after it; full states of the apexes
# passed (up to the capacity); ``count`` = [events logged, apexes passed] (int64[2]).
EventLog = namedtuple("EventLog", ("t", "guard", "phase", "apex_y", "count"))
# Samples every ``dt`` seconds (``dt`` <= 0: off) and at every event: time, state, phase index,
# total energy [J]; ``count`` = [samples taken] (int64[1]).
Recorder = namedtuple("Recorder", ("dt", "t", "y", "phase", "energy", "count"))
EV_LOGGED, EV_APEXES = 0, 1  # entries of EventLog.count


@jit
def event_log(capacity, apex_y):
    """An empty `EventLog` for ``capacity`` events, storing apex states into ``apex_y``."""
    return EventLog(
        np.empty(capacity),
        np.empty(capacity, dtype=np.int64),
        np.empty(capacity, dtype=np.int64),
        apex_y,
        np.zeros(2, dtype=np.int64),
    )


@jit
def recorder(capacity, dt):
    """An empty `Recorder` for ``capacity`` samples every ``dt`` seconds (``dt`` <= 0: off)."""
    return Recorder(
        dt,
        np.empty(capacity),
        np.empty((capacity, 8)),
        np.empty(capacity, dtype=np.int64),
        np.empty(capacity),
        np.zeros(1, dtype=np.int64),
    )


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
def _record(rec, t, y, aux):
    k = rec.count[0]
    if k < rec.t.shape[0]:
        rec.t[k] = t
        rec.y[k, :] = y
        rec.phase[k] = phase_index(aux)
        rec.energy[k] = total_energy(y, aux)
        rec.count[0] = k + 1


@jit
def _log_events(log, t, fired, ph):
    for i in range(N_GUARDS):
        k = log.count[EV_LOGGED]
        if fired[i] and k < log.t.shape[0]:
            log.t[k] = t
            log.guard[k] = i
            log.phase[k] = ph
            log.count[EV_LOGGED] = k + 1


@jit
def advance(y, aux, flags, t, t_end, h, opts, log, rec):
    """Integrate the hybrid system from (t, y) to the apex (if ``opts.stop_at_apex``) or t_end.

    ``y``, ``aux`` (contacts, toes) and ``flags`` are updated in place; ``h`` is the first step
    to try (0: choose one). Events go to the `EventLog` ``log``; with ``stop_at_apex`` false
    every apex is stored in ``log.apex_y`` and starts a new stride. With ``rec.dt > 0`` the
    state is sampled every ``rec.dt`` and at every event into the `Recorder` ``rec``. Both
    counts start from zero.

    Returns (status, t, h_next).
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
    log.count[:] = 0
    rec.count[:] = 0
    rtol, atol = opts.rtol, opts.atol
    recording = rec.dt > 0.0
    t_next_rec = t

    status = start_status(y, aux)
    if status != CONTINUE:
        return status, t, h
    rhs(t, y, aux, fy)
    guard_values(y, aux, flags, g_old)
    if recording:
        _record(rec, t, y, aux)
        t_next_rec = t + rec.dt
    if not h > 0.0:
        h = initial_step(t, y, fy, aux, rtol, atol, 1.0, t_end - t, y_new, f_new)

    for _ in range(MAX_STEPS):
        if t >= t_end:
            return TIME_UP, t, h
        h_try = min(h, t_end - t)
        if h_try < H_MIN:
            if t_end - t < H_MIN:  # reached t_end up to rounding
                return TIME_UP, t_end, h
            return F_INTEGRATION, t, h
        err = rk_step(t, y, fy, h_try, aux, rtol, atol, K, y_new, f_new)
        if not err <= 1.0:  # rejected (or NaN)
            finite = True
            for i in range(n):
                if not math.isfinite(y_new[i]):
                    finite = False
            if not finite and h_try < 1e-9:
                return F_NON_FINITE, t, h
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
                ti = _locate(
                    i, t, g_old[i], t + h_try, g_new[i], F, y, t, h_try, aux, flags, ybuf, gbuf
                )
                if first < 0 or ti < t_star:
                    t_star, first = ti, i
        if recording:
            if not dense_ready:
                dense_prepare(t, y, y_new, h_try, aux, K, F)
                dense_ready = True
            while t_next_rec < t_star:
                dense_eval(F, y, t, h_try, t_next_rec, ybuf)
                _record(rec, t_next_rec, ybuf, aux)
                t_next_rec += rec.dt
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
        _log_events(log, t, fired, phase_index(aux))
        if recording:
            _record(rec, t, y, aux)
        if status == APEX:
            if opts.stop_at_apex:
                return APEX, t, h
            k = log.count[EV_APEXES]
            if k < log.apex_y.shape[0]:
                log.apex_y[k, :] = y
            log.count[EV_APEXES] = k + 1
        elif status != CONTINUE:
            return status, t, h
        rhs(t, y, aux, fy)
        guard_values(y, aux, flags, g_old)
        h = max(h_try * step_factor(err), 1e-6)
    return F_INTEGRATION, t, h


@jit
def _stride(y, aux, flags, t0, t_end, rtol, atol, record_dt, record_capacity):
    """`advance` to the apex with fresh buffers (allocated here: a call from Python with
    scalars and arrays dispatches faster than one with named tuples)."""
    log = event_log(EVENT_CAPACITY, np.empty((1, 8)))
    rec = recorder(record_capacity, record_dt)
    status, t, _ = advance(y, aux, flags, t0, t_end, 0.0, Options(rtol, atol, True), log, rec)
    return status, t, log, rec


def simulate_fast(y0, aux, flags, t0=0.0, t_end=2.0, rtol=1e-10, atol=1e-10, record_dt=None):
    """Python wrapper with the same return as `bound_env.model.reference.simulate_reference`."""
    y = np.array(y0, dtype=float)
    cap = int((t_end - t0) / record_dt) + 2 * EVENT_CAPACITY if record_dt else 1
    status, t, log, rec = _stride(
        y, aux, flags, float(t0), float(t_end), rtol, atol, float(record_dt or 0.0), cap
    )
    events = [
        Event(float(log.t[k]), GUARD_NAMES[log.guard[k]], PHASES[log.phase[k]])
        for k in range(log.count[EV_LOGGED])
    ]
    samples = [
        (float(rec.t[k]), rec.y[k].copy(), PHASES[rec.phase[k]], float(rec.energy[k]))
        for k in range(rec.count[0])
    ]
    return int(status), float(t), y, events, samples
