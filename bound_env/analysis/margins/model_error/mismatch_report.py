"""Text and markdown of the margins under model error (JSON ``mismatch``, `mismatch_tasks`).

`mismatch_text` is the command line's summary of one result; `mismatch_markdown` the results
page's section (`mismatch_summary`, its numbers as JSON, then `mismatch_tables`): every
column's hold and r50 under each spec (by default ``pm5`` and ``pm10``), with intervals, and
paired against a reference column where both met the same plants and directions (the same
spec, seeds and budget): McNemar's exact test on the per-plant hold outcomes and the
bootstrap of Delta r50 over the shared plant-direction pairs (`bound_env.analysis.paired`).
A censored r50 (the curve fails already at the smallest size, or never) is printed as the
bound it is ("< 0.01"), and so is a difference that rests on one
(`bound_env.analysis.paired.delta_text`). A privileged column (it reads the robot's true
plant: `bound_env.control.privileged`) is labelled so.
"""

from __future__ import annotations

import math

import numpy as np

from ...paired import bootstrap_delta_x50, delta_text, mcnemar_exact
from ..stats import crossing_censored, x50_text

DEFAULT_SPECS = ("pm5", "pm10")


def _num(x, fmt: str = ".3g") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def r50_text(block: dict) -> str:
    """r50 under error with its interval, each censored end printed as the bound it is
    ("< 0.01" where the curve fails already at the smallest size, "> 0.4" where it never
    fails)."""
    curve = block.get("curve") or []
    sizes = [c["size"] for c in curve]
    if not sizes or any(k not in curve[0] for k in ("success", "ci_low", "ci_high")):
        lo, hi = block["r50_ci"]
        return f"{_num(block['r50'])} [{_num(lo)}, {_num(hi)}]"
    parts = [
        x50_text(v, crossing_censored(sizes, [c[key] for c in curve]), sizes)
        for v, key in zip(
            (block["r50"], *block["r50_ci"]), ("success", "ci_low", "ci_high"), strict=True
        )
    ]
    return f"{parts[0]} [{parts[1]}, {parts[2]}]"


def mismatch_text(mm: dict) -> str:
    """A few lines per spec: the spec, hold (with its effort), r50 under error, MFPT. ``mm``:
    a result's ``mismatch`` ({spec name: block}) or one block."""
    if "hold" not in mm:
        return "\n".join(mismatch_text(b) for b in mm.values())
    h = mm["hold"]
    spec = mm["spec"]
    lines = [
        f"model error {spec['name']}: {h['n']} plants, delay {spec['delay']}, "
        f"noise {'yes' if any(v > 0 for v in spec['noise'].values()) else 'no'}",
        f"  hold ({h['strides']} strides from z*): {h['k']}/{h['n']} "
        f"[{h['ci'][0]:.2f}, {h['ci'][1]:.2f}]; median mean |tau| over the last "
        f"{h['effort_strides']} strides {_num(h['effort_median'])} N m"
        + (
            f" [{_num(h['effort_median_ci'][0])}, {_num(h['effort_median_ci'][1])}]"
            if h["effort_median_ci"]
            else ""
        ),
        f"  r50 under error (no fall in {mm['curve_strides']} strides, apex settled): "
        f"{r50_text(mm)}",
    ]
    for m in mm["mfpt"]:
        bound = ">=" if m["lower_bound"] else ""
        lines.append(f"  MFPT at sigma {m['sigma_deg']} deg: {bound}{_num(m['mfpt'])} strides")
    return "\n".join(lines)


def _blocks(value) -> dict:
    """{spec name: mismatch block} of a column's value: a margins result (key ``mismatch``),
    a mismatch block, or a list / dict of them."""
    if isinstance(value, dict) and "hold" in value:
        return {value["spec"]["name"]: value}
    if isinstance(value, dict) and "mismatch" in value:
        return _blocks(value["mismatch"])
    if not isinstance(value, (dict, list, tuple)):  # a string would recurse without end
        return {}
    items = value.values() if isinstance(value, dict) else value
    out = {}
    for v in items:
        out.update(_blocks(v))
    return out


def paired_with(a: dict, b: dict) -> bool:
    """Did the two blocks meet the same plants and directions (spec, seeds, budget)?"""
    return (
        a["spec"] == b["spec"]
        and a["seeds"] == b["seeds"]
        and a["budget"] == b["budget"]
        and a["plants"] == b["plants"]
    )


def paired_mismatch(a: dict, b: dict, n_boot: int = 2000, seed: int = 0) -> dict:
    """Column ``a`` against reference ``b`` on shared plants: McNemar on hold, bootstrap of
    Delta r50 (resampling the plant-direction pairs)."""
    sizes = [c["size"] for c in a["curve"]]
    oa = np.array([c["outcomes"] for c in a["curve"]], dtype=float)
    ob = np.array([c["outcomes"] for c in b["curve"]], dtype=float)
    return {
        "hold": mcnemar_exact(a["hold"]["outcomes"], b["hold"]["outcomes"]),
        "delta_r50": bootstrap_delta_x50(sizes, oa, ob, n_boot=n_boot, seed=seed),
    }


