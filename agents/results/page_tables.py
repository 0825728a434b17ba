"""The results page's tables of the columns' measures (`agents.results.page`).

`MEASURES` lists the rows of the full table: (name, title, the value of one result, digits,
ratio against the passive column?). `columns_table` is that table (a column with several seeds
shows the mean [95 % Student-t interval] over them), `seed_details` each such column's per-seed
values, `direction_table` one measure per apex direction and sign, `ceiling_table` what stops
each ceiling and `failure_table` the first failure found beyond each basin edge.
"""

from __future__ import annotations

import math
from pathlib import Path

from bound_env.analysis.margins import Z_LABELS

from .formatting import agg, fmt, value
from .provenance import trained
from .table_split import split_table

# (name, value of one result, digits, ratio against passive?)
MEASURES = [
    (
        "basin_min",
        "**basin_min** (zstar scale: units of \\|z*_i\\|, worst of 12 directions)",
        lambda r: r["basin_min"],
        3,
        True,
    ),
    (
        "basin_min_cycle",
        "basin_min_cycle (units of the passive peak-to-peak range)",
        lambda r: r.get("basin_min_cycle"),
        3,
        True,
    ),
    (
        "basin_share_min",
        "basin_share_min (basin / ceiling, worst direction)",
        lambda r: r.get("basin_share_min"),
        3,
        False,
    ),
    (
        "r50",
        "random-direction **r50** (P(return) crosses 0.5; zstar scale)",
        lambda r: r["basin_curve"]["r50"],
        3,
        True,
    ),
    (
        "terrain_sigma50_deg",
        "rough terrain **σ50** [deg] (survival crosses 1/2)",
        lambda r: r.get("terrain_sigma50_deg"),
        3,
        True,
    ),
    (
        "mfpt_sigma_100_deg",
        "rough terrain σ at which the **MFPT** falls to 100 strides [deg]",
        lambda r: r.get("mfpt_sigma_100_deg"),
        3,
        True,
    ),
    ("emax", "**emax** (closed-loop apex map)", lambda r: r["emax"], 4, False),
    (
        "fp_residual",
        "closed-loop fixed point residual max\\|P(z) − z\\| (> 1e-6: no cycle "
        "found, the other rows measure around a non-periodic start)",
        lambda r: r["fixed_point_residual"],
        2,
        False,
    ),
    (
        "slope_lo",
        "slope window α, low edge [deg] (survive 50 strides)",
        lambda r: r["slope_window_deg"][0],
        4,
        False,
    ),
    ("slope_hi", "slope window α, high edge [deg]", lambda r: r["slope_window_deg"][1], 4, False),
    ("kc_lo", "k_c window, low edge [N m/rad]", lambda r: r["kc_window"][0], 4, False),
    ("kc_hi", "k_c window, high edge [N m/rad]", lambda r: r["kc_window"][1], 4, False),
    ("push_xdot", "push p50, Δẋ [m/s]", lambda r: r["push"]["xdot"]["p50"], 3, False),
    ("push_th1dot", "push p50, Δθ̇1 [rad/s]", lambda r: r["push"]["th1dot"]["p50"], 3, False),
    ("effort", "**effort** mean \\|τ\\| on the cycle [N m]", lambda r: r["effort"], 3, False),
]


# measures that cannot be negative: their seed intervals respect 0 (`agg`'s ``lower``)
NON_NEGATIVE = {
    "basin_min",
    "basin_min_cycle",
    "basin_share_min",
    "r50",
    "terrain_sigma50_deg",
    "mfpt_sigma_100_deg",
    "emax",
    "fp_residual",
    "push_xdot",
    "push_th1dot",
    "effort",
}


def cell(g, base, name, fn, digits, ratio) -> str:
    """One cell of the full table: column ``g``'s measure ``name`` (and its ratio to ``base``)."""
    runs = g["runs"]
    vals = [value(fn, r) for r in runs]
    text = agg(vals, digits, 0.0 if name in NON_NEGATIVE else None)
    if name == "basin_min":
        dirs = sorted({r["basin_min_direction"] or "—" for r in runs})
        text += f" ({', '.join(dirs)})"
    elif name == "basin_min_cycle":
        dirs = sorted({r.get("basin_min_cycle_direction") or "—" for r in runs})
        text += f" ({', '.join(dirs)})"
    elif name == "basin_share_min":
        dirs = sorted({r.get("basin_share_min_direction") or "—" for r in runs})
        text += f" ({', '.join(dirs)})"
    elif name == "r50" and len(runs) == 1:
        lo, hi = runs[0]["basin_curve"].get("r50_ci", [math.nan, math.nan])
        text += f" (Wilson-based [{fmt(lo, 3)}, {fmt(hi, 3)}])"
    elif name == "terrain_sigma50_deg" and len(runs) == 1:
        lo, hi = runs[0].get("terrain_sigma50_ci_deg", [math.nan, math.nan])
        text += f" (Wilson-based [{fmt(lo, 3)}, {fmt(hi, 3)}])"
    elif name == "effort" and runs[0]["policy"] == "passive":
        text = "0 (zero action)"
    if ratio and g is not base:
        b = value(fn, base["runs"][0])
        ratios = [v / b if b and not math.isnan(v) else math.nan for v in vals]
        if not all(math.isnan(x) for x in ratios):
            text += f", **{agg(ratios, 3, 0.0)}×**"
    return text


