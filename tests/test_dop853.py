"""Tests for the numba DOP853 integrator in ``bound_env.model._dop853``."""

import numba
import numpy as np
import pytest
from scipy.integrate import DOP853, solve_ivp

from bound_env.model import _dop853 as d

NO_AUX = np.zeros(0)


@numba.njit(cache=True)
def oscillator(t, y, aux, out):
    out[0] = y[1]
    out[1] = -y[0]


@numba.njit(cache=True)
def kepler(t, y, aux, out):
    r3 = (y[0] * y[0] + y[1] * y[1]) ** 1.5
    out[0] = y[2]
    out[1] = y[3]
    out[2] = -aux[0] * y[0] / r3
    out[3] = -aux[0] * y[1] / r3


@numba.njit(cache=True)
def van_der_pol(t, y, aux, out):
    out[0] = y[1]
    out[1] = aux[0] * (1.0 - y[0] * y[0]) * y[1] - y[0]


@numba.njit(cache=True)
def nan_rhs(t, y, aux, out):
    out[0] = np.nan if t > 0.5 else 1.0


def scipy_rhs(rhs, aux):
    def fun(t, y):
        out = np.empty_like(y)
        rhs(t, np.ascontiguousarray(y, dtype=np.float64), aux, out)
        return out

    return fun


def oscillator_exact(t):
    return np.array([np.cos(t), -np.sin(t)])


E_KEPLER = 0.5
KEPLER_Y0 = np.array([1.0 - E_KEPLER, 0.0, 0.0, np.sqrt((1.0 + E_KEPLER) / (1.0 - E_KEPLER))])
KEPLER_AUX = np.array([1.0])  # GM = 1, a = 1 -> period 2*pi

# name, rhs, y0, t_end, aux, exact solution at t_end (None if unknown),
# allowed deviation from it.  Kepler (e = 0.5, one orbit) at tol 1e-12 has a
# global error of 1.3e-10 in v_x, identical with scipy's DOP853.
PROBLEMS = [
    ("oscillator", oscillator, np.array([1.0, 0.0]), 10.0, NO_AUX, oscillator_exact(10.0), 1e-10),
    ("kepler", kepler, KEPLER_Y0, 2.0 * np.pi, KEPLER_AUX, KEPLER_Y0, 3e-10),
    ("van_der_pol", van_der_pol, np.array([2.0, 0.0]), 10.0, np.array([1.0]), None, None),
]


@pytest.mark.slow  # each right-hand side compiles its own integrator (~5-10 s on a first run)
@pytest.mark.parametrize(
    "name,rhs,y0,t_end,aux,exact,exact_tol", PROBLEMS, ids=[p[0] for p in PROBLEMS]
)
def test_integrate_vs_exact_and_scipy(name, rhs, y0, t_end, aux, exact, exact_tol):
    tol = 1e-12
    y, t, n_steps, n_rej, status = d.make_dop853(rhs).integrate(
        0.0, y0, t_end, aux, tol, tol, 100_000
    )
    assert status == d.SUCCESS
    assert t == t_end
    if exact is not None:
        np.testing.assert_allclose(y, exact, rtol=0, atol=exact_tol)

    sol = solve_ivp(scipy_rhs(rhs, aux), (0.0, t_end), y0, method="DOP853", rtol=tol, atol=tol)
    assert sol.success
    np.testing.assert_allclose(y, sol.y[:, -1], rtol=0, atol=1e-9)

    # Same controller: accepted steps and total attempts match scipy's.
    # scipy: nfev = 1 (f(t0)) + 1 (initial-step probe) + 12 per attempt.
    scipy_steps = len(sol.t) - 1
    scipy_attempts = (sol.nfev - 2) // 12
    assert abs(n_steps - scipy_steps) <= 0.05 * scipy_steps + 1
    assert abs(n_steps + n_rej - scipy_attempts) <= 0.05 * scipy_attempts + 1
    assert 0.67 < n_steps / (sol.nfev / 12) < 1.5


