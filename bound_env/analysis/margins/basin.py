"""The basin along each axis (a minimal fatal shock per apex component and sign, JSON ``basin``):
the start geometry, the physical cap of a direction, and the grown-then-bisected search that
the ceiling uses too (`grown_search`)."""

from __future__ import annotations

import math

from ..numerics import bisect_threshold
from .closed_loop import ClosedLoop, Setup, loop_for

BASIN_LO, BASIN_HI = 1e-3, 1.0  # first bracket of the relative basin search (then it grows)
BASIN_CAP = 64.0  # largest relative perturbation tried where the start state stays valid


def start_geometry(z, loop: ClosedLoop) -> dict:
    """What the apex start state z itself rules out: ``invalid`` (the start failure, or None)
    and ``mechanisms``: geometric reasons a stride from z cannot go as the gait does."""
    from bound_env.dynamics import back_hip, front_hip, make_aux
    from bound_env.hybrid import failure_name, start_status, state_from_z
    from bound_env.params import P_GB, P_GF, P_LB, P_LF

    y = state_from_z(z)
    aux = make_aux(loop.env.params.to_array())
    code = start_status(y, aux)
    invalid = failure_name(code) if code != 0 else None
    mech = []
    if invalid is not None:
        mech.append(f"start state invalid ({invalid})")
    if back_hip(y, aux)[1] < aux[P_LB] * math.cos(aux[P_GB]):
        mech.append("back hip below touchdown height at the apex")
    if front_hip(y, aux)[1] < aux[P_LF] * math.cos(aux[P_GF]):
        mech.append("front hip below touchdown height at the apex")
    return {"invalid": invalid, "mechanisms": mech}


def physical_cap(loop: ClosedLoop, zc, zs, i: int, sign: int) -> tuple[float, str]:
    """(cap, reason): the smallest relative size s (units of |z*_i|) at which the start state
    z_cl + sign s z*_i e_i is invalid (doubling scan, then 40 bisection steps), or
    (BASIN_CAP, "numeric cap") if it stays valid up to BASIN_CAP."""

    def invalid(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return start_geometry(z, loop)["invalid"]

    good, bad = 0.0, BASIN_LO
    while bad <= BASIN_CAP and invalid(bad) is None:
        good, bad = bad, 2.0 * bad
    if bad > BASIN_CAP:
        return BASIN_CAP, "numeric cap"
    for _ in range(40):
        mid = 0.5 * (good + bad)
        if invalid(mid) is None:
            good = mid
        else:
            bad = mid
    return bad, f"start state invalid beyond ({invalid(bad)})"


def hip_thresholds(loop: ClosedLoop, zc, zs, i: int, sign: int, cap: float) -> dict:
    """For "back" and "front": the smallest relative size s <= cap at which that hip starts
    below its touchdown height l cos gamma at the apex (None if it never does up to cap);
    found by a doubling scan and 40 bisection steps on the start geometry alone."""
    out = {}
    for end in ("back", "front"):
        text = f"{end} hip below touchdown height at the apex"

        def below(s, text=text):
            z = zc.copy()
            z[i] += sign * s * zs[i]
            return text in start_geometry(z, loop)["mechanisms"]

        good, bad = 0.0, BASIN_LO
        while bad <= cap and not below(bad):
            good, bad = bad, 2.0 * bad
        if bad > cap:
            out[end] = None
            continue
        for _ in range(40):
            mid = 0.5 * (good + bad)
            if below(mid):
                bad = mid
            else:
                good = mid
        out[end] = bad
    return out


def grown_search(ok, cap: float, iters: int) -> tuple[float, bool, float | None]:
    """`bisect_threshold` grown up to ``cap``, remembering the tested points: returns
    (edge, capped, smallest failing size tested or None)."""
    fails = []

    def test(s):
        good = ok(s)
        if not good:
            fails.append(s)
        return good

    s, capped = bisect_threshold(
        test, min(BASIN_LO, cap / 2), min(BASIN_HI, cap), iters, grow=True, cap=cap
    )
    first_fail = min(fails) if fails else None
    if not capped and first_fail is not None and first_fail >= cap:
        capped = True  # every size below the (invalid-start) cap returned
    return s, capped, first_fail


def task_basin(setup: Setup, i: int, sign: int) -> dict:
    loop = loop_for(setup)
    zs, zc = setup.z_star, setup.z_cl
    n = setup.budget.basin_strides

    def start(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return z

    cap, cap_reason = physical_cap(loop, zc, zs, i, sign)
    s, capped, fail = grown_search(
        lambda s: loop.run(start(s), zc, n)[0], cap, setup.budget.basin_iters
    )
    beyond = None
    if fail is not None:
        ok, strides, failure = loop.run(start(fail), zc, n)
        geo = start_geometry(start(fail), loop)
        beyond = {
            "rel": fail,
            "reason": failure or "no_return",
            "stride": strides,
            "phase": loop.last_phase if failure else None,
            "mechanisms": geo["mechanisms"],
        }
    return {
        "rel": s,
        "abs": abs(s * zs[i]),
        "capped": capped,
        "cap": cap,
        "cap_reason": cap_reason,
        "beyond": beyond,
    }