def basin_cell(runs, label, sym, key, field="rel", digits=3) -> str:
    """One direction's ``key``/``field`` over the runs of a column; ≥ at the cap."""
    vals = [r[key][label][sym][field] if r[key].get(label, {}).get(sym) else math.nan for r in runs]
    vals = [math.nan if v is None else float(v) for v in vals]
    text = agg(vals, digits, 0.0)
    capped = sum(
        bool(r[key][label][sym].get("capped")) for r in runs if r[key].get(label, {}).get(sym)
    )
    if capped:
        text = ("≥" if capped == len(runs) else f"({capped}/{len(runs)} capped) ") + text
    return text


def _separator(groups) -> str:
    return "| --- |" + " --- |" * len(groups)


def columns_table(groups) -> str:
    """The full table: one row per `MEASURES` entry, one column per group (ratios against the
    first group, the passive column), as narrow tables with the headline columns first
    (`agents.results.table_split.split_table`)."""
    base = groups[0]
    labels = [
        f"{g['label']} ({len(g['runs'])} seed{'s' if len(g['runs']) > 1 else ''})"
        if trained(g)
        else g["label"]
        for g in groups
    ]
    # a privileged column reads the robot's true plant: an upper reference, never deployable
    labels = [
        f"{lab} (privileged)" if any(r.get("privileged") for r in g["runs"]) else lab
        for lab, g in zip(labels, groups, strict=True)
    ]
    rows = [("gait", [f"`{g['gait']}`" for g in groups])]
    for name, title, fn, digits, ratio in MEASURES:
        rows.append((title, [cell(g, base, name, fn, digits, ratio) for g in groups]))
    return split_table(labels, rows)


def seed_details(groups) -> list[str]:
    """A collapsible table of per-seed values for every column with several seeds."""
    details = []
    for g in groups:
        if len(g["runs"]) < 2:
            continue
        names = [Path(p).name for p in g["policies"]]
        dh = "| measure | " + " | ".join(names) + " |"
        ds = "| --- |" + " --- |" * len(names)
        drows = []
        for name, _title, fn, digits, _ in MEASURES:
            drows.append(
                f"| {name} | " + " | ".join(fmt(value(fn, r), digits) for r in g["runs"]) + " |"
            )
        drows.append(
            "| basin_min direction | "
            + " | ".join(r.get("basin_min_direction") or "—" for r in g["runs"])
            + " |"
        )
        details.append(
            f'<details markdown="1"><summary>per-seed values: {g["label"]}</summary>\n\n'
            + "\n".join([dh, ds, *drows])
            + "\n\n</details>"
        )
    return details


def direction_table(groups, key, field="rel", digits=3) -> str:
    """One row per apex direction and sign: each column's ``key``/``field`` (`basin_cell`)."""
    bhead = "| direction | " + " | ".join(g["label"] for g in groups) + " |"
    brows = []
    for c in Z_LABELS:
        for sym in ("+", "-"):
            cells = [basin_cell(g["runs"], c, sym, key, field, digits) for g in groups]
            brows.append(f"| {c}{sym} | " + " | ".join(cells) + " |")
    return "\n".join([bhead, _separator(groups), *brows])


def ceiling_table(groups) -> str:
    """What stops each direction's ceiling (first seed of each column)."""
    mech_rows = []
    for g in groups:
        r = g["runs"][0]
        for c in Z_LABELS:
            for sym in ("+", "-"):
                e = r.get("basin_ceiling", {}).get(c, {}).get(sym)
                if not e:
                    continue
                bey = e.get("beyond") or {}
                mech_rows.append(
                    f"| {g['label']} | {c}{sym} | {fmt(e['rel'], 3)} | "
                    f"{'yes' if e.get('geometric') else 'no'} | {e.get('mechanism') or '—'} | "
                    f"{fmt(bey.get('rel'), 3)} |"
                )
    return "\n".join(
        [
            "| column (first seed) | direction | ceiling (zstar) | geometric | "
            "what stops it | first failing size |",
            "| --- | --- | --- | --- | --- | --- |",
            *mech_rows,
        ]
    )


def failure_table(groups) -> str:
    """The first failing perturbation found beyond each basin edge (first seed of each
    column)."""
    fail_rows = []
    for g in groups:
        r = g["runs"][0]
        for c in Z_LABELS:
            for sym in ("+", "-"):
                bey = r["basin"][c][sym].get("beyond") or {}
                if not bey:
                    continue
                fail_rows.append(
                    f"| {g['label']} | {c}{sym} | {fmt(bey.get('rel'), 3)} | "
                    f"{bey.get('reason')} | {bey.get('stride')} | {bey.get('phase') or '—'} | "
                    f"{'; '.join(bey.get('mechanisms') or []) or '—'} |"
                )
    return "\n".join(
        [
            "| column (first seed) | direction | size | failure | stride | phase | "
            "start geometry |",
            "| --- | --- | --- | --- | --- | --- | --- |",
            *fail_rows,
        ]
    )
