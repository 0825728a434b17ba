"""Paths along the fixed points: the paper's process and pseudo-arclength, on the one engine in
`bound_env.analysis.continuation_engine` (the fallback ladder is its on_stall hook)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...model.numerics import NEWTON_MAX_ITER, newton
from ...model.params import Params, z_to_si
from ..continuation_engine import (
    CORRECTOR_MAX_ITER,
    FixedPointPath,
    StepControl,
    arclength,
    natural,
)
from ..fixed_point import ladder
from ..poincare import StrideFailure
from ..stability import DZ, stability
from .settings import FP_TOL


@dataclass
class PathResult:
    """A followed path: its points, why it stopped, and what happened on the way."""

    points: list  # natural_path: (Params, z SI); arclength_path: (s, u = [z SI, freed values])
    reason: str
    reached: bool  # the target was reached
    ladder: list = field(default_factory=list)  # natural_path: the fallback changes made
    folds: list = field(default_factory=list)  # arclength_path: s where the branch turned


def _fixed_path(params_of, free, pins) -> FixedPointPath:
    """Fixed points along s at the reproduction's tolerance (FP_TOL), default simulation."""
    return FixedPointPath(params_of, tuple(free), list(pins), {}, FP_TOL)


def _newton_at(params: Params, u0, free, pins, max_iter=CORRECTOR_MAX_ITER):
    """Newton for [z, freed values] at fixed parameters."""
    return _fixed_path(lambda _s: params, free, pins).correct(0.0, u0, max_iter=max_iter)


def natural_path(
    params: Params,
    u0,
    s_to: float,
    pins,
    free=("alpha_deg",),
    h0=0.1,
    h_max=0.25,
    h_min=1e-3,
    use_ladder=True,
    max_points=300,
    log=None,
) -> dict:
    """The paper's process (III.D.4 A-F) in s = ln kc: step kc, solve z* and the freed alpha
    with the pins (eq. 27's energy balance is the energy pin), halve the step when Newton
    fails, and below ``h_min`` walk the fallback ladder (touchdown angles +-0.5 deg up to
    +-4 deg, then kb = kf +-100 N/m), keeping the first change that converges. The
    continuation is `continuation.natural`; the ladder is its ``on_stall`` hook.

    ``params`` carries the start (kc, alpha); u0 = [z (SI), alpha]. Returns the points as
    (Params, z) pairs plus the ladder changes made and why the path stopped (`PathResult`).
    """
    free = tuple(free)
    base = {"params": params}  # the ladder replaces it
    path = _fixed_path(lambda s: base["params"].with_values(kc=math.exp(s)), free, pins)
    s0 = math.log(params.kc)
    out = _newton_at(params, u0, free, pins, max_iter=NEWTON_MAX_ITER)
    if not out.converged:
        return PathResult([], f"no fixed point at the start: {out.reason}", False)
    pts = [(params.with_values(**dict(zip(free, out.u[6:], strict=True))), out.u[:6].copy())]
    trail = [(s0, out.u.copy())]
    changes: list = []

    def on_point(s, u, iterations, step):
        cur = path.params_at(s, u)
        pts.append((cur, u[:6].copy()))
        if log:
            log(f"  kc = {cur.kc:9.2f}  alpha = {u[6]:.5f} deg")

    def ladder_hook(s, u, info, direction):  # steps E-F: touchdown angles, then leg stiffness
        cur = pts[-1][0]
        s_try = s + direction * 2.0 * h_min
        for ch in ladder(cur)[1:]:
            try:
                p_try = cur.with_values(kc=math.exp(s_try), **ch)
            except ValueError:
                continue
            o = _newton_at(p_try, u, free, pins)
            if o.converged:
                break
        else:
            return f"ladder exhausted at kc = {cur.kc:.6g}"
        changes.append({"kc": p_try.kc, "changes": ch})
        if log:
            log(f"  ladder at kc = {p_try.kc:.2f}: {ch}")
        base["params"] = p_try
        pts.append((p_try.with_values(**dict(zip(free, o.u[6:], strict=True))), o.u[:6].copy()))
        return s_try, o.u.copy()

    control = StepControl(h0, h_max, h_min, guard_first_step=True)
    stop = natural(
        path,
        trail,
        s_to,
        control,
        max_points,
        on_point=on_point,
        on_stall=ladder_hook if use_ladder else None,
    )
    if stop.kind == "reached":
        reason = "reached the target"
    elif stop.kind == "stalled":
        reason = f"step below {h_min} at kc = {pts[-1][0].kc:.6g}: {stop.info}"
    elif stop.kind == "max_points":
        reason = f"stopped after {max_points} points"
    else:
        reason = stop.kind  # the ladder's message
    return PathResult(pts, reason, stop.reached, ladder=changes)


