"""The compiled equations of motion against an independent sympy derivation (paper eqs. 1-16).

The model is rebuilt here from the paper, not from `bound_env.model.dynamics`: q = [x_g, y_g, th1,
th2]; body COMs by eqs. (5)-(8); T by eq. (3); V by eq. (2) with the leg lengths of eqs.
(9)-(14) (a stance leg's length is the hip-to-toe distance, a flight leg stores no energy);
the spine spring rests at th2 = 0; the dissipation Delta = c_c th2dot^2 / 2 (eq. 4) enters
as -dDelta/dqdot and the spine torque tau as a generalized force on th2. The Lagrange
equations (15)-(16) are written as M(q) qddot + h(q, qdot) = 0; M and h are lambdified and
solved numerically.
"""

import numpy as np
import pytest
import sympy as sp

from bound_env.model.dynamics import kinetic_energy, make_aux, potential_energy, rhs
from bound_env.model.params import P_L1, Params

CONDITIONS = {"df": (False, False), "bs": (True, False), "fs": (False, True), "ds": (True, True)}
N_STATES = 20
ACC_TOL = 1e-10
ENERGY_TOL = 1e-12

# Symbol order of every lambdified function: (q, qdot, params); the params are below.
PARAM_NAMES = (
    "g",
    "alpha",
    "m1",
    "m2",
    "l1",
    "l2",
    "I1",
    "I2",
    "lb_bar",
    "lf_bar",
    "kb",
    "kf",
    "kc",
    "c_c",
    "tau",
    "x_toe_b",
    "x_toe_f",
)


def _derive():
    """Symbolic T, V_sigma, M(q) and h_sigma(q, qdot) for the four stance conditions."""
    q = sp.symbols("x_g y_g theta1 theta2", real=True)
    qd = sp.symbols("xd_g yd_g theta1d theta2d", real=True)
    qdd = sp.symbols("xdd_g ydd_g theta1dd theta2dd", real=True)
    par = sp.symbols(" ".join(PARAM_NAMES), real=True)
    g, alpha, m1, m2, l1, l2, I1, I2, lb_bar, lf_bar, kb, kf, kc, cc, tau, xtb, xtf = par
    xg, yg, th1, th2 = q

    # eqs. (5)-(8)
    rx = l1 * sp.cos(th1) + l2 * sp.cos(th1 + th2)
    ry = l1 * sp.sin(th1) + l2 * sp.sin(th1 + th2)
    x1 = xg - m2 / (m1 + m2) * rx
    y1 = yg - m2 / (m1 + m2) * ry
    x2 = xg + m1 / (m1 + m2) * rx
    y2 = yg + m1 / (m1 + m2) * ry

    def ddt(expr):  # time derivative along qdot (expr depends on q only)
        return sum(sp.diff(expr, qi) * qdi for qi, qdi in zip(q, qd, strict=True))

    # eq. (3)
    T = sp.Rational(1, 2) * (
        m1 * (ddt(x1) ** 2 + ddt(y1) ** 2)
        + m2 * (ddt(x2) ** 2 + ddt(y2) ** 2)
        + I1 * qd[2] ** 2
        + I2 * (qd[2] + qd[3]) ** 2
    )
    # eqs. (13)-(14): A = x_toe_b - hip_b_x, C = hip_b_y; B = x_toe_f - hip_f_x, D = hip_f_y
    hip_b = (x1 - l1 * sp.cos(th1), y1 - l1 * sp.sin(th1))
    hip_f = (x2 + l2 * sp.cos(th1 + th2), y2 + l2 * sp.sin(th1 + th2))
    A, C = xtb + l1 * sp.cos(th1) - x1, y1 - l1 * sp.sin(th1)
    B, D = xtf - l2 * sp.cos(th1 + th2) - x2, y2 + l2 * sp.sin(th1 + th2)
    lb = sp.sqrt(A**2 + C**2)
    lf = sp.sqrt(B**2 + D**2)
    # eq. (2), spine rest angle 0; flight legs (eqs. 9-11) store no energy
    v_base = (
        (m1 * y1 + m2 * y2) * g * sp.cos(alpha)
        - (m1 * x1 + m2 * x2) * g * sp.sin(alpha)
        + sp.Rational(1, 2) * kc * th2**2
    )
    v_back = sp.Rational(1, 2) * kb * (lb - lb_bar) ** 2
    v_front = sp.Rational(1, 2) * kf * (lf - lf_bar) ** 2
    delta = sp.Rational(1, 2) * cc * qd[3] ** 2  # eq. (4)

    # eq. (15) with L = T - V: d/dt dT/dqd - dT/dq + dV/dq + dDelta/dqd - [0,0,0,tau] = 0
    dT_dqd = [sp.diff(T, v) for v in qd]
    e_kin = sp.Matrix(
        [
            sum(
                sp.diff(p, qj) * qdj + sp.diff(p, qdj) * qddj
                for qj, qdj, qddj in zip(q, qd, qdd, strict=True)
            )
            - sp.diff(T, qi)
            for p, qi in zip(dT_dqd, q, strict=True)
        ]
    )
    M = e_kin.jacobian(qdd)
    h_kin = e_kin.subs(dict.fromkeys(qdd, 0))
    e_force = sp.Matrix([sp.diff(delta, v) for v in qd]) - sp.Matrix([0, 0, 0, tau])
    assert not (M.free_symbols & set(qdd))  # M depends on q only

    args = (q, qd, par)
    out = {
        "M": sp.lambdify(args, M, modules="numpy", cse=True),
        "T": sp.lambdify(args, T, modules="numpy", cse=True),
        "hips": sp.lambdify(args, [*hip_b, *hip_f], modules="numpy", cse=True),
    }
    for name, (cb, cf) in CONDITIONS.items():
        V = v_base + (v_back if cb else 0) + (v_front if cf else 0)
        h = h_kin + sp.Matrix([sp.diff(V, qi) for qi in q]) + e_force
        out["h_" + name] = sp.lambdify(args, h, modules="numpy", cse=True)
        out["V_" + name] = sp.lambdify(args, V, modules="numpy", cse=True)
    return out


