"""Numerics on any map ``f(z) -> z | None``: the analysis, the controllers' designs and the
agents share these.

A map that returns ``None`` has failed there (a stride that fell); every function here says
what it does with such a point. Nothing in this module knows about strides or parameters.

- `fd_jacobian`: central differences (eq. 23), one-sided where one side fails.
- `newton`: damped Newton for F(u) = 0 (square, or overdetermined and consistent),
  globalised by backtracking on ||F||: the fixed points of the Poincare map with free
  parameters and pins (`bound_env.analysis.fixed_point`) and the continuation correctors.
- `map_fixed_point`: a fixed point of f by plain iteration, then Newton steps on
  f(z) - z kept while the residual falls (the closed-loop maps of `margins`, where
  one map evaluation is an episode and the map may be rough).
- `sorted_eigenvalues`: largest modulus first.
- `bisect_threshold`: the largest s at which a yes/no test still holds (`threshold_steps`,
  the same search as a generator; `run_together`: many searches, one batch of tests a step).

Following scipy.optimize, they take callables and return a result object where the outcome
is a result (``converged``/``reason``); a map that cannot be evaluated where it must is a
`MapFailure`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

NEWTON_TOL = 1e-10  # converged when max |F| <= this (SI; J for an energy pin)
NEWTON_MAX_ITER = 50  # Newton iterations
MAX_HALVINGS = 16  # line-search halvings of one Newton step before giving up
ARMIJO = 1e-4  # sufficient decrease: ||F_new|| <= (1 - ARMIJO lambda) ||F||
SINGULAR_RCOND = 1e-8  # column-scaled s_min / s_max below this: singular (FD noise ~1e-8)

MAP_SETTLE = 60  # map_fixed_point: plain iterations before Newton
MAP_NEWTON_ITERS = 8  # map_fixed_point: Newton steps
MAP_TOL = 1e-11  # map_fixed_point: done when max |f(z) - z| < this
MAP_DIVERGED = 10.0  # map_fixed_point: stop iterating once the residual grows this much


class MapFailure(RuntimeError):
    """The map failed (returned None) where a method needed its value."""

    prefix = "map failed"

    def __init__(self, reason: str, z=None):
        super().__init__(f"{self.prefix}: {reason}")
        self.reason = reason
        self.z = z


# --------------------------------------------------------------------------------------------
# Derivatives and eigenvalues
# --------------------------------------------------------------------------------------------


def fd_jacobian(fun, u, steps, *, one_sided: bool = True) -> np.ndarray:
    """Central differences of a vector function (eq. 23), one column per entry of u.

    ``fun(u)`` returns an array or None (failed). ``steps`` is one step or one per entry.
    With ``one_sided`` a side that fails is replaced by the one-sided difference from u;
    where both sides (or u itself) fail, or any side fails without ``one_sided``,
    `MapFailure` is raised.
    """
    u = np.asarray(u, dtype=float)
    f0 = None
    cols = []
    for i, h in enumerate(np.broadcast_to(steps, u.shape)):
        e = np.zeros_like(u)
        e[i] = h
        fp, fm = fun(u + e), fun(u - e)
        if fp is not None and fm is not None:
            cols.append((np.asarray(fp) - np.asarray(fm)) / (2.0 * h))
            continue
        if not one_sided:
            raise MapFailure(f"no value within {h:g} of the point (component {i})", u)
        if f0 is None:
            f0 = fun(u)
        if f0 is None:
            raise MapFailure("stride failed at the differentiation point", u)
        if fp is not None:
            cols.append((fp - f0) / h)
        elif fm is not None:
            cols.append((f0 - fm) / h)
        else:
            raise MapFailure(f"strides fail on both sides of component {i}", u)
    return np.column_stack(cols)


def sorted_eigenvalues(jac) -> np.ndarray:
    """Eigenvalues, largest modulus first (ties: positive imaginary part first)."""
    lam = np.linalg.eigvals(np.asarray(jac, dtype=float))
    return lam[np.lexsort((-lam.imag, -np.abs(lam)))]


def scaled_rcond(jac) -> float:
    """s_min / s_max of the Jacobian with unit-norm columns (independent of the units)."""
    norms = np.linalg.norm(jac, axis=0)
    if np.any(norms == 0.0):
        return 0.0
    s = np.linalg.svd(jac / norms, compute_uv=False)
    return float(s[-1] / s[0])


def inf_norm(r) -> float:
    """max |r|, inf for a failed evaluation (None)."""
    return math.inf if r is None else float(np.max(np.abs(r)))


# --------------------------------------------------------------------------------------------
# Newton for F(u) = 0, globalised by backtracking
# --------------------------------------------------------------------------------------------


@dataclass
class NewtonOutcome:
    u: np.ndarray  # last iterate (the solution when converged)
    residual: np.ndarray | None  # F(u), None if F failed at u
    converged: bool
    reason: str
    iterations: int
    jacobian: np.ndarray | None = None  # the last Jacobian of F computed
    history: list = field(default_factory=list)  # per iteration: |F|, step length lambda


def newton(
    residual,
    u0,
    steps,
    tol=NEWTON_TOL,
    max_iter=NEWTON_MAX_ITER,
    max_halvings=MAX_HALVINGS,
    jacobian=None,
) -> NewtonOutcome:
    """Solve F(u) = 0 (square, or overdetermined and consistent) by damped Newton.

    ``residual(u)`` returns F or None where it fails; ``steps`` are the central difference
    steps per unknown; ``jacobian(u)`` may replace the differences. The line search halves
    lambda until ||F(u + lambda du)||_2 <= (1 - ARMIJO lambda) ||F(u)||_2; converged when
    max |F| <= ``tol``. For the fixed points of a map f, F(z) = f(z) - z.
    """
    u = np.array(u0, dtype=float)
    r = residual(u)
    hist: list = []
    if r is None:
        return NewtonOutcome(u, None, False, "the start falls", 0, history=hist)
    jac = None
    for it in range(max_iter + 1):
        norm = inf_norm(r)
        hist.append({"residual": norm})
        if norm <= tol:
            return NewtonOutcome(u, r, True, "converged", it, jac, hist)
        if it == max_iter:
            break
        try:
            jac = jacobian(u) if jacobian is not None else fd_jacobian(residual, u, steps)
        except MapFailure as e:
            return NewtonOutcome(
                u, r, False, f"stride failed while differentiating: {e.reason}", it, jac, hist
            )
        if not np.all(np.isfinite(jac)):
            return NewtonOutcome(u, r, False, "non-finite Jacobian", it, jac, hist)
        rcond = scaled_rcond(jac)
        if jac.shape[0] == jac.shape[1] and rcond < SINGULAR_RCOND:
            return NewtonOutcome(
                u,
                r,
                False,
                f"singular Jacobian (scaled rcond {rcond:.1e}): "
                "the solution is not isolated or the pins are redundant; "
                "free fewer parameters or add a pin",
                it,
                jac,
                hist,
            )
        du = np.linalg.lstsq(jac, -r, rcond=None)[0]
        lam, n2 = 1.0, float(np.linalg.norm(r))
        for _ in range(max_halvings + 1):
            r_new = residual(u + lam * du)
            if r_new is not None and np.linalg.norm(r_new) <= (1.0 - ARMIJO * lam) * n2:
                break
            lam *= 0.5
        else:
            return NewtonOutcome(
                u,
                r,
                False,
                f"line search failed: no decrease of |F| = "
                f"{norm:.3e} along the Newton step after {max_halvings} "
                "halvings",
                it,
                jac,
                hist,
            )
        hist[-1]["lambda"] = lam
        u, r = u + lam * du, r_new
    return NewtonOutcome(
        u,
        r,
        False,
        f"no convergence in {max_iter} iterations (|F| = {inf_norm(r):.3e})",
        max_iter,
        jac,
        hist,
    )


# --------------------------------------------------------------------------------------------
# A fixed point of a rough map: iterate, then Newton while the residual falls
# --------------------------------------------------------------------------------------------


@dataclass
class MapFixedPoint:
    """The best point found by `map_fixed_point` and the map's Jacobian there."""

    z: np.ndarray
    residual: float  # max |f(z) - z|
    jacobian: np.ndarray  # of f (not of f - I) at z, central differences
    converged: bool  # residual < tol

    def __iter__(self):  # z, residual, jacobian = map_fixed_point(...)
        return iter((self.z, self.residual, self.jacobian))


