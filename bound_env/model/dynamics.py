"""Equations of motion of the two-body bounding model (paper Sec. III.C, eqs. 1-16).

Small pure functions, compiled with Numba so that both integrator back-ends (and the
environment) evaluate exactly the same equations.

Conventions (see the sketch in docs/model.md):

- Slope-aligned frame: x along the slope, downhill = forward; y normal to it, ground y = 0.
  Gravity is (g sin alpha, -g cos alpha) per unit mass (eq. 2).
- q = [x_g, y_g, theta1, theta2]: centre of mass of the whole robot, pitch of the back body
  (positive raises the front, as eqs. 1 and 5-8 imply), front body relative to the back.
- Back hip at the rear end of the back body, front hip at the front end of the front body,
  spine joint between them (eqs. 13-14).
- Leg angle gamma is measured from the slope normal, positive with the toe ahead of the hip;
  at touchdown the toe lands at x_hip + l_bar sin(gamma_td).

The state vector is y = [q, qdot] (8 floats). ``aux`` is the parameter vector of
`bound_env.model.params.Params.to_array` followed by the contact state (indices ``A_*``).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .params import (  # A_* and N_AUX are re-exported from here
    A_CB,
    A_CF,
    A_XB,
    A_XF,
    N_AUX,
    N_PARAMS,
    P_ALPHA,
    P_CC,
    P_G,
    P_GX,
    P_GY,
    P_I1,
    P_I2,
    P_KB,
    P_KC,
    P_KF,
    P_L1,
    P_L2,
    P_LB,
    P_LF,
    P_M1,
    P_M2,
    P_TAU,
)

# No fast-math: with ``reassoc``/``contract`` LLVM may reorder sums and fuse multiply-adds
# differently when a function is compiled with its callers than when it is loaded from the
# cache, so the last bits of a stride depended on the cache's history (docs/developers.md,
# "Same commit, same numbers"). IEEE arithmetic in source order rounds the same everywhere.
jit = nb.njit(cache=True, error_model="numpy")


def make_aux(p: np.ndarray, back_stance=False, front_stance=False, x_toe_b=0.0, x_toe_f=0.0):
    """Parameter vector plus contact state, as the right-hand side reads it."""
    aux = np.zeros(N_AUX)
    aux[:N_PARAMS] = p
    aux[A_CB], aux[A_CF], aux[A_XB], aux[A_XF] = back_stance, front_stance, x_toe_b, x_toe_f
    return aux


@jit
def mass_fractions(aux):
    """mu1 = m2/(m1+m2), mu2 = m1/(m1+m2): the COM offsets of eqs. (5)-(8)."""
    m = aux[P_M1] + aux[P_M2]
    return aux[P_M2] / m, aux[P_M1] / m


@jit
def trig(q):
    """(sin th1, cos th1, sin phi, cos phi) with phi = th1 + th2, the front body's pitch."""
    th1, phi = q[2], q[2] + q[3]
    return np.sin(th1), np.cos(th1), np.sin(phi), np.cos(phi)


@jit
def body_points(q, aux, s1, c1, sp, cp):
    """Back hip, spine joint and front hip (eqs. 5-8, 13-14), from precomputed `trig`.

    Back hip = rear end of the back body (x1 - l1 cos th1, y1 - l1 sin th1); spine joint =
    front end of the back body (x1 + l1 cos th1, y1 + l1 sin th1); front hip = front end of
    the front body (x2 + l2 cos phi, y2 + l2 sin phi).
    """
    mu1, mu2 = mass_fractions(aux)
    l1, l2 = aux[P_L1], aux[P_L2]
    rx = l1 * c1 + l2 * cp  # COM of the back body -> COM of the front body
    ry = l1 * s1 + l2 * sp
    x1, y1 = q[0] - mu1 * rx, q[1] - mu1 * ry  # eqs. (5)-(6)
    x2, y2 = q[0] + mu2 * rx, q[1] + mu2 * ry  # eqs. (7)-(8)
    return (x1 - l1 * c1, y1 - l1 * s1, x1 + l1 * c1, y1 + l1 * s1, x2 + l2 * cp, y2 + l2 * sp)


@jit
def back_hip(q, aux):
    """Back hip (x, y): the rear end of the back body."""
    p = body_points(q, aux, *trig(q))
    return p[0], p[1]


