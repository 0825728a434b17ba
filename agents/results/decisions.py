"""What a gated controller's decisions are, and what they cost, measured fairly.

**Who decides** (`margins` JSON ``decision_shares``, computed by the core from each
controller's ``decision_kinds``): at every apex of the random-direction curve and of the rough
terrain runs, the gate (within the safe radius, the LQR alone), the LQR's own plan chosen past
it (mpc: it returns on the planning model; a learned chooser: row 0) or an override (a
searched or chosen profile). `shares_rows` puts them in a table.

**Decision times** (`fair_decision_times`): every controller that plans at the apex
(``coefficients(z)``: mpc and the learned stride controllers) is timed on the *same* apex
states, all past the safe radius (where the planner, not the gate, decides): the test
directions' starts z* + r |z*| d at the curve's sizes, one decision each, one process, after
the margins' workers have finished (an otherwise idle machine: the load average is recorded
beside the times).
"""

from __future__ import annotations

import os
import time

import numpy as np

FAIR_SIZES = (0.15, 0.2, 0.25, 0.3, 0.35)  # relative perturbation sizes of the timed states
FAIR_SAFE = 0.05  # states with max |z - z*| / s above this (mpc's and default's safe radius)


def timing_states(z_star, seed: int, n_dirs: int = 32, sizes=FAIR_SIZES) -> np.ndarray:
    """The apex states every planner is timed on: z* + r |z*| d for the first ``n_dirs`` test
    directions d of ``seed`` and each r, kept where max |z - z*| / s > `FAIR_SAFE`."""
    from bound_env.analysis.margins import sample_seeds
    from bound_env.analysis.margins.budget import random_directions
    from bound_env.task import APEX_SCALES

    zs = np.asarray(z_star, dtype=float)
    dirs = random_directions(n_dirs, sample_seeds(seed)["directions"])
    Z = np.concatenate([zs + r * np.abs(zs) * dirs for r in sizes])
    past = np.max(np.abs(Z - zs) / np.asarray(APEX_SCALES), axis=1) > FAIR_SAFE
    return Z[past]


def planner_of(ctrl):
    """The object whose ``coefficients(z)`` is ``ctrl``'s apex decision, or None."""
    for c in (ctrl, getattr(ctrl, "base", None)):
        if c is not None and callable(getattr(c, "coefficients", None)):
            if getattr(c, "decision_kinds", None) is not None:  # a gated planner
                return c
    return None


def time_decisions(ctrl, Z) -> dict | None:
    """p50/p99/mean/max [s] of ``ctrl``'s apex decisions on the states Z (None: not a planner)."""
    planner = planner_of(ctrl)
    if planner is None:
        return None
    planner.coefficients(Z[0])  # compiled and warm
    ts = []
    for z in Z:
        t0 = time.perf_counter()
        planner.coefficients(z)
        ts.append(time.perf_counter() - t0)
    from bound_env.analysis.margins.curve import time_stats

    return time_stats(ts)


def fair_decision_times(groups, load_controller, seed: int) -> dict:
    """{label: times of its first policy} for every column whose controller plans at the
    apex, all timed on `timing_states` (default gait only: other gaits' states differ)."""
    from bound_env.params import load_gait

    Z = timing_states(load_gait("default").z0, seed)
    out: dict = {
        "states": int(len(Z)),
        "measured_on": "the same apex states for every controller: the test directions' "
        f"starts z* + r |z*| d (32 directions, r = {', '.join(map(str, FAIR_SIZES))}) past the "
        f"safe radius {FAIR_SAFE}, one decision each, in one process after the margins' "
        "workers finished",
        "load_average_before": list(os.getloadavg()),
        "controllers": {},
    }
    for g in groups:
        if g["gait"] != "default":
            continue
        ctrl = load_controller(g["policies"][0])
        t = time_decisions(ctrl, Z)
        if t is not None:
            out["controllers"][g["label"]] = t
    out["load_average_after"] = list(os.getloadavg())
    return out


def shares_rows(groups) -> list[tuple[str, str, dict]]:
    """(label, where, shares) for every column with decision shares (first policy's run)."""
    rows = []
    for g in groups:
        shares = g["runs"][0].get("decision_shares") or {}
        for where in ("curve", "terrain"):
            if shares.get(where) and shares[where].get("n"):  # no decisions: no row
                rows.append((g["label"], where, shares[where]))
    return rows


def decisions_text(times: dict, groups) -> str:
    """The page's section on who decides and how long a decision takes."""
    lines = ["", "## Who decides, and how long a decision takes", ""]
    rows = shares_rows(groups)
    if rows:
        lines += [
            "Apex decisions of the gated controllers (first seed), on the random-direction "
            "curve and on rough terrain (terrain and MFPT runs): the gate (within the safe "
            "radius: the LQR alone), the LQR's own plan chosen past it (mpc: it returns on "
            "the planning model; a learned chooser: row 0), an override (a searched or chosen "
            "profile). A step-level residual reports its base's decisions.",
            "",
            "| controller | where | gate | LQR's plan | override | decisions |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        for label, where, s in rows:
            cells = [f"{100 * s[k]:.1f} %" for k in ("gate", "lqr", "override")]
            lines.append(f"| {label} | {where} | {' | '.join(cells)} | {s['n']} |")
        lines.append("")
    ctrls = (times or {}).get("controllers") or {}
    if ctrls:
        load = times.get("load_average_before", [float("nan")])[0]
        lines += [
            f"Decision times on {times['measured_on']} ({times['states']} states; load "
            f"average {load:.2f} before):",
            "",
            "| controller | p50 [ms] | p99 [ms] | mean [ms] | max [ms] |",
            "| --- | --- | --- | --- | --- |",
        ]
        for label, t in ctrls.items():
            ms = [f"{1e3 * t[k]:.3g}" for k in ("p50", "p99", "mean", "max")]
            lines.append(f"| {label} | {' | '.join(ms)} |")
        lines.append("")
    return "\n".join(lines) + "\n" if len(lines) > 3 else ""


def real_time_text(groups) -> str:
    """The page's real-time yardstick: each column's decision p50 and p99 over every apex
    decision of its own margins measures (its first seed's ``decision_times``), and the row
    "best controller within 1 ms per decision (p99)" by the columns' mean r50 over seeds
    (`bound_env.analysis.margins.decision_times.real_time_table`). Empty when no column has
    decision times (pages measured before they were recorded)."""
    from bound_env.analysis.margins.decision_times import real_time_table

    columns = {}
    for g in groups:
        runs = g["runs"]
        r50s = [r["basin_curve"]["r50"] for r in runs if r.get("basin_curve")]
        columns[g["label"]] = {
            "decision_times": runs[0].get("decision_times"),
            "r50": float(np.mean(r50s)) if r50s else None,
        }
    if not any(c["decision_times"] for c in columns.values()):
        return ""
    return (
        "\n## Real time: every apex decision of each controller's own measures\n\n"
        "Wall time of every apex decision a controller made during its own margins measures "
        "(first seed; a controller without apex decisions has none):\n\n" + real_time_table(columns)
    )
