"""A margins task gives the same result whatever its worker process ran before: the per-worker
store of closed loops (`bound_env.analysis.margins.closed_loop.loop_for`) keeps nothing that a
task's result depends on.

The ceiling search once scored its profiles by a stride period that the loop kept from the task
that built it: the cycle task (no period yet, 0.39 s) in one worker, a later task (the cycle's
period) in another. `lqr literal`'s ceiling in the ``xdot_g-`` direction was 0.209 or 0.193 by
which worker ran it.
"""

from dataclasses import replace

import numpy as np
import pytest

from bound_env.analysis.margins import as_budget
from bound_env.analysis.margins.closed_loop import _LOOPS, Setup
from bound_env.analysis.margins.report import Z_LABELS
from bound_env.analysis.margins.run import TASKS, setup_key
from bound_env.control import load_controller
from bound_env.model.params import load_gait

GAIT = "literal-cycle"


def setup_of(ctrl, gait: str, budget: str) -> Setup:
    """A column's setup before its cycle is known (no period), as `compute_margins` makes it."""
    b = as_budget(budget)
    return Setup(
        controller=ctrl,
        gait=gait,
        budget=b,
        z_star=np.asarray(load_gait(gait).z0, float),
        key=setup_key(ctrl, gait, b, 12345, ()),
        seed=12345,
    )


@pytest.fixture
def setup() -> Setup:
    """lqr on the literal gait at the full budget."""
    return setup_of(load_controller("lqr", gait=GAIT), GAIT, "full")


@pytest.mark.slow
def test_the_ceiling_does_not_depend_on_the_task_that_built_the_loop(setup):
    _LOOPS.clear()
    cyc = TASKS["cycle"](setup)  # builds the loop, as the first task of a worker does
    known = replace(
        setup,
        z_cl=np.array(cyc["z_cl"]),
        cycle_steps=int(cyc["cycle_steps"]),
        period=float(cyc["period"]),
    )
    i = list(Z_LABELS).index("xdot_g")
    after_cycle = TASKS["ceiling"](known, i, -1)
    _LOOPS.clear()  # another worker: the ceiling task builds the loop itself
    alone = TASKS["ceiling"](known, i, -1)
    _LOOPS.clear()
    assert after_cycle == alone


@pytest.mark.slow
def test_decision_counts_do_not_depend_on_the_decisions_counted_before():
    """A controller run as one copy per robot (step-ppo: a residual over the distilled
    student) records its copies' decisions into its own record at the end of a loop. A copy
    starts with an empty record (the MPC pickles without it), so counting each copy from the
    length of the controller's record before the loop dropped a copy's first decisions: the
    more a worker had counted before, the fewer it counted (step-ppo's decision shares were 0
    in one run of the page and hundreds in another)."""
    from agents.runtime.policy import load_controller as load_policy

    setup = setup_of(load_policy("agents/policies/step-ppo/s0"), "default", "test")
    budget = setup.budget
    _LOOPS.clear()
    cyc = TASKS["cycle"](setup)
    setup = replace(
        setup,
        z_cl=np.array(cyc["z_cl"]),
        cycle_steps=int(cyc["cycle_steps"]),
        period=float(cyc["period"]),
    )
    size = budget.curve_sizes[-1]
    first = TASKS["curve"](setup, size)["decision_kinds"]
    again = TASKS["curve"](setup, size)["decision_kinds"]
    _LOOPS.clear()
    assert sum(first.values()) > 0  # the copies decided
    assert again == first