@jit
def spine_joint(q, aux):
    """Spine joint (x, y): the front end of the back body."""
    p = body_points(q, aux, *trig(q))
    return p[2], p[3]


@jit
def front_hip(q, aux):
    """Front hip (x, y): the front end of the front body."""
    p = body_points(q, aux, *trig(q))
    return p[4], p[5]


@jit
def hip_velocities(y, aux):
    """Velocities of the back and front hips: (vbx, vby, vfx, vfy)."""
    mu1, mu2 = mass_fractions(aux)
    l1, l2 = aux[P_L1], aux[P_L2]
    th1, phi = y[2], y[2] + y[3]
    w1, wphi = y[6], y[6] + y[7]
    # d/dt of r = l1 e(th1) + l2 e(phi), with e' = (-sin, cos)
    rdx = -l1 * np.sin(th1) * w1 - l2 * np.sin(phi) * wphi
    rdy = l1 * np.cos(th1) * w1 + l2 * np.cos(phi) * wphi
    vbx = y[4] - mu1 * rdx + l1 * np.sin(th1) * w1
    vby = y[5] - mu1 * rdy - l1 * np.cos(th1) * w1
    vfx = y[4] + mu2 * rdx - l2 * np.sin(phi) * wphi
    vfy = y[5] + mu2 * rdy + l2 * np.cos(phi) * wphi
    return vbx, vby, vfx, vfy


@jit
def leg_back(q, aux):
    """Back leg: length l_b and unit vector toe->hip (eqs. 10, 13-14: l_b = sqrt(A^2 + C^2))."""
    hx, hy = back_hip(q, aux)
    dx, dy = hx - aux[A_XB], hy  # (-A, C)
    lb = np.sqrt(dx * dx + dy * dy)
    return lb, dx / lb, dy / lb


@jit
def leg_front(q, aux):
    """Front leg: length l_f and unit vector toe->hip (eqs. 11, 13-14: l_f = sqrt(B^2 + D^2))."""
    hx, hy = front_hip(q, aux)
    dx, dy = hx - aux[A_XF], hy  # (-B, D)
    lf = np.sqrt(dx * dx + dy * dy)
    return lf, dx / lf, dy / lf


@jit
def rotational_inertia(th2, aux):
    """Entries (M33, M34, M44) of the mass matrix at spine angle th2."""
    return rotational_inertia_c2(np.cos(th2), aux)


@jit
def rotational_inertia_c2(c2, aux):
    """Entries (M33, M34, M44) of the mass matrix (eq. 3 in q coordinates).

    T = 1/2 (m1+m2)|v_g|^2 + 1/2 mu |r_dot|^2 + 1/2 I1 th1d^2 + 1/2 I2 (th1d+th2d)^2 with the
    reduced mass mu = m1 m2/(m1+m2): translation and rotation decouple.
    """
    m1, m2 = aux[P_M1], aux[P_M2]
    l1, l2 = aux[P_L1], aux[P_L2]
    mu = m1 * m2 / (m1 + m2)
    a = mu * l1 * l1 + aux[P_I1]
    b = mu * l2 * l2 + aux[P_I2]
    c = mu * l1 * l2 * c2
    return a + b + 2.0 * c, b + c, b


