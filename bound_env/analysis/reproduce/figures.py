"""Figures: analogues of the paper's Figs. 3-8 (PNG with CSV beside them), drawn from the stage
results. Nothing here simulates."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ...model.params import z_labels
from .claims import CLAIMS, published

Z_LABELS = z_labels("text")  # θ1 [deg]
Z_TEX = z_labels("tex")  # $\theta_1^*$ [deg]
Z_LABELS_UNITS = z_labels("inline")  # θ1 deg
Z_COLUMNS = z_labels("column")  # theta1_deg
Z_FMT = ("{:.6f}", "{:.6f}", "{:.6f}", "{:.6f}", "{:.4f}", "{:.4f}")
PATH_STYLE = {
    "speed": ("C0", f"stiff spine → {published().kc:g}, α holds the forward speed"),
    "energy": ("C3", f"stiff spine → {published().kc:g}, α balances the energy (eq. 27)"),
    "energy_star": ("C1", "published gait's energy level, followed upwards"),
}
DPI = 100


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _write_csv(path: Path, header, rows) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in rows:
            w.writerow(
                ["" if v is None else (repr(float(v)) if isinstance(v, float) else v) for v in r]
            )
    return path


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------


def write_figures(results: dict, fig_dir) -> list[Path]:
    fig_dir = Path(fig_dir)
    fig_dir.mkdir(parents=True, exist_ok=True)
    out = []
    out += _fig3_fig4(results, fig_dir)
    out += _fig5(results, fig_dir)
    out += _fig6(results, fig_dir)
    out += _fig78(results, fig_dir)
    out += _fig_literal(results, fig_dir)
    return out


def _path_rows(results):
    rows = []
    for name, path in (results["stiff"].get("paths") or {}).items():
        for q in path["points"]:
            rows.append(
                [
                    name,
                    q["kc"],
                    q["alpha_deg"],
                    q["gamma_b_deg"],
                    q["gamma_f_deg"],
                    q["kb"],
                    q["kf"],
                    *q["z"],
                    q["emax"],
                    int(q["has_ds"]),
                    "-".join(q["phases"]),
                    q["energy"],
                ]
            )
    return rows


def _scatter_ds(ax, x, y, has_ds, color, label=None, filled=False, size=22):
    x, y, ds = np.asarray(x, float), np.asarray(y, float), np.asarray(has_ds, bool)
    face = color if filled else "white"
    ax.scatter(
        x[~ds],
        y[~ds],
        marker="o",
        s=size,
        facecolors=face,
        edgecolors=color,
        linewidths=0.9,
        label=label,
        zorder=3,
    )
    ax.scatter(
        x[ds],
        y[ds],
        marker="s",
        s=size,
        facecolors=face,
        edgecolors=color,
        linewidths=0.9,
        zorder=3,
    )


def _mark_published(ax, kc, published, ours, legend, published_label, ours_label):
    """The published value (star) and ours at the published parameters (cross) at k_c; the
    labels only on the panel that feeds the legend."""
    ax.scatter(
        [kc],
        [published],
        marker="*",
        s=90,
        color="k",
        zorder=4,
        label=published_label if legend else None,
    )
    ax.scatter(
        [kc], [ours], marker="x", s=50, color="k", zorder=4, label=ours_label if legend else None
    )


def _save_figure(fig, path: Path, title=None, *, fontsize=10, legend_from=None, ncol=5) -> Path:
    """Title, a shared legend along the bottom (from the axes ``legend_from``), layout, PNG."""
    rect = (0, 0, 1, 1)
    if legend_from is not None:
        fig.legend(
            *legend_from.get_legend_handles_labels(),
            loc="lower center",
            ncol=ncol,
            fontsize=7,
            frameon=False,
        )
        rect = (0, 0.05, 1, 1)
    if title is not None:
        fig.suptitle(title, fontsize=fontsize)
    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=DPI)
    _plt().close(fig)
    return path


def _fig3_fig4(results, d: Path) -> list[Path]:
    pub = published()
    plt = _plt()
    paths = results["stiff"].get("paths") or {}
    header = [
        "path",
        "kc",
        "alpha_deg",
        "gamma_b_deg",
        "gamma_f_deg",
        "kb",
        "kf",
        *Z_COLUMNS,
        "emax",
        "has_ds",
        "phases",
        "apex_energy_J",
    ]
    rows = _path_rows(results)
    c3 = _write_csv(d / "fig3_fixed_points_vs_kc.csv", header, rows)
    c4 = _write_csv(d / "fig4_parameters_vs_kc.csv", header, rows)
    zstar = results["reproducing"]["fixed_point"]["z"]
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.2))
    for name, path in paths.items():
        pts = path["points"]
        if not pts:
            continue
        color, label = PATH_STYLE[name]
        kc = [q["kc"] for q in pts]
        ds = [q["has_ds"] for q in pts]
        for i, ax in enumerate(axes.flat):
            y = [q["z"][i] for q in pts]
            ax.plot(kc, y, "-", color=color, lw=0.6, alpha=0.6)
            _scatter_ds(ax, kc, y, ds, color, label if i == 0 else None)
    for i, ax in enumerate(axes.flat):
        _mark_published(
            ax,
            pub.kc,
            pub.z[i],
            zstar[i],
            i == 0,
            "published z*",
            "our z* at the published parameters",
        )
        ax.set_xscale("log")
        ax.set_xlabel(r"$k_c$ [N m/rad]")
        ax.set_ylabel(Z_TEX[i])
        ax.grid(alpha=0.3, which="both")
    p3 = _save_figure(
        fig,
        d / "fig3_fixed_points_vs_kc.png",
        "Fig. 3 analogue: fixed points on S_apex against the spine stiffness, ζ = 0.2 "
        "(circles: no ds, squares: ds)",
        legend_from=axes.flat[0],
        ncol=5,
    )

    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5))
    for name, path in paths.items():
        pts = path["points"]
        if not pts:
            continue
        color, label = PATH_STYLE[name]
        kc = [q["kc"] for q in pts]
        ds = [q["has_ds"] for q in pts]
        ax = axes[0, 0]
        e = [q["emax"] if q["emax"] is not None else np.nan for q in pts]
        ax.plot(kc, e, "-", color=color, lw=0.6, alpha=0.6)
        _scatter_ds(ax, kc, e, ds, color, label)
        ax = axes[0, 1]
        _scatter_ds(ax, kc, [q["gamma_b_deg"] for q in pts], ds, color)
        _scatter_ds(ax, kc, [q["gamma_f_deg"] for q in pts], ds, color, filled=True)
        ax = axes[1, 0]
        _scatter_ds(ax, kc, [q["kb"] for q in pts], ds, color)
        _scatter_ds(ax, kc, [q["kf"] for q in pts], ds, color, filled=True, size=8)
        ax = axes[1, 1]
        a = [q["alpha_deg"] for q in pts]
        ax.plot(kc, a, "-", color=color, lw=0.6, alpha=0.6)
        _scatter_ds(ax, kc, a, ds, color)
    axes[0, 0].axhline(1.0, color="k", lw=0.6, ls="--")
    axes[0, 0].scatter(
        [pub.kc],
        [CLAIMS.emax],
        marker="*",
        s=90,
        color="k",
        zorder=4,
        label=f"paper: ≈ {CLAIMS.emax:g} at the published gait",
    )
    axes[1, 1].scatter([pub.kc], [pub.alpha_deg], marker="*", s=90, color="k", zorder=4)
    labels = (
        r"$e_{max}$",
        r"$\gamma_b^{td}$ (open), $\gamma_f^{td}$ (filled) [deg]",
        r"$k_b$ (open), $k_f$ (filled) [N/m]",
        r"slope $\alpha$ [deg]",
    )
    for ax, lab in zip(axes.flat, labels, strict=True):
        ax.set_xscale("log")
        ax.set_xlabel(r"$k_c$ [N m/rad]")
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3, which="both")
    axes[1, 1].set_yscale("log")
    p4 = _save_figure(
        fig,
        d / "fig4_parameters_vs_kc.png",
        "Fig. 4 analogue: e_max, touchdown angles, leg stiffness and slope along the "
        "paths (circles: no ds, squares: ds)",
        legend_from=axes[0, 0],
        ncol=4,
    )

    # zoom on the published gait: the three paths near its kc on a linear axis
    fig, axes = plt.subplots(2, 4, figsize=(14, 6.2))
    lo, hi = 285.0, 345.0
    for name, path in paths.items():
        pts = [q for q in path["points"] if lo <= q["kc"] <= hi]
        if not pts:
            continue
        color, label = PATH_STYLE[name]
        kc = [q["kc"] for q in pts]
        ds = [q["has_ds"] for q in pts]
        cols = [[q["z"][i] for q in pts] for i in range(6)]
        cols.append([q["emax"] if q["emax"] is not None else np.nan for q in pts])
        cols.append([q["alpha_deg"] for q in pts])
        for i, ax in enumerate(axes.flat):
            ax.plot(kc, cols[i], "-", color=color, lw=0.6, alpha=0.6)
            _scatter_ds(ax, kc, cols[i], ds, color, label if i == 0 else None, size=14)
    marks = list(pub.z) + [CLAIMS.emax, pub.alpha_deg]
    ours = list(zstar) + [results["reproducing"]["fixed_point"]["emax"], pub.alpha_deg]
    labels = list(Z_TEX) + [r"$e_{max}$", r"slope $\alpha$ [deg]"]
    for i, ax in enumerate(axes.flat):
        _mark_published(
            ax, pub.kc, marks[i], ours[i], i == 0, "published", "our z* (published parameters)"
        )
        ax.set_xlim(lo, hi)
        ax.set_xlabel(r"$k_c$ [N m/rad]")
        ax.set_ylabel(labels[i])
        ax.grid(alpha=0.3)
    axes[1, 2].axhline(1.0, color="k", lw=0.6, ls="--")
    pz = _save_figure(
        fig,
        d / "fig3b_near_published.png",
        "Figs. 3-4 near the published gait (kc 285-345, linear axis; circles: no ds, squares: ds)",
        legend_from=axes.flat[0],
        ncol=5,
    )
    return [p3, c3, p4, c4, pz]


def _fig5(results, d: Path) -> list[Path]:
    pub = published()
    plt = _plt()
    tr = results["reproducing"]["trajectory"]
    t = np.asarray(tr["t"])
    q, qd = np.asarray(tr["q"]), np.asarray(tr["qd"])
    series = [
        ("x_g [m]", q[:, 0]),
        ("y_g [m]", q[:, 1]),
        ("θ1 [deg]", np.degrees(q[:, 2])),
        ("θ2 [deg]", np.degrees(q[:, 3])),
        ("ẋ_g [m/s]", qd[:, 0]),
        ("ẏ_g [m/s]", qd[:, 1]),
        ("θ̇1 [deg/s]", np.degrees(qd[:, 2])),
        ("θ̇2 [deg/s]", np.degrees(qd[:, 3])),
    ]
    csvp = _write_csv(
        d / "fig5_periodic_solution.csv",
        ["t_s", *[s[0] for s in series], "phase"],
        [[float(t[i]), *[float(s[1][i]) for s in series], tr["phase"][i]] for i in range(len(t))],
    )
    fig, axes = plt.subplots(4, 2, figsize=(10, 8.5), sharex=True)
    ev = [e for e in tr["events"]]
    for ax, (lab, y) in zip(axes.T.flat, series, strict=True):
        ax.plot(t, y, color="C0", lw=1.2)
        for e in ev:
            ax.axvline(e["t"], color="k", ls=":", lw=0.8)
        ax.set_ylabel(lab)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    names = ", ".join(f"{e['name']} {e['t'] * 1e3:.2f} ms" for e in ev)
    p = _save_figure(
        fig,
        d / "fig5_periodic_solution.png",
        f"Fig. 5 analogue: one stride of the periodic gait, kc = {pub.kc:g}, "
        f"ζ = {pub.zeta:g} "
        "(dotted: transitions)\n" + names,
        fontsize=8.5,
    )
    return [p, csvp]


def _fig6(results, d: Path) -> list[Path]:
    pub = published()
    plt = _plt()
    zstar = np.asarray(results["reproducing"]["fixed_point"]["z"])
    rows = []
    fig, axes = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    for rec, color in zip(results["reproducing"]["recovery"], ("C0", "C3"), strict=True):
        h = np.asarray(rec["history"]) - zstar
        n = np.arange(len(h))
        lab = f"{rec['rel'] * 100:+.0f} % on y_g"
        for i, ax in enumerate(axes.T.flat):
            ax.plot(n, h[:, i], "-o", ms=2, lw=0.8, color=color, label=lab if i == 0 else None)
        rows += [[rec["rel"], int(k), *h[k]] for k in n]
    for i, ax in enumerate(axes.T.flat):
        ax.set_ylabel("Δ" + Z_LABELS[i])
        ax.axhline(0, color="k", lw=0.5)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("stride")
    axes[0, 0].legend(fontsize=7)
    p = _save_figure(
        fig,
        d / "fig6_convergence.png",
        f"Fig. 6 analogue: Δz = z_n − z* after ±1 % on y_g, α = {pub.alpha_deg:g}, "
        f"kc = {pub.kc:g}, ζ = {pub.zeta:g}",
    )
    c = _write_csv(
        d / "fig6_convergence.csv", ["perturbation", "stride", *[f"d_{s}" for s in Z_COLUMNS]], rows
    )
    return [p, c]


def _fig78(results, d: Path) -> list[Path]:
    plt = _plt()
    out = []
    for key, num, xl, paper_w in (
        ("alpha_deg", 7, r"slope $\alpha$ [deg]", CLAIMS.alpha_window),
        ("kc", 8, r"$k_c$ [N m/rad]", CLAIMS.kc_window),
    ):
        sw = results["sweeps"][key]
        pts = [q for q in sw["points"] if q["found"]]
        name = f"fig{num}_emax_vs_{'alpha' if key == 'alpha_deg' else 'kc'}"
        rows = [
            [
                q["value"],
                int(q["converged"]),
                q["error"],
                q["failure"] or "",
                int(q["found"]),
                q["emax"],
                int(q["has_ds"]),
                "-".join(q["phases"]),
                *(q["z"] if q["z"] is not None else [None] * 6),
            ]
            for q in sw["points"]
        ]
        c = _write_csv(
            d / f"{name}.csv",
            [
                key,
                "converged_100_strides",
                "error_z99_z100",
                "failure",
                "fixed_point_found",
                "emax",
                "has_ds",
                "phases",
                *Z_COLUMNS,
            ],
            rows,
        )
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        x = np.array([q["value"] for q in pts])
        e = np.array([q["emax"] for q in pts], float)
        ds = np.array([q["has_ds"] for q in pts], bool)
        conv = np.array([q["converged"] for q in pts], bool)
        for m, marker, color, lab in (
            (~ds, "o", "tab:blue", "without ds"),
            (ds, "s", "tab:green", "with ds"),
        ):
            ax.scatter(
                x[m & conv],
                e[m & conv],
                marker=marker,
                color=color,
                s=24,
                label=f"{lab}, converged in 100 strides",
                zorder=3,
            )
            ax.scatter(
                x[m & ~conv],
                e[m & ~conv],
                marker=marker,
                facecolors="none",
                edgecolors=color,
                s=24,
                label=f"{lab}, not converged",
                zorder=3,
            )
        ax.axhline(1.0, color="k", lw=0.6, ls="--")
        ax.axvline(sw["base"], color="0.5", lw=0.6, ls=":")
        ax.axvspan(*paper_w, color="0.5", alpha=0.12, hatch="//", label="paper's window")
        w = sw["converged_window"]
        if w:
            ax.axvspan(w[0], w[1], color="tab:blue", alpha=0.10, label="our 100-stride window")
        ax.set_xlabel(xl)
        ax.set_ylabel(r"$e_{max}$")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6.5, loc="upper left")
        ax.set_title(
            f"Fig. {num} analogue: e_max when {'α' if key == 'alpha_deg' else 'kc'} is changed",
            fontsize=10,
        )
        p = _save_figure(fig, d / f"{name}.png")
        out += [p, c]
    return out


def _fig_literal(results, d: Path) -> list[Path]:
    lit = results["literal"]
    kp = lit.get("kc_path")
    if not kp or not kp["points"]:
        return []
    plt = _plt()
    pts = kp["points"]
    rows = [
        [
            q["kc"],
            q["alpha_deg"],
            *q["z"],
            q["emax"],
            int(q["has_ds"]),
            "-".join(q["phases"]),
            q["energy"],
        ]
        for q in pts
    ]
    c = _write_csv(
        d / "figL_literal_kc_path.csv",
        ["kc", "alpha_deg", *Z_COLUMNS, "emax", "has_ds", "phases", "apex_energy_J"],
        rows,
    )
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    kc = [q["kc"] for q in pts]
    ds = [q["has_ds"] for q in pts]
    e = [q["emax"] if q["emax"] is not None else np.nan for q in pts]
    axes[0].plot(kc, e, "-", color="C4", lw=0.6)
    _scatter_ds(axes[0], kc, e, ds, "C4")
    axes[0].axhline(1.0, color="k", lw=0.6, ls="--")
    axes[0].set_ylabel(r"$e_{max}$")
    a = [q["alpha_deg"] for q in pts]
    axes[1].plot(kc, a, "-", color="C4", lw=0.6)
    _scatter_ds(axes[1], kc, a, ds, "C4")
    axes[1].set_ylabel(r"slope $\alpha$ [deg]")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel(r"$k_c$ [N m/rad]")
        ax.grid(alpha=0.3, which="both")
    p = _save_figure(
        fig,
        d / "figL_literal_kc_path.png",
        "Literal reading: the periodic gait at the published parameters followed to "
        "stiffer spines, α balancing the energy (circles: no ds, squares: ds)",
        fontsize=9,
    )
    return [p, c]
