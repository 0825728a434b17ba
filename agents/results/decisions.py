"""What a gated controller's decisions are, and what they cost, measured fairly.

**Who decides** (`margins` JSON ``decision_shares``, computed by the core from each
controller's ``decision_kinds``): at every apex of the random-direction curve and of the rough
terrain runs, the gate (within the safe radius, the LQR alone), the LQR's own plan chosen past
it (mpc: it returns on the planning model; a learned chooser: row 0) or an override (a
searched or chosen profile). `shares_rows` puts them in a table.

**Decision times** (`fair_decision_times`): every controller that decides at the apex
(``coefficients(z)``: lqr, deadbeat, mpc and the learned stride controllers, a step-level
residual through its base) is timed on the *same* apex states, all past the safe radius (where
a gated planner, not its gate, decides): the test directions' starts z* + r |z*| d at the
curve's sizes, in one process, after the margins' workers have finished. A decision's time is
the CPU time of the process (`time.process_time_ns`: a busy machine's other processes do not
count) and, per state, the minimum over `DECISION_REPEATS` repeats (an interrupt or a cache
miss adds time, never removes it), so a rerun reproduces it; the load average is recorded
beside the times, and the minimum wall time per state too (``wall``).
"""

from __future__ import annotations

import os
import time

import numpy as np

FAIR_SIZES = (0.15, 0.2, 0.25, 0.3, 0.35)  # relative perturbation sizes of the timed states
FAIR_SAFE = 0.05  # states with max |z - z*| / s above this (mpc's and default's safe radius)
DECISION_REPEATS = 5  # each state's decision is timed this many times; the minimum counts
CLOCK = (
    f"CPU time of the process (time.process_time_ns), per state the minimum over "
    f"{DECISION_REPEATS} repeats"
)


def timing_states(z_star, seed: int, n_dirs: int = 32, sizes=FAIR_SIZES) -> np.ndarray:
    """The apex states every planner is timed on: z* + r |z*| d for the first ``n_dirs`` test
    directions d of ``seed`` and each r, kept where max |z - z*| / s > `FAIR_SAFE`."""
    from bound_env.analysis.margins import sample_seeds
    from bound_env.analysis.margins.budget import random_directions
    from bound_env.sim.task import APEX_SCALES

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


def decider_of(ctrl):
    """The object whose ``coefficients(z)`` (one apex state) is ``ctrl``'s apex decision,
    gated or not (lqr, deadbeat: a matrix product), or None (passive, a plain step policy)."""
    import inspect

    for c in (ctrl, getattr(ctrl, "base", None)):
        f = getattr(c, "coefficients", None) if c is not None else None
        if callable(f):
            try:
                inspect.signature(f).bind(np.zeros(6))
            except (TypeError, ValueError):  # another protocol (a stride residual's (z, du))
                continue
            return c
    return None


def time_decisions(ctrl, Z, repeats: int = DECISION_REPEATS, gated: bool = True) -> dict | None:
    """p50/p99/mean/max [s] of ``ctrl``'s apex decisions on the states Z, each state's the
    minimum over ``repeats`` timings of the process's CPU time (`CLOCK`), and ``wall`` (the
    same of the minimum wall times); None: not a planner (``gated``: a gated planner,
    `planner_of`; else any apex decider, `decider_of`)."""
    planner = planner_of(ctrl) if gated else decider_of(ctrl)
    if planner is None:
        return None
    planner.coefficients(Z[0])  # compiled and warm
    cpu, wall = np.full(len(Z), np.inf), np.full(len(Z), np.inf)
    for _ in range(repeats):
        for i, z in enumerate(Z):
            c0, w0 = time.process_time_ns(), time.perf_counter_ns()
            planner.coefficients(z)
            w1, c1 = time.perf_counter_ns(), time.process_time_ns()
            cpu[i], wall[i] = min(cpu[i], 1e-9 * (c1 - c0)), min(wall[i], 1e-9 * (w1 - w0))
    from bound_env.analysis.margins.curve import time_stats

    out = time_stats(cpu)
    w = time_stats(wall)
    out["wall"] = {k: w[k] for k in ("p50", "p99", "mean", "max")}
    out["gated"] = planner_of(ctrl) is not None
    return out


