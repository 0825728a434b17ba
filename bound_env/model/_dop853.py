"""Numba-compiled Dormand-Prince 8(5,3) integrator with 7th-order dense output.

Explicit Runge-Kutta pair DOP853 of Dormand & Prince as described in
E. Hairer, S. P. Norsett, G. Wanner, *Solving Ordinary Differential
Equations I: Nonstiff Problems*, 2nd ed., Springer 1993, Sec. II.5 (the
method, its 3rd/5th-order combined error estimator) and Sec. II.6 (dense
output); the starting step heuristic is from Sec. II.4.  The Butcher tableau is
taken as data from ``scipy.integrate._ivp.dop853_coefficients``; the code is an
independent allocation-free re-implementation meant to be called from inside
other ``numba.njit`` functions (no Python objects in the loop).

Right-hand side convention: ``f(t, y, aux, out)`` is an ``njit`` function that
writes dy/dt into ``out``; ``aux`` is a float64 parameter vector.  All work
arrays are passed in by the caller:

* ``K``: shape ``(N_STAGES_EXTENDED, n)`` = (16, n), RK stages;
* ``F``: shape ``(INTERPOLATOR_POWER, n)`` = (7, n), dense-output coefficients.

Tolerances ``rtol``/``atol`` are scalars; the error norm is the RMS norm of the
error scaled by ``atol + rtol * max(|y|, |y_new|)``.
"""

import hashlib
import sys
import types
from pathlib import Path
from types import SimpleNamespace

import numba
import numpy as np
from scipy.integrate._ivp import dop853_coefficients as _coef

N_STAGES = _coef.N_STAGES  # 12
N_STAGES_EXTENDED = _coef.N_STAGES_EXTENDED  # 16
INTERPOLATOR_POWER = _coef.INTERPOLATOR_POWER  # 7

# Tableau as contiguous float64 arrays (frozen as constants by numba).
_A = np.ascontiguousarray(_coef.A, dtype=np.float64)  # (16, 16)
_B = np.ascontiguousarray(_coef.B, dtype=np.float64)  # (12,)
_C = np.ascontiguousarray(_coef.C, dtype=np.float64)  # (16,)
_E3 = np.ascontiguousarray(_coef.E3, dtype=np.float64)  # (13,)
_E5 = np.ascontiguousarray(_coef.E5, dtype=np.float64)  # (13,)
_D = np.ascontiguousarray(_coef.D, dtype=np.float64)  # (4, 16)

SAFETY = 0.9
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
ERROR_EXPONENT = -1.0 / 8.0  # -1 / (error_estimator_order + 1)
_EPS = np.finfo(np.float64).eps

# Status codes returned by ``integrate``.
SUCCESS = 0
MAX_STEPS_EXCEEDED = 1
STEP_TOO_SMALL = 2


@numba.njit(cache=True)
def _rms(x, y_a, y_b, rtol, atol):
    """RMS norm of ``x`` scaled by ``atol + rtol * max(|y_a|, |y_b|)``."""
    n = x.shape[0]
    s = 0.0
    for i in range(n):
        sc = atol + rtol * max(abs(y_a[i]), abs(y_b[i]))
        s += (x[i] / sc) ** 2
    return np.sqrt(s / n)


@numba.njit(cache=True)
def _stage_state(y, h, s, K, out):
    """out = y + sum_{j<s} (h * A[s, j]) * K[j]  (state for stage s)."""
    n = y.shape[0]
    for i in range(n):
        out[i] = y[i]
    for j in range(s):
        c = h * _A[s, j]
        for i in range(n):
            out[i] += c * K[j, i]


@numba.njit(cache=True)
def dense_eval(F, y_old, t_old, h, t, out):
    """Write the 7th-order interpolant at ``t`` (in ``[t_old, t_old + h]``)."""
    x = (t - t_old) / h
    x1 = 1.0 - x
    n = y_old.shape[0]
    for i in range(n):
        acc = 0.0
        for k in range(INTERPOLATOR_POWER - 1, -1, -1):
            acc += F[k, i]
            # Alternating factors x, (1-x), x, ... starting from the top row.
            if (INTERPOLATOR_POWER - 1 - k) % 2 == 0:
                acc *= x
            else:
                acc *= x1
        out[i] = y_old[i] + acc


