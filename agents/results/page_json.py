"""The results page's own JSON beside ``MARGINS.md``: ``columns.json`` and ``model_error.json``.

``paired.json`` (the paired differences, the fair decision times) and ``headline.json`` (the
headline's rows) are the page's older files; these two complete them, so that every number
the docs quote of the page is one value of a committed JSON (`agents.results.numbers`):

- ``columns.json`` (`columns_json`): every column, with each policy's **fingerprint** (what
  decided its numbers: `bound_env.analysis.margins.fingerprint`, recorded in its
  ``margins.json`` when it was computed), its r50, the σ where the MFPT falls to 100 strides
  and σ50 with their 95 % intervals, its wall time in the run and the tasks it took from the
  cache; and ``run``: the page run's wall time, workers, load and commit (`run_record`).
- ``model_error.json`` (`model_error_json`), when the columns were measured under model error
  (``compare --mismatch``): the page's "Model error" section as numbers
  (`bound_env.analysis.margins.mismatch_report.mismatch_summary`), each column's fingerprints
  and the run.

tests/test_page_fingerprints.py checks that every committed column's fingerprint is what its
controller is now; tests/test_docs_numbers.py that the docs quote these files.
"""

from __future__ import annotations

import os
import platform
import time

from bound_env.analysis.margins.fingerprint import git_commit

from .formatting import rel
from .headline import _headline_measure, mfpt_sigma_100_interval

COLUMNS_FILE = "columns.json"
MODEL_ERROR_FILE = "model_error.json"


def run_record(t0: float, workers: int, scheduler, load_before, groups, command: str) -> dict:
    """How the page run went: its wall time since ``t0`` (`time.perf_counter`), the workers
    and scheduler, the machine's load before and after, the tasks its columns took from the
    cache and computed (a page made from an empty cache computed them all), and the commit."""
    tasks = {"cached": 0, "computed": 0}
    for g in groups:
        for r in g["runs"]:
            for k in tasks:
                tasks[k] += int((r.get("tasks") or {}).get(k, 0))
    commit, dirty = git_commit()
    return {
        "wall_seconds": time.perf_counter() - t0,
        "workers": workers,
        "scheduler": scheduler,
        "cores": os.cpu_count(),
        "machine": platform.machine(),
        "load_average_before": load_before,
        "load_average_after": [round(v, 2) for v in os.getloadavg()],
        "tasks": tasks,
        "commit": commit,
        "dirty": dirty,
        "command": command,
    }


def _fingerprints(g) -> list:
    return [r.get("fingerprint") for r in g["runs"]]


def _sigma50_interval(r: dict) -> list:
    return list(r.get("terrain_sigma50_ci_deg") or [None, None])


def columns_json(groups, budget: str, seed: int, run: dict) -> dict:
    """``columns.json``: every column's fingerprints and headline measures, and the run."""
    cols = []
    for g in groups:
        runs = g["runs"]
        tasks = {"cached": 0, "computed": 0}
        for r in runs:
            for k in tasks:
                tasks[k] += int((r.get("tasks") or {}).get(k, 0))
        cols.append(
            {
                "label": g["label"],
                "gait": g["gait"],
                "policies": [rel(p) for p in g["policies"]],
                "fingerprints": _fingerprints(g),
                "seconds": sum(float(r.get("seconds") or 0.0) for r in runs),
                "tasks": tasks,
                "r50": _headline_measure(
                    runs,
                    lambda r: r["basin_curve"]["r50"],
                    lambda r: r["basin_curve"].get("r50_ci", [None, None]),
                    "Wilson-based (the directions' sampling error)",
                ),
                "mfpt_sigma_100_deg": _headline_measure(
                    runs,
                    lambda r: r.get("mfpt_sigma_100_deg"),
                    mfpt_sigma_100_interval,
                    "Poisson-based (the robots' sampling error)",
                ),
                "terrain_sigma50_deg": _headline_measure(
                    runs,
                    lambda r: r.get("terrain_sigma50_deg"),
                    _sigma50_interval,
                    "Wilson-based (the terrain runs' sampling error)",
                ),
            }
        )
    return {"budget": budget, "seed": seed, "run": run, "columns": cols}


def measured_under_error(groups) -> dict:
    """{label: first run} of the columns measured under model error."""
    return {g["label"]: g["runs"][0] for g in groups if g["runs"][0].get("mismatch")}


def model_error_json(groups, budget: str, seed: int, run: dict) -> dict | None:
    """``model_error.json``: the "Model error" section's numbers (paired against lqr where it
    is a column), the columns' fingerprints and the run; None when no column was measured
    under model error."""
    from bound_env.analysis.margins.mismatch_report import mismatch_summary

    measured = measured_under_error(groups)
    if not measured:
        return None
    specs = list(dict.fromkeys(k for r in measured.values() for k in r["mismatch"]))
    ref = "lqr" if "lqr" in measured else None
    summary = mismatch_summary(measured, specs=specs, reference=ref)
    return {
        "budget": budget,
        "seed": seed,
        "reference": summary["reference"],
        "specs": summary["specs"],
        "columns": [
            {
                "label": g["label"],
                "gait": g["gait"],
                "policies": [rel(p) for p in g["policies"][:1]],
                "fingerprints": _fingerprints(g)[:1],
            }
            for g in groups
            if g["label"] in measured
        ],
        "run": run,
    }
