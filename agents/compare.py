"""Passive vs learned margins side by side: ``docs/MARGINS.md`` (``bound-env compare``).

Runs `agents.margins.compute_margins` for the passive gait and for each shipped policy (results
cached under ``out/margins/<label>/``, so a second run only rewrites the page), then writes the
table and the plots (``docs/margins_*.png``) and copies each policy's training curve.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

from .margins import Z_LABELS, compute_margins, plot_margins

POLICIES_DIR = Path(__file__).resolve().parent / "policies"
ROOT = Path(__file__).resolve().parent.parent
DEFAULT_DOCS = ROOT / "docs"
DEFAULT_OUT = Path("out") / "margins"


def default_entries() -> list[tuple[str, str, str]]:
    """(label, policy, gait) for the passive gait and every shipped policy."""
    entries = [("passive", "passive", "default")]
    if (POLICIES_DIR / "default" / "model.zip").is_file():
        entries.append(("learned", str(POLICIES_DIR / "default"), "default"))
    if (POLICIES_DIR / "literal-cycle" / "model.zip").is_file():
        entries.append(("passive literal", "passive", "literal-cycle"))
        entries.append(("learned literal", str(POLICIES_DIR / "literal-cycle"), "literal-cycle"))
    return entries


def parse_entry(text: str) -> tuple[str, str, str]:
    """``LABEL=PATH`` or ``LABEL=PATH@GAIT``."""
    if "=" not in text:
        raise ValueError(f"--policy {text!r} must look like LABEL=PATH (or LABEL=PATH@GAIT)")
    label, rest = text.split("=", 1)
    path, _, gait = rest.partition("@")
    return label.strip(), path.strip(), (gait.strip() or "default")


def compare(entries=None, budget: str = "full", workers: int = 2, out: str | Path = DEFAULT_OUT,
            docs: str | Path = DEFAULT_DOCS, progress: bool = True, executor=None) -> Path:
    """Compute (or reuse) every entry's margins and write ``docs/MARGINS.md``; returns its path."""
    entries = entries or default_entries()
    out, docs = Path(out), Path(docs)
    docs.mkdir(parents=True, exist_ok=True)
    results = []
    for label, policy, gait in entries:
        r = compute_margins(policy, budget=budget, gait=gait, workers=workers,
                            executor=executor, out=out / label, progress=progress)
        r["label"] = label
        results.append(r)
    plots = plot_margins(results, docs, prefix="margins_")
    curves = []
    for label, policy, _ in entries:
        src = Path(policy) / "eval.png"
        if policy != "passive" and src.is_file():
            dst = docs / f"training_{label.replace(' ', '_')}.png"
            shutil.copyfile(src, dst)
            curves.append((label, policy, dst))
    page = render_markdown(results, entries, plots, curves, budget)
    path = docs / "MARGINS.md"
    path.write_text(page)
    return path


def _fmt(v, digits=4) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.{digits}g}"


def _window(r, key, capped_key, digits) -> str:
    lo, hi = r[key]
    c = r.get(capped_key, [False, False])
    return f"{'≤' if c[0] else ''}{_fmt(lo, digits)} – {'≥' if c[1] else ''}{_fmt(hi, digits)}"


def _ratio(a, b) -> str:
    try:
        return f"{a / b:.2f}×"
    except (TypeError, ZeroDivisionError):
        return "—"


