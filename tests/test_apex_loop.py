"""The one batched closed loop (bound_env.analysis.apex_loop): all robots advanced together
give each robot the outcome of its own loop, one robot at a time, for every kind of
controller (a stride controller through the stride map, a step policy with ``batch``, a
step-level residual with ``on_apex`` through copies); margins and basin-map run it; margins
times every apex decision; every robot starts with a fresh controller state."""

from __future__ import annotations

import numpy as np
import pytest

from agents.runtime.policy import load_controller
from bound_env.analysis.apex_loop import CLOCK, FELL, RETURNED, UNDECIDED, apex_loop
from bound_env.analysis.basin import controller_batch
from bound_env.analysis.margins import ClosedLoop, random_directions

NAMES = ["lqr", "passive", "agents/policies/archive/ppo-v1", "step-ppo/s0"]


def starts(z_ref, n=6, seed=777, r_max=0.4):
    """Validation directions at r = 0.005 .. r_max: some return, some fall."""
    r = np.geomspace(0.005, r_max, n)[:, None]
    return z_ref + r * np.abs(z_ref) * random_directions(n, seed)


@pytest.mark.parametrize("name", NAMES)
def test_the_batch_is_each_robot_alone(name):
    """`run_many` (one batch) equals `run` robot by robot, kicks included, and different
    outcomes occur (a fall, and a return or a run
    to the stride limit): a robot's strides are its own."""
    loop = ClosedLoop(load_controller(name), "default")
    z_ref = loop.plant.z_ref
    Z = starts(z_ref)
    kicks = [None, (3, 4, 0.4), None, (0, 7, -2.0), None, None]
    many = loop.run_many(Z, z_ref, 30, kicks=kicks)
    one = [loop.run(z, z_ref, 30, kick=k) for z, k in zip(Z, kicks, strict=True)]
    assert many == one
    # a fall and a return or an undecided run (ppo-v1 settles on its own cycle, not z*)
    assert len({(ok, f is None) for ok, _, f in one}) == 2, one
    assert len({n for _, n, _ in one}) > 1


def test_basin_map_runs_the_same_loop():
    """basin-map's `controller_batch` and margins' `run_many` are one loop: the same outcome,
    stride count and failure per start (basin's reason code names margins' failure)."""
    from bound_env.model.events import FAILURES

    for name in ("lqr", "step-ppo/s0"):
        ctrl = load_controller(name)
        loop = ClosedLoop(ctrl, "default")
        z_ref = loop.plant.z_ref
        Z = starts(z_ref, 8, seed=778, r_max=0.8)
        runs = loop.run_many(Z, z_ref, 30)
        out = controller_batch(ctrl, Z, z_ref, "default", max_strides=30)
        for i, (ok, n, failure) in enumerate(runs):
            assert (out["outcome"][i] == RETURNED) == ok
            assert out["strides"][i] == n
            if failure is None:
                assert out["reason"][i] == 0
            else:
                assert out["outcome"][i] == FELL
                assert FAILURES[out["reason"][i] - 1] == failure
        assert set(out["outcome"].tolist()) >= {RETURNED, FELL}


def test_undecided_and_bad_kicks():
    lqr = load_controller("lqr")
    loop = ClosedLoop(lqr, "default")
    z = starts(loop.plant.z_ref, 1)
    out = apex_loop(z, loop.plant.z_ref + 1.0, 3, strides=loop.strides)  # never "returns"
    assert out["outcome"][0] == UNDECIDED and out["strides"][0] == 3 and out["apexes"] == 3
    with pytest.raises(ValueError, match="state index"):
        apex_loop(z, z[0], 3, strides=loop.strides, kicks=[(0, 2, 1.0)])


def test_margins_times_every_apex_decision_of_its_loops():
    """With the clock on (margins' tasks), every stride started gets one decision time: the
    MPC's own timings (each of its decisions), a step-level residual's ``on_apex`` hook; and
    the times are the decisions' own: the MPC's searched decisions take longer than its gate
    decisions. The passive gait decides nothing."""
    for name in ("mpc", "step-ppo/s0", "passive"):
        ctrl = load_controller(name)
        loop = ClosedLoop(ctrl, "default")
        z_ref = loop.plant.z_ref
        CLOCK.seconds.clear()
        CLOCK.on = True
        try:
            runs = loop.run_many(starts(z_ref, 4, seed=779), z_ref, 20)
        finally:
            CLOCK.on = False
        started = sum(n for _, n, _ in runs)
        if name == "passive":  # zero torque whatever the apex: no decision
            assert CLOCK.seconds == []
            continue
        assert len(CLOCK.seconds) == started, name
        if name == "mpc":
            assert CLOCK.seconds == ctrl.decision_seconds[-started:]
            kinds = np.array(ctrl.decision_kinds[-started:])
            t = np.array(CLOCK.seconds)
            assert (kinds == "override").any() and (kinds == "gate").any()
            assert np.median(t[kinds == "override"]) > 5 * np.median(t[kinds == "gate"])
    CLOCK.seconds.clear()


def test_every_robot_starts_with_a_fresh_controller_state():
    """One reset rule: an offset-free controller (its estimate of the plant's offset is
    state) gives the same per-direction outcome whatever ran before it in the worker. Here a
    spine-stiffness window task (a plant off its model, stepped through the same controller
    object) leaves the controller with a large offset estimate; the random-direction curve
    after it is the curve of a fresh worker, on the nominal plant and under model error."""
    from dataclasses import replace

    from bound_env.analysis.margins.budget import BUDGETS
    from bound_env.analysis.margins.closed_loop import _LOOPS, Setup
    from bound_env.analysis.margins.model_error.mismatch_tasks import MISMATCH_BUDGETS
    from bound_env.analysis.margins.run import run_task
    from bound_env.model.mismatch import as_spec

    z_star = load_controller("lqr").z_ref
    budget = replace(BUDGETS["test"], curve_dirs=4, basin_strides=80)
    mb = replace(MISMATCH_BUDGETS["test"], plants=4, curve_strides=30)

    def worker(before=None):
        _LOOPS.clear()  # a new worker process: no loop, a controller as loaded
        setup = Setup(load_controller("lqr-of"), "default", budget, z_star, z_star, key="of",
                      mismatch=as_spec("pm5"), mismatch_budget=mb)  # fmt: skip
        if before is not None:
            run_task(setup, *before)
            assert np.max(np.abs(setup.controller.offset)) > 1.0  # it learned an offset
        return [
            run_task(setup, "curve", (0.01,))["outcomes"],
            run_task(setup, "mm_curve", (0.01,))["outcomes"],
        ]

    fresh = worker()
    assert sum(fresh[0]) > 0  # some directions return (a carried offset loses them all)
    assert worker(("window", ("kc", 1))) == fresh
    _LOOPS.clear()
