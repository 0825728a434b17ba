"""The ceiling of the basin (JSON ``basin_ceiling``): the largest perturbation from which some
admissible open-loop torque profile completes the first strides, found by a profile search
(zero, constant extremes, bang-bang, random pieces, then a (1+1)-ES shooting optimizer)."""

from __future__ import annotations

import math

import numpy as np

from .basin import grown_search, hip_thresholds, physical_cap, start_geometry
from .budget import Budget
from .closed_loop import PROFILE_SEG, PROFILE_SPAN, ClosedLoop, Setup, loop_for

# ceiling search, (1+1)-ES: share of pieces mutated, first step, growth on success, shrink on
# failure, step bounds
CEILING_ES = {"mutate": 0.3, "step": 0.5, "grow": 1.5, "shrink": 0.85, "min": 0.05, "max": 2.0}


def _profile_search(
    loop: ClosedLoop,
    z,
    n_strides: int,
    n_pieces: int,
    period: float,
    b: Budget,
    rng: np.random.Generator,
) -> tuple[bool, dict]:
    """Is there an admissible torque profile that completes ``n_strides`` strides from z?
    Candidates in order: zero, +-max, bang-bang with one switch, random piecewise-constant
    (half bang-bang valued, half uniform), then a (1+1)-ES shooting optimizer from the best;
    ``period`` [s] scores a failure by the share of a stride survived (`ClosedLoop.profile`).
    Returns (found, best: {score, failure, phase, stride})."""
    best = {"score": -1.0}
    best_a = None

    def trial(a):
        nonlocal best, best_a
        ok, score, failure, phase, strides = loop.profile(z, a, n_strides, period)
        if score > best["score"]:
            best = {"score": score, "failure": failure, "phase": phase, "stride": strides}
            best_a = np.array(a, dtype=float)
        return ok

    cands = [np.zeros(n_pieces), np.ones(n_pieces), -np.ones(n_pieces)]
    per_stride = max(2, n_pieces // max(1, n_strides))
    for k in range(1, per_stride, max(1, per_stride // 6)):
        a = np.where(np.arange(n_pieces) < k, 1.0, -1.0)
        cands += [a, -a]
    for j in range(b.ceiling_random):
        if j % 2 == 0:
            cands.append(rng.choice([-1.0, 1.0], n_pieces))
        else:
            cands.append(rng.uniform(-1.0, 1.0, n_pieces))
    for a in cands:
        if trial(a):
            return True, best
    es = CEILING_ES
    step = es["step"]
    for _ in range(b.ceiling_opt):
        mask = rng.random(n_pieces) < es["mutate"]
        child = np.clip(best_a + mask * rng.normal(0.0, step, n_pieces), -1.0, 1.0)
        before = best["score"]
        if trial(child):
            return True, best
        if best["score"] > before:
            step = min(es["max"], step * es["grow"])
        else:
            step = max(es["min"], step * es["shrink"])
    return False, best


def task_ceiling(setup: Setup, i: int, sign: int) -> dict:
    """The largest perturbation along (i, sign) from which some admissible open-loop torque
    profile completes the first ``ceiling_strides`` strides (see the package docstring)."""
    loop = loop_for(setup)
    zs, zc, b = setup.z_star, setup.z_cl, setup.budget
    n = b.ceiling_strides
    period = setup.period if math.isfinite(setup.period) else 0.39
    n_pieces = int(math.ceil(PROFILE_SPAN * n * period / loop.dt / PROFILE_SEG))
    found_at: dict = {}

    def start(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return z

    def ok(s):
        rng = np.random.default_rng([i, 1 if sign > 0 else 0, int(round(s * 1e9)) % 2**32])
        found, best = _profile_search(loop, start(s), n, n_pieces, period, b, rng)
        found_at[s] = best
        return found

    cap, cap_reason = physical_cap(loop, zc, zs, i, sign)
    s, capped, fail = grown_search(ok, cap, b.ceiling_iters)
    hips = hip_thresholds(loop, zc, zs, i, sign, cap)
    mechanism, beyond, geometric = None, None, False
    if capped:
        mechanism = cap_reason
        geometric = cap_reason != "numeric cap"
    elif fail is not None:
        geo = start_geometry(start(fail), loop)
        best = found_at.get(fail, {})
        beyond = {
            "rel": fail,
            "reason": best.get("failure"),
            "stride": best.get("stride"),
            "phase": best.get("phase"),
            "mechanisms": geo["mechanisms"],
        }
        # geometric: the edge sits at the size where a hip starts below its touchdown height
        # (within the bisection's resolution) and the best profile fails by that hip
        for end, at in hips.items():
            if (
                at is not None
                and s <= at <= fail * 1.001
                and f"ground_contact_{end}_hip" == best.get("failure")
            ):
                mechanism = f"{end} hip below touchdown height at the apex (from s = {at:.4g})"
                geometric = True
                # the geometric edge is known to ~1e-12: the ceiling is just below it if a
                # profile still completes the strides there (sharper than the bisection)
                if at * (1 - 1e-6) > s and ok(at * (1 - 1e-6)):
                    s = at * (1 - 1e-6)
        if mechanism is None:
            mechanism = (
                f"no admissible profile found within the search budget (best: "
                f"{best.get('failure')} in stride {(best.get('stride') or 0) + 1}, "
                f"phase {best.get('phase')})"
            )
    return {
        "rel": s,
        "abs": abs(s * zs[i]),
        "capped": capped,
        "cap": cap,
        "cap_reason": cap_reason,
        "mechanism": mechanism,
        "geometric": geometric,
        "hip_below_touchdown_from": hips,
        "beyond": beyond,
        "profile_pieces": n_pieces,
    }
