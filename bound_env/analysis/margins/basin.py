"""The basin along each axis (a minimal fatal shock per apex component and sign, JSON ``basin``):
the start geometry, the physical cap of a direction, and the grown-then-bisected search that
the ceiling uses too (`grown_search`).

A direction's search is a generator (`basin_steps`): `task_basins` runs the searches of
several directions in lockstep (`bound_env.model.numerics.run_together`), each step's
closed-loop runs as one batch of robots advanced together (`closed_loop_runs`); each search
sees the outcomes it would see alone, so its result is `task_basin`'s."""

from __future__ import annotations

import math

import numpy as np

from ...model.events import PHASES
from ...model.numerics import run_together, threshold_steps
from ..apex_loop import RETURNED, apex_loop
from .closed_loop import FAILURES_BY_REASON, STRIDES, ClosedLoop, Setup, loop_for

BASIN_LO, BASIN_HI = 1e-3, 1.0  # first bracket of the relative basin search (then it grows)
BASIN_CAP = 64.0  # largest relative perturbation tried where the start state stays valid
# the (component, sign) directions of each margins task `task_basins`: their bisections
# advance together (one batch of robots per step); two tasks, one per worker of the page
BASIN_GROUPS = tuple(tuple((i, sign) for i in range(6)) for sign in (1, -1))


def start_geometry(z, loop: ClosedLoop) -> dict:
    """What the apex start state z itself rules out: ``invalid`` (the start failure, or None)
    and ``mechanisms``: geometric reasons a stride from z cannot go as the gait does."""
    from bound_env.model.dynamics import back_hip, front_hip, make_aux
    from bound_env.model.hybrid import failure_name, start_status, state_from_z
    from bound_env.model.params import P_GB, P_GF, P_LB, P_LF

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
    (edge, capped, smallest failing size tested or None) (`grown_steps`, run with ``ok``)."""
    return run_together([grown_steps(cap, iters)], lambda sizes: [ok(sizes[0])])[0]


def grown_steps(cap: float, iters: int):
    """`grown_search` as a generator (`bound_env.model.numerics.threshold_steps`): it
    yields each size to test, is sent whether it held, and returns what `grown_search`
    returns."""
    fails = []
    search = threshold_steps(min(BASIN_LO, cap / 2), min(BASIN_HI, cap), iters, grow=True, cap=cap)
    try:
        s = next(search)
        while True:
            good = yield s
            if not good:
                fails.append(s)
            s = search.send(good)
    except StopIteration as done:
        s, capped = done.value
    first_fail = min(fails) if fails else None
    if not capped and first_fail is not None and first_fail >= cap:
        capped = True  # every size below the (invalid-start) cap returned
    return s, capped, first_fail


def basin_steps(setup: Setup, loop: ClosedLoop, i: int, sign: int):
    """The basin along component ``i`` with ``sign`` as a generator: it yields each start
    state to test (a closed-loop run from it to z_cl, ``basin_strides`` strides), is sent
    that run's (returned, strides, failure, phase), and returns the task's result."""
    zs, zc = setup.z_star, setup.z_cl

    def start(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return z

    cap, cap_reason = physical_cap(loop, zc, zs, i, sign)
    runs = {}  # size -> its run (the first failing size's is reported: no second run)
    search = grown_steps(cap, setup.budget.basin_iters)
    try:
        s = next(search)
        while True:
            runs[s] = yield start(s)
            s = search.send(runs[s][0])
    except StopIteration as done:
        s, capped, fail = done.value
    beyond = None
    if fail is not None:
        _, strides, failure, phase = runs[fail]
        geo = start_geometry(start(fail), loop)
        beyond = {
            "rel": fail,
            "reason": failure or "no_return",
            "stride": strides,
            "phase": phase if failure else None,
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


def closed_loop_runs(loop: ClosedLoop, Z, z_target, max_strides: int) -> list[tuple]:
    """`ClosedLoop.run` from every row of Z, all robots advanced together by the one batched
    closed loop (`bound_env.analysis.apex_loop`, as `ClosedLoop.run_many`): per robot
    (returned, strides, failure, phase), ``phase`` the stance condition at a failure (as
    ``loop.last_phase`` after `ClosedLoop.run`), else None."""
    Z = np.array(np.atleast_2d(Z), dtype=float)
    if loop.stride_map is not None:
        r = apex_loop(Z, z_target, max_strides, strides=loop.strides)
    else:
        r = apex_loop(Z, z_target, max_strides, task=loop.env.task, controller=loop.controller)
        STRIDES[0] += r["apexes"]
    out = []
    for i in range(len(Z)):
        reason = int(r["reason"][i])
        failure = FAILURES_BY_REASON[reason]
        phase = PHASES[int(r["phase"][i])] if failure and r["phase"][i] >= 0 else None
        out.append((bool(r["outcome"][i] == RETURNED), int(r["strides"][i]), failure, phase))
    return out


def task_basins(setup: Setup, *directions) -> dict:
    """The basins along several (component, sign) ``directions`` at once: their bisections
    advance together, one batch of closed-loop runs per step (`closed_loop_runs`); each
    direction's result is `task_basin`'s (``{"basins": [...]}``, in order)."""
    loop = loop_for(setup)
    zc, n = setup.z_cl, setup.budget.basin_strides
    searches = [basin_steps(setup, loop, int(i), int(sign)) for i, sign in directions]
    return {"basins": run_together(searches, lambda Z: closed_loop_runs(loop, Z, zc, n))}


def task_basin(setup: Setup, i: int, sign: int) -> dict:
    """The basin along component ``i`` with ``sign``: its bisection alone, one
    `ClosedLoop.run` per step."""
    loop = loop_for(setup)
    zc, n = setup.z_cl, setup.budget.basin_strides

    def one(Z):
        ok, strides, failure = loop.run(Z[0], zc, n)
        return [(ok, strides, failure, loop.last_phase if failure else None)]

    return run_together([basin_steps(setup, loop, i, sign)], one)[0]