def map_fixed_point(
    f,
    z0,
    steps,
    settle: int = MAP_SETTLE,
    newton_iters: int = MAP_NEWTON_ITERS,
    tol: float = MAP_TOL,
) -> MapFixedPoint:
    """Fixed point of the map f: iterate ``settle`` times (stopping early when converged or
    when the residual grows MAP_DIVERGED-fold), keep the best point, then Newton steps
    z <- z - (J - I)^-1 (f(z) - z) with J by central differences (no one-sided fallback),
    each kept only if max |f(z) - z| falls.

    Raises `MapFailure` if f fails at z0 or within a difference step of the point.
    """
    z = np.asarray(z0, dtype=float)
    fz = f(z)
    if fz is None:
        raise MapFailure("the map fails at the start point", z)
    res = np.max(np.abs(fz - z))
    best = (res, z, fz)
    for _ in range(settle):
        if res < tol:
            break
        z, fz = fz, f(fz)
        if fz is None:
            break
        res = np.max(np.abs(fz - z))
        if res < best[0]:
            best = (res, z, fz)
        elif res > MAP_DIVERGED * best[0]:
            break
    res, z, fz = best
    jac = fd_jacobian(f, z, steps, one_sided=False)
    for _ in range(newton_iters):
        if res < tol:
            break
        try:
            dz = np.linalg.solve(jac - np.eye(len(z)), -(fz - z))
        except np.linalg.LinAlgError:
            break
        z_new = z + dz
        f_new = f(z_new)
        if f_new is None:
            break
        r_new = np.max(np.abs(f_new - z_new))
        if r_new >= res:
            break
        z, fz, res = z_new, f_new, r_new
        jac = fd_jacobian(f, z, steps, one_sided=False)
    return MapFixedPoint(z=z, residual=float(res), jacobian=jac, converged=bool(res < tol))


