"""The real-time yardstick (bound_env.analysis.margins.decision_times): per-task histograms of
decision times merge into the p50 and p99 of all of them, to the bin width; the page's table
names the best controller within 1 ms per decision (p99)."""

from __future__ import annotations

import numpy as np
import pytest

from bound_env.analysis.margins.decision_times import (
    BINS_PER_DECADE,
    histogram,
    real_time_table,
    summary,
)

WIDTH = 10 ** (1 / BINS_PER_DECADE)  # a bin's ratio of its ends


def test_merged_histograms_give_the_quantiles_of_all_times():
    rng = np.random.default_rng(0)
    ts = np.exp(rng.normal(np.log(3e-4), 1.2, 5000))  # 0.3 ms median, a long tail
    tasks = [{"decision_hist": histogram(part)} for part in np.array_split(ts, 7)]
    tasks.append({"seconds": 1.0})  # a task without decisions
    s = summary(tasks)
    assert s["n"] == ts.size
    for key, q in (("p50", 0.5), ("p99", 0.99)):
        exact = float(np.quantile(ts, q))
        assert exact / WIDTH <= s[key] <= exact * WIDTH, key
    assert summary([{"seconds": 1.0}, {}]) is None  # no decisions: no entry


def test_the_table_names_the_best_real_time_controller():
    columns = {
        "mpc": {"decision_times": {"p50": 2e-3, "p99": 9e-3, "n": 10}, "r50": 0.29},
        "default": {
            "decision_times": {"p50": 2e-5, "p99": 4e-5, "n": 10},
            "basin_curve": {"r50": 0.26},
        },
        "lqr": {"decision_times": {"p50": 1e-5, "p99": 2e-5, "n": 10}, "r50": 0.19},
        "passive": {"decision_times": None, "r50": 0.01},
    }
    text = real_time_table(columns)
    assert "| mpc | 2 | 9 | 10 |" in text and "| passive | no apex decisions | | |" in text
    assert "**default** (r50 0.260, p99 0.04 ms)" in text  # mpc is better but too slow
    columns["mpc"]["decision_times"]["p99"] = 1e-3  # now within 1 ms
    assert "**mpc**" in real_time_table(columns)
    none = real_time_table({"mpc": {"decision_times": {"p50": 1, "p99": 2, "n": 1}}})
    assert none.endswith("(p99): none.\n")


@pytest.mark.parametrize("t", [0.0, 1e-9, 5.0])
def test_extreme_times_land_in_the_end_bins(t):
    assert sum(histogram([t]).values()) == 1
