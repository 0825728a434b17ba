"""Hold against the size of the model error: the model-error yardstick's hold at each delta.

For each controller and each delta of `DELTAS` (2.5, 5, 7.5, 10 and 15 %): the hold of
``bound-env margins --mismatch pmD`` (`mismatch_tasks.task_mm_hold`: robot i on plant i of
the seed, m1, m2, I1, I2, kb, kf, kc and zeta each scaled by U(1 - delta, 1 + delta), from the
nominal z*, no fall in 100 strides; the quick budget's 32 plants), with its Wilson interval,
the median effort of the held plants and the wall time of every apex decision (p50, p99). At
5 and 10 % the plants, and so the outcomes, are those of the margins' own ``pm5`` and
``pm10`` (the same spec, seed and budget).

Any spec gives a family of errors (`spec_at`): the parameters it varies at each delta, its
sensor noise and its delay kept (``pm10+noise`` → pmD+noise, ``all10`` → allD, ``pm15+delay1``
→ pmD+delay1). `hold_row` measures one (controller, delta) of a family (default: ``pm``, the
eight factors alone); `hold_delta_figure` draws the JSON's curves, one panel per family (a
privileged column dashed and labelled so); ``scripts/hold_vs_delta.py`` runs the rows with
resume and writes the JSON and the figure atomically.
"""

from __future__ import annotations

import math

import numpy as np

DELTAS = (0.025, 0.05, 0.075, 0.10, 0.15)


def family(spec) -> str:
    """The family name of ``spec`` (a `MismatchSpec`, a preset or a file): its parameter part
    as ``pm`` (the eight factors), ``all`` (every key of `PLANT_KEYS`) or ``params(k1,k2,..)``,
    then its noise and delay as they are named (``pm10+noise`` → ``pm+noise``). A spec that
    varies no parameter is a one-line ValueError: there is no delta to sweep."""
    from ....model.mismatch import EIGHT, PLANT_KEYS, as_spec

    spec = as_spec(spec)
    keys = tuple(k for k, d in spec.ranges if d > 0)
    if not keys:
        raise ValueError(
            f"mismatch {spec.name!r}: it varies no plant parameter (no delta to sweep)"
        )
    head = {EIGHT: "pm", PLANT_KEYS: "all"}.get(keys, f"params({','.join(keys)})")
    rest = [p for p in spec.name.split("+") if p.startswith(("noise", "delay"))]
    if len(rest) != (spec.has_noise + (spec.delay > 0)):  # a file: its own name for the rest
        rest = (["noise"] if spec.has_noise else []) + (
            [f"delay{spec.delay}"] if spec.delay else []
        )
    return "+".join([head, *rest])


def spec_at(spec, delta: float):
    """``spec`` with each parameter it varies at ``delta``, its noise and delay kept (module
    docstring). Named as the presets would name it (``pm10+noise``, ``all5``) when its
    parameter part is ``pm`` or ``all``, so that at a delta with a preset the spec, and so
    the plants and outcomes, are the preset's."""
    from ....model.mismatch import as_spec

    spec = as_spec(spec)
    return _at(spec, family(spec), delta)


def _at(spec, fam: str, delta: float):
    """`spec_at` of a `MismatchSpec` whose `family` is ``fam``."""
    from dataclasses import replace

    delta = float(delta)
    if not 0.0 < delta < 1.0:
        raise ValueError(f"delta {delta!r}: must lie in (0, 1)")
    head, *rest = fam.split("+")
    if head in ("pm", "all"):
        name = "+".join([f"{head}{100.0 * delta:g}", *rest])
    else:
        name = f"{spec.name} at {100.0 * delta:g} pct"
    ranges = tuple((k, delta if d > 0 else 0.0) for k, d in spec.ranges)
    return replace(spec, ranges=ranges, name=name, source=name)


def hold_row(
    controller, delta: float, seed: int, gait="default", budget: str = "quick", spec="pm10"
) -> dict:
    """The hold of ``controller`` at ``delta`` of ``spec``'s family (`spec_at`; default: the
    eight factors alone) on ``seed``'s plants (module docstring)."""
    from ....model.mismatch import as_spec
    from ....model.params import load_gait
    from ...apex_loop import CLOCK
    from ..budget import as_budget
    from ..closed_loop import Setup
    from ..decision_times import histogram, summary
    from ..stats import wilson_interval
    from .mismatch_tasks import MISMATCH_BUDGETS, median_interval, task_mm_hold

    spec = as_spec(spec)
    fam = family(spec)
    spec = _at(spec, fam, delta)
    mb = MISMATCH_BUDGETS[budget]
    setup = Setup(
        controller=controller,
        gait=str(gait),
        budget=as_budget(budget),
        z_star=np.asarray(load_gait(gait).z0, dtype=float),
        key=f"hold-delta-{controller.fingerprint()}-{gait}",
        seed=int(seed),
        mismatch=spec,
        mismatch_budget=mb,
    )
    CLOCK.seconds.clear()
    CLOCK.on = True
    try:
        r = task_mm_hold(setup)
    finally:
        CLOCK.on = False
    seconds = list(CLOCK.seconds)
    CLOCK.seconds.clear()
    k, n = int(sum(r["outcomes"])), len(r["outcomes"])
    eff = [e for e, o in zip(r["effort"], r["outcomes"], strict=True) if o and e is not None]
    failures: dict = {}
    for f in r["failure"]:
        if f is not None:
            failures[f] = failures.get(f, 0) + 1
    return {
        "delta": float(delta),
        "family": fam,
        "spec": spec.name,
        "seed": int(seed),
        "k": k,
        "n": n,
        "ci": list(wilson_interval(k, n)),
        "outcomes": r["outcomes"],
        "strides_reached": r["strides"],
        "failures": failures,
        "effort_median": float(np.median(eff)) if eff else None,
        "effort_median_ci": median_interval(eff) if eff else None,
        "decision_times": summary([{"decision_hist": histogram(seconds)}]) if seconds else None,
    }


