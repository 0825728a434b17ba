"""Exact linearized Poincare map: variational equations plus saltation matrices.

The paper estimates grad P(z*) (eq. 22) by central differences of whole strides (eq. 23,
dz = 1e-6), i.e. 12 strides whose accuracy is limited by the integrator tolerance / dz.
Here dP/dz is obtained from *one* stride integrated together with its sensitivity matrix:

* Augmented state w = [y (8), x_b^toe, x_f^toe] with d(x^toe)/dt = 0, so the toe positions
  a touchdown sets become states and their sensitivities are carried along.
* Between events, dPsi/dt = A(t) Psi with A = d f_aug / d w. The y-columns of A come from a
  complex step through the compiled `rhs` (exact to rounding). The toe columns use the
  translation symmetry of the leg forces: a stance leg's force depends on x_g and its toe
  only through hip_x - x^toe, so d f / d x_k^toe = -d f / d x_g with only leg k in stance.
* At every event with guard g, reset R and fields f- (before) and f+ = f_aug(R(w)) (after),
  Psi jumps by the saltation matrix (Aizerman & Gantmacher 1958; Mueller 1995; the hybrid
  framework of Remy et al.) S = dR + (f+ - dR f-) grad g^T / (grad g . f-). Liftoff: R =
  identity (the contact flag changes). Touchdown of leg k: R sets
  x_k^toe = x_hip,k(y) + l_bar sin(gamma_k), a row of dR.
* The stride ends on S_apex (eq. 17, guard ydot_g = 0), where the time correction gives
  dP/dz = Pz (I - f e_ydot^T / f_ydot) Psi(T), Psi(0) = E (the embedding z -> w, x_g = 0,
  ydot_g = 0), Pz the projection w -> z (eqs. 18-22).

The event sequence is replayed from a stride of `simulate_stride` (either back-end, same
tolerances); each event is re-located on the combined system (solve_ivp DOP853) and must
agree in time to `EVENT_TIME_TOL`.

Simultaneous events (guards within `EVENT_COINCIDENCE` of zero at one instant, e.g. a
liftoff and a touchdown at once) are handled by composing their saltations in the order
`apply_events` resets them (liftoffs, then touchdowns), each using the vector fields of the
intermediate contact condition. At an exactly simultaneous event P is only piecewise smooth;
the composition is then the one-sided Jacobian of that ordering.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from .dynamics import A_CB, A_XB, A_XF, body_points, jit, make_aux, rhs, trig
from .hybrid import simulate_stride, state_from_z
from .params import P_GB, P_GF, P_LB, P_LF, Z_IN_Y, Params

N_W = 10  # augmented state: y (8) + two toe positions
Z_ROWS = np.array(Z_IN_Y)  # z = w[Z_ROWS] (eq. 17)
H_CS = 1e-30  # complex-step size
EVENT_TIME_TOL = 1e-6  # re-located events must agree with the reference stride [s]
_LEG = {"back": 0, "front": 1}


@jit
def augmented_jacobian(y, aux, A, toe_columns):
    """A = d f_aug / d w (rows 0-7; the toe rows are zero) by complex step into ``A`` (8x10)."""
    yc = y.astype(np.complex128)
    out = np.empty(8, dtype=np.complex128)
    for i in range(8):
        yc[i] += 1j * H_CS
        rhs(0.0, yc, aux, out)
        for r in range(8):
            A[r, i] = out[r].imag / H_CS
        yc[i] = y[i]
    for k in range(2):
        for r in range(8):
            A[r, 8 + k] = 0.0
        if toe_columns and aux[A_CB + k] > 0.5:  # translation: d/dx_toe = -d/dx_g (leg k only)
            one_leg = aux.copy()
            one_leg[A_CB + 1 - k] = 0.0
            yc[0] += 1j * H_CS
            rhs(0.0, yc, one_leg, out)
            for r in range(8):
                A[r, 8 + k] = -out[r].imag / H_CS
            yc[0] = y[0]


@jit
def variational_rhs(v, aux, toe_columns, out):
    """d/dt of v = [y (8), Psi (10x6, row-major)]: f(y) and A Psi."""
    y = v[:8].copy()
    f = np.empty(8)
    rhs(0.0, y, aux, f)
    A = np.empty((8, N_W))
    augmented_jacobian(y, aux, A, toe_columns)
    out[:8] = f
    out[8:] = 0.0
    for r in range(8):
        for c in range(6):
            s = 0.0
            for k in range(N_W):
                s += A[r, k] * v[8 + 6 * k + c]
            out[8 + 6 * r + c] = s


def f_aug(w, aux) -> np.ndarray:
    """Augmented vector field [rhs(y), 0, 0] with the toes taken from w."""
    a = aux.copy()
    a[A_XB], a[A_XF] = w[8].real, w[9].real
    out = np.zeros(N_W)
    rhs(0.0, np.asarray(w[:8], dtype=float), a, out[:8])
    return out


def _hips(w, aux):
    q = np.asarray(w[:4])
    hbx, hby, _, _, hfx, hfy = body_points(q, aux, *trig(q))
    return (hbx, hby), (hfx, hfy)


def guard(kind: str, leg: int, w, aux):
    """Guard value at w (real or complex): the formulas of `hybrid.guard_values`."""
    if kind == "apex":
        return w[5]
    hx, hy = _hips(w, aux)[leg]
    lbar = aux[P_LB if leg == 0 else P_LF]
    if kind == "touchdown":
        return hy - lbar * np.cos(aux[P_GB if leg == 0 else P_GF])
    dx = hx - w[8 + leg]  # liftoff: leg length - rest length
    return np.sqrt(dx * dx + hy * hy) - lbar


def touchdown_reset(leg: int, w, aux):
    """R(w) at a touchdown of ``leg``: the toe lands at x_hip + l_bar sin(gamma_td)."""
    w = np.array(w)
    hx = _hips(w, aux)[leg][0]
    g = aux[P_GB if leg == 0 else P_GF]
    w[8 + leg] = hx + aux[P_LB if leg == 0 else P_LF] * np.sin(g)
    return w


def complex_step(fun, w) -> np.ndarray:
    """Jacobian (or gradient) of fun at real w by complex step."""
    w = np.asarray(w, dtype=float)
    cols = []
    for i in range(w.size):
        wc = w.astype(complex)
        wc[i] += 1j * H_CS
        cols.append(np.imag(fun(wc)) / H_CS)
    return np.array(cols).T


def saltation_matrix(dR, f_minus, f_plus, grad_g) -> np.ndarray:
    """S = dR + (f+ - dR f-) grad_g^T / (grad_g . f-)."""
    dR, f_minus, f_plus, grad_g = map(np.asarray, (dR, f_minus, f_plus, grad_g))
    return dR + np.outer(f_plus - dR @ f_minus, grad_g) / (grad_g @ f_minus)


def _parse(name: str) -> tuple[str, int]:
    if name == "apex":
        return "apex", -1
    kind, side = name.split("_")
    if kind not in ("touchdown", "liftoff"):
        raise ValueError(f"unexpected event {name!r} in the stride")
    return kind, _LEG[side]


def _event_function(name, toes, aux):
    """Terminal solve_ivp event for the guard of ``name`` on v = [y, Psi]."""
    kind, leg = _parse(name)

    def ev(_t, v):
        return guard(kind, leg, np.concatenate([v[:8], toes]), aux)

    ev.terminal = True
    ev.direction = 1.0 if kind == "liftoff" else -1.0
    return ev


def _event_saltation(name, w, aux, use_saltation):
    """(S, w+, aux+) for one event at w in the condition ``aux``."""
    kind, leg = _parse(name)
    aux_new = aux.copy()
    if kind == "liftoff":
        aux_new[A_CB + leg] = 0.0
        dR, w_new = np.eye(N_W), w.copy()
    else:
        aux_new[A_CB + leg] = 1.0
        dR = complex_step(lambda u: touchdown_reset(leg, u, aux), w)
        w_new = touchdown_reset(leg, w, aux)
        aux_new[A_XB + leg] = w_new[8 + leg]
    if not use_saltation:
        return dR, w_new, aux_new
    grad = complex_step(lambda u: guard(kind, leg, u, aux), w)
    return saltation_matrix(dR, f_aug(w, aux), f_aug(w_new, aux_new), grad), w_new, aux_new


def jacobian_variational(
    z,
    params: Params,
    tau: float = 0.0,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    *,
    strict: bool = False,
    backend: str = "fast",
    saltation: bool = True,
    toe_columns: bool = True,
) -> tuple[np.ndarray, dict]:
    """dP/dz (6x6, SI) at the apex state z from the variational equations of one stride.

    ``saltation`` and ``toe_columns`` exist for diagnostics: switching either off gives the
    (wrong) result of ignoring the event-time corrections or the toe sensitivities.
    ``backend`` is the `simulate_stride` back-end whose event sequence is replayed.
    Returns (DP, info) with info keys ``z1``, ``period``, ``events`` [(t, name)],
    ``eigenvalues`` (sorted by decreasing modulus), ``saltations`` (10x10, one per event
    before the apex) and ``max_event_time_error`` (re-located vs replayed event times) [s].
    """
    z = np.asarray(z, dtype=float).reshape(6)
    ref = simulate_stride(z, params, backend=backend, tau=tau, strict=strict, rtol=rtol, atol=atol)
    if not ref.ok:
        raise ValueError(f"the stride from z fails ({ref.failure}); P has no derivative there")
    groups: list[list] = []  # events at one instant, in apply_events order
    for e in ref.events:
        if groups and e.t == groups[-1][0].t:
            groups[-1].append(e)
        else:
            groups.append([e])
    order = {"liftoff": 0, "touchdown": 1, "apex": 2}
    for grp in groups:
        grp.sort(key=lambda e: (order[_parse(e.name)[0]], _parse(e.name)[1]))

    aux = make_aux(params.to_array(tau))
    w = np.zeros(N_W)
    w[:8] = state_from_z(z)
    psi = np.zeros((N_W, 6))
    psi[Z_ROWS, np.arange(6)] = 1.0  # E
    t, dt_max, events, jumps = 0.0, 0.0, [], []
    out = np.empty(8 + 6 * N_W)

    def fun(_t, v):
        variational_rhs(v, aux, toe_columns, out)
        return out.copy()

    for grp in groups:
        evs = [_event_function(e.name, w[8:].copy(), aux) for e in grp]
        v0 = np.concatenate([w[:8], psi.ravel()])
        sol = solve_ivp(
            fun, (t, grp[0].t + 0.05), v0, method="DOP853", rtol=rtol, atol=atol, events=evs
        )
        if sol.status != 1:
            raise RuntimeError(f"event {grp[0].name} near t={grp[0].t:.6f} s not re-located")
        t = float(sol.t[-1])
        dt_max = max(dt_max, abs(t - grp[0].t))
        if abs(t - grp[0].t) > EVENT_TIME_TOL:
            raise RuntimeError(f"event {grp[0].name} re-located at {t} s, reference {grp[0].t}")
        w[:8] = sol.y[:8, -1]
        psi = sol.y[8:, -1].reshape(N_W, 6).copy()
        for e in grp:
            events.append((t, e.name))
            if e.name == "apex":  # section S_apex: ydot_g = 0, dP/dz = Pz (I - f e5^T/f5) Psi
                f = f_aug(w, aux)
                proj = np.eye(N_W)
                proj[:, 5] -= f / f[5]
                dp = (proj @ psi)[Z_ROWS]
                eig = np.linalg.eigvals(dp)
                info = {
                    "z1": w[Z_ROWS].copy(),
                    "period": t,
                    "events": events,
                    "eigenvalues": eig[np.argsort(-np.abs(eig))],
                    "saltations": jumps,
                    "max_event_time_error": dt_max,
                }
                return dp, info
            S, w, aux = _event_saltation(e.name, w, aux, saltation)
            jumps.append(S)
            psi = S @ psi
    raise RuntimeError("the reference stride has no apex event")