@pytest.mark.slow
def test_backward_integration():
    y, t, n_steps, _, status = d.make_dop853(oscillator).integrate(
        3.0, oscillator_exact(3.0), -2.0, NO_AUX, 1e-12, 1e-12, 100_000
    )
    assert status == d.SUCCESS and t == -2.0 and n_steps > 0
    np.testing.assert_allclose(y, oscillator_exact(-2.0), rtol=0, atol=1e-10)


@pytest.mark.slow
def test_max_steps_and_step_too_small():
    y0 = np.array([1.0, 0.0])
    _, t, n_steps, n_rej, status = d.make_dop853(oscillator).integrate(
        0.0, y0, 1000.0, NO_AUX, 1e-12, 1e-12, 20
    )
    assert status == d.MAX_STEPS_EXCEEDED
    assert n_steps + n_rej == 20 and 0.0 < t < 1000.0

    # A RHS that turns NaN makes every attempt fail -> h shrinks to the floor.
    _, t, _, n_rej, status = d.make_dop853(nan_rhs).integrate(
        0.0, np.zeros(1), 1.0, NO_AUX, 1e-8, 1e-8, 100_000
    )
    assert status == d.STEP_TOO_SMALL
    assert 0.4 < t <= 0.5 and n_rej > 0


def test_step_factor():
    assert d.step_factor(0.0) == d.MAX_FACTOR
    assert d.step_factor(1e-30) == d.MAX_FACTOR
    assert d.step_factor(1e30) == d.MIN_FACTOR
    assert d.step_factor(np.nan) == d.MIN_FACTOR
    assert d.step_factor(1.0) == pytest.approx(0.9)
    assert d.step_factor(2.0**-8) == pytest.approx(1.8)


def test_initial_step_matches_scipy():
    from scipy.integrate._ivp.common import select_initial_step

    y0 = KEPLER_Y0
    fy = np.empty(4)
    kepler(0.0, y0, KEPLER_AUX, fy)
    h0 = d.make_dop853(kepler).initial_step(
        0.0, y0, fy, KEPLER_AUX, 1e-9, 1e-9, 1.0, 10.0, np.empty(4), np.empty(4)
    )
    ref = select_initial_step(
        scipy_rhs(kepler, KEPLER_AUX), 0.0, y0, 10.0, np.inf, fy, 1.0, 7, 1e-9, 1e-9
    )
    assert h0 == pytest.approx(ref, rel=1e-12)


def _controlled_step(rhs, t, y, aux, tol):
    """Return (h, y_new, K, err) of an accepted step of near-maximal size."""
    n = y.shape[0]
    fy = np.empty(n)
    rhs(t, y, aux, fy)
    K = np.empty((d.N_STAGES_EXTENDED, n))
    y_new = np.empty(n)
    f_new = np.empty(n)
    h = d.make_dop853(rhs).initial_step(
        t, y, fy, aux, tol, tol, 1.0, 100.0, np.empty(n), np.empty(n)
    )
    for _ in range(20):  # iterate the controller to its equilibrium step
        err = d.make_dop853(rhs).rk_step(t, y, fy, h, aux, tol, tol, K, y_new, f_new)
        h *= min(d.step_factor(err), 1.0 if err >= 1.0 else 2.0)
    err = d.make_dop853(rhs).rk_step(t, y, fy, h, aux, tol, tol, K, y_new, f_new)
    while err >= 1.0:
        h *= d.step_factor(err)
        err = d.make_dop853(rhs).rk_step(t, y, fy, h, aux, tol, tol, K, y_new, f_new)
    return h, y_new, K, err