def row_family(row: dict) -> str:
    """The family of a row of `hold_row` (a row from before the families has none: ``pm``)."""
    return row.get("family", "pm")


def family_rows(rows, fam: str) -> list[dict]:
    """The rows of family ``fam`` (`row_family`)."""
    return [r for r in rows if row_family(r) == fam]


def families_of(data: dict) -> list[str]:
    """The families of ``data``'s rows, in order of appearance (a row without one: ``pm``)."""
    rows = [r for c in data["columns"].values() for r in c["rows"]]
    return list(dict.fromkeys(row_family(r) for r in rows)) or ["pm"]


def hold_delta_figure(data: dict, path) -> None:
    """Held fraction against delta for every column of ``data`` (the JSON of
    ``scripts/hold_vs_delta.py``: {"columns": {label: {"privileged", "rows"}}}), one panel per
    family, with the Wilson intervals; a privileged column dashed and labelled so; written
    atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ....files.cache import atomic_path

    fams = families_of(data)
    fig, axes = plt.subplots(
        1, len(fams), figsize=(6.4 * len(fams), 4.2), squeeze=False, sharey=True
    )
    n = next((r["n"] for c in data["columns"].values() for r in c["rows"]), None)
    for ax, fam in zip(axes[0], fams, strict=True):
        xs = set()
        for label, col in data["columns"].items():
            rows = sorted(family_rows(col["rows"], fam), key=lambda r: r["delta"])
            if not rows:
                continue
            x = np.array([100.0 * r["delta"] for r in rows])
            xs.update(x.tolist())
            y = np.array([r["k"] / r["n"] for r in rows])
            lo = np.array([r["ci"][0] for r in rows])
            hi = np.array([r["ci"][1] for r in rows])
            priv = bool(col.get("privileged"))
            name = f"{label} (privileged)" if priv else label
            line = ax.errorbar(
                x, y, yerr=[y - lo, hi - y], marker="o", capsize=3, ls="--" if priv else "-",
                label=name, alpha=0.9,
            )  # fmt: skip
            if priv:
                line[0].set_dashes((4, 2))
        what = "m1, m2, I1, I2, kb, kf, kc, ζ" if fam.startswith("pm") else "its parameters"
        if fam.startswith("all"):
            what = "all 11 parameters"
        ax.set_xlabel(f"model error δ [%] ({what} each × U(1 ± δ))")
        ax.set_xticks(sorted(xs))
        ax.axvline(10.0, color="0.8", lw=0.8, zorder=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower left")
        ax.set_title(f"{fam} (seed {data.get('seed')}, 95 % Wilson intervals)", fontsize=10)
    axes[0][0].set_ylabel(f"held: no fall in 100 strides from z* ({n} plants)")
    axes[0][0].set_ylim(-0.03, 1.03)
    fig.tight_layout()
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


def hold_delta_table(data: dict) -> str:
    """A Markdown table of ``data`` per family: per column and delta, held / n and the median
    effort of the held plants; a privileged column labelled so."""
    out = []
    fams = families_of(data)
    for fam in fams:
        rows_of = {label: family_rows(col["rows"], fam) for label, col in data["columns"].items()}
        deltas = sorted({r["delta"] for rows in rows_of.values() for r in rows})
        if len(fams) > 1:
            out.append(f"{fam}:\n")
        out.append("| column | " + " | ".join(f"±{100 * d:g} %" for d in deltas) + " |")
        out.append("| --- |" + " --- |" * len(deltas))
        for label, col in data["columns"].items():
            by = {r["delta"]: r for r in rows_of[label]}
            cells = []
            for d in deltas:
                r = by.get(d)
                if r is None:
                    cells.append("")
                    continue
                e = r["effort_median"]
                eff = "" if e is None or not math.isfinite(e) else f", {e:.2g} N·m"
                cells.append(f"{r['k']}/{r['n']}{eff}")
            name = f"{label} (**privileged**)" if col.get("privileged") else label
            out.append(f"| {name} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)
