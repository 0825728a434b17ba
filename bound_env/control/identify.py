"""Identifying a robot's plant from its strides: the eight factors through the stride map.

A robot that observes its apex states z_k and knows the interval actions a_k it commanded
sees transitions (z_k, a_k, z_{k+1}). Its plant differs from the model by the factors
f = (m1, m2, I1, I2, kb, kf, kc, zeta) / nominal (`bound_env.model.mismatch.EIGHT`), and

    z_{k+1} = P(z_k, a_k; f) + noise

with P the stride map on the plant of the factors f (the step env's, `bound_env.sim.stride_map`;
all transitions and all probes of one fitting step in one batch of strides, each row on
its own parameters). `PlantIdentifier.fit` is maximum a posteriori in theta = log f with a
Gaussian prior theta ~ N(0, prior^2) toward the nominal plant and Gaussian errors of standard
deviation ``sigma`` on the normalized apex components (z - z*) / s:

    min_theta  sum_k |(P(z_k, a_k; e^theta) - z_{k+1}) / (s sigma)|^2 + |theta / prior|^2,

by Levenberg-Marquardt with the Jacobian of the residuals by central differences in theta.
The posterior covariance (J'J + I / prior^2)^-1 in theta comes with the estimate. The prior
keeps the fit well posed with few transitions: with zero torque, scaling every mass, inertia
and stiffness by one factor leaves the dynamics unchanged (only the actuator's torque is not
scaled), so passive strides cannot see that direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.dynamics import make_aux
from ..model.mismatch import EIGHT, plant_params, plant_values
from ..model.params import load_gait
from ..sim.stride_map import StrideMap

FD_THETA = 1e-4  # central-difference step in each log factor
FAILED_RESIDUAL = 10.0  # normalized residual of a transition that falls on a trial plant
MAX_HALVINGS = 8  # rejected Levenberg-Marquardt steps (damping x4 each) before stopping
MAX_STEP = 0.1  # a step's largest change of one log factor
LM_MU0 = 1e-3  # Levenberg-Marquardt's first damping (relative to diag of the normal matrix)
SEARCH_SPAN = 2.0  # the search's candidates lie within this many prior standard deviations


@dataclass
class Fit:
    """The estimate after `PlantIdentifier.fit`."""

    theta: np.ndarray  # log factors (8,)
    cov: np.ndarray  # posterior covariance in theta (8, 8)
    cost: float  # the fit's cost (residuals and prior)
    rms: float  # root mean square of the normalized residuals (z - P) / s
    transitions: int
    # the posterior's standard deviation of the predicted apex (normalized), the largest over
    # the fitted strides' components: sqrt(diag(J cov J')); small once the data pin down what
    # the strides depend on (directions they cannot see do not count)
    pred_std: float = math.nan

    @property
    def factors(self) -> dict:
        return dict(zip(EIGHT, np.exp(self.theta).tolist(), strict=True))

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.cov), 0.0))


class PlantIdentifier:
    """The MAP fit of the eight factors to transitions (module docstring) on ``gait``'s stride
    map at the control interval ``dt``, the saturation ``max_torque`` and the integrator
    tolerance ``rtol`` (runs of equal interval actions as one segment: the MPC's planning
    map)."""

    def __init__(
        self,
        gait="default",
        dt: float = 0.01,
        max_torque: float = 80.0,
        rtol: float = 1e-8,
        prior: float = 0.1,
        sigma: float = 0.01,
        candidates: int = 128,
    ):
        from ..sim.task import APEX_SCALES

        self.nominal = load_gait(gait).params
        self.map = StrideMap(gait, None, dt, max_torque, rtol, segments=True)
        self.scales = np.asarray(APEX_SCALES, dtype=float)
        self.prior, self.sigma = float(prior), float(sigma)
        self.candidates = self.sobol(candidates)
        self.chunk: int | None = None  # at most this many strides in one batch (None: any)

    def sobol(self, n: int) -> np.ndarray:
        """``n`` starting points of the search in theta: a scrambled Sobol set (seed 0) in the
        cube of +-`SEARCH_SPAN` prior standard deviations (deterministic)."""
        from scipy.stats import qmc

        if n <= 0:
            return np.zeros((0, len(EIGHT)))
        u = qmc.Sobol(len(EIGHT), seed=0).random(int(n))
        return (2.0 * u - 1.0) * SEARCH_SPAN * self.prior

    def params(self, theta):
        """The `Params` of the factors e^theta."""
        return plant_params(self.nominal, dict(zip(EIGHT, np.exp(theta).tolist(), strict=True)))

    def overrides(self, theta) -> dict:
        """The gait-file values of the factors e^theta (for `StrideMap`'s gait_overrides)."""
        v = plant_values(self.params(theta))
        return {k: v[k] for k in EIGHT}

    def predict(self, Z, A, thetas) -> np.ndarray:
        """z1 of the strides from Z[i] with the interval actions A[i] on the plant e^thetas[i]
        (NaN where a stride fails)."""
        aux = np.array([make_aux(self.params(t).to_array()) for t in np.atleast_2d(thetas)])
        Z, A = np.atleast_2d(Z), np.atleast_2d(A)
        c = self.chunk
        if c is None or len(Z) <= c:
            return self.map.run(Z, A, aux=aux).z1
        # in batches of at most ``chunk`` strides (each row's stride is its own: the same z1)
        parts = [self.map.run(Z[i : i + c], A[i : i + c], aux=aux[i : i + c]).z1
                 for i in range(0, len(Z), c)]  # fmt: skip
        return np.concatenate(parts)

    def residuals(self, Z, A, Z1, theta) -> np.ndarray:
        """(n, 6): (P(z_k, a_k; e^theta) - z_{k+1}) / s (`FAILED_RESIDUAL` where it falls)."""
        n = len(Z)
        r = (self.predict(Z, A, np.tile(theta, (n, 1))) - Z1) / self.scales
        return np.where(np.isfinite(r), r, FAILED_RESIDUAL)

    def _residuals_and_jacobian(self, Z, A, Z1, theta):
        n, p = len(Z), len(theta)
        T = np.tile(theta, (1 + 2 * p, 1))
        T[1 : 1 + p] += FD_THETA * np.eye(p)
        T[1 + p :] -= FD_THETA * np.eye(p)
        rows = np.repeat(np.arange(n), 1 + 2 * p)
        thetas = np.tile(T, (n, 1))
        z1 = self.predict(Z[rows], A[rows], thetas).reshape(n, 1 + 2 * p, 6)
        r = (z1[:, 0] - Z1) / self.scales
        J = (z1[:, 1 : 1 + p] - z1[:, 1 + p :]) / (2.0 * FD_THETA) / self.scales  # (n, p, 6)
        ok = np.isfinite(r).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
        r = np.where(ok[:, None], r, FAILED_RESIDUAL)
        J = np.where(ok[:, None, None], J, 0.0)
        return r.reshape(-1), J.transpose(0, 2, 1).reshape(-1, p)

    def cost(self, r, theta) -> float:
        return float(np.sum((r / self.sigma) ** 2) + np.sum((theta / self.prior) ** 2))

    def costs(self, Z, A, Z1, thetas) -> np.ndarray:
        """The fit's cost (`cost`) of each row of ``thetas`` on the transitions, in one batch
        of len(thetas) x len(Z) strides."""
        thetas = np.atleast_2d(thetas)
        m, n = len(thetas), len(Z)
        z1 = self.predict(np.tile(Z, (m, 1)), np.tile(A, (m, 1)), np.repeat(thetas, n, axis=0))
        r = (z1 - np.tile(Z1, (m, 1))) / self.scales
        r = np.where(np.isfinite(r), r, FAILED_RESIDUAL).reshape(m, -1)
        return np.sum((r / self.sigma) ** 2, axis=1) + np.sum((thetas / self.prior) ** 2, axis=1)

    def fit(self, Z, A, Z1, theta0=None, iters: int = 10, search: int = 0) -> Fit:
        """The MAP estimate from the transitions (Z[k], A[k]) -> Z1[k] (A: interval actions,
        rows padded with their last action): at most ``iters`` Levenberg-Marquardt steps
        (each at most `MAX_STEP` in every log factor) from ``theta0`` (default: the nominal
        plant). The cost has local minima away from the truth: ``search`` > 0 also descends
        from the ``search`` cheapest of the candidates (`candidates`: a scrambled Sobol set
        within `SEARCH_SPAN` prior standard deviations, the nominal plant and ``theta0``),
        and keeps the cheapest end."""
        Z, A, Z1 = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (Z, A, Z1))
        p = len(EIGHT)
        start = np.zeros(p) if theta0 is None else np.asarray(theta0, dtype=float)
        best = self._descend(Z, A, Z1, start, iters)
        if search > 0:
            C = np.vstack([self.candidates, np.zeros(p)])
            for j in np.argsort(self.costs(Z, A, Z1, C), kind="stable")[:search]:
                other = self._descend(Z, A, Z1, C[j], iters)
                if other.cost < best.cost:
                    best = other
        return best

    def _descend(self, Z, A, Z1, theta, iters: int) -> Fit:
        p = len(theta)
        theta = theta.copy()
        w, wp = 1.0 / self.sigma**2, 1.0 / self.prior**2
        r, J = self._residuals_and_jacobian(Z, A, Z1, theta)
        c = self.cost(r, theta)
        mu = LM_MU0
        for _ in range(iters):
            H = w * J.T @ J + wp * np.eye(p)
            g = w * J.T @ r + wp * theta
            moved = False
            for _h in range(MAX_HALVINGS):
                step = -np.linalg.solve(H + mu * np.diag(np.diag(H)), g)
                big = np.max(np.abs(step))
                if big > MAX_STEP:
                    step *= MAX_STEP / big
                t_new = theta + step
                r_new = self.residuals(Z, A, Z1, t_new).reshape(-1)
                c_new = self.cost(r_new, t_new)
                if c_new < c:
                    moved = True
                    mu = max(mu / 3.0, 1e-9)
                    break
                mu *= 4.0
            if not moved:
                break
            theta = t_new
            r, J = self._residuals_and_jacobian(Z, A, Z1, theta)
            c_old, c = c, self.cost(r, theta)
            if np.max(np.abs(step)) < 1e-7 or c_old - c < 1e-9 * c_old:
                break
        H = w * J.T @ J + wp * np.eye(p)
        rms = float(math.sqrt(np.mean(r**2))) if r.size else 0.0
        cov = np.linalg.inv(H)
        var = np.sum((J @ cov) * J, axis=1)
        pred = float(math.sqrt(max(float(np.max(var)), 0.0))) if var.size else math.nan
        return Fit(theta, cov, c, rms, len(Z), pred)
