"""Linearized stride map and the classical gain designs (LQR, deadbeat).

The controlled stride map z_{k+1} = P(z_k, u_k) (`bound_env.sim.stride_task.StrideSimulator`) is
linearized at the passive fixed point z* with u = 0:

    z_{k+1} - z* ~ A (z_k - z*) + B u_k,   A = dP/dz (6 x 6, SI),  B = dP/du (6 x K),

A and B by central differences through the simulator (``jacobian="fd"``), or A from the exact
variational equations with saltation matrices (`bound_env.model.variational`,
``jacobian="variational"``; B is always by central differences, the torque being a parameter).

The designs work in normalized apex coordinates x = S (z - z*) with S = diag(1 / s) and s the
apex scales of the tasks (about the passive basin's half-width per component), so that the
weights Q are comparable across components: A_n = S A S^-1, B_n = S B, and the gain in SI
units is G = G_n S, u = sat(-G (z - z*)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FD_REL_Z = 1e-5  # central-difference step in z, relative to max(|z*_i|, FD_FLOOR_Z_i)
FD_FLOOR_Z = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1])  # SI floors of the step scale
FD_U = 1e-4  # central-difference step in each coefficient u_i (normalized)
DESIGN_RTOL = 1e-12  # integrator tolerance of the linearization


@dataclass
class Linearization:
    """A, B of the stride map at (z*, u = 0), SI."""

    A: np.ndarray
    B: np.ndarray
    z_ref: np.ndarray
    method: str

    def normalized(self, scales) -> tuple[np.ndarray, np.ndarray]:
        """(A_n, B_n) in the coordinates x = (z - z*) / scales."""
        s = np.asarray(scales, dtype=float)
        return self.A * s[None, :] / s[:, None], self.B / s[:, None]


def central_jacobian(f, x0, steps) -> np.ndarray:
    """Jacobian of f at x0 by central differences (`bound_env.model.numerics.fd_jacobian`);
    ValueError if f fails (returns None) at a probe."""
    from ..model.numerics import MapFailure, fd_jacobian

    try:
        return fd_jacobian(f, x0, steps, one_sided=False)
    except MapFailure as e:
        raise ValueError(
            f"the stride map fails near the linearization point ({e}): no linearization there"
        ) from None


def linearize(sim, z_ref, jacobian: str = "fd") -> Linearization:
    """A, B of ``sim`` (a `StrideSimulator`) at (z_ref, u = 0)."""
    z_ref = np.asarray(z_ref, dtype=float)
    u0 = np.zeros(sim.basis.K)
    if jacobian == "fd":
        steps = FD_REL_Z * np.maximum(np.abs(z_ref), FD_FLOOR_Z)
        A = central_jacobian(lambda z: sim.map(z, u0), z_ref, steps)
    elif jacobian == "variational":
        from ..model.variational import jacobian_variational

        A, _ = jacobian_variational(z_ref, sim.params, rtol=sim.rtol, atol=sim.rtol)
    else:
        raise ValueError(f"jacobian must be 'fd' or 'variational', got {jacobian!r}")
    B = central_jacobian(lambda u: sim.map(z_ref, u), u0, np.full(sim.basis.K, FD_U))
    return Linearization(A, B, z_ref, jacobian)


def spectral_radius(M) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(np.asarray(M, dtype=float)))))


def lqr_gain(A_n, B_n, Q, R) -> np.ndarray:
    """Discrete LQR gain G_n (K x 6) for x+ = A_n x + B_n u, cost sum x'Qx + u'Ru.

    ValueError, saying so, if the discrete Riccati equation has no stabilizing solution.
    """
    from scipy.linalg import solve_discrete_are

    Q = np.asarray(Q, dtype=float)
    R = np.asarray(R, dtype=float)
    try:
        P = solve_discrete_are(A_n, B_n, Q, R)
    except (np.linalg.LinAlgError, ValueError) as e:
        raise ValueError(
            f"the discrete Riccati equation has no stabilizing solution for "
            f"these Q, R and basis ({e})"
        ) from None
    if not np.all(np.isfinite(P)):
        raise ValueError(
            "the discrete Riccati equation has no stabilizing solution for these "
            "Q, R and basis (non-finite solution)"
        )
    G = np.linalg.solve(R + B_n.T @ P @ B_n, B_n.T @ P @ A_n)
    rho = spectral_radius(A_n - B_n @ G)
    if not rho < 1.0:
        raise ValueError(
            f"the discrete Riccati equation has no stabilizing solution for these "
            f"Q, R and basis (closed-loop spectral radius {rho:.4g} >= 1)"
        )
    return G


def deadbeat_gain(A_n, B_n, rank_tol: float = 1e-8) -> np.ndarray:
    """One-stride deadbeat gain: G_n = pinv(B_n) A_n, so A_n - B_n G_n = 0 (every closed-loop
    eigenvalue at 0), the minimum-norm such gain. Needs rank B_n = 6 (K >= 6 independent
    basis functions); ValueError otherwise."""
    sv = np.linalg.svd(B_n, compute_uv=False)
    rank = int(np.sum(sv > rank_tol * sv[0])) if sv.size else 0
    if rank < A_n.shape[0]:
        raise ValueError(
            f"deadbeat needs B of rank {A_n.shape[0]} (K >= {A_n.shape[0]} "
            f"independent basis functions); this basis has K={B_n.shape[1]} and "
            f"rank {rank}: use more windows, or lqr"
        )
    return np.linalg.pinv(B_n) @ A_n
