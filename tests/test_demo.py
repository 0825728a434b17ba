"""The main job's comparison (``bound-env demo``, agents/results/demo.py): a start chosen on the
validation directions from which the passive gait falls, ``lqr`` falls and the shipped
``default`` controller returns; the ``comparison`` object of summary.json, compare.gif and
the table; and bound_env's demo without the agents part (the core does not need agents)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.results.demo import (
    DEMO_BASELINE,
    DEMO_DIRECTIONS,
    DEMO_INDEX,
    DEMO_POLICY,
    DEMO_SEED,
    DEMO_SIZE,
    DEMO_STRIDES,
    compare_from_start,
    demo_start,
    table_lines,
)
from agents.runtime.controllers import ZeroController
from agents.runtime.policy import load_controller
from bound_env.analysis.margins import DEFAULT_SEED, ClosedLoop, random_directions


def test_the_start_is_a_validation_direction_not_the_test_set():
    assert DEMO_SEED == 777 and DEMO_SEED != DEFAULT_SEED  # 12345: the test set
    z0, z_star, xi = demo_start("default")
    want = random_directions(DEMO_DIRECTIONS, DEMO_SEED)[DEMO_INDEX]
    assert np.array_equal(xi, want) and np.max(np.abs(xi)) == 1.0
    assert np.allclose(z0, z_star + DEMO_SIZE * np.abs(z_star) * xi, rtol=0, atol=0)


def test_passive_falls_and_the_default_controller_returns_from_the_start():
    """Checked on the margins' own closed loop, independently of the demo's recording."""
    z0, z_star, _ = demo_start("default")
    ok, _, failure = ClosedLoop(ZeroController(), "default").run(z0, z_star, DEMO_STRIDES)
    assert not ok and failure is not None  # passive falls
    lqr = load_controller(DEMO_BASELINE)
    ok, _, failure = ClosedLoop(lqr, "default").run(z0, z_star, DEMO_STRIDES)
    assert not ok and failure is not None  # the LQR falls too
    ctrl = load_controller(DEMO_POLICY)
    ok, strides, failure = ClosedLoop(ctrl, "default").run(z0, z_star, DEMO_STRIDES)
    assert ok and failure is None and strides <= DEMO_STRIDES  # default returns
    c = compare_from_start()
    assert c["passive"]["fell"] and c["passive"]["failure"] is not None
    assert c["lqr"]["fell"] and c["lqr"]["failure"] is not None and not c["lqr"]["returned"]
    assert c["learned"]["returned"] and c["learned"]["strides"] == strides
    assert 0.0 < c["learned"]["mean_abs_tau"] <= c["learned"]["max_torque"]
    # the recorded runs read as one run: time and position only go forward
    for states in c["_states"]:
        x = np.array([s[0][0] for s in states])
        t = np.array([s[2] for s in states])
        assert np.all(np.diff(x) > 0) and np.all(np.diff(t) > 0)


def test_bound_env_demo_writes_the_comparison(tmp_path, capsys):
    from bound_env.commands.cli import main

    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--gif-strides", "0.5", "--no-progress"]) == 0
    printed = capsys.readouterr()
    assert printed.err == ""  # --no-progress: no bars
    summary = json.loads((out / "summary.json").read_text())
    c = summary["comparison"]
    assert set(c) >= {"start", "passive", "lqr", "learned"}
    assert set(c["start"]) >= {"z", "seed", "index", "r", "direction"}
    assert (c["start"]["seed"], c["start"]["index"], c["start"]["r"]) == (777, 6, 0.2)
    assert set(c["passive"]) >= {"fell", "failure", "strides"}
    assert set(c["learned"]) >= {"returned", "strides", "mean_abs_tau"}
    assert set(c["lqr"]) >= {"fell", "failure", "strides", "mean_abs_tau"}
    assert c["passive"]["fell"] is True and c["learned"]["returned"] is True
    assert c["lqr"]["fell"] is True
    assert summary["max_apex_error_si"] < 1e-8  # the passive cycle part is unchanged
    from PIL import Image

    with Image.open(out / "compare.gif") as im:
        assert im.n_frames > 50 and im.size[0] > 3 * im.size[1]  # three panels side by side
    # the four-line table closes the output
    last = printed.out.strip().splitlines()[-4:]
    assert last == table_lines(c)
    assert last[0].startswith("controller") and last[1].startswith("passive")
    assert last[2].startswith("lqr") and last[3].startswith("learned")


def test_the_core_demo_runs_without_the_agents_part(tmp_path, monkeypatch, capsys):
    from bound_env.commands import render_cli
    from bound_env.commands.cli import build_parser

    monkeypatch.setattr(render_cli, "DEMO_PARTS", {})
    args = build_parser([render_cli.register]).parse_args(
        ["demo", "--out", str(tmp_path), "--gif-strides", "0.3", "--json", "--quiet"]
    )
    assert args.func(args) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert "comparison" not in summary and not (tmp_path / "compare.gif").exists()
    assert json.loads(capsys.readouterr().out)["strides"] == summary["strides"]


@pytest.mark.parametrize("gait", ["literal-cycle"])
def test_the_comparison_is_skipped_on_another_gait(gait):
    from agents.results.demo import demo_comparison

    c, lines = demo_comparison(gait=gait, out=None)
    assert "skipped" in c and gait in c["skipped"] and len(lines) == 1