@jit
def generalized_forces(y, aux):
    """Q = -dV/dq - dDelta/dqdot + [0, 0, 0, tau] (eqs. 2, 4, 15), for the current contacts."""
    mu1, mu2 = mass_fractions(aux)
    m = aux[P_M1] + aux[P_M2]
    l1, l2 = aux[P_L1], aux[P_L2]
    s1, c1, sp, cp = trig(y)
    hbx, hby, _, _, hfx, hfy = body_points(y, aux, s1, c1, sp, cp)
    qx = m * aux[P_GX]  # gravity (g sin alpha, -g cos alpha), eq. (2)
    qy = -m * aux[P_GY]
    q1 = 0.0
    q2 = -aux[P_KC] * y[3] - aux[P_CC] * y[7] + aux[P_TAU]
    if aux[A_CB] > 0.5:  # back leg spring, eqs. (10), (13)-(14): Q = -k_b (l_b - lb_bar) dl_b/dq
        dx, dy = hbx - aux[A_XB], hby
        lb = np.sqrt(dx * dx + dy * dy)
        f = -aux[P_KB] * (lb - aux[P_LB]) / lb
        # d(back hip)/d th1 and /d th2
        j1x = (mu1 + 1.0) * l1 * s1 + mu1 * l2 * sp
        j1y = -(mu1 + 1.0) * l1 * c1 - mu1 * l2 * cp
        j2x = mu1 * l2 * sp
        j2y = -mu1 * l2 * cp
        qx += f * dx
        qy += f * dy
        q1 += f * (dx * j1x + dy * j1y)
        q2 += f * (dx * j2x + dy * j2y)
    if aux[A_CF] > 0.5:  # front leg spring, eqs. (11), (13)-(14)
        dx, dy = hfx - aux[A_XF], hfy
        lf = np.sqrt(dx * dx + dy * dy)
        f = -aux[P_KF] * (lf - aux[P_LF]) / lf
        # d(front hip)/d th1 and /d th2
        j1x = -mu2 * l1 * s1 - (mu2 + 1.0) * l2 * sp
        j1y = mu2 * l1 * c1 + (mu2 + 1.0) * l2 * cp
        j2x = -(mu2 + 1.0) * l2 * sp
        j2y = (mu2 + 1.0) * l2 * cp
        qx += f * dx
        qy += f * dy
        q1 += f * (dx * j1x + dy * j1y)
        q2 += f * (dx * j2x + dy * j2y)
    return qx, qy, q1, q2, s1, c1, sp, cp


@jit
def rhs(t, y, aux, out):
    """dy/dt for the current stance condition: M(q) qddot + h(q, qdot) = Q (eq. 15)."""
    m1, m2 = aux[P_M1], aux[P_M2]
    qx, qy, q1, q2, s1, c1, sp, cp = generalized_forces(y, aux)
    s2, c2 = sp * c1 - cp * s1, cp * c1 + sp * s1  # sin, cos of th2 = phi - th1
    mu = m1 * m2 / (m1 + m2)
    k = mu * aux[P_L1] * aux[P_L2] * s2
    m33, m34, m44 = rotational_inertia_c2(c2, aux)
    w1, wphi = y[6], y[6] + y[7]
    # velocity terms from the theta2-dependence of M (Christoffel symbols)
    r1 = q1 - k * (w1 * w1 - wphi * wphi)
    r2 = q2 - k * w1 * w1
    det = m33 * m44 - m34 * m34
    out[0] = y[4]
    out[1] = y[5]
    out[2] = y[6]
    out[3] = y[7]
    out[4] = qx / (m1 + m2)
    out[5] = qy / (m1 + m2)
    out[6] = (m44 * r1 - m34 * r2) / det
    out[7] = (m33 * r2 - m34 * r1) / det


@jit
def kinetic_energy(y, aux):
    """T of eq. (3)."""
    m = aux[P_M1] + aux[P_M2]
    m33, m34, m44 = rotational_inertia(y[3], aux)
    w1, w2 = y[6], y[7]
    return 0.5 * m * (y[4] * y[4] + y[5] * y[5]) + 0.5 * (
        m33 * w1 * w1 + 2.0 * m34 * w1 * w2 + m44 * w2 * w2
    )


@jit
def potential_energy(y, aux):
    """V_sigma of eq. (2) for the current contacts (sum m_i y_i = (m1+m2) y_g)."""
    m = aux[P_M1] + aux[P_M2]
    g, alpha = aux[P_G], aux[P_ALPHA]
    v = m * g * (y[1] * np.cos(alpha) - y[0] * np.sin(alpha)) + 0.5 * aux[P_KC] * y[3] ** 2
    if aux[A_CB] > 0.5:
        lb = leg_back(y, aux)[0]
        v += 0.5 * aux[P_KB] * (lb - aux[P_LB]) ** 2
    if aux[A_CF] > 0.5:
        lf = leg_front(y, aux)[0]
        v += 0.5 * aux[P_KF] * (lf - aux[P_LF]) ** 2
    return v


@jit
def total_energy(y, aux):
    """T + V_sigma [J]."""
    return kinetic_energy(y, aux) + potential_energy(y, aux)


def accelerations(y, aux) -> np.ndarray:
    """qddot at state y (a convenience wrapper around `rhs` for Python callers)."""
    out = np.empty(8)
    rhs(0.0, np.asarray(y, dtype=float), aux, out)
    return out[4:]
