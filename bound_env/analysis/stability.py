"""Stability of a periodic gait: the linearised Poincare map (eqs. 19-23), e_max, recovery
from perturbations (Fig. 6) and the number of spine oscillations per stride (Fig. 5).

Jacobians. ``method="fd"`` is the paper's central difference (eq. 23) with dz = 1e-6 on every
component of z in SI units; ``method="variational"`` integrates the variational equations with
saltation matrices (`bound_env.model.variational`, imported only when asked for).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..model.numerics import MapFailure, fd_jacobian, sorted_eigenvalues  # both once defined here
from ..model.params import Params
from .poincare import StrideFailure, poincare_map, sim_options, stride

DZ = 1e-6  # central-difference step of eq. (23), SI units
RECOVERY_REL = 0.01  # Fig. 6: each component of z* perturbed by +-1 %
RECOVERY_TOL = 1e-5  # recovered once max |z - z*| < this (the paper's criterion), SI
RECOVERY_TOL_LOOSE = 1e-4  # a looser criterion, reported beside it
RECOVERY_MAX_STRIDES = 300  # bound on the strides of one recovery run
REAL_EIG_TOL = 1e-7  # |Im lambda| below this counts as a real eigenvalue


def jacobian_fd(z, params: Params, dz: float = DZ, **sim_kw) -> np.ndarray:
    """The linearised Poincare map by central differences, eqs. (22)-(23)."""
    try:
        return fd_jacobian(lambda zz: poincare_map(zz, params, **sim_kw), z, dz)
    except MapFailure as e:
        raise StrideFailure(e.reason, e.z) from e


def jacobian(z, params: Params, method: str = "fd", dz: float = DZ, **sim_kw) -> np.ndarray:
    """nabla P(z) (6x6), by ``"fd"`` (eq. 23) or ``"variational"`` (saltation matrices)."""
    if method == "fd":
        return jacobian_fd(z, params, dz=dz, **sim_kw)
    if method == "variational":
        from ..model.variational import jacobian_variational

        kw = sim_options(**sim_kw)
        try:
            out = jacobian_variational(np.asarray(z, dtype=float), params, **kw)
        except (ValueError, RuntimeError) as e:  # the stride fails or an event is lost
            raise StrideFailure(str(e), z) from e
        return np.asarray(out[0] if isinstance(out, tuple) else out, dtype=float)
    raise ValueError(f"jacobian method must be 'fd' or 'variational', got {method!r}")


@dataclass
class Stability:
    """Linear stability of a fixed point (eq. 21): stable iff every |lambda_j| < 1."""

    jacobian: np.ndarray
    eigenvalues: np.ndarray  # complex, largest modulus first
    emax: float  # max_j |lambda_j| (the paper's e_max, Fig. 4)

    @property
    def stable(self) -> bool:
        return self.emax < 1.0

    @property
    def moduli(self) -> np.ndarray:
        return np.abs(self.eigenvalues)


def stability_of(jac) -> Stability:
    lam = sorted_eigenvalues(jac)
    return Stability(jacobian=np.asarray(jac), eigenvalues=lam, emax=float(np.abs(lam[0])))


def stability(z, params: Params, method: str = "fd", dz: float = DZ, **sim_kw) -> Stability:
    """Jacobian, eigenvalues and e_max at z (a fixed point, for the result to mean much)."""
    return stability_of(jacobian(z, params, method=method, dz=dz, **sim_kw))


def eigen_counts(eigenvalues) -> tuple[int, int, int]:
    """(real eigenvalues < -1, real eigenvalues > +1, complex ones outside the unit circle).

    A change of the first count between two points of a branch is a period doubling, of the
    second a fold (or another real crossing of +1), of the third a Neimark-Sacker crossing.
    """
    lam = np.asarray(eigenvalues)
    real = np.abs(lam.imag) < REAL_EIG_TOL
    return (
        int(np.sum(real & (lam.real < -1.0))),
        int(np.sum(real & (lam.real > 1.0))),
        int(np.sum(~real & (np.abs(lam) > 1.0))),
    )


# --------------------------------------------------------------------------------------------
# Recovery from perturbations (Fig. 6)
# --------------------------------------------------------------------------------------------


@dataclass
class Recovery:
    """Strides from z* + perturbation back to within the tolerances of z* (None: never)."""

    component: int  # index into z
    rel: float  # the relative perturbation applied, e.g. +0.01
    strides: int | None  # first n with max |z_n - z*| < RECOVERY_TOL (paper's criterion)
    strides_loose: int | None  # ... < RECOVERY_TOL_LOOSE
    failure: str | None = None  # the run fell before recovering
    deviation: np.ndarray = field(default_factory=lambda: np.empty(0))  # max |z_n - z*| per n
    history: np.ndarray = field(default_factory=lambda: np.empty((0, 6)))  # z_n, SI


def recovery(
    z_star,
    params: Params,
    component: int = 0,
    rel: float = RECOVERY_REL,
    tol: float = RECOVERY_TOL,
    tol_loose: float = RECOVERY_TOL_LOOSE,
    max_strides: int = RECOVERY_MAX_STRIDES,
    **sim_kw,
) -> Recovery:
    """Perturb z*_i by a factor (1 + rel) and iterate P until back within ``tol`` (Fig. 6).

    A zero component is perturbed by ``rel`` in absolute SI units instead.
    """
    z_star = np.asarray(z_star, dtype=float)
    z = z_star.copy()
    z[component] = z[component] * (1.0 + rel) if z[component] != 0.0 else rel
    hist, dev = [z.copy()], [float(np.max(np.abs(z - z_star)))]
    n_tight = n_loose = None
    failure = None
    for n in range(1, max_strides + 1):
        res = stride(z, params, **sim_kw)
        if res.z1 is None:
            failure = res.failure
            break
        z = res.z1
        d = float(np.max(np.abs(z - z_star)))
        hist.append(z.copy())
        dev.append(d)
        if n_loose is None and d < tol_loose:
            n_loose = n
        if d < tol:
            n_tight = n
            break
    return Recovery(
        component=component,
        rel=rel,
        strides=n_tight,
        strides_loose=n_loose,
        failure=failure,
        deviation=np.array(dev),
        history=np.array(hist),
    )


def recovery_all(z_star, params: Params, rel: float = RECOVERY_REL, **kw) -> list[Recovery]:
    """`recovery` for every component of z and both signs (+-rel): 12 runs."""
    return [recovery(z_star, params, i, s * rel, **kw) for i in range(6) for s in (1.0, -1.0)]


# --------------------------------------------------------------------------------------------
# Spine oscillations (Fig. 5)
# --------------------------------------------------------------------------------------------


@dataclass
class SpineOscillations:
    """Bends of the spine over one stride, from the extrema of theta2."""

    count: float  # oscillations per stride = extrema / 2 (one max and one min each)
    extrema_t: np.ndarray  # times of the extrema [s] from the apex
    extrema_theta2: np.ndarray  # theta2 there [rad]
    extrema_phase: list  # stance condition at each extremum
    minima: int  # bends to negative theta2 relative to neighbours (local minima)
    maxima: int


def spine_oscillations(
    z,
    params: Params,
    record_dt: float = 1e-4,
    min_swing: float = math.radians(0.05),
    **sim_kw,
) -> SpineOscillations:
    """Count the spine oscillations in the stride from z (Fig. 5).

    Definition: the extrema of theta2 are the sign changes of theta2dot on a trajectory
    sampled every ``record_dt`` (plus every event); extrema whose theta2 differs from the
    previous kept extremum by less than ``min_swing`` are merged (sampling noise). On a
    periodic stride the extrema alternate between maxima and minima, and one oscillation is
    one maximum plus one minimum, so ``count = extrema / 2``; the paper's gait has 2.
    """
    res = stride(z, params, record_dt=record_dt, **sim_kw)
    if res.trajectory is None or res.failure is not None:
        raise StrideFailure(res.failure or "no trajectory", z)
    tr = res.trajectory
    th2, w2 = tr.q[:, 3], tr.qd[:, 3]
    s = np.sign(w2)
    idx = [int(i) + 1 for i in np.flatnonzero(s[1:] * s[:-1] < 0)]
    kept: list[int] = []
    for i in idx:
        if kept and abs(th2[i] - th2[kept[-1]]) < min_swing:
            kept.pop()  # a wiggle: drop both the previous extremum and this one
            continue
        kept.append(i)
    kind = [1 if w2[i - 1] > 0 else -1 for i in kept]  # rising before: a maximum
    return SpineOscillations(
        count=len(kept) / 2.0,
        extrema_t=tr.t[kept],
        extrema_theta2=th2[kept],
        extrema_phase=[tr.phase[i] for i in kept],
        minima=kind.count(-1),
        maxima=kind.count(1),
    )