# --------------------------------------------------------------------------------------------
# Bisection of a yes/no threshold
# --------------------------------------------------------------------------------------------


def bisect_threshold(
    ok,
    lo: float,
    hi: float,
    iters: int,
    log: bool = True,
    grow: bool = False,
    cap: float = math.inf,
):
    """Largest s in [lo, hi] with ``ok(s)``, assuming ok holds below a threshold and fails
    above. Returns (s, capped): (hi, True) if ok(hi); (0.0, False) if not ok(lo); else the
    last ``ok`` point after ``iters`` bisection steps (on log s if ``log``, else linear).

    Calls: ok(hi), ok(lo), then one per step, in that order. Extensions (for example
    growing ``hi`` while ok(hi) holds, for an uncapped basin) belong here as keyword
    arguments whose defaults keep this behaviour.

    With ``grow`` (the uncapped basin of `margins`), an ``ok(hi)`` does not stop the
    search: the bracket grows by doubling from the last success (2 hi, 4 hi, ..., never
    beyond ``cap``) until ok fails, then bisects between the last success and the first
    failure; (cap, True) if ok still holds at ``cap``.

    The search itself is `threshold_steps` (the same points, in the same order): this runs
    it with ``ok``; `run_together` runs many such searches with one batch of tests per step.
    """
    return run_together([threshold_steps(lo, hi, iters, log, grow, cap)], lambda s: [ok(s[0])])[0]


def threshold_steps(
    lo: float, hi: float, iters: int, log: bool = True, grow: bool = False, cap: float = math.inf
):
    """`bisect_threshold` as a generator: it yields each point s to test, is sent ok(s), and
    returns (s, capped)."""
    if (yield hi):
        if not grow:
            return hi, True
        lo = hi
        while True:
            if lo >= cap:
                return lo, True
            nxt = min(2.0 * lo, cap)
            if (yield nxt):
                lo = nxt
            else:
                hi = nxt
                break
    elif not (yield lo):
        return 0.0, False
    for _ in range(iters):
        mid = math.sqrt(lo * hi) if log else 0.5 * (lo + hi)
        if (yield mid):
            lo = mid
        else:
            hi = mid
    return lo, False


def run_together(searches, test_many) -> list:
    """Run generator searches in lockstep: each yields a query and is sent its answer, until
    it returns. At every step the pending queries of all searches are answered by one call
    ``test_many(queries) -> answers`` (the same order), so a caller can answer them as one
    batch (robots advanced together). Returns each search's return value, in order. Each
    search sees exactly the answers it would see alone: its queries and result are its own."""
    searches = list(searches)
    results: list = [None] * len(searches)
    pending = {}
    for k, g in enumerate(searches):
        try:
            pending[k] = next(g)
        except StopIteration as e:
            results[k] = e.value
    while pending:
        keys = list(pending)
        answers = list(test_many([pending[k] for k in keys]))
        if len(answers) != len(keys):
            raise ValueError(f"test_many answered {len(answers)} of {len(keys)} queries")
        for k, a in zip(keys, answers, strict=True):
            try:
                pending[k] = searches[k].send(a)
            except StopIteration as e:
                results[k] = e.value
                del pending[k]
    return results
