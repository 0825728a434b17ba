"""The margins' outputs: margins.json, the CSV tables and the plots (`write_outputs`,
`plot_margins`), and a few human-readable lines (`summary_text`)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from bound_env.files.cache import atomic_write
from bound_env.model.params import Z_NAMES, Z_SI_UNITS

from .budget import MFPT_LEVEL

Z_LABELS, Z_UNITS = Z_NAMES, Z_SI_UNITS  # apex components and their SI units


def write_outputs(result: dict, out_dir: Path) -> None:
    """margins.json, basin.csv, curve.csv, push.csv, mfpt.csv and PNG plots."""
    atomic_write(out_dir / "margins.json", json.dumps(result, indent=2) + "\n")
    for name, key in (("basin.csv", "basin"), ("ceiling.csv", "basin_ceiling")):
        with (out_dir / name).open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(
                [
                    "component",
                    "unit",
                    "sign",
                    "rel",
                    "abs",
                    "capped",
                    "rel_cycle",
                    "share",
                    "cap",
                    "beyond_rel",
                    "beyond_reason",
                    "beyond_stride",
                    "beyond_phase",
                    "mechanisms",
                ]
            )
            for label, e in result[key].items():
                for sym in ("+", "-"):
                    v = e.get(sym)
                    if v is None:
                        continue
                    bey = v.get("beyond") or {}
                    w.writerow(
                        [
                            label,
                            e["unit"],
                            sym,
                            v["rel"],
                            v["abs"],
                            v["capped"],
                            v.get("rel_cycle"),
                            v.get("share"),
                            v.get("cap"),
                            bey.get("rel"),
                            bey.get("reason"),
                            bey.get("stride"),
                            bey.get("phase"),
                            "; ".join(bey.get("mechanisms") or []),
                        ]
                    )
    c = result["basin_curve"]
    with (out_dir / "curve.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["size_rel", "success", "k", "n", "ci_low", "ci_high"])
        for row in zip(
            c["sizes"], c["success"], c["k"], c["n"], c["ci_low"], c["ci_high"], strict=True
        ):
            w.writerow(row)
    t = result["terrain"]
    with (out_dir / "terrain.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["sigma_deg", "survival", "k", "n", "ci_low", "ci_high", "mean_strides"])
        for row in zip(
            t["sigmas_deg"],
            t["survival"],
            t["k"],
            t["n"],
            t["ci_low"],
            t["ci_high"],
            t["mean_strides"],
            strict=True,
        ):
            w.writerow(row)
    if result.get("mfpt"):
        with (out_dir / "mfpt.csv").open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(
                [
                    "sigma_deg",
                    "strides_total",
                    "failures",
                    "mfpt",
                    "lower_bound",
                    "ci_low",
                    "ci_high",
                ]
            )
            for m in result["mfpt"]:
                w.writerow(
                    [
                        m["sigma_deg"],
                        m["strides_total"],
                        m["failures"],
                        m["mfpt"],
                        m["lower_bound"],
                        *m["ci"],
                    ]
                )
    with (out_dir / "push.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["kind", "unit", "size", "success"])
        for kind, e in result["push"].items():
            for s, p in zip(e["sizes"], e["success"], strict=True):
                w.writerow([kind, e["unit"], s, p])
    plot_margins([result], out_dir)


# Colours for columns without a style of their own (`column_styles`): matplotlib's tab10,
# then strong colours of ColorBrewer's Dark2 that tab10 lacks (so that a column added beside
# tab10's is still told apart), then tab20's lighter halves: up to 25 columns never share one.
_PALETTE = (
    *(f"tab:{c}" for c in "blue orange green red purple brown pink gray olive cyan".split()),
    "#1b9e77",
    "#7570b3",
    "#e6ab02",
    "#e7298a",
    "#66a61e",
    "#aec7e8",
    "#ffbb78",
    "#98df8a",
    "#ff9896",
    "#c5b0d5",
    "#c49c94",
    "#f7b6d2",
    "#c7c7c7",
    "#dbdb8d",
    "#9edae5",
)
_LINESTYLES = ("-", "--", ":", "-.")
# the hatch of a bar drawn for a column whose line style is not solid (the basin plot)
_HATCH = {"-": None, "--": "//", ":": "..", "-.": "\\\\"}


def column_styles(labels, styles: dict | None = None) -> dict:
    """One (colour, line style) per label, the same in every plot: ``styles`` (label ->
    ``{"color": ..., "ls": ...}``) first, then the palette's colours not used yet, solid; past
    the palette, its colours again with the next line style. No two labels share a pair."""
    styles = dict(styles or {})
    out, used = {}, set()
    for lab in labels:
        if lab in styles and lab not in out:
            st = {"color": styles[lab]["color"], "ls": styles[lab].get("ls", "-")}
            out[lab] = st
            used.add((st["color"], st["ls"]))
    free = [(c, ls) for ls in _LINESTYLES for c in _PALETTE if (c, ls) not in used]
    used_colours = {c for c, _ in used}
    free.sort(key=lambda cl: (_LINESTYLES.index(cl[1]), cl[0] in used_colours))
    for lab in labels:
        if lab not in out:
            color, ls = free.pop(0)
            out[lab] = {"color": color, "ls": ls}
    return out


# The columns drawn bold on the comparison plots when the caller names none: the passive
# gait, the classical lqr and mpc, and the shipped learned controllers (their columns'
# usual labels); every other column is drawn thinner and lighter behind them.
HEADLINE_COLUMNS = ("passive", "lqr", "mpc", "default", "fine-tuned", "step-ppo")
FIG_WIDTH = 10.0  # inches at FIG_DPI: 1000 px wide
FIG_DPI = 100


def _legend(ax, n: int) -> None:
    """The legend outside the data, right of the axes (one column up to 14 entries)."""
    ax.legend(
        fontsize=8,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        borderaxespad=0.0,
        frameon=False,
        ncol=1 if n <= 14 else 2,
    )


def plot_margins(
    results: list[dict],
    out_dir: Path,
    prefix: str = "",
    styles: dict | None = None,
    emphasis=None,
) -> list[Path]:
    """basin, curve and push plots of one or more results: one colour and line style per
    result's label, the same in every plot (`column_styles`; ``styles`` fixes some). The
    labels of ``emphasis`` (default `HEADLINE_COLUMNS`) are drawn bold, the others thinner
    and lighter; legends sit outside the data, right of the axes; figures are 1000 px wide."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    paths = []
    labels = [r.get("label") or r["policy"] for r in results]
    # a privileged column (it reads the robot's true plant) is marked in every legend
    shown = {
        lab: f"{lab} (privileged)" if r.get("privileged") is True else lab
        for r, lab in zip(results, labels, strict=True)
    }
    sty = column_styles(labels, styles)
    bold = set(HEADLINE_COLUMNS if emphasis is None else emphasis)
    if len(results) > 1:  # one result alone is always the one to see
        for lab in labels:
            sty[lab]["bold"] = lab in bold
    n = len(results)

    fig, ax = plt.subplots(figsize=(FIG_WIDTH, 4.2), dpi=FIG_DPI, layout="constrained")
    names = [f"{lab}{s}" for lab in Z_LABELS for s in ("+", "-")]
    x = np.arange(len(names))
    wbar = 0.8 / len(results)
    for k, (r, lab) in enumerate(zip(results, labels, strict=True)):
        vals = [r["basin"][c][s]["rel"] for c in Z_LABELS for s in ("+", "-")]
        st = sty[lab]
        ax.bar(
            x + (k - (len(results) - 1) / 2) * wbar,
            vals,
            wbar,
            label=shown[lab],
            color=st["color"],
            hatch=_HATCH.get(st["ls"]),
            edgecolor="white" if _HATCH.get(st["ls"]) else None,
            alpha=0.45 if st.get("bold") is False else 1.0,
        )
    if any(r["basin"][c][s]["rel"] > 0 for r in results for c in Z_LABELS for s in "+-"):
        ax.set_yscale("log")  # an empty basin (all zero) has nothing to put on a log axis
    ax.set_xticks(x, names, rotation=45, ha="right")
    for k in range(1, len(names)):  # a thin rule between the components' groups of bars
        ax.axvline(k - 0.5, color="0.85", lw=0.6, zorder=0)
    ax.set_xlim(-0.5, len(names) - 0.5)
    ax.set_ylabel("largest relative perturbation")
    ax.set_title("Basin along each apex component (units of |z*_i|; uncapped)")
    _legend(ax, n)
    paths.append(out_dir / f"{prefix}basin.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(FIG_WIDTH, 4.6), dpi=FIG_DPI, layout="constrained")
    for r, lab in zip(results, labels, strict=True):
        c = r["basin_curve"]
        line = ax.plot(
            c["sizes"], c["success"], marker="o", label=shown[lab], ms=3, **_line(sty[lab])
        )[0]
        if "ci_low" in c:
            ax.fill_between(
                c["sizes"], c["ci_low"], c["ci_high"], color=line.get_color(), alpha=_band(sty[lab])
            )
    ax.set_xscale("log")
    ax.set_xlabel("relative perturbation size r (random direction)")
    ax.set_ylabel("P(return)")
    ax.set_ylim(-0.05, 1.05)
    _legend(ax, n)
    paths.append(out_dir / f"{prefix}curve.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    fig, axes = plt.subplots(
        1, 2, figsize=(FIG_WIDTH + 1.0, 4.2), dpi=FIG_DPI, layout="constrained"
    )
    for ax, kind, unit in ((axes[0], "xdot", "m/s"), (axes[1], "th1dot", "rad/s")):
        for r, lab in zip(results, labels, strict=True):
            ax.plot(
                r["push"][kind]["sizes"],
                r["push"][kind]["success"],
                marker="o",
                ms=3,
                label=shown[lab],
                **_line(sty[lab]),
            )
        ax.set_xlabel(f"kick in {kind} [{unit}]")
        ax.set_ylabel("success rate")
        ax.set_ylim(-0.05, 1.05)
    _legend(axes[1], n)
    paths.append(out_dir / f"{prefix}push.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    if all("terrain" in r for r in results):
        fig, ax = plt.subplots(figsize=(FIG_WIDTH, 4.6), dpi=FIG_DPI, layout="constrained")
        for r, lab in zip(results, labels, strict=True):
            t = r["terrain"]
            line = ax.plot(
                t["sigmas_deg"],
                t["survival"],
                marker="o",
                label=shown[lab],
                ms=3,
                **_line(sty[lab]),
            )[0]
            ax.fill_between(
                t["sigmas_deg"],
                t["ci_low"],
                t["ci_high"],
                color=line.get_color(),
                alpha=_band(sty[lab]),
            )
        ax.set_xscale("log")
        ax.set_xlabel("slope noise sigma per apex [deg]")
        ax.set_ylabel(f"P(survive {results[0]['terrain']['strides']} strides)")
        ax.set_ylim(-0.05, 1.05)
        _legend(ax, n)
        paths.append(out_dir / f"{prefix}terrain.png")
        fig.savefig(paths[-1])
        plt.close(fig)

    if any(r.get("mfpt") for r in results):
        from matplotlib.ticker import NullFormatter

        fig, ax = plt.subplots(figsize=(FIG_WIDTH, 4.6), dpi=FIG_DPI, layout="constrained")
        for r, lab in zip(results, labels, strict=True):
            m = r.get("mfpt") or []
            if not m:
                continue
            sig = np.array([e["sigma_deg"] for e in m])
            val = np.array([e["mfpt"] for e in m], dtype=float)
            lb = np.array([e["lower_bound"] for e in m], dtype=bool)
            line = ax.plot(sig, val, label=shown[lab], **_line(sty[lab]))[0]
            ax.plot(sig[~lb], val[~lb], "o", ms=3, color=line.get_color())
            ax.plot(sig[lb], val[lb], "^", ms=5, mfc="none", color=line.get_color())
            lo = np.array([e["ci"][0] for e in m], dtype=float)
            hi = np.array([e["ci"][1] if e["ci"][1] is not None else np.nan for e in m])
            ok = ~lb & np.isfinite(lo) & np.isfinite(hi)
            if ok.any():
                ax.vlines(sig[ok], lo[ok], hi[ok], color=line.get_color(), alpha=0.5)
        ax.axhline(MFPT_LEVEL, color="0.6", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        grid = sorted({e["sigma_deg"] for r in results for e in (r.get("mfpt") or [])})
        ax.set_xticks(grid, [f"{v:g}" for v in grid])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("slope noise sigma per apex [deg]")
        ax.set_ylabel("MFPT [strides] (^: lower bound)")
        _legend(ax, n)
        paths.append(out_dir / f"{prefix}mfpt.png")
        fig.savefig(paths[-1])
        plt.close(fig)
    return paths


def _line(st: dict) -> dict:
    """A column's line: bold (headline, or no emphasis given) or thin and lighter."""
    if st.get("bold") is False:
        return {"color": st["color"], "linestyle": st["ls"], "lw": 1.0, "alpha": 0.6}
    return {"color": st["color"], "linestyle": st["ls"], "lw": 2.2, "zorder": 3}


def _band(st: dict) -> float:
    """The opacity of a column's interval band: the headline's visible, the others' faint."""
    return 0.05 if st.get("bold") is False else 0.15


def summary_text(r: dict) -> str:
    """A few human-readable lines."""
    lines = [
        f"policy {r['policy']}  gait {r['gait']}  budget {r['budget']}  seed {r.get('seed')}"
        f"  ({r['seconds']:.1f} s)",
        *(
            ["PRIVILEGED: reads the robot's true plant (an upper reference, never deployable)"]
            if r.get("privileged") is True
            else []
        ),
        f"basin_min {r['basin_min']:.4g} ({r['basin_min_direction']}, "
        f"abs {r['basin_min_abs']:.4g})   cycle scale {r['basin_min_cycle']:.4g} "
        f"({r['basin_min_cycle_direction']})   share of ceiling "
        f"{_num(r['basin_share_min'])} ({r['basin_share_min_direction']})",
        f"r50 {r['basin_curve']['r50']:.3g} [{r['basin_curve']['r50_ci'][0]:.3g}, "
        f"{r['basin_curve']['r50_ci'][1]:.3g}]   terrain sigma50 "
        f"{r['terrain_sigma50_deg']:.3g} deg [{r['terrain_sigma50_ci_deg'][0]:.3g}, "
        f"{r['terrain_sigma50_ci_deg'][1]:.3g}]   MFPT = 100 strides at sigma "
        f"{_num(r.get('mfpt_sigma_100_deg'), 3)} deg",
        f"emax {r['emax']:.4f}   fixed-point shift max |dz| "
        f"{np.max(np.abs(r['fixed_point_shift'])):.3g}",
        f"slope window {r['slope_window_deg'][0]:.4f} .. {r['slope_window_deg'][1]:.4f} deg   "
        f"kc window {r['kc_window'][0]:.2f} .. {r['kc_window'][1]:.2f} N m/rad",
        f"push p50: xdot {r['push']['xdot']['p50']:g} m/s, th1dot {r['push']['th1dot']['p50']:g}"
        f" rad/s   effort {r['effort']:.3g} N m ({100 * r['effort_frac']:.2f} % of max torque)",
    ]
    d = r.get("decision_seconds")
    if d:
        lines.append(
            f"decision time p50 {1e3 * d['p50']:.3g} ms, p99 {1e3 * d['p99']:.3g} ms, mean "
            f"{1e3 * d['mean']:.3g} ms, max {1e3 * d['max']:.3g} ms ({d['n']} decisions)"
        )
    d = r.get("decision_times")
    if d:
        lines.append(
            f"every apex decision of these measures: p50 {1e3 * d['p50']:.3g} ms, p99 "
            f"{1e3 * d['p99']:.3g} ms ({d['n']} decisions)"
        )
    return "\n".join(lines)


def _num(v, digits: int = 4) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}g}"
