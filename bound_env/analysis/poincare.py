"""The Poincare map on S_apex (eqs. 17-18), stride iteration and the paper's convergence check.

``z = [y_g, theta1, theta2, xdot_g, theta1dot, theta2dot]`` in SI (m, rad, m/s, rad/s). One
application of the map is one apex-to-apex stride of `bound_env.model.hybrid.simulate_stride`.

Tolerances: analysis integrates with ``rtol = atol = 1e-12`` (`ANALYSIS_TOL`) unless told
otherwise. The map is then reproducible to ~1e-13, so central differences with dz = 1e-6
(eq. 23) carry a rounding error of ~1e-13 / 1e-6 = 1e-7 at most (1e-8 measured), and Newton
can drive ``|P(z) - z|`` to ~1e-13.

Apex energy. The potential of eq. (2) contains ``-(m1 + m2) g sin(alpha) x_g``, which grows
without bound down the slope; each stride starts at x_g = 0. `apex_energy` is the energy in
the slope frame *without* that term: T + (m1 + m2) g cos(alpha) y_g + kc theta2^2 / 2 at an
apex (both legs in flight, so no leg spring is loaded). Over one stride it changes by the
work of gravity along the slope, (m1 + m2) g sin(alpha) dx_g, minus the energy the spine
damper dissipates; a periodic gait balances the two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..model.dynamics import make_aux, total_energy
from ..model.hybrid import StrideResult, simulate_stride, state_from_z
from ..model.numerics import MapFailure
from ..model.params import Params

ANALYSIS_TOL = 1e-12  # rtol = atol of the integrator for every analysis stride
PAPER_STRIDES = 100  # strides simulated before the convergence check (III.D.4 C, IV.B.3)
PAPER_CONV_TOL = 1e-5  # converged iff max |z_99 - z_100| < this (SI units), ibid.


class StrideFailure(MapFailure):
    """A stride of the Poincare map failed (the robot fell, or the integration did)."""

    prefix = "stride failed"


def sim_options(**sim_kw) -> dict:
    """`simulate_stride` keyword arguments with the analysis tolerances filled in."""
    kw = dict(sim_kw)
    kw.setdefault("rtol", ANALYSIS_TOL)
    kw.setdefault("atol", ANALYSIS_TOL)
    return kw


def stride(z, params: Params, **sim_kw) -> StrideResult:
    """One stride from the apex state z (SI) at the analysis tolerances."""
    return simulate_stride(np.asarray(z, dtype=float), params, **sim_options(**sim_kw))


def poincare_map(z, params: Params, *, raise_on_failure: bool = False, **sim_kw):
    """z_1 = P(z_0) (eq. 18), SI; None if the stride fails (or `StrideFailure` if asked)."""
    res = stride(z, params, **sim_kw)
    if res.z1 is None or not np.all(np.isfinite(res.z1)):
        if raise_on_failure:
            raise StrideFailure(res.failure or "non_finite", z)
        return None
    return res.z1


def apex_energy(z, params: Params) -> float:
    """Slope-frame energy at an apex [J]: eqs. (2)-(3) at x_g = 0, ydot_g = 0, legs unloaded."""
    aux = make_aux(params.to_array())
    return float(total_energy(state_from_z(z), aux))


@dataclass
class IterationResult:
    """``strides`` strides of P from ``history[0]``; the paper's convergence verdict."""

    history: np.ndarray  # (strides + 1, 6) apex states, SI; stops at a failure
    strides: int  # strides completed
    failure: str | None = None  # why the next stride failed, if one did
    error: float = math.nan  # max |z_{n-1} - z_n| over the last completed stride (SI)
    converged: bool = False  # error < tol after all requested strides
    energy_error: float = math.nan  # apex energy of z_n minus that of z_{n-1} [J]
    energies: np.ndarray = field(default_factory=lambda: np.empty(0))  # apex energy per state

    @property
    def z_last(self) -> np.ndarray:
        return self.history[-1].copy()


def iterate(
    z,
    params: Params,
    n: int,
    *,
    tol: float = PAPER_CONV_TOL,
    energies: bool = False,
    **sim_kw,
) -> IterationResult:
    """Apply P n times from z. ``converged`` follows the paper: all n strides completed and
    max |z_{n-1} - z_n| < tol (III.D.4 step C with n = 100, tol = 1e-5)."""
    if n < 1:
        raise ValueError(f"n must be at least 1, got {n}")
    hist = [np.asarray(z, dtype=float).reshape(6).copy()]
    failure = None
    for _ in range(int(n)):
        res = stride(hist[-1], params, **sim_kw)
        if res.z1 is None or not np.all(np.isfinite(res.z1)):
            failure = res.failure or "non_finite"
            break
        hist.append(res.z1)
    h = np.array(hist)
    k = len(h) - 1
    err = float(np.max(np.abs(h[-1] - h[-2]))) if k >= 1 else math.nan
    e = np.array([apex_energy(zz, params) for zz in h]) if energies else np.empty(0)
    de = float(e[-1] - e[-2]) if energies and k >= 1 else math.nan
    return IterationResult(
        history=h,
        strides=k,
        failure=failure,
        error=err,
        converged=failure is None and k == n and err < tol,
        energy_error=de,
        energies=e,
    )


def paper_convergence(z, params: Params, **kw) -> IterationResult:
    """The paper's check: 100 strides, converged iff max |z_99 - z_100| < 1e-5."""
    return iterate(z, params, PAPER_STRIDES, tol=PAPER_CONV_TOL, **kw)