def arclength_path(
    params_of,
    s0: float,
    s1: float,
    u0,
    free=(),
    pins=(),
    ds=0.05,
    ds_max=0.2,
    ds_min=1e-5,
    max_points=300,
    stop_below_start=True,
    log=None,
) -> dict:
    """Pseudo-arclength continuation of [z, freed values] in a scalar s (ln kc, a homotopy
    parameter, alpha, ...) by `continuation.arclength`: ``params_of(s)`` gives the
    parameters at s (freed values are applied on top); the second point by a natural step
    of ``ds``; a fold is where ds/d(arclength) changes sign.

    Returns a `PathResult` with points [(s, u)] and the folds [s].
    """
    path = _fixed_path(params_of, free, pins)
    u0 = np.asarray(u0, float)
    steps_u = path.steps_of(u0)
    first = newton(path.residual_at(s0), u0, steps_u, tol=FP_TOL)
    if not first.converged:
        return PathResult([], f"start: {first.reason}", False)
    trail = [(s0, first.u)]
    first_step: list = []
    stop = natural(
        path,
        trail,
        s1,
        StepControl(ds, ds, ds_min),
        max_points=2,
        on_point=lambda s, u, iterations, step: first_step.append(abs(step)),
    )
    if len(trail) < 2:
        return PathResult([(float(s), u) for s, u in trail], f"no second point: {stop.info}", False)
    folds: list = []

    def on_point(s, u, iterations, step, turned):
        if turned:
            folds.append(float(trail[-2][0]))
        if log:
            log(f"  s = {s:.6g}")

    stop = arclength(
        path,
        trail,
        s1,
        first_step[0],
        ds_max,
        ds_min,
        np.append(steps_u, DZ),
        max_points,
        stop_past_start=0 if stop_below_start else None,
        on_point=on_point,
    )
    reason = {
        "reached": "reached the target",
        "stalled": f"step below minimum at s = {stop.s:.6g}: {stop.info}",
        "turned_back": f"the branch turned back past the start (s = {stop.s:.6g})",
        "max_points": f"stopped after {max_points} points",
    }[stop.kind]
    return PathResult(
        [(float(s), np.array(u, copy=True)) for s, u in trail], reason, stop.reached, folds=folds
    )


def refine_emax_crossing(base: Params, q0: dict, q1: dict, pins, n: int = 12) -> list:
    """Bisect (in ln kc) between two path points on opposite sides of e_max = 1; each
    midpoint solved by Newton (alpha freed, ``pins``) from the interpolated neighbours.
    Returns [kc on the q0 side, kc on the q1 side]."""

    def u_of(q):
        return np.append(z_to_si(q["z"]), q["alpha_deg"])

    a = (math.log(q0["kc"]), u_of(q0), q0["emax"] >= 1.0)
    b = (math.log(q1["kc"]), u_of(q1), q1["emax"] >= 1.0)
    for _ in range(n):
        sm = 0.5 * (a[0] + b[0])
        o = _newton_at(base.with_values(kc=math.exp(sm)), 0.5 * (a[1] + b[1]), ("alpha_deg",), pins)
        if not o.converged:
            break
        try:
            em = stability(o.u[:6], base.with_values(kc=math.exp(sm), alpha_deg=o.u[6])).emax
        except StrideFailure:
            break
        if (em >= 1.0) == a[2]:
            a = (sm, o.u, a[2])
        else:
            b = (sm, o.u, b[2])
    return [math.exp(a[0]), math.exp(b[0])]
