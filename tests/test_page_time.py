"""Where the page's time goes: each margins task's wall and CPU time, a column's in
``columns.json``, and the page's progress line with an estimate of the time left
(agents/results/headline.py)."""

from __future__ import annotations

import io
import json
import time
from types import SimpleNamespace

import pytest

from agents.results.headline import PageProgress, columns_json, previous_seconds
from bound_env.analysis.margins import run as margins_run
from bound_env.files.cache import TaskCache
from bound_env.sim.parallel import SerialExecutor


def _busy(setup, cpu_ms: float, sleep_ms: float) -> dict:
    t0 = time.process_time()
    while time.process_time() - t0 < 1e-3 * cpu_ms:
        pass
    time.sleep(1e-3 * sleep_ms)
    return {"done": True}


@pytest.fixture
def busy_task(monkeypatch):
    monkeypatch.setitem(margins_run.TASKS, "busy", _busy)


def test_a_task_records_its_cpu_time_beside_its_wall_time(busy_task):
    r = margins_run.run_task(SimpleNamespace(), "busy", (30.0, 60.0))
    assert 0.09 <= r["seconds"] and 0.03 <= r["cpu_seconds"] < 0.06  # the sleep is not CPU


def test_the_cpu_time_of_the_computed_tasks_adds_up(busy_task):
    """A column's ``cpu_seconds`` is its computed tasks' (a cached task adds none)."""
    setup = SimpleNamespace(key="k")
    cache = TaskCache(None)
    cached = margins_run.task_key("k", "busy", (1.0, 0.0))
    cache.put(cached, {"done": True, "seconds": 9.0, "cpu_seconds": 9.0})
    counts: dict = {}
    jobs = [("busy", (1.0, 0.0)), ("busy", (20.0, 0.0)), ("busy", (30.0, 0.0))]
    out = margins_run._run_all(SerialExecutor(), setup, jobs, cache, False, "", counts)
    assert len(out) == 3 and counts["cached"] == 1 and counts["computed"] == 2
    assert 0.05 <= counts["cpu_seconds"] < 0.2  # 20 + 30 ms, not the cached 9 s


def test_columns_json_gives_each_column_its_wall_and_cpu_time():
    runs = [
        {"seconds": 10.0, "cpu_seconds": 18.0, "tasks": {"cached": 0, "computed": 5}},
        {"seconds": 4.0, "cpu_seconds": 7.5, "tasks": {"cached": 1, "computed": 2}},
    ]
    for r in runs:
        r["basin_curve"] = {"r50": 0.2, "r50_ci": [0.1, 0.3]}
    groups = [{"label": "x", "gait": "default", "policies": ["a/s0", "a/s1"], "runs": runs}]
    col = columns_json(groups, "full", 12345, None)["columns"][0]
    assert col["wall_seconds"] == col["seconds"] == 14.0 and col["cpu_seconds"] == 25.5


def test_the_progress_line_estimates_the_time_left_from_the_last_run(tmp_path):
    """The last run took 100 s per policy of a, 300 s of b; this run's a took twice as long,
    so b's two policies are estimated at 2 x 600 s; without a last run, the mean so far."""
    last = tmp_path / "columns.json"
    cols = [
        {"label": "a", "policies": ["passive"], "seconds": 100.0},
        {"label": "b", "policies": ["x/s0", "x/s1"], "seconds": 600.0},
    ]
    last.write_text(json.dumps({"columns": cols}))
    assert previous_seconds(last)[("b", "s1")] == 300.0
    entries = [("a", ["passive"], "default"), ("b", ["x/s0", "x/s1"], "default")]
    out = io.StringIO()
    p = PageProgress(entries, last, stream=out)
    p._t -= 200.0  # a took 200 s
    line = p.done("a", "passive", {"cpu_seconds": 390.0, "tasks": {"computed": 3}})
    assert line.startswith("[page 1/3] a: 200 s wall, 390 s CPU in its workers;")
    assert line.endswith("about 1200 s left") and out.getvalue() == line + "\n"
    fresh = PageProgress(entries, tmp_path / "none.json", enabled=False)
    fresh._t -= 50.0
    assert fresh.done("a", "passive", {}).endswith("about 100 s left")
    # a policy taken from the cache (nothing computed) says nothing of the time left
    cached = PageProgress(entries, last, enabled=False)
    cached.done("a", "passive", {"tasks": {"computed": 0}})
    assert "left" not in cached.done("b", "x/s0", {"tasks": {"computed": 0}})
    (tmp_path / "bad.json").write_text("{")
    assert previous_seconds(tmp_path / "bad.json") == {}