@pytest.fixture(scope="module")
def sym():
    return _derive()


def _random_params(rng):
    """Random non-default parameters; m1 != m2 and l1 != l2 to expose swapped indices."""
    m1 = rng.uniform(5.0, 15.0)
    m2 = m1 * rng.uniform(1.2, 1.8)
    l1 = rng.uniform(0.1, 0.3)
    l2 = l1 * rng.uniform(0.5, 0.8)
    return Params(
        g=rng.uniform(8.0, 12.0),
        m1=m1,
        m2=m2,
        l1=l1,
        l2=l2,
        I1=rng.uniform(0.1, 1.0),
        I2=rng.uniform(0.1, 1.0),
        lb_bar=rng.uniform(0.25, 0.4),
        lf_bar=rng.uniform(0.25, 0.4),
        kb=rng.uniform(1000.0, 5000.0),
        kf=rng.uniform(1000.0, 5000.0),
        kc=rng.uniform(50.0, 500.0),
        zeta=rng.uniform(0.05, 0.6),
        alpha=rng.uniform(0.0, 0.15),
        gamma_b=rng.uniform(0.2, 1.2),
        gamma_f=rng.uniform(0.2, 1.2),
    )


def _cases(sym, condition, seed, n=N_STATES):
    """(params, tau, state y, aux, symbolic parameter tuple) for n random states."""
    rng = np.random.default_rng(seed)
    cb, cf = CONDITIONS[condition]
    for _ in range(n):
        params = _random_params(rng)
        tau = rng.uniform(-20.0, 20.0)
        q = np.array(
            [
                rng.uniform(-1.0, 1.0),
                rng.uniform(0.2, 0.3),
                rng.uniform(-0.5, 0.5),
                rng.uniform(-0.5, 0.5),
            ]
        )
        qd = rng.uniform(-5.0, 5.0, 4)
        base = (
            params.g,
            params.alpha,
            params.m1,
            params.m2,
            params.l1,
            params.l2,
            params.I1,
            params.I2,
            params.lb_bar,
            params.lf_bar,
            params.kb,
            params.kf,
            params.kc,
            params.c_c,
            tau,
        )
        hbx, _, hfx, _ = sym["hips"](q, qd, (*base, 0.0, 0.0))
        xtb = hbx + rng.uniform(-0.3, 0.3)
        xtf = hfx + rng.uniform(-0.3, 0.3)
        y = np.concatenate([q, qd])
        aux = make_aux(params.to_array(tau=tau), cb, cf, xtb, xtf)
        yield params, tau, y, aux, (*base, xtb, xtf)


def _sym_acc(sym, condition, y, spar):
    q, qd = y[:4], y[4:]
    M = np.array(sym["M"](q, qd, spar), dtype=float)
    h = np.array(sym["h_" + condition](q, qd, spar), dtype=float).reshape(4)
    return np.linalg.solve(M, -h)


def _max_rel_acc_error(sym, condition, seed, perturb=None):
    worst = 0.0
    for _, _, y, aux, spar in _cases(sym, condition, seed):
        if perturb is not None:
            perturb(aux)
        out = np.empty(8)
        rhs(0.0, y, aux, out)
        np.testing.assert_array_equal(out[:4], y[4:])
        ref = _sym_acc(sym, condition, y, spar)
        err = np.max(np.abs(out[4:] - ref)) / max(1.0, np.max(np.abs(ref)))
        worst = max(worst, err)
    return worst


@pytest.mark.parametrize("condition", list(CONDITIONS))
def test_accelerations_match_symbolic(sym, condition):
    seed = 1000 + list(CONDITIONS).index(condition)
    err = _max_rel_acc_error(sym, condition, seed)
    print(f"{condition}: max relative acceleration error {err:.3e}")
    assert err <= ACC_TOL, (condition, err)


@pytest.mark.parametrize("condition", list(CONDITIONS))
def test_energies_match_symbolic(sym, condition):
    seed = 2000 + list(CONDITIONS).index(condition)
    worst_t = worst_v = 0.0
    for _, _, y, aux, spar in _cases(sym, condition, seed):
        q, qd = y[:4], y[4:]
        t_ref = float(sym["T"](q, qd, spar))
        v_ref = float(sym["V_" + condition](q, qd, spar))
        worst_t = max(worst_t, abs(kinetic_energy(y, aux) - t_ref) / max(1.0, abs(t_ref)))
        worst_v = max(worst_v, abs(potential_energy(y, aux) - v_ref) / max(1.0, abs(v_ref)))
    print(f"{condition}: max relative error T {worst_t:.3e}, V {worst_v:.3e}")
    assert worst_t <= ENERGY_TOL, (condition, worst_t)
    assert worst_v <= ENERGY_TOL, (condition, worst_v)


@pytest.mark.parametrize("condition", list(CONDITIONS))
def test_comparison_is_sensitive(sym, condition):
    """A wrong half-length l1 in the compiled model must show up as a large error."""

    def wrong_l1(aux):
        aux[P_L1] *= 1.05

    err = _max_rel_acc_error(sym, condition, 3000, perturb=wrong_l1)
    assert err > 1e-6, (condition, err)
