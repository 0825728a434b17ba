"""scripts/hold_eval.py is the hold measure of ``bound-env margins --mismatch pmD`` alone: its
``--seed`` names the plants the margins' seed names (the library's sampling and seeds), and a
row's outcomes are `task_mm_hold`'s."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from bound_env.analysis.margins.budget import BUDGETS
from bound_env.analysis.margins.closed_loop import Setup
from bound_env.analysis.margins.model_error.mismatch_tasks import plants_of
from bound_env.model.mismatch import as_spec
from bound_env.model.params import load_gait


def test_seed_777_names_the_plants_of_the_margins_seed_777(load_script):
    hold_eval = load_script("hold_eval")
    z_star = np.zeros(6)
    for delta, preset in ((0.05, "pm5"), (0.1, "pm10")):
        spec = hold_eval.spec_of(delta)
        assert spec.ranges == as_spec(preset).ranges and spec.name == preset
        margins = Setup(None, "default", BUDGETS["test"], z_star, seed=777, mismatch=spec)
        want = plants_of(margins, 5)
        assert hold_eval.plants(delta, 5, 777) == want
        # not the plants of numpy's generator seeded 777 directly (the earlier script's)
        assert hold_eval.plants(delta, 5, 777) != plants_of(
            Setup(None, "default", BUDGETS["test"], z_star, seed=12345, mismatch=spec), 5
        )


def test_a_row_is_the_margins_hold(tmp_path, capsys, load_script):
    """A row of ``--delta 0.1 --seed 777 --robots 8 --strides 20`` is the hold of ``bound-env
    margins --policy lqr --budget test --mismatch pm10 --seed 777`` (its task, run here)."""
    from agents.policy import load_controller

    from bound_env.analysis.margins.model_error.mismatch_tasks import MISMATCH_BUDGETS
    from bound_env.analysis.margins.run import run_task

    hold_eval = load_script("hold_eval")
    out = tmp_path / "rows.jsonl"
    # the test budget's plants and strides, the effort over the quick and full budgets' tail
    mb = replace(MISMATCH_BUDGETS["test"], effort_strides=MISMATCH_BUDGETS["quick"].effort_strides)
    argv = ["--policy", "lqr", "--delta", "0.1", "--seed", "777", "--robots", str(mb.plants)]
    assert hold_eval.main([*argv, "--strides", str(mb.hold_strides), "--out", str(out)]) == 0
    row = json.loads(out.read_text())
    assert row["measure"] == "mm_hold" and row["n"] == mb.plants
    z_star = np.asarray(load_gait("default").z0, dtype=float)  # compute_margins' start
    setup = Setup(load_controller("lqr"), "default", BUDGETS["test"], z_star, key="margins",
                  seed=777, mismatch=as_spec("pm10"), mismatch_budget=mb)  # fmt: skip
    margins = run_task(setup, "mm_hold", ())
    assert row["held"] == [bool(o) for o in margins["outcomes"]]
    assert row["strides"] == margins["strides"] and row["tail_effort"] == margins["effort"]
    assert 0 < sum(row["held"]) < mb.plants  # +-10 %: some plants fall, some are held
    # resumed: the finished row is not run again
    assert hold_eval.main([*argv, "--strides", str(mb.hold_strides), "--out", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 1
    with pytest.raises(SystemExit) as bad:  # a one-line usage error, exit 2
        hold_eval.main(["--seed", "-1"])
    assert bad.value.code == 2 and "--seed" in capsys.readouterr().err


def test_set_tags_and_changes_only_the_offset_free_rows(tmp_path, capsys, load_script):
    """``--set gain=0.5`` reaches the '+of' policy (its row is tagged, and its torques are not
    those of the default gain) and not ``lqr``, which has no gain to take: lqr's row is
    untagged and is the row of a run without ``--set``. ``estimator=`` is a setting too."""
    hold_eval = load_script("hold_eval")
    argv = ["--policy", "lqr", "lqr-of", "--delta", "0.1", "--seed", "777", "--robots", "3"]
    argv += ["--strides", "12"]
    plain, tuned = tmp_path / "plain.jsonl", tmp_path / "tuned.jsonl"
    assert hold_eval.main([*argv, "--out", str(plain)]) == 0
    sets = ["--set", "gain=0.5", "estimator=torque"]
    assert hold_eval.main([*argv, *sets, "--out", str(tuned)]) == 0
    assert "lqr is not offset-free" in capsys.readouterr().err
    a = {r["policy"]: r for r in map(json.loads, plain.read_text().splitlines())}
    b = {r["policy"]: r for r in map(json.loads, tuned.read_text().splitlines())}
    assert b["lqr"]["set"] == "" and b["lqr-of"]["set"] == "estimator=torque,gain=0.5"
    assert b["lqr"]["tail_effort"] == a["lqr"]["tail_effort"]
    assert b["lqr-of"]["tail_effort"] != a["lqr-of"]["tail_effort"]