@numba.njit(cache=True)
def step_factor(err_norm):
    """Step-size multiplier from the error norm of the last attempt."""
    if not err_norm >= 0.0:  # NaN: shrink as much as allowed
        return MIN_FACTOR
    if err_norm == 0.0:
        return MAX_FACTOR
    return min(MAX_FACTOR, max(MIN_FACTOR, SAFETY * err_norm**ERROR_EXPONENT))


# The integrator, written once with the right-hand side as the global ``_rhs``: `make_dop853`
# compiles a copy of each function below for one right-hand side (never called as they are).
_rhs = None


def _rk_step(t, y, fy, h, aux, rtol, atol, K, y_new, f_new):
    """One DOP853 step of size ``h`` from ``(t, y)``; ``fy = f(t, y)``.

    Fills ``K[0:N_STAGES + 1]`` (``K[0] = fy``, ``K[N_STAGES] = f_new``),
    ``y_new`` (8th-order solution) and ``f_new = f(t + h, y_new)``.
    Returns the scaled error norm (accept the step if it is < 1).
    """
    n = y.shape[0]
    K[0, :] = fy
    # Stages 1..N_STAGES-1; y_new serves as the stage-state buffer.
    for s in range(1, N_STAGES):
        _stage_state(y, h, s, K, y_new)
        _rhs(t + _C[s] * h, y_new, aux, K[s])
    _stage_state(y, h, N_STAGES, K, y_new)  # row N_STAGES of A is B
    _rhs(t + h, y_new, aux, f_new)
    K[N_STAGES, :] = f_new

    # Combined 5th/3rd order error estimate (Hairer's DOP853 ``err``).
    err5 = 0.0
    err3 = 0.0
    for i in range(n):
        e5 = 0.0
        e3 = 0.0
        for j in range(N_STAGES + 1):
            e5 += _E5[j] * K[j, i]
            e3 += _E3[j] * K[j, i]
        sc = atol + rtol * max(abs(y[i]), abs(y_new[i]))
        err5 += (e5 / sc) ** 2
        err3 += (e3 / sc) ** 2
    if err5 == 0.0 and err3 == 0.0:
        return 0.0
    return abs(h) * err5 / np.sqrt((err5 + 0.01 * err3) * n)


def _dense_prepare(t, y, y_new, h, aux, K, F):
    """Dense-output coefficients ``F`` for the step ``[t, t + h]``.

    Must follow the ``rk_step`` that produced ``y_new`` with the same ``K``
    (rows ``0..N_STAGES``); evaluates the three extra stages into
    ``K[N_STAGES + 1:]``.
    """
    n = y.shape[0]
    # Extra stages; F[0] serves as the stage-state buffer.
    for s in range(N_STAGES + 1, N_STAGES_EXTENDED):
        _stage_state(y, h, s, K, F[0])
        _rhs(t + _C[s] * h, F[0], aux, K[s])
    for i in range(n):
        dy = y_new[i] - y[i]
        F[0, i] = dy
        F[1, i] = h * K[0, i] - dy
        F[2, i] = 2.0 * dy - h * (K[N_STAGES, i] + K[0, i])
        for r in range(INTERPOLATOR_POWER - 3):
            acc = 0.0
            for j in range(N_STAGES_EXTENDED):
                acc += _D[r, j] * K[j, i]
            F[3 + r, i] = h * acc


def _initial_step(t, y, fy, aux, rtol, atol, direction, h_max, y1, f1):
    """Starting step size |h0| (Hairer's heuristic, order 8).

    ``direction`` is +1.0 or -1.0; ``h_max`` bounds the result (pass e.g.
    ``min(|t_end - t|, max_step)``).  ``y1``, ``f1`` are work arrays of size n.
    """
    n = y.shape[0]
    if n == 0 or h_max <= 0.0:
        return h_max
    d0 = _rms(y, y, y, rtol, atol)
    d1 = _rms(fy, y, y, rtol, atol)
    if d0 < 1e-5 or d1 < 1e-5:
        h0 = 1e-6
    else:
        h0 = 0.01 * d0 / d1
    h0 = min(h0, h_max)
    for i in range(n):
        y1[i] = y[i] + direction * h0 * fy[i]
    _rhs(t + direction * h0, y1, aux, f1)
    for i in range(n):
        y1[i] = f1[i] - fy[i]  # reuse y1 for the difference
    d2 = _rms(y1, y, y, rtol, atol) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1, h_max)


