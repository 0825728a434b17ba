"""Bisections in lockstep: many threshold searches advance together, each step's tests answered
as one batch (bound_env.model.numerics.run_together), and the margins' basin searches of
several directions run that way (`task_basins`: one batch of closed-loop robots per step),
each with the result it has alone (`task_basin`, one `ClosedLoop.run` per step)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bound_env.model.numerics import bisect_threshold, run_together, threshold_steps


@pytest.mark.parametrize(
    "threshold, kw",
    [(0.37, {}), (5.0, {"grow": True, "cap": 100.0}), (500.0, {"grow": True, "cap": 64.0}),
     (1e-5, {}), (2.0, {}), (0.6, {"log": False})],
)  # fmt: skip
def test_the_generator_asks_what_the_callable_search_asks(threshold, kw):
    """`threshold_steps` yields the points `bisect_threshold` tests, in its order, and
    returns its result (capped, grown, below lo, linear)."""
    asked = []

    def ok(s):
        asked.append(s)
        return s <= threshold

    expected = bisect_threshold(ok, 1e-3, 1.0, 12, **kw)
    search = threshold_steps(1e-3, 1.0, 12, **kw)
    seen, s = [], next(search)
    try:
        while True:
            seen.append(s)
            s = search.send(s <= threshold)
    except StopIteration as done:
        assert done.value == expected
    assert seen == asked


def test_searches_together_are_each_search_alone():
    """Searches of different lengths run together: each gets its own result; every batch
    holds one query per search still running, so there are as many batches as the longest
    search has steps, not as many as all steps together."""
    thresholds = [0.002, 0.3, 7.0, 0.0001, 50.0]
    alone = [bisect_threshold(lambda s, t=t: s <= t, 1e-3, 1.0, 9, grow=True, cap=64.0)
             for t in thresholds]  # fmt: skip
    batches = []

    def tagged(k, search):  # its queries as (k, s): whose query it is
        try:
            s = next(search)
            while True:
                s = search.send((yield (k, s)))
        except StopIteration as done:
            return done.value

    def answer(queries):
        batches.append(len(queries))
        return [s <= thresholds[k] for k, s in queries]

    searches = [tagged(k, threshold_steps(1e-3, 1.0, 9, grow=True, cap=64.0))
                for k in range(len(thresholds))]  # fmt: skip
    assert run_together(searches, answer) == alone
    assert batches[0] == len(thresholds) and len(batches) < sum(batches)
    assert len(batches) == max(steps(t) for t in thresholds)


def steps(threshold):
    n = []
    bisect_threshold(lambda s: n.append(s) or s <= threshold, 1e-3, 1.0, 9, grow=True, cap=64.0)
    return len(n)


def test_a_batch_must_answer_every_query():
    with pytest.raises(ValueError, match="answered 1 of 2"):
        run_together([threshold_steps(1e-3, 1.0, 3) for _ in range(2)], lambda q: [True])


def _setup(policy: str):
    from agents.runtime.policy import load_controller
    from bound_env.analysis.margins import BUDGETS, Setup, run_task
    from bound_env.model.params import load_gait

    ctrl = load_controller(policy)
    setup = Setup(ctrl, "default", BUDGETS["test"], np.asarray(load_gait("default").z0, float))
    setup.key = f"test-lockstep-{policy}"
    cyc = run_task(setup, "cycle", ())
    setup.z_cl = np.array(cyc["z_cl"])
    setup.cycle_steps, setup.period = int(cyc["cycle_steps"]), float(cyc["period"])
    return setup


def _same(a, b) -> bool:
    """Two results equal number for number (NaN equal to NaN)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


@pytest.mark.parametrize("policy", ["lqr", pytest.param("step-ppo/s0", marks=pytest.mark.slow)])
def test_basins_together_are_each_basin_alone(policy):
    """`task_basins` (the margins' task: the bisections of several directions in lockstep,
    one batch of robots per step) gives every direction `task_basin`'s result (its bisection
    alone, one closed-loop run per step), for a stride controller and a step-level residual
    policy; the directions' results differ (the searches are not one search)."""
    from bound_env.analysis.margins import run_task

    setup = _setup(policy)
    directions = [(0, 1), (1, -1), (3, 1), (3, -1), (4, 1)]
    together = run_task(setup, "basins", tuple(directions))["basins"]
    for d, r in zip(directions, together, strict=True):
        alone = run_task(setup, "basin", d)
        alone.pop("seconds"), alone.pop("cpu_seconds"), alone.pop("decision_hist", None)
        assert _same(r, alone), (d, r, alone)
    assert len({r["rel"] for r in together}) > 2
    assert any(r["beyond"] is not None for r in together)


def test_the_page_runs_every_direction_once():
    """The margins' jobs hold each of the 12 directions in exactly one lockstep task, and
    their results come out keyed per direction as before."""
    from bound_env.analysis.margins.basin import BASIN_GROUPS
    from bound_env.analysis.margins.run import basin_results

    dirs = [d for g in BASIN_GROUPS for d in g]
    assert sorted(dirs) == sorted((i, s) for i in range(6) for s in (1, -1))
    res = {("basins", g): {"basins": [{"rel": float(k)} for k in range(len(g))]}
           for g in BASIN_GROUPS}  # fmt: skip
    res[("basins", BASIN_GROUPS[1])] = {"error": "boom"}
    out = basin_results(res)
    assert set(out) == {("basin", d) for d in dirs}
    assert out[("basin", BASIN_GROUPS[0][2])] == {"rel": 2.0}
    assert out[("basin", BASIN_GROUPS[1][0])] == {"error": "boom"}