def render_markdown(results, entries, plots, curves, budget) -> str:
    labels = [r["label"] for r in results]
    base = results[0]
    head = "| measure | " + " | ".join(labels) + " |"
    sep = "| --- |" + " --- |" * len(labels)
    rows = []

    def row(name, fn):
        rows.append(f"| {name} | " + " | ".join(fn(r) for r in results) + " |")

    row("**basin_min** (relative, worst of 12 directions)",
        lambda r: f"**{_fmt(r['basin_min'], 3)}** ({r['basin_min_direction']}, "
                  f"{_fmt(r['basin_min_abs'], 3)} {_unit(r['basin_min_direction'])})"
                  + ("" if r is base else f", {_ratio(r['basin_min'], base['basin_min'])}"))
    row("random-direction r50 (P(return) ≥ 0.5 up to)",
        lambda r: _fmt(r["basin_curve"]["r50"], 3))
    row("**emax** (closed-loop apex map)", lambda r: f"**{r['emax']:.4f}**")
    row("eigenvalue moduli",
        lambda r: ", ".join(f"{math.hypot(*e):.3f}" for e in r["eigenvalues"]))
    row("fixed-point shift z_cl − z* [m, rad, rad, m/s, rad/s, rad/s]",
        lambda r: "[" + ", ".join(_fmt(v, 2) for v in r["fixed_point_shift"]) + "]")
    row("slope window α [deg] (survive 50 strides)",
        lambda r: _window(r, "slope_window_deg", "slope_window_capped", 4))
    row("k_c window [N m/rad] (survive 50 strides)",
        lambda r: _window(r, "kc_window", "kc_window_capped", 4))
    row("push p50, Δẋ [m/s]", lambda r: _fmt(r["push"]["xdot"]["p50"], 3))
    row("push p50, Δθ̇1 [rad/s]", lambda r: _fmt(r["push"]["th1dot"]["p50"], 3))
    row("**effort** mean \\|τ\\| on the cycle [N m]",
        lambda r: "**0** (zero action)" if r["policy"] == "passive" else
                  f"**{_fmt(r['effort'], 3)}** ({100 * r['effort_frac']:.2f} % of "
                  f"max_torque {r['max_torque']:g} N m)")
    main = "\n".join([head, sep, *rows])

    bhead = "| direction | " + " | ".join(labels) + " |"
    bsep = "| --- |" + " --- |" * len(labels)
    brows = []
    for c in Z_LABELS:
        for s in ("+", "-"):
            cells = []
            for r in results:
                e = r["basin"][c]
                v = e[s]
                mark = "≥" if v["capped"] else ""
                cells.append(f"{mark}{_fmt(v['rel'], 3)} ({_fmt(v['abs'], 3)} {e['unit']})")
            brows.append(f"| {c}{s} | " + " | ".join(cells) + " |")
    basin_table = "\n".join([bhead, bsep, *brows])

    train_lines = []
    for label, policy, png in curves:
        info_path = Path(policy) / "run.json"
        info = json.loads(info_path.read_text()) if info_path.is_file() else {}
        t = info.get("wall_time_s")
        exp_path = Path(policy) / "exported.json"
        exp = json.loads(exp_path.read_text()) if exp_path.is_file() else {}
        kept = (f" The shipped model is the checkpoint with the best basin validation, at "
                f"{exp['timesteps']} timesteps (score {exp['basin_validation']:.4f}; lower "
                f"panel)." if "timesteps" in exp else "")
        train_lines.append(
            f"- **{label}** (`{_rel(policy)}`): seed {info.get('seed', '?')}, "
            f"{info.get('timesteps_done', '?')} timesteps, "
            f"{'%.1f min' % (t / 60) if t else '?'} of training on {info.get('machine', '?')}; "
            f"command `{_command(info.get('command', '?'))}`.{kept}\n\n"
            f"  ![training curve {label}]({png.name})"
        )
    settings = base["settings"]
    return f"""# Stability margins: passive vs learned spine control

Generated by `bound-env compare --budget {budget}` (agents/compare.py); do not edit by hand.
Every column is measured on the same yardsticks by `bound-env margins` (agents/margins.py):
the closed-loop apex-to-apex map, each stride an episode started at an apex with
`reset(options={{"apex_state": z}})` so the control intervals restart at the apex, integrator
tolerance {settings['rtol']:g}, "returned" = max-abs apex error below {settings['return_tol']:g}
(SI) within {settings['basin_strides']} strides.

{main}

Relative perturbations are z*_i·s added to the controller's own cycle z_cl, with z* the
passive fixed point, so the absolute sizes are the same for every column. Windows: the
connected range around the nominal value (α = {base['slope_nominal_deg']:.4f}°,
k_c = {base['kc_nominal']:g} N m/rad) in which the loop started at z_cl survives 50 strides;
≤/≥ mark an edge at the end of the scanned range. The paper's passive windows
(1.92–2.05°, 294–308 N m/rad) come from its own criterion (a stable fixed point that the
gait converges to); survival for 50 strides is a looser test, so the passive windows here
differ from the paper's, mostly on the low side. Push: a kick of the given size,
random sign, at a random control instant of a cycle stride; p50 = the largest size up to
which at least half of the {settings['push_samples']} trials return.

## Basin along each apex component

Largest relative perturbation s (and its absolute size) from which the loop returns; ≥ marks
the bracket's end (s = 1).

{basin_table}

![basin per direction](margins_basin.png)

![success probability against the size of a random-direction perturbation](margins_curve.png)

![push recovery](margins_push.png)

## Training

{chr(10).join(train_lines) if train_lines else "(no trained policy)"}

The literal reading of Table II (`PassiveBoundLiteral-v0`, section of `configs/ppo.yaml`):
its published apex state falls within the first stride (PPO started there never completed a
stride in 3-4·10⁶ steps), so its task starts on the literal reading's own periodic gait at the
published parameters (`configs/gaits/literal-cycle.yaml`, found by `bound-env reproduce`), a
saddle with e_max 1.364: its passive basin is empty. The "literal" columns, where present,
measure that cycle, passive and with `agents/policies/literal-cycle`; their ratios are against
the first column (the default gait's passive basin), since the literal passive basin is zero.
"""


def _command(cmd: str) -> str:
    """The command as a reader would type it (``bound-env ...``, not the venv's path)."""
    parts = cmd.split()
    if parts and parts[0].endswith("bound-env"):
        parts[0] = "bound-env"
    return " ".join(parts)


def _rel(p: str) -> str:
    try:
        return str(Path(p).resolve().relative_to(ROOT))
    except ValueError:
        return p


def _unit(direction: str | None) -> str:
    if not direction:
        return ""
    from .margins import Z_UNITS

    return Z_UNITS[Z_LABELS.index(direction[:-1])]