def _integrate(t0, y0, t_end, aux, rtol, atol, max_steps):
    """Adaptive integration of ``y' = f(t, y)`` from ``t0`` to ``t_end``.

    Returns ``(y, t, n_steps, n_rejected, status)`` where ``n_steps`` counts
    accepted steps, ``t`` is the time reached and ``status`` is ``SUCCESS``,
    ``MAX_STEPS_EXCEEDED`` (accepted + rejected attempts reached
    ``max_steps``) or ``STEP_TOO_SMALL``.  Testing/convenience driver; it
    mirrors the controller of scipy's DOP853 (no increase right after a
    rejection).
    """
    n = y0.shape[0]
    y = y0.copy()
    y_new = np.empty(n)
    fy = np.empty(n)
    f_new = np.empty(n)
    K = np.empty((N_STAGES_EXTENDED, n))
    t = t0
    n_steps = 0
    n_rejected = 0
    if t_end == t0:
        return y, t, n_steps, n_rejected, SUCCESS
    direction = 1.0 if t_end > t0 else -1.0
    _rhs(t, y, aux, fy)
    h_abs = _initial_step(t, y, fy, aux, rtol, atol, direction, abs(t_end - t0), y_new, f_new)
    rejected = False
    while direction * (t - t_end) < 0.0:
        if n_steps + n_rejected >= max_steps:
            return y, t, n_steps, n_rejected, MAX_STEPS_EXCEEDED
        min_step = 10.0 * _EPS * abs(t)
        if rejected:
            if h_abs < min_step or h_abs == 0.0:
                return y, t, n_steps, n_rejected, STEP_TOO_SMALL
        else:
            h_abs = max(h_abs, min_step)
        t_new = t + direction * h_abs
        if direction * (t_new - t_end) > 0.0:
            t_new = t_end
        h = t_new - t
        h_abs = abs(h)
        err = _rk_step(t, y, fy, h, aux, rtol, atol, K, y_new, f_new)
        factor = step_factor(err)
        if err < 1.0:
            if rejected:
                factor = min(1.0, factor)
            rejected = False
            n_steps += 1
            t = t_new
            y[:] = y_new
            fy[:] = f_new
        else:
            rejected = True
            n_rejected += 1
        h_abs *= factor
    return y, t, n_steps, n_rejected, SUCCESS


_TEMPLATES = (_rk_step, _dense_prepare, _initial_step, _integrate)
_INTEGRATORS = {}


def make_dop853(f):
    """DOP853 specialised to the right-hand side ``f(t, y, aux, out)`` (an ``njit`` function).

    Returns a namespace with ``rk_step``, ``dense_prepare``, ``initial_step`` and ``integrate``,
    compiled with ``f`` as a compile-time global rather than passed as an argument: a
    dispatcher argument's type changes every process, so functions taking one cannot use
    numba's on-disk cache. Nor can a closure over ``f``: numba keys a closure's cache entry on
    its pickled cells, and a dispatcher pickles with a uuid drawn per process, so every
    process compiled the integrator again and added a cache entry. A module-level ``f`` gets
    its own cache files instead, named by its module, its name and its source file's contents
    (an edit of that file compiles anew); any other ``f`` (a closure, a function made at run
    time) is compiled in memory only, as two of them may share a name.
    """
    if f in _INTEGRATORS:
        return _INTEGRATORS[f]
    tag = _cache_tag(f)
    namespace = dict(globals(), _rhs=f)
    for template in _TEMPLATES:
        fn = types.FunctionType(template.__code__, namespace, template.__name__)
        fn.__doc__ = template.__doc__
        name = template.__name__.lstrip("_")
        fn.__qualname__ = f"{name}[{tag}]" if tag else name
        namespace[template.__name__] = numba.njit(cache=tag is not None)(fn)
    ns = SimpleNamespace(**{t.__name__.lstrip("_"): namespace[t.__name__] for t in _TEMPLATES})
    _INTEGRATORS[f] = ns
    return ns


def _cache_tag(f) -> str | None:
    """``module.name-digest`` of a module-level ``f`` (the digest of its source file), or None
    for a function that its module does not hold under its name."""
    py = f.py_func
    if getattr(sys.modules.get(py.__module__), py.__qualname__, None) is not f:
        return None
    try:
        source = Path(py.__code__.co_filename).read_bytes()
    except OSError:
        return None
    digest = hashlib.sha256(source + py.__code__.co_code).hexdigest()[:12]
    return f"{py.__module__}.{py.__qualname__}-{digest}"
