"""The exact linearized Poincare map (variational equations + saltation) vs eq. (23)."""

import numpy as np
import pytest

from bound_env.model.dynamics import A_XB, A_XF, make_aux, rhs
from bound_env.model.hybrid import (
    G_LO_B,
    G_LO_F,
    G_TD_B,
    G_TD_F,
    N_FLAGS,
    N_GUARDS,
    guard_values,
    simulate_stride,
    state_from_z,
)
from bound_env.model.params import load_gait
from bound_env.model.variational import (
    augmented_jacobian,
    guard,
    jacobian_variational,
    saltation_matrix,
)

TOL = 1e-12


def fd_jacobian(z, params, backend, dz=1e-6):
    """Central differences of whole strides, eqs. (22)-(23)."""
    J = np.empty((6, 6))
    for i in range(6):
        zp, zm = z.copy(), z.copy()
        zp[i] += dz
        zm[i] -= dz
        rp = simulate_stride(zp, params, backend=backend, rtol=TOL, atol=TOL)
        rm = simulate_stride(zm, params, backend=backend, rtol=TOL, atol=TOL)
        J[:, i] = (rp.z1 - rm.z1) / (2 * dz)
    return J


def by_modulus(ev):
    return ev[np.lexsort((ev.imag, np.abs(ev)))]


@pytest.fixture(scope="module")
def gait(default_gait):
    return default_gait


@pytest.fixture(scope="module")
def fixed_point(gait):
    DP, info = jacobian_variational(gait.z_star, gait.params)
    return DP, info, fd_jacobian(gait.z_star, gait.params, "reference")


def test_matches_finite_differences_at_fixed_point(fixed_point):
    DP, info, J = fixed_point
    err = np.abs(DP - J).max()  # measured: 1.3e-8 (reference back-end), 2.7e-8 (fast)
    assert err <= 1e-6, err
    assert [n for _, n in info["events"]] == [
        "touchdown_back",
        "liftoff_back",
        "touchdown_front",
        "liftoff_front",
        "apex",
    ]
    assert info["max_event_time_error"] < 1e-9


def test_eigenvalues_match_finite_differences(fixed_point):
    DP, info, J = fixed_point
    ev_fd = by_modulus(np.linalg.eigvals(J))
    ev = by_modulus(info["eigenvalues"])
    assert np.abs(ev - ev_fd).max() <= 1e-6  # measured: 2e-8
    assert np.allclose(np.abs(info["eigenvalues"]), np.sort(np.abs(ev))[::-1])
    assert np.abs(ev).max() < 1.0  # the default gait is stable


@pytest.mark.parametrize(
    "case", ["perturbed", "published", "double_stance", "two_back_stances", "torque"]
)
def test_matches_finite_differences_elsewhere(gait, case):
    z, p, tau = gait.z_star, gait.params, 0.0
    if case == "perturbed":  # not a fixed point
        z = 1.01 * z
    elif case == "published":
        z = gait.z_published
    elif case == "double_stance":  # df bs ds fs df: both toe columns act at once
        p = p.with_values(alpha_deg=1.0)
    elif case == "two_back_stances":  # df bs df fs df bs df
        p = p.with_values(kc=100.0)
    elif case == "torque":
        tau = 1.5
    DP, info = jacobian_variational(z, p, tau=tau)
    if case == "torque":  # FD with the torque: simulate_stride takes tau directly
        J = np.empty((6, 6))
        for i in range(6):
            dz = np.zeros(6)
            dz[i] = 1e-6
            zp = simulate_stride(z + dz, p, backend="fast", tau=tau, rtol=TOL, atol=TOL).z1
            zm = simulate_stride(z - dz, p, backend="fast", tau=tau, rtol=TOL, atol=TOL).z1
            J[:, i] = (zp - zm) / 2e-6
    else:
        J = fd_jacobian(z, p, "fast")
    assert np.abs(DP - J).max() <= 1e-6
    r = simulate_stride(z, p, backend="reference", tau=tau)
    assert np.abs(info["z1"] - r.z1).max() < 1e-9
    if case == "double_stance":
        assert "ds" in r.phases
    if case == "two_back_stances":
        assert r.phases.count("bs") == 2


def test_failing_stride_has_no_jacobian():
    lit = load_gait("paper-literal")  # overcompresses the front leg from z_published
    with pytest.raises(ValueError, match="fails"):
        jacobian_variational(lit.z_published, lit.params)