def test_dense_output_accuracy_and_endpoints():
    tol = 1e-10
    t0 = 0.3
    y0 = oscillator_exact(t0)
    h, y_new, K, err = _controlled_step(oscillator, t0, y0, NO_AUX, tol)
    assert 0.1 < err < 1.0 and h > 0.3  # a genuinely large step

    F = np.empty((d.INTERPOLATOR_POWER, 2))
    d.make_dop853(oscillator).dense_prepare(t0, y0, y_new, h, NO_AUX, K, F)
    out = np.empty(2)

    d.dense_eval(F, y0, t0, h, t0, out)
    np.testing.assert_allclose(out, y0, rtol=0, atol=1e-14)
    d.dense_eval(F, y0, t0, h, t0 + h, out)
    np.testing.assert_allclose(out, y_new, rtol=0, atol=1e-14)

    # scipy's DOP853 stepping from the same state with the same first step.
    solver = DOP853(
        scipy_rhs(oscillator, NO_AUX), t0, y0, t0 + 10.0, first_step=h, rtol=tol, atol=tol
    )
    solver.step()
    assert solver.t == pytest.approx(t0 + h, rel=1e-15)
    np.testing.assert_allclose(solver.y, y_new, rtol=0, atol=1e-15)
    ref_dense = solver.dense_output()

    for x in np.linspace(0.0, 1.0, 17)[1:-1]:
        t = t0 + x * h
        d.dense_eval(F, y0, t0, h, t, out)
        exact = oscillator_exact(t)
        assert np.max(np.abs(out - exact)) <= 1e-9 * np.max(np.abs(exact))
        np.testing.assert_allclose(out, ref_dense(t), rtol=0, atol=1e-14)


def test_dense_output_order():
    """Local interpolation error at mid-step is O(h^8)."""
    n = 2
    K = np.empty((d.N_STAGES_EXTENDED, n))
    F = np.empty((d.INTERPOLATOR_POWER, n))
    y_new, f_new, fy, out = (np.empty(n) for _ in range(4))
    y0 = np.array([1.0, 0.0])
    oscillator(0.0, y0, NO_AUX, fy)
    errs = []
    for h in (0.8, 0.4, 0.2):
        d.make_dop853(oscillator).rk_step(0.0, y0, fy, h, NO_AUX, 1e-6, 1e-6, K, y_new, f_new)
        d.make_dop853(oscillator).dense_prepare(0.0, y0, y_new, h, NO_AUX, K, F)
        d.dense_eval(F, y0, 0.0, h, 0.37 * h, out)
        errs.append(np.max(np.abs(out - oscillator_exact(0.37 * h))))
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders > 7.0) & (orders < 9.0)), (errs, orders)


_osc_rk_step = d.make_dop853(oscillator).rk_step


@numba.njit(cache=True)
def _fixed_step_oscillator(n_steps, t_end):
    y = np.array([1.0, 0.0])
    fy = np.empty(2)
    y_new = np.empty(2)
    f_new = np.empty(2)
    K = np.empty((d.N_STAGES_EXTENDED, 2))
    aux = np.zeros(0)
    h = t_end / n_steps
    t = 0.0
    oscillator(t, y, aux, fy)
    for _ in range(n_steps):
        _osc_rk_step(t, y, fy, h, aux, 1e-6, 1e-6, K, y_new, f_new)
        t += h
        y[:] = y_new
        fy[:] = f_new
    return y


def test_convergence_order():
    t_end = 10.0
    errs = []
    for n_steps in (10, 20, 40):
        y = _fixed_step_oscillator(n_steps, t_end)
        errs.append(np.max(np.abs(y - oscillator_exact(t_end))))
    assert errs[-1] > 1e-13  # still well above round-off
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all((orders > 7.0) & (orders < 9.0)), (errs, orders)


def test_error_norm_matches_scipy():
    """rk_step's error norm equals scipy's DOP853 estimate for the same K."""
    y0 = KEPLER_Y0
    n = 4
    fy = np.empty(n)
    kepler(0.0, y0, KEPLER_AUX, fy)
    K = np.empty((d.N_STAGES_EXTENDED, n))
    y_new = np.empty(n)
    f_new = np.empty(n)
    rtol, atol = 1e-8, 1e-9
    for h in (0.05, 0.2, 0.5):
        err = d.make_dop853(kepler).rk_step(0.0, y0, fy, h, KEPLER_AUX, rtol, atol, K, y_new, f_new)
        solver = DOP853(
            scipy_rhs(kepler, KEPLER_AUX), 0.0, y0, 10.0, first_step=h, rtol=rtol, atol=atol
        )
        scale = atol + rtol * np.maximum(np.abs(y0), np.abs(y_new))
        ref = solver._estimate_error_norm(K[: d.N_STAGES + 1], h, scale)
        # The estimate is a cancelling sum of stages: agreement ~1e-9 relative.
        assert err == pytest.approx(ref, rel=1e-7)
        np.testing.assert_array_equal(K[d.N_STAGES], f_new)
