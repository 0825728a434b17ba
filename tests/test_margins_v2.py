"""Margins v2: the uncapped bisection, intervals, the validation/test split, the controller
protocol, the cache key, the compare entries."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from agents.results.compare import parse_entry
from agents.results.margins import as_controller
from agents.runtime.controllers import ZeroController
from agents.training.train_callbacks import VALIDATION_SEED, BasinValidationCallback
from bound_env.analysis import margins
from bound_env.analysis.margins import (
    BUDGETS,
    CURVE_SEED,
    Setup,
    random_directions,
    run_task,
    setup_key,
)
from bound_env.analysis.margins.budget import sample_seeds
from bound_env.analysis.margins.stats import (
    crossing_on_grid,
    t_interval,
    threshold_on_grid,
    wilson_interval,
)
from bound_env.model.numerics import bisect_threshold


def test_bisection_grows_past_one_to_a_known_basin_of_five():
    calls = []

    def ok(s):
        calls.append(s)
        return s <= 5.0

    s, capped = bisect_threshold(ok, 1e-3, 1.0, iters=30, grow=True, cap=1000.0)
    assert not capped and s == pytest.approx(5.0, rel=1e-6) and s <= 5.0
    assert calls[:4] == [1.0, 2.0, 4.0, 8.0]  # doubling from the last success
    # without growing, the old behaviour: capped at the bracket's end
    assert bisect_threshold(ok, 1e-3, 1.0, iters=30) == (1.0, True)
    # a cap below the edge is reported as reached
    assert bisect_threshold(ok, 1e-3, 1.0, iters=30, grow=True, cap=3.0) == (3.0, True)
    assert bisect_threshold(lambda s: False, 1e-3, 1.0, 5, grow=True) == (0.0, False)


def test_wilson_interval_known_cases():
    # Wilson (1927) score interval, 95 %: 5/10 -> [0.2366, 0.7634]; 0/10 -> [0, 0.2775];
    # 10/10 -> [0.7225, 1]
    lo, hi = wilson_interval(5, 10)
    assert (lo, hi) == (pytest.approx(0.2366, abs=1e-4), pytest.approx(0.7634, abs=1e-4))
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson_interval(10, 10)
    assert lo == pytest.approx(0.7225, abs=1e-4) and hi == 1.0
    lo, hi = wilson_interval(50, 100)
    assert hi - lo < wilson_interval(5, 10)[1] - wilson_interval(5, 10)[0]  # n shrinks it
    with pytest.raises(ValueError):
        wilson_interval(11, 10)


def test_t_interval_and_grid_threshold():
    ti = t_interval([1.0, 2.0, 3.0])  # mean 2, s = 1, t_{0.975,2} = 4.3027
    assert ti["mean"] == 2.0 and ti["n"] == 3
    assert ti["high"] - 2.0 == pytest.approx(4.302653 / math.sqrt(3), rel=1e-5)
    assert t_interval([4.0])["low"] == 4.0
    assert threshold_on_grid([1, 2, 3, 4], [1.0, 0.6, 0.4, 0.7]) == 2
    assert threshold_on_grid([1, 2], [0.2, 0.9]) == 0.0
    # the crossing of 0.5, log-linear between the grid points around it: 0.75 -> 0.25 at
    # x = 1 -> 4 crosses halfway, at x = 2
    assert crossing_on_grid([1.0, 4.0, 8.0], [0.75, 0.25, 0.0]) == pytest.approx(2.0)
    assert crossing_on_grid([1.0, 2.0], [0.4, 0.1]) == 0.0
    assert crossing_on_grid([1.0, 2.0], [0.9, 0.6]) == 2.0


def test_validation_directions_are_disjoint_from_the_test_set():
    cb = BasinValidationCallback()
    val = cb.validation_directions()
    assert val.shape == (8, 6) and VALIDATION_SEED != CURVE_SEED
    # the callback draws its own sample: the directions of the validation seed, which share
    # no row with the test curve's (a generator of the test seed would give the test's rows
    # first: default_rng(seed).standard_normal((n, 6)) starts with the same rows for every n)
    assert np.array_equal(val, random_directions(8, VALIDATION_SEED))
    n_test = max(BUDGETS[b].curve_dirs for b in ("test", "quick", "full"))
    test = random_directions(n_test)
    assert not any(np.array_equal(v, t) for v in val for t in test)
    # and no validation direction is one of the basin's 12 axis directions (test set)
    assert np.all(np.sum(np.abs(val) == 1.0, axis=1) == 1)  # scaled to max |u_i| = 1 ...
    assert np.all(np.sum(val != 0.0, axis=1) == 6)  # ... and never along one axis
    assert sample_seeds(VALIDATION_SEED)["directions"] != sample_seeds()["directions"]
    assert np.array_equal(
        random_directions(4, seed=CURVE_SEED), random_directions(4)
    )  # the test set is the default


class Proportional:
    """A controller written outside the package: torque against the spine rate."""

    name = "proportional"
    env_kwargs = {"max_torque": 40.0}

    def __init__(self):
        self.apexes = 0

    def __call__(self, obs) -> float:
        return float(np.clip(-0.05 * obs[6], -1.0, 1.0))

    def fingerprint(self) -> str:
        return "proportional-0.05"

    def on_apex(self, z, time_since_apex):
        self.apexes += 1


def test_any_controller_with_the_protocol_runs_in_the_loop():
    ctrl = Proportional()
    assert as_controller(ctrl) is ctrl
    loop = margins.ClosedLoop(ctrl, "default")
    ok, n, failure = loop.run(loop.env.z_ref, loop.env.z_ref, 3)
    assert failure is None and ctrl.apexes == 3
    with pytest.raises(ValueError, match="controller"):
        as_controller(object())


def test_passive_theta1_basin_is_no_longer_capped_at_one():
    from bound_env.model.params import load_gait

    z = np.asarray(load_gait("default").z0)
    b = replace(BUDGETS["test"], basin_strides=300)  # e_max 0.878: ~100 strides to return
    setup = Setup(
        controller=ZeroController(),
        gait="default",
        budget=b,
        z_star=z,
        z_cl=z,
        key="t-theta1",
        period=0.39,
    )
    r = run_task(setup, "basin", (1, 1))
    assert r["rel"] > 1.0 and not r["capped"]  # theta1 grows past |z*_theta1|
    assert r["cap_reason"] == "numeric cap" and r["beyond"]["rel"] > r["rel"]
    r = run_task(setup, "basin", (3, -1))  # xdot: the start is invalid at s = 1 (xdot = 0)
    assert r["cap"] == pytest.approx(1.0, rel=1e-9) and r["rel"] < 0.1
    assert r["cap_reason"].startswith("start state invalid")


def test_every_setting_is_in_the_cache_key(monkeypatch):
    c = ZeroController()
    k0 = setup_key(c, "default", BUDGETS["quick"])
    assert setup_key(c, "default", replace(BUDGETS["quick"], ceiling_opt=1)) != k0
    assert setup_key(c, "literal-cycle", BUDGETS["quick"]) != k0
    monkeypatch.setitem(margins.SETTINGS, "basin_cap", 128.0)
    assert setup_key(c, "default", BUDGETS["quick"]) != k0


def test_compare_entries_take_several_policies():
    assert parse_entry("learned=runs/s0,runs/s1,runs/s2") == (
        "learned",
        ["runs/s0", "runs/s1", "runs/s2"],
        "default",
    )
    assert parse_entry("lit=a,b@literal-cycle") == ("lit", ["a", "b"], "literal-cycle")
    assert parse_entry("p=passive") == ("p", ["passive"], "default")
    for bad in ("nolabel", "x=", "=a"):
        with pytest.raises(ValueError, match="entry"):
            parse_entry(bad)


def test_compare_default_columns_are_the_pages():
    """The page's columns are the curated set (issue 30): passive, lqr, deadbeat, mpc, the
    best learned (the fine-tuned seeds; `default` is s0, not a column of its own), step-level
    PPO (step-ppo), plain PPO (ppo-v1's final-model seeds) and the literal-cycle pair; the
    archived policies (distilled, stride-residual, warm-started, the ppo-v1 checkpoint) and
    damping are added by --entry only."""
    from agents.results.compare import CLASSICAL, EXTRA_GROUPS, default_entries, seed_group

    entries = {label: (policies, gait) for label, policies, gait in default_entries()}
    assert [p.split("/")[-1] for p in entries["fine-tuned"][0]] == ["s0", "s1", "s2"]
    assert [p.split("/")[-1] for p in entries["step-ppo"][0]] == ["s0", "s1", "s2"]
    assert all("ppo-v1-final/s" in p for p in entries["ppo-v1"][0])
    assert CLASSICAL == ("lqr", "deadbeat", "mpc") and set(CLASSICAL) <= set(entries)
    learned = {"fine-tuned", "step-ppo", "ppo-v1"}
    literal = {"passive literal", "learned literal", "lqr literal"}
    assert set(entries) == {"passive", *CLASSICAL, *learned, *literal}
    assert not any(p.rstrip("/").endswith("default") for e in entries.values() for p in e[0])
    for _label, group in EXTRA_GROUPS:  # the archived seed groups still load by path
        assert group.startswith("archive/") and len(seed_group(group)) == 3


def test_the_page_shows_the_basin_maps_in_its_folder(tmp_path):
    from agents.results.compare import basin_maps

    assert basin_maps(tmp_path) == ""
    (tmp_path / "basin_mpc_xdot_y.png").write_bytes(b"png")
    (tmp_path / "basin_default_th1_th1dot.png").write_bytes(b"png")
    text = basin_maps(tmp_path)
    assert "](basin_mpc_xdot_y.png)" in text and "](basin_default_th1_th1dot.png)" in text
    assert "basin_lqr" not in text