def mismatch_summary(results_by_column: dict, specs=DEFAULT_SPECS, reference=None) -> dict:
    """The numbers of the "model error" section as JSON: per spec (``specs``), its description
    and settings, and per column its hold (k/n and the Wilson interval), the median mean |tau|
    of its held plants (order-statistic interval), r50 under error (interval from the Wilson
    bounds), and, where it met the same plants as the ``reference`` column (default: the
    first), McNemar's test on hold and the bootstrap of Delta r50. What the results page's
    section (`mismatch_tables`) and ``model_error.json`` beside it are made of.

    ``results_by_column``: {column label: a margins result with key ``mismatch``, a mismatch
    block, or a list/dict of those (one per spec)}."""
    cols = {c: _blocks(v) for c, v in results_by_column.items()}
    ref = reference if reference is not None else next(iter(cols), None)
    out = {"reference": ref, "specs": []}
    for name in specs:
        have = {c: b[name] for c, b in cols.items() if name in b}
        if not have:
            continue
        any_block = next(iter(have.values()))
        h0 = any_block["hold"]
        entry = {
            "name": name,
            "spec": any_block["spec"],
            "what": _describe(any_block["spec"]),
            "plants": h0["n"],
            "hold_strides": h0["strides"],
            "effort_strides": h0["effort_strides"],
            "curve_strides": any_block["curve_strides"],
            "rows": [],
        }
        for c, b in have.items():
            h = b["hold"]
            ci = h["effort_median_ci"] or [None, None]
            row = {
                "column": c,
                "hold": {"k": h["k"], "n": h["n"], "low": h["ci"][0], "high": h["ci"][1]},
                "torque": {
                    "median": _finite(h["effort_median"]),
                    "low": _finite(ci[0]),
                    "high": _finite(ci[1]),
                },
                "r50": {
                    "value": _finite(b["r50"]),
                    "low": _finite(b["r50_ci"][0]),
                    "high": _finite(b["r50_ci"][1]),
                },
                "r50_text": r50_text(b),
                "privileged": bool(b.get("privileged")),
                "paired": None,
                "delta_r50": None,
            }
            rb = have.get(ref)
            if c != ref and rb is not None and paired_with(b, rb):
                p = paired_mismatch(b, rb)
                row["paired"] = {k: p["hold"][k] for k in ("b", "c", "p")}
                row["delta_r50"] = {k: p["delta_r50"][k] for k in ("delta", "low", "high")}
                sizes = [x["size"] for x in b["curve"]]
                row["delta_r50"]["text"] = delta_text(p["delta_r50"], sizes)
            entry["rows"].append(row)
        out["specs"].append(entry)
    return out


def _finite(x):
    return float(x) if x is not None and math.isfinite(float(x)) else None


def mismatch_tables(summary: dict, level: int = 3) -> str:
    """The "model error" section's tables from `mismatch_summary` (or the JSON it became):
    per spec a heading of ``level``, what the measures are, and one row per column."""
    ref = summary["reference"]
    parts = []
    for e in summary["specs"]:
        parts.append(
            f"{'#' * level} {e['name']}: {e['what']}\n\n"
            f"{e['plants']} plants; hold: no fall in {e['hold_strides']} strides from the "
            f"nominal z*, effort over the last {e['effort_strides']}; r50: no fall in "
            f"{e['curve_strides']} strides and the apex settled.\n"
        )
        rows = [
            "| column | hold | median mean \\|τ\\| of held [N m] | r50 under error "
            f"| paired with {ref}: hold b/c, p | Δr50 [95 %] |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        for r in e["rows"]:
            h, t, q = r["hold"], r["torque"], r["r50"]
            eff = _num(t["median"])
            if t["low"] is not None or t["high"] is not None:
                eff += f" [{_num(t['low'])}, {_num(t['high'])}]"
            r50 = r.get("r50_text") or f"{_num(q['value'])} [{_num(q['low'])}, {_num(q['high'])}]"
            hold = f"{h['k']}/{h['n']} [{h['low']:.2f}, {h['high']:.2f}]"
            pair, dr = "–", "–"
            if r["paired"] is not None:
                p, d = r["paired"], r["delta_r50"]
                pair = f"{p['b']}/{p['c']}, p = {p['p']:.2g}"
                dr = d.get("text") or f"{d['delta']:+.3g} [{d['low']:+.3g}, {d['high']:+.3g}]"
            label = r["column"]
            if r.get("privileged"):
                label += " (**privileged**: reads the true plant)"
            rows.append(f"| {label} | {hold} | {eff} | {r50} | {pair} | {dr} |")
        parts.append("\n".join(rows) + "\n")
    return "\n".join(parts)


def mismatch_markdown(results_by_column: dict, specs=DEFAULT_SPECS, reference=None) -> str:
    """The "model error" section (a subsection of the page: level-3 headings): one table per
    spec with every column's hold, the effort of its held plants and r50 under error, plus
    the paired comparison with the ``reference`` column (`mismatch_summary`,
    `mismatch_tables`)."""
    return mismatch_tables(mismatch_summary(results_by_column, specs, reference))


def _describe(spec: dict) -> str:
    params = spec["params"]
    deltas = sorted(set(params.values()))
    text = (
        (
            f"{', '.join(params)} each x U(1 ± {deltas[0]:g})"
            if len(deltas) == 1
            else ", ".join(f"{k} ± {v:g}" for k, v in params.items())
        )
        if params
        else "nominal parameters"
    )
    if any(v > 0 for v in spec["noise"].values()):
        text += "; sensor noise"
    if spec["delay"]:
        text += f"; delay {spec['delay']} interval(s)"
    return text
