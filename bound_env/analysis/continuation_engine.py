"""The continuation engine: natural and pseudo-arclength continuation of the fixed points of
the Poincare map along any scalar path (a gait key's value, ln kc, a homotopy parameter).

- `natural`: step s, predict u by the secant of the last two points, correct at the new s
  (`FixedPointPath.correct`); cannot pass a fold; an ``on_stall`` hook (the paper's fallback
  ladder, `bound_env.analysis.reproduce.paths`) may go on where the step stalls.
- `arclength` (pseudo-arclength): unknowns v = [u, (s - origin) / scale], predictor along the
  unit chord of the last two points, corrector with the extra condition t . (v - v_k) = ds.

Both are bounded (``max_points``; steps halve on a failed corrector down to a minimum) and
return a `Stop` saying why they stopped. `bound_env.analysis.continuation` traces a branch with
them (`continue_branch`: analysis of each point, bifurcation flags, files, plot).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..model.numerics import NewtonOutcome, newton
from ..model.params import Params
from .fixed_point import NEWTON_TOL, make_residual, param_step
from .stability import DZ

CORRECTOR_MAX_ITER = 12  # Newton iterations per corrector before the step is halved
GROW = 1.5  # step growth after an easy corrector (<= EASY_ITER iterations)
EASY_ITER = 3
MAX_POINTS = 400  # bound on the points of one branch
TARGET_TOL = 1e-12  # the target is reached within this (natural continuation; x max(1, |to|))
JUMP_FACTOR = 5.0  # natural: reject a correction moving z more than this x the last change
JUMP_FLOOR = 1e-2  # ... or more than this (SI), whichever is larger


@dataclass
class FixedPointPath:
    """Fixed points of the map along a scalar s: the unknowns u = [z (SI), freed values] solve
    F(u; s) = [P(z) - z, pins] = 0 at the parameters ``params_of(s)`` (which may raise
    ValueError for an invalid value). s is any coordinate: a gait key's value, ln kc, a
    homotopy parameter. The fallback ladder changes ``params_of`` as it goes."""

    params_of: Callable[[float], Params]
    free: tuple = ()
    pins: list = field(default_factory=list)
    sim_kw: dict = field(default_factory=dict)
    tol: float = NEWTON_TOL
    dz: float = DZ

    def params_at(self, s: float, u) -> Params:
        """The parameters at s with the freed values of u."""
        p = self.params_of(s)
        return p.with_values(**dict(zip(self.free, (float(x) for x in u[6:]), strict=True)))

    def residual_at(self, s: float):
        """F(.; s), or a function returning None everywhere if s is not a valid value."""
        try:
            p = self.params_of(s)
        except ValueError:
            return lambda u: None
        return make_residual(p, self.free, self.pins, self.sim_kw)

    def steps_of(self, u) -> np.ndarray:
        """Central-difference steps of the unknowns (eq. 23; `param_step` for freed values)."""
        freed = [param_step(k, u[6 + i], self.dz) for i, k in enumerate(self.free)]
        return np.concatenate([np.full(6, self.dz), freed])

    def correct(self, s: float, u_pred, max_iter: int = CORRECTOR_MAX_ITER) -> NewtonOutcome:
        """Newton at fixed s from the prediction."""
        try:
            self.params_of(s)
        except ValueError as e:
            return NewtonOutcome(np.asarray(u_pred, dtype=float), None, False, str(e), 0)
        return newton(
            self.residual_at(s),
            np.asarray(u_pred, dtype=float),
            self.steps_of(u_pred),
            tol=self.tol,
            max_iter=max_iter,
        )


@dataclass(frozen=True)
class StepControl:
    """Step sizes of natural continuation, in units of s."""

    first: float  # first step
    largest: float  # steps grow up to this
    smallest: float  # a step halved below this stalls the continuation
    guard_first_step: bool = False  # without a secant yet, reject corrections > JUMP_FLOOR too
    target_tol: float = TARGET_TOL  # reached when |s_to - s| <= this


@dataclass
class Stop:
    """Why a continuation stopped: ``kind`` is "reached", "stalled" (the step fell below its
    minimum; ``info`` is the corrector's last reason), "max_points", "turned_back" (past the
    start, arclength only) or the message of an ``on_stall`` hook that gave up."""

    kind: str
    s: float  # the last point's s
    info: str = ""

    @property
    def reached(self) -> bool:
        return self.kind == "reached"


def _secant(hist, s_new):
    """Predictor through the last two points of ``hist`` [(s, u)], or None with fewer."""
    if len(hist) < 2 or hist[-2][0] == hist[-1][0]:
        return None
    (s1, u1), (s2, u2) = hist[-2], hist[-1]
    return u2 + (u2 - u1) * (s_new - s2) / (s2 - s1)


def natural(
    path: FixedPointPath,
    pts: list,
    s_to: float,
    control: StepControl,
    max_points: int = MAX_POINTS,
    on_point=None,
    on_stall=None,
    on_reject=None,
) -> Stop:
    """Natural continuation from the points ``pts`` [(s, u)] (at least one, corrected) to
    s_to; new points are appended to ``pts``. Secant predictor through the last two points,
    Newton corrector at the new s (`FixedPointPath.correct`), a correction moving z more than
    JUMP_FACTOR x the predicted change (at least JUMP_FLOOR) rejected as a jump to another
    branch; the step grows by GROW after an easy correction (<= EASY_ITER iterations) and
    halves after a failed one.

    Hooks: ``on_point(s, u, iterations, step)`` after each new point; ``on_reject(s, reason,
    new_step)`` after a failed correction; ``on_stall(s, u, reason, direction)`` when the
    step falls below ``control.smallest``: it returns a new corrected point (s, u) to go on
    from (the paper's fallback ladder, III.D.4 steps E-F, changes the parameters this way),
    or a message to stop with. Without it the continuation stops ("stalled").
    """
    direction = math.copysign(1.0, s_to - pts[0][0])
    hist = list(pts[-2:])  # the predictor's memory, restarted by a stall hook
    h = control.first
    while len(pts) < max_points:
        s_last, u_last = pts[-1]
        remaining = direction * (s_to - s_last)
        if remaining <= control.target_tol:
            return Stop("reached", s_last)
        h_try = min(h, remaining)
        s_new = s_to if h_try == remaining else s_last + direction * h_try
        u_pred = _secant(hist, s_new)
        if u_pred is None:  # no secant yet: trust the corrector (or guard with the floor)
            u_pred, jump_max = u_last, JUMP_FLOOR if control.guard_first_step else math.inf
        else:  # a correction much larger than the predicted change has left the branch
            jump_max = max(JUMP_FACTOR * float(np.max(np.abs(u_pred[:6] - u_last[:6]))), JUMP_FLOOR)
        out = path.correct(s_new, u_pred)
        ok, info = out.converged, out.reason
        if ok and np.max(np.abs(out.u[:6] - u_pred[:6])) > jump_max:
            ok, info = False, "the corrector jumped (another branch?)"
        if not ok:
            h = h_try / 2.0
            if on_reject is not None:
                on_reject(s_new, info, h)
            if h >= control.smallest:
                continue
            fix = None if on_stall is None else on_stall(s_last, u_last, info, direction)
            if fix is None:
                return Stop("stalled", s_last, info)
            if isinstance(fix, str):
                return Stop(fix, s_last, info)
            pts.append(fix)
            hist = [fix]
            h = control.first
            continue
        pts.append((s_new, out.u))
        hist.append((s_new, out.u))
        if on_point is not None:
            on_point(s_new, out.u, out.iterations, direction * h_try)
        h = min(h_try * GROW, control.largest) if out.iterations <= EASY_ITER else h_try
    return Stop("max_points", pts[-1][0])


def arclength(
    path: FixedPointPath,
    pts: list,
    s_to: float,
    ds: float,
    ds_max: float,
    ds_min: float,
    steps,
    max_points: int = MAX_POINTS,
    origin: float = 0.0,
    scale: float = 1.0,
    stop_past_start: int | None = 0,
    on_point=None,
    on_reject=None,
) -> Stop:
    """Pseudo-arclength continuation from the last two points of ``pts`` [(s, u)] (at least
    two, corrected) towards s_to; new points are appended to ``pts``.

    Unknowns v = [u, (s - origin) / scale]; predictor v_k + ds t with t the unit chord of the
    last two points; corrector Newton on [F(u; s), t . (v - v_k) - ds] with the central
    difference ``steps`` of v. ds halves after a failed correction (stop below ``ds_min``) and
    grows by GROW after an easy one, up to ``ds_max``. Past s_to the point is replaced by
    the correction at s_to exactly (from the chord's interpolation). ``on_point(s, u,
    iterations, step, turned)``: turned is True where ds/d(arclength) changed sign (a fold
    between the last point and this one). With ``stop_past_start`` = n it stops once the
    branch has turned back past the first point and ``pts`` holds more than n points.
    """
    s0 = pts[0][0]
    direction = math.copysign(1.0, s_to - s0)
    n_u = len(pts[-1][1])

    def v_of(s, u):
        return np.append(u, (s - origin) / scale)

    def residual_v(v):
        return path.residual_at(origin + v[-1] * scale)(v[:-1])

    while len(pts) < max_points:
        (s_prev, u_prev), (s_last, u_last) = pts[-2], pts[-1]
        vk = v_of(s_last, u_last)
        chord = vk - v_of(s_prev, u_prev)
        t = chord / np.linalg.norm(chord)  # secant tangent

        def residual(v, vk=vk, t=t, ds=ds):
            r = residual_v(v)
            return None if r is None else np.append(r, t @ (v - vk) - ds)  # arclength

        out = newton(residual, vk + ds * t, steps, tol=path.tol, max_iter=CORRECTOR_MAX_ITER)
        if not out.converged:
            ds /= 2.0
            if on_reject is not None:
                on_reject(s_last, out.reason, ds)
            if ds < ds_min:
                return Stop("stalled", s_last, out.reason)
            continue
        v = out.u
        s_new = origin + v[-1] * scale
        if direction * (s_new - s_to) >= 0.0:  # passed the target: land on it exactly
            frac = (s_to - s_last) / (s_new - s_last)
            land = path.correct(s_to, u_last + frac * (v[:n_u] - u_last))
            if land.converged:
                pts.append((s_to, land.u))
                if on_point is not None:
                    on_point(s_to, land.u, land.iterations, s_to - s_last, False)
                return Stop("reached", s_to)
            ds /= 2.0
            if on_reject is not None:
                on_reject(s_to, land.reason, ds)
            if ds < ds_min:
                return Stop("stalled", s_last, land.reason)
            continue
        turned = (v[-1] - vk[-1]) * chord[-1] < 0.0  # d s / d(arclength) changed sign: a fold
        pts.append((s_new, v[:n_u].copy()))
        if on_point is not None:
            on_point(s_new, v[:n_u], out.iterations, ds, turned)
        if (
            stop_past_start is not None
            and direction * (s_new - s0) < 0.0
            and len(pts) > stop_past_start
        ):
            return Stop("turned_back", s_new)
        if out.iterations <= EASY_ITER:
            ds = min(ds * GROW, ds_max)
    return Stop("max_points", pts[-1][0])