def fair_decision_times(groups, load_controller, seed: int, repeats: int = DECISION_REPEATS):
    """{label: times of its first policy} for every column whose controller decides at the
    apex (`decider_of`), each timed on its gait's `timing_states` (``gait`` per controller;
    ``states`` counts the default gait's, ``states_by_gait`` every gait's)."""
    from bound_env.model.params import load_gait

    by_gait: dict = {}
    out: dict = {
        "states": 0,
        "measured_on": "the same apex states for every controller: the test directions' "
        f"starts z* + r |z*| d (32 directions, r = {', '.join(map(str, FAIR_SIZES))}) past the "
        f"safe radius {FAIR_SAFE}, in one process after the margins' workers finished; "
        f"{CLOCK}",
        "clock": "process_time",
        "repeats": int(repeats),
        "load_average_before": list(os.getloadavg()),
        "controllers": {},
    }
    for g in groups:
        gait = g["gait"]
        if gait not in by_gait:
            by_gait[gait] = timing_states(load_gait(gait).z0, seed)
        ctrl = load_controller(g["policies"][0])
        t = time_decisions(ctrl, by_gait[gait], repeats, gated=False)
        if t is not None:
            t["gait"] = gait
            out["controllers"][g["label"]] = t
    out["states"] = int(len(by_gait.get("default", ())))
    out["states_by_gait"] = {k: int(len(v)) for k, v in by_gait.items()}
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


def real_time_text(groups, times: dict | None = None) -> str:
    """The page's real-time yardstick: each column's decision p50 and p99 and the row "best
    controller within 1 ms per decision (p99)" by the columns' mean r50 over seeds
    (`bound_env.analysis.margins.decision_times.real_time_table`). A column timed by the
    dedicated pass (``times``, `fair_decision_times`: CPU time on fixed states, minimum over
    repeats, which a rerun reproduces) is given by it; another one by the wall times of every
    apex decision of its own margins measures (its first seed's ``decision_times``, inside
    busy workers). Empty when no column has decision times (pages measured before they were
    recorded)."""
    from bound_env.analysis.margins.decision_times import real_time_table

    fixed = (times or {}).get("controllers") or {}
    columns = {}
    for g in groups:
        runs = g["runs"]
        r50s = [r["basin_curve"]["r50"] for r in runs if r.get("basin_curve")]
        columns[g["label"]] = {
            "decision_times": runs[0].get("decision_times"),
            "fixed": fixed.get(g["label"]),
            "r50": float(np.mean(r50s)) if r50s else None,
        }
    if not any(c["decision_times"] or c["fixed"] for c in columns.values()):
        return ""
    how = (
        f"the {times.get('states_by_gait', {}).get('default', times.get('states'))} fixed apex "
        f"states above ({times.get('clock', 'wall')} time, per state the minimum over "
        f"{times.get('repeats', 1)} repeat(s); load average "
        f"{(times.get('load_average_before') or [float('nan')])[0]:.2f} before)"
        if fixed
        else ""
    )
    intro = (
        f"A decision's time on {how}, where the column was timed there (`timed on`: fixed); "
        "else the wall time of every apex decision it made during its own margins measures "
        "(first seed, inside busy workers: `timed on`: its measures). `decisions`: how many "
        "apex decisions its measures made. A controller without apex decisions has none.\n\n"
        if fixed
        else "Wall time of every apex decision a controller made during its own margins "
        "measures (first seed; a controller without apex decisions has none):\n\n"
    )
    return (
        "\n## Real time: every apex decision of each controller's own measures\n\n"
        + intro
        + real_time_table(columns)
    )
