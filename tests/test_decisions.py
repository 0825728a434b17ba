"""Who decides at the apex, and what a decision costs (agents/decisions.py, margins'
decision_shares)."""

from __future__ import annotations

import numpy as np

from agents.decisions import (
    FAIR_SAFE,
    decisions_text,
    planner_of,
    shares_rows,
    time_decisions,
    timing_states,
)
from agents.policy import load_controller
from bound_env.analysis.margins.curve import Decisions, decision_shares
from bound_env.task import APEX_SCALES


def test_timing_states_are_the_same_for_everyone_and_past_the_safe_radius():
    z_star = np.array([0.3, 0.01, -0.02, 2.8, 0.1, -0.2])
    a, b = timing_states(z_star, 12345), timing_states(z_star, 12345)
    assert np.array_equal(a, b) and len(a) > 100
    assert np.all(np.max(np.abs(a - z_star) / np.asarray(APEX_SCALES), axis=1) > FAIR_SAFE)


def test_only_gated_planners_are_timed():
    default = load_controller("default")
    assert planner_of(load_controller("lqr")) is None  # no gate, no search: not timed
    assert planner_of(default) is default
    Z = timing_states(default.z_ref, 12345)[:5]
    t = time_decisions(default, Z)
    assert t["n"] == 5 and 0 < t["p50"] <= t["p99"] <= t["max"]
    assert time_decisions(load_controller("passive"), Z) is None


def test_decision_shares_count_what_the_controller_recorded():
    default = load_controller("default")
    rec = Decisions(default)
    default.coefficients(default.z_ref)  # the gate
    z = default.z_ref + 0.3 * np.abs(default.z_ref) * np.array([0, 0, 0, 1, 0, 0])
    default.coefficients(z)
    out = rec.into({})
    assert sum(out["decision_kinds"].values()) == 2 and out["decision_kinds"]["gate"] == 1
    s = decision_shares([out, {"decision_kinds": {"gate": 0, "lqr": 2, "override": 0}}])
    assert s["n"] == 4 and abs(s["gate"] + s["lqr"] + s["override"] - 1) < 1e-12
    assert decision_shares([{}]) is None
    assert Decisions(load_controller("lqr")).into({}) == {}  # no gate: nothing recorded


def test_the_page_section_lists_shares_and_times():
    shares = {"curve": {"gate": 0.5, "lqr": 0.25, "override": 0.25, "n": 4}}
    groups = [{"label": "x", "runs": [{"decision_shares": shares}]}]
    assert shares_rows(groups) == [("x", "curve", shares["curve"])]
    times = {
        "measured_on": "states",
        "states": 3,
        "load_average_before": [0.2, 0, 0],
        "controllers": {"x": {"p50": 1e-4, "p99": 2e-4, "mean": 1e-4, "max": 3e-4}},
    }
    text = decisions_text(times, groups)
    assert "| x | curve | 50.0 % | 25.0 % | 25.0 % | 4 |" in text and "| x | 0.1 | 0.2 |" in text
    assert decisions_text(None, []) == ""
