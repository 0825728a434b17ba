"""Hold against the size of the model error: the model-error yardstick's hold at each delta.

For each controller and each delta of `DELTAS` (2.5, 5, 7.5, 10 and 15 %): the hold of
``bound-env margins --mismatch pmD`` (`mismatch_tasks.task_mm_hold`: robot i on plant i of
the seed, m1, m2, I1, I2, kb, kf, kc and zeta each scaled by U(1 - delta, 1 + delta), from the
nominal z*, no fall in 100 strides; the quick budget's 32 plants), with its Wilson interval,
the median effort of the held plants and the wall time of every apex decision (p50, p99). At
5 and 10 % the plants, and so the outcomes, are those of the margins' own ``pm5`` and
``pm10`` (the same spec, seed and budget).

`hold_row` measures one (controller, delta); `hold_delta_figure` draws the JSON's curves (a
privileged column dashed and labelled so); ``scripts/hold_vs_delta.py`` runs the rows with
resume and writes the JSON and the figure atomically.
"""

from __future__ import annotations

import math

import numpy as np

DELTAS = (0.025, 0.05, 0.075, 0.10, 0.15)


def spec_name(delta: float) -> str:
    """The preset of ``delta`` (`bound_env.model.mismatch.PRESETS`: pm2.5, pm5, ..., pm15)."""
    from ...model.mismatch import PRESETS

    name = f"pm{100.0 * float(delta):g}"
    if name not in PRESETS:
        known = sorted(k for k in PRESETS if k.startswith("pm"))
        raise ValueError(f"delta {delta!r}: no preset {name!r} (known: {known})")
    return name


def hold_row(controller, delta: float, seed: int, gait="default", budget: str = "quick") -> dict:
    """The hold of ``controller`` at ``delta`` on ``seed``'s plants (module docstring)."""
    from ...model.mismatch import as_spec
    from ...model.params import load_gait
    from ..apex_loop import CLOCK
    from .budget import as_budget
    from .closed_loop import Setup
    from .decision_times import histogram, summary
    from .mismatch_tasks import MISMATCH_BUDGETS, median_interval, task_mm_hold
    from .stats import wilson_interval

    spec = as_spec(spec_name(delta))
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


def hold_delta_figure(data: dict, path) -> None:
    """Held fraction against delta for every column of ``data`` (the JSON of
    ``scripts/hold_vs_delta.py``: {"columns": {label: {"privileged", "rows"}}}), with the
    Wilson intervals; a privileged column dashed and labelled so; written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ...files.cache import atomic_path

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for label, col in data["columns"].items():
        rows = sorted(col["rows"], key=lambda r: r["delta"])
        if not rows:
            continue
        x = np.array([100.0 * r["delta"] for r in rows])
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
    n = next((r["n"] for c in data["columns"].values() for r in c["rows"]), None)
    ax.set_xlabel("model error δ [%] (m1, m2, I1, I2, kb, kf, kc, ζ each × U(1 ± δ))")
    ax.set_ylabel(f"held: no fall in 100 strides from z* ({n} plants)")
    ax.set_ylim(-0.03, 1.03)
    ax.set_xticks([100.0 * d for d in DELTAS])
    ax.axvline(10.0, color="0.8", lw=0.8, zorder=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    seed = data.get("seed")
    ax.set_title(f"Hold against model error (seed {seed}, 95 % Wilson intervals)", fontsize=10)
    fig.tight_layout()
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)


def hold_delta_table(data: dict) -> str:
    """A Markdown table of ``data``: per column and delta, held / n and the median effort of
    the held plants; a privileged column labelled so."""
    deltas = sorted({r["delta"] for c in data["columns"].values() for r in c["rows"]})
    head = "| column | " + " | ".join(f"±{100 * d:g} %" for d in deltas) + " |"
    out = [head, "| --- |" + " --- |" * len(deltas)]
    for label, col in data["columns"].items():
        by = {r["delta"]: r for r in col["rows"]}
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
    return "\n".join(out) + "\n"