@pytest.mark.parametrize("switch", ["saltation", "toe_columns"])
def test_saltation_and_toe_sensitivity_matter(gait, fixed_point, switch):
    _, _, J = fixed_point
    DP, _ = jacobian_variational(gait.z_star, gait.params, **{switch: False})
    assert np.abs(DP - J).max() > 1e-3  # measured: 190 and 208


def test_liftoff_saltation_is_identity_touchdown_moves_only_the_toe(fixed_point):
    """Massless legs at rest length carry no force at either event, so f is continuous and
    the only jump is in the touchdown toe's sensitivity (timed by the guard)."""
    _, info, _ = fixed_point
    for (_, name), S in zip(info["events"], info["saltations"], strict=False):
        D = S - np.eye(10)
        if name.startswith("liftoff"):
            assert np.abs(D).max() < 1e-10
        else:
            toe = 8 if name.endswith("back") else 9
            assert np.abs(np.delete(D, toe, axis=0)).max() < 1e-10
            assert np.abs(D[toe]).max() > 0.1


def test_saltation_closed_form():
    """Constant fields f- = (1, a) until p = 1, reset (p, q) -> (p, q + b p^2), then
    f+ = (c, d): the flow map over a fixed time has Jacobian [[c, 0], [d - a, 1]]."""
    a, b, c, d = 0.7, -1.3, 2.1, 0.4
    S = saltation_matrix([[1, 0], [2 * b, 1]], [1, a], [c, d], [1, 0])
    assert np.allclose(S, [[c, 0], [d - a, 1]], atol=1e-15)

    def flow(p0, q0, T=2.0):  # closed-form solution of the switched system
        ts = 1.0 - p0
        q = q0 + a * ts + b
        return np.array([1.0 + c * (T - ts), q + d * (T - ts)])

    h = 1e-6
    J = np.column_stack(
        [
            (flow(0.3 + h, 0.5) - flow(0.3 - h, 0.5)) / (2 * h),
            (flow(0.3, 0.5 + h) - flow(0.3, 0.5 - h)) / (2 * h),
        ]
    )
    assert np.allclose(S, J, atol=1e-8)


def test_guards_agree_with_hybrid(gait):
    y = state_from_z(gait.z_star)
    aux = make_aux(gait.params.to_array(), True, True, -0.3, 0.4)
    w = np.concatenate([y, [-0.3, 0.4]])
    out = np.empty(N_GUARDS)
    guard_values(y, aux, np.zeros(N_FLAGS, dtype=np.bool_), out)
    assert guard("liftoff", 0, w, aux) == pytest.approx(out[G_LO_B], abs=1e-14)
    assert guard("liftoff", 1, w, aux) == pytest.approx(out[G_LO_F], abs=1e-14)
    aux_flight = make_aux(gait.params.to_array())
    guard_values(y, aux_flight, np.zeros(N_FLAGS, dtype=np.bool_), out)
    assert guard("touchdown", 0, w, aux_flight) == pytest.approx(out[G_TD_B], abs=1e-14)
    assert guard("touchdown", 1, w, aux_flight) == pytest.approx(out[G_TD_F], abs=1e-14)


def test_augmented_jacobian_matches_finite_differences(gait):
    """Including the toe columns obtained from the translation symmetry."""
    y = state_from_z(gait.z_star)
    y[1] -= 0.04  # both legs compressed
    aux = make_aux(gait.params.to_array(), True, True, -0.55, 0.2)
    A = np.empty((8, 10))
    augmented_jacobian(y, aux, A, True)
    h, fp, fm = 1e-6, np.empty(8), np.empty(8)
    J = np.empty((8, 10))
    for i in range(10):
        yp, ym, ap, am = y.copy(), y.copy(), aux.copy(), aux.copy()
        if i < 8:
            yp[i] += h
            ym[i] -= h
        else:
            k = (A_XB, A_XF)[i - 8]
            ap[k] += h
            am[k] -= h
        rhs(0.0, yp, ap, fp)
        rhs(0.0, ym, am, fm)
        J[:, i] = (fp - fm) / (2 * h)
    assert np.abs(A[:, 8:]).max() > 1.0
    assert np.allclose(A, J, rtol=1e-6, atol=1e-5)
