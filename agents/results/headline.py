"""The headline: the results page's first table and the README's (``python -m
agents.results.headline``).

`headline_numbers` makes the numbers of the `HEADLINE` rows (r50 and the sigma at which the
MFPT falls to 100 strides, each with its 95 % interval) from the page's columns;
``bound-env compare --docs docs`` writes them to ``docs/headline.json`` beside
``docs/MARGINS.md`` and puts their table (`headline_table`) first on the page. This module's
command puts the same table into README.md, between the markers ``<!-- headline:start -->`` and
``<!-- headline:end -->``, so that it is regenerated, never edited by hand; ``--check`` only
says whether the README is up to date (exit 1 if not). tests/test_docs.py checks both tables
against the JSON.

The page's other JSON beside it, so that every number the docs quote of the page is one value
of a committed file (`agents.results.numbers`):

- ``columns.json`` (`columns_json`): every column, with each policy's **fingerprint** (what
  decided its numbers: `bound_env.analysis.margins.provenance.fingerprint`, recorded in its
  ``margins.json`` when it was computed), its r50, the sigma where the MFPT falls to 100
  strides and sigma50 with their 95 % intervals, its wall time in the run and the tasks it
  took from the cache; and ``run``: the page run's wall time, workers, load and commit
  (`run_record`);
- ``model_error.json`` (`model_error_json`), when the columns were measured under model error
  (``compare --mismatch``): the page's "Model error" section as numbers
  (`bound_env.analysis.margins.model_error.mismatch_report.mismatch_summary`), each column's
  fingerprints and the run.

tests/test_page_fingerprints.py checks that every committed column's fingerprint is what its
controller is now.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

from bound_env.analysis.margins.provenance.fingerprint import git_commit
from bound_env.analysis.margins.stats import t_interval
from bound_env.files.cache import atomic_write
from bound_env.files.schema import check_keys, load_json_strict

from .formatting import ROOT, num3, rel, slug, value

# The headline table (the page's first table and the README's): (role, column label, what it
# is). The step-level PPO row is the shipped step-level recipe's column (`step-ppo`: residual
# PPO on PassiveBound-v0; ppo-v1's plain recipe is the `ppo-v1` column of the full table).
HEADLINE = (
    ("passive", "passive", "zero spine torque"),
    ("lqr", "lqr", "stride-to-stride LQR (classical)"),
    ("mpc", "mpc", "model-predictive search over the next stride (classical, the teacher)"),
    (
        "best learned",
        "fine-tuned",
        "`default`: distilled from `mpc`, fine-tuned by PPO (3 seeds; `default` = s0)",
    ),
    (
        "step-level PPO",
        "step-ppo",
        "PPO on PassiveBound-v0: a residual on `default`'s torques past its safe radius "
        "(configs/ppo-residual.yaml, 3 final-model seeds)",
    ),
)
HEADLINE_FILE = "headline.json"  # beside MARGINS.md and paired.json


def mfpt_sigma_100_interval(r: dict) -> list:
    """The Poisson-based interval of one run's ``mfpt_sigma_100_deg``: where the lower and the
    upper ends of the MFPT's exact Poisson intervals cross 100 strides (log-log interpolated,
    as the estimate; an unbounded upper end counts as above). The analogue of r50's
    Wilson-based interval: the sampling error of the robots' runs. None where a bound does not
    cross on the grid."""
    from bound_env.analysis.margins.budget import MFPT_LEVEL
    from bound_env.analysis.margins.stats import mfpt_crossing

    m = r.get("mfpt") or []
    if not m:
        return [None, None]
    sig = [e["sigma_deg"] for e in m]
    lo = [e["ci"][0] for e in m]
    hi = [math.inf if e["ci"][1] is None else e["ci"][1] for e in m]
    # an infinite upper end is "above" for mfpt_crossing only as a huge finite number
    hi = [1e300 if math.isinf(v) else v for v in hi]
    no = [False] * len(m)
    return [mfpt_crossing(sig, lo, no, MFPT_LEVEL), mfpt_crossing(sig, hi, no, MFPT_LEVEL)]


def headline_measure(runs, fn, single_interval, single_method) -> dict:
    vals = [value(fn, r) for r in runs]
    if len(runs) > 1:
        ti = t_interval(vals)
        return {
            "value": ti["mean"],
            "low": ti["low"],
            "high": ti["high"],
            "interval": f"Student-t over {ti['n']} seeds",
            "per_seed": vals,
        }
    lo, hi = single_interval(runs[0])
    return {"value": vals[0], "low": lo, "high": hi, "interval": single_method}


def headline_measures(runs) -> dict:
    """A column's two headline measures over its runs (one per seed), each with its 95 %
    interval (`headline_measure`): r50 and the sigma at which the MFPT falls to 100 strides.
    The measures of a headline row (`headline_numbers`) and of a column (`columns_json`)."""
    return {
        "r50": headline_measure(
            runs,
            lambda r: r["basin_curve"]["r50"],
            lambda r: r["basin_curve"].get("r50_ci", [None, None]),
            "Wilson-based (the directions' sampling error)",
        ),
        "mfpt_sigma_100_deg": headline_measure(
            runs,
            lambda r: r.get("mfpt_sigma_100_deg"),
            mfpt_sigma_100_interval,
            "Poisson-based (the robots' sampling error)",
        ),
    }


def headline_numbers(groups, budget: str, seed: int, yours=()) -> dict:
    """The headline (`HEADLINE`): per row present among the default-gait columns, r50 and the
    sigma at which the MFPT falls to 100 strides, each with its 95 % interval (Student-t over
    seeds; one run: Wilson-based for r50, Poisson-based for the sigma). ``yours``: the labels
    of a user's own columns (``compare --entry``), each a row after them. What
    docs/headline.json holds and `headline_table` renders."""
    rows = []
    known = {label for _, label, _ in HEADLINE}
    mine = []
    for label in yours:
        g = next((g for g in groups if g["label"] == label), None)
        if label not in known and g is not None:
            what = "your column: " + ", ".join(f"`{rel(p)}`" for p in g["policies"])
            if g["gait"] != "default":
                what += f" (gait `{g['gait']}`)"
            mine.append((label, label, what))
    for role, label, what in (*HEADLINE, *mine):
        gaits = ("default",) if label in known else (None,)  # a user's column: any gait
        g = next(
            (g for g in groups if g["label"] == label and (g["gait"] in gaits or not gaits[0])),
            None,
        )
        if g is None:
            continue
        runs = g["runs"]
        rows.append(
            {
                "role": role,
                "label": label,
                "what": what,
                "policies": [rel(p) for p in g["policies"]],
                # it reads the robot's true plant (bound_env.control.privileged): marked
                "privileged": any(r.get("privileged") is True for r in runs),
                **headline_measures(runs),
            }
        )
    return {"budget": budget, "seed": seed, "rows": rows}


# The model-error column that stands for each headline row in "held at ±10 % / ±15 %"
# (`agents.results.compare.model_error_entries`: the best learned row's is its first seed,
# `default`); a row without one (the step-level PPO) is "not measured"
HELD_COLUMNS = {"passive": "passive", "lqr": "lqr", "mpc": "mpc", "fine-tuned": "default"}
HELD_SPECS = ("pm10", "pm15")


def add_held(head: dict, held: dict, budget: str) -> dict:
    """``head`` (`headline_numbers`) with each row's ``held``: its model-error column's hold
    at ±10 % and ±15 % ({column, budget, pm10: {k, n}, pm15: {k, n}}; ``held``:
    `held_at`), None where the row has no such column."""
    for row in head["rows"]:
        col = HELD_COLUMNS.get(row["label"])
        h = held.get(col) if col else None
        if h is None or not all(s in h for s in HELD_SPECS):
            row["held"] = None
            continue
        row["held"] = {"column": col, "budget": budget, **{s: h[s] for s in HELD_SPECS}}
    return head


def _held_cell(row: dict) -> str:
    h = row.get("held")
    if not h:
        return "not measured"
    text = " / ".join(f"{h[s]['k']}/{h[s]['n']}" for s in HELD_SPECS)
    return text if h["column"] == row["label"] else f"{text} (`{h['column']}`)"


def headline_table(head: dict) -> str:
    """The headline table in Markdown (five columns; one row per `HEADLINE` row present), from
    the numbers `headline_numbers` made (docs/headline.json): the page's first table and the
    README's results table are this text."""
    held = any("held" in row for row in head["rows"])  # a page with its model-error section
    budgets = {row["held"]["budget"] for row in head["rows"] if row.get("held")}
    held_head = " held at ±10 % / ±15 %" + (
        f" (model-error budget `{budgets.pop()}`) |" if len(budgets) == 1 else " |"
    )
    lines = [
        "| controller | what it is | r50 [95 % interval] | σ (deg) where MFPT = 100 "
        "strides [95 % interval] | interval |" + (held_head if held else ""),
        "| --- | --- | --- | --- | --- |" + (" --- |" if held else ""),
    ]
    for row in head["rows"]:
        cells = []
        for key in ("r50", "mfpt_sigma_100_deg"):
            m = row[key]
            cells.append(f"{num3(m['value'])} [{num3(m['low'])}, {num3(m['high'])}]")
        kinds = {row["r50"]["interval"], row["mfpt_sigma_100_deg"]["interval"]}
        kind = (
            kinds.pop()
            if len(kinds) == 1
            else "r50: Wilson-based; σ: Poisson-based (one run's sampling error)"
        )
        name = row["role"] if row["role"] == row["label"] else f"{row['role']} ({row['label']})"
        if row.get("privileged"):
            name += " (privileged: reads the true plant)"
        line = f"| **{name}** | {row['what']} | {cells[0]} | {cells[1]} | {kind} |"
        lines.append(line + (f" {_held_cell(row)} |" if held else ""))
    return "\n".join(lines)


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
                # where the time goes: the column's wall time (= seconds) and its workers'
                # CPU time over the tasks it computed (none for a cached task)
                "wall_seconds": sum(float(r.get("seconds") or 0.0) for r in runs),
                "cpu_seconds": sum(float(r.get("cpu_seconds") or 0.0) for r in runs),
                "tasks": tasks,
                **headline_measures(runs),
                "terrain_sigma50_deg": headline_measure(
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
    from bound_env.analysis.margins.model_error.mismatch_report import mismatch_summary

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


def held_at(groups) -> dict:
    """{label: {spec: {k, n}}} of the hold of every model-error column (the headline's "held
    at ±10 % / ±15 %")."""
    out = {}
    for g in groups:
        mm = g["runs"][0].get("mismatch") or {}
        out[g["label"]] = {
            name: {"k": int(b["hold"]["k"]), "n": int(b["hold"]["n"])} for name, b in mm.items()
        }
    return out


def time_rows(groups) -> list[dict]:
    """``columns.json``'s ``model_error``: each section column's fingerprint, wall and CPU
    time (its workers', over the tasks it computed) and tasks, as the page's columns have."""
    rows = []
    for g in groups:
        r = g["runs"][0]
        rows.append(
            {
                "label": g["label"],
                "gait": g["gait"],
                "policies": [rel(p) for p in g["policies"]],
                "fingerprints": [r.get("fingerprint")],
                "seconds": float(r.get("seconds") or 0.0),
                "wall_seconds": float(r.get("seconds") or 0.0),
                "cpu_seconds": float(r.get("cpu_seconds") or 0.0),
                "tasks": dict(r.get("tasks") or {"cached": 0, "computed": 0}),
            }
        )
    return rows


class PageProgress:
    """The page's progress line (stderr), after every column's policy: how many are done,
    that one's wall and CPU time, the page's time so far and an estimate of the time left.

    The estimate: where the last run's ``columns.json`` (``previous``) has a column's time
    (`previous_seconds`: its ``seconds`` per policy), the time left is those of the policies
    still to run, scaled by how this run compares with it so far (the sum of this run's
    seconds over the last run's, for the policies done that it has); otherwise the mean time
    of a policy so far times the policies left. A policy whose every task came from the cache
    (seconds, not minutes) counts in neither; the estimate supposes the ones left compute
    theirs."""

    def __init__(self, entries, previous: Path, enabled: bool = True, stream=None):
        self.todo = [(label, pol) for label, pols, _gait in entries for pol in pols]
        self.before = previous_seconds(previous)
        self.enabled, self.stream = enabled, stream
        self.t0, self.k = time.perf_counter(), 0
        self.spent: list = []  # (seconds, the last run's or None, computed?) per policy done
        self._t = self.t0

    def start(self) -> None:
        self._t = time.perf_counter()

    def estimate_left(self) -> float | None:
        """Seconds left (module docstring), None before the first policy is done."""
        spent = [(a, b) for a, b, computed in self.spent if computed]
        if not spent:
            return None
        left = self.todo[self.k :]
        known = [(a, b) for a, b in spent if b]
        scale = sum(a for a, _ in known) / sum(b for _, b in known) if known else None
        mean = sum(a for a, _ in spent) / len(spent)
        total = 0.0
        for label, pol in left:
            prev = self.before.get((label, slug(Path(pol).name)))
            total += prev * scale if (prev and scale is not None) else mean
        return total

    def done(self, label: str, policy: str, result: dict) -> str:
        """Count a policy done; its line (printed when enabled)."""
        now = time.perf_counter()
        prev = self.before.get((label, slug(Path(policy).name)))
        computed = int((result.get("tasks") or {}).get("computed", 1)) > 0
        self.spent.append((now - self._t, prev, computed))
        self.k += 1
        left = self.estimate_left()
        name = label if Path(policy).name in (label, policy) else f"{label} {Path(policy).name}"
        line = (
            f"[page {self.k}/{len(self.todo)}] {name}: {now - self._t:.0f} s wall, "
            f"{float(result.get('cpu_seconds') or 0.0):.0f} s CPU in its workers; "
            f"page {now - self.t0:.0f} s so far"
            + (f", about {left:.0f} s left" if self.k < len(self.todo) and left is not None else "")
        )
        if self.enabled:
            print(line, file=self.stream or sys.stderr, flush=True)
        self._t = time.perf_counter()  # the next column starts now, unless `start` says later
        return line


def previous_seconds(path: Path) -> dict:
    """{(label, policy folder name): seconds per policy} of the last run's ``columns.json``
    (its column's ``seconds`` shared equally by its policies; a model-error column's label
    ``model error <label>``); {} without a readable one (an
    estimate only: a broken file is not an error here)."""
    try:
        data = json.loads(Path(path).read_text())
        cols = list(data.get("columns") or [])
        # the model-error section's columns, as the progress line names them
        cols += [{**c, "label": f"model error {c['label']}"} for c in data.get("model_error") or []]
        out = {}
        for c in cols:
            pols = c.get("policies") or []
            secs = float(c.get("seconds") or 0.0) / max(1, len(pols))
            for p in pols:
                out[(c["label"], slug(Path(p).name))] = secs
        return out
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return {}


START, END = "<!-- headline:start -->", "<!-- headline:end -->"
README = ROOT / "README.md"
HEADLINE_JSON = ROOT / "docs" / HEADLINE_FILE


# what each row of headline.json holds (`agents.results.compare.headline_numbers`): a measure is its
# value and 95 % interval (null where it could not be measured) and the interval's kind
_MEASURE = {"value": (float, None), "low": (float, None), "high": (float, None), "interval": str}
_ROW = {
    "role": str,
    "label": str,
    "what": str,
    "r50": _MEASURE,
    "mfpt_sigma_100_deg": _MEASURE,
}
_HELD = {"column": str, "budget": str, **{s: {"k": int, "n": int} for s in HELD_SPECS}}


def load_headline(path: Path = HEADLINE_JSON) -> dict:
    """docs/headline.json, checked: strict JSON (a NaN or Infinity is refused, so it never
    reaches the README), ``budget``, ``seed`` and ``rows``, and each row's keys and types
    (`_ROW`); a one-line ValueError naming the file and the key otherwise."""
    path = Path(path)
    head = load_json_strict(path, {"budget": str, "seed": int, "rows": list})
    for i, row in enumerate(head["rows"]):
        check_keys(row, _ROW, str(path), f"rows[{i}].")
        if not isinstance(row.get("privileged", False), bool):  # absent: an older file
            raise ValueError(f"{path}: rows[{i}].privileged must be true or false")
        if row.get("held") is not None:  # the page's model-error section's hold (optional)
            check_keys(row["held"], _HELD, str(path), f"rows[{i}].held.")
    if not head["rows"]:
        raise ValueError(f"{path}: rows: empty (write it with bound-env compare --docs)")
    return head


def render_block(head: dict) -> str:
    """The README's block: the markers around the table and the line saying where it is from."""
    held = [r["held"] for r in head["rows"] if r.get("held")]
    budgets = f"r50 and σ: the **{head['budget']}** budget"
    if held:
        from bound_env.analysis.margins.model_error.mismatch_tasks import MISMATCH_BUDGETS

        mb = MISMATCH_BUDGETS.get(held[0]["budget"])
        budgets += f"; held at ±10 % / ±15 %: the model-error budget `{held[0]['budget']}`"
        if mb is not None:
            budgets += f" ({mb.plants} plants, {mb.hold_strides} strides from the nominal z*)"
    return (
        f"{START}\n{headline_table(head)}\n\n"
        f"{budgets}; on the test set (seed {head['seed']}); generated from "
        f"`docs/{HEADLINE_FILE}` by `python -m agents.results.headline`.\n{END}"
    )


def update_readme(text: str, head: dict, where: str = "README.md") -> str:
    """``text`` with its headline block replaced: a ValueError naming ``where`` unless it
    holds exactly one ``START`` and one ``END`` after it (a lost marker, or a second block,
    would have the rewrite cut the text between them, or leave a stale copy)."""
    starts, ends = text.count(START), text.count(END)
    if not starts and not ends:
        raise ValueError(f"{where}: no {START} ... {END} block")
    if starts != 1 or ends != 1:
        raise ValueError(
            f"{where}: {starts} {START} and {ends} {END} markers (one block of each expected; "
            "a lost or doubled marker: mend it by hand)"
        )
    i, j = text.find(START), text.find(END)
    if j < i:
        raise ValueError(f"{where}: {END} before {START}")
    return text[:i] + render_block(head) + text[j + len(END) :]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.results.headline", description=__doc__)
    ap.add_argument("--json", default=str(HEADLINE_JSON), help="the page's headline.json")
    ap.add_argument("--readme", default=str(README), help="the README to update")
    ap.add_argument("--check", action="store_true", help="only check; exit 1 if out of date")
    args = ap.parse_args(argv)
    try:
        head = load_headline(Path(args.json))
        readme = Path(args.readme)
        old = readme.read_text()
        new = update_readme(old, head, str(readme))
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.check:
        print("README.md headline up to date" if new == old else "README.md headline is stale")
        return 0 if new == old else 1
    if new != old:
        atomic_write(readme, new)
    print(f"wrote {readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
