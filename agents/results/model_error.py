"""The results page's model-error section (``bound-env compare``, on by default for the page's
own columns; ``--no-mismatch`` leaves it out): which controller holds a robot that is not its
model, beside which one has the widest basin.

The section's columns (`model_error_entries`): passive, lqr, mpc, `default` (the fine-tuned
student's first seed, the best learned column's s0), `mpc-adaptive` (the MPC that identifies
its plant online), the learned adaptive controller (`agents/policies/adaptive/s0`, where it is
shipped) and `mpc-privileged` (re-designed on each robot's true plant: **privileged**, an
upper reference, never a deployable controller; the tables label it). Each is measured under
`MODEL_ERROR_SPECS` (pm10, pm15, pm10+noise) on the model-error budget `model_error_budget`
(``page``: hold on 32 plants for 100 strides and r50 under error on five sizes, no MFPT;
``test`` for ``--budget test``), the model-error measures only (`compute_margins` with
``nominal=False``): its nominal margins are the page's other columns. Results under
``<out>/model-error/<label>/``; the paired comparisons are against lqr.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..runtime.policy import SHIPPED_DIR
from .formatting import rel, slug

MODEL_ERROR_SPECS = ("pm10", "pm15", "pm10+noise")
ADAPTIVE = SHIPPED_DIR / "adaptive" / "s0"  # the learned adaptive controller's first seed


def model_error_budget(budget: str) -> str:
    """The model-error budget (`bound_env.analysis.margins.mismatch_tasks.MISMATCH_BUDGETS`)
    of the page's ``budget``: ``test`` for the test budget, else ``page``."""
    return "test" if budget == "test" else "page"


def model_error_entries() -> list[tuple[str, str]]:
    """(label, policy) of the section's columns (module docstring), all on the default gait."""
    out = [("passive", "passive"), ("lqr", "lqr"), ("mpc", "mpc"), ("default", "default")]
    out.append(("mpc-adaptive", "mpc-adaptive"))
    if (ADAPTIVE / "adaptive.npz").is_file():
        out.append(("adaptive", str(ADAPTIVE)))
    out.append(("mpc-privileged", "mpc-privileged"))
    return out


def run_model_error(
    budget: str,
    out: Path,
    seed: int,
    executor=None,
    workers: int = 1,
    progress: bool = False,
    render_only: bool = False,
    specs=MODEL_ERROR_SPECS,
    on_column=None,
) -> list[dict]:
    """The section's columns as the page's groups ({label, gait, policies, runs}), computed
    (or taken from the cache) under ``specs``, or with ``render_only`` read from their
    ``margins.json`` (a ValueError naming the file where one is missing or of another budget,
    seed or spec). ``on_column(label, policy, result)`` is called after each."""
    from bound_env.mismatch import parse_specs

    from .margins import compute_margins

    parsed = parse_specs(",".join(specs))
    mb = model_error_budget(budget)
    groups = []
    for label, policy in model_error_entries():
        sub = Path(out) / "model-error" / slug(label)
        if render_only:
            r = load_model_error(sub / "margins.json", budget, seed, parsed, mb)
        else:
            r = compute_margins(
                policy,
                budget=budget,
                workers=workers,
                executor=executor,
                out=sub,
                progress=progress,
                seed=seed,
                mismatch=parsed,
                mismatch_budget=mb,
                nominal=False,
            )
        r["label"], r["source"] = label, policy
        if on_column is not None:
            on_column(label, policy, r)
        groups.append({"label": label, "gait": "default", "policies": [policy], "runs": [r]})
    return groups


def load_model_error(path: Path, budget: str, seed: int, specs, mb: str) -> dict:
    """A model-error column's ``margins.json`` for ``--render-only``: of ``budget`` and
    ``seed``, with a block of each spec measured under it on the model-error budget ``mb``;
    a one-line ValueError naming the file otherwise."""
    from dataclasses import asdict

    from bound_env.analysis.margins.mismatch_tasks import MISMATCH_BUDGETS

    again = "run compare without --render-only first (or give --no-mismatch)"
    if not path.is_file():
        raise ValueError(f"{path}: no model-error result to render; {again}")
    try:
        r = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a margins result ({e})") from None
    if not isinstance(r, dict) or r.get("budget") != budget or r.get("seed") != seed:
        raise ValueError(f"{path}: not of budget {budget!r} and seed {seed}; {again}")
    held = r.get("mismatch") if isinstance(r.get("mismatch"), dict) else {}
    want = json.loads(json.dumps(asdict(MISMATCH_BUDGETS[mb])))  # as the JSON holds it
    for spec in specs:
        b = held.get(spec.name)
        if not isinstance(b, dict) or b.get("spec") != spec.to_dict():
            raise ValueError(f"{path}: no model-error block {spec.name!r} of its spec; {again}")
        if b.get("budget") != want:
            raise ValueError(f"{path}: block {spec.name!r} is not of the {mb} budget; {again}")
    r["mismatch"] = {s.name: held[s.name] for s in specs}
    return r


def model_error_section(groups, budget: str) -> str:
    """The page's "Model error" section of the columns `run_model_error` made: how they were
    measured, then one table per spec, paired against lqr
    (`bound_env.analysis.margins.mismatch_report.mismatch_markdown`)."""
    from bound_env.analysis.margins.mismatch_report import mismatch_markdown
    from bound_env.analysis.margins.mismatch_tasks import MISMATCH_BUDGETS

    measured = {g["label"]: g["runs"][0] for g in groups if g["runs"][0].get("mismatch")}
    if not measured:
        return ""
    mb = MISMATCH_BUDGETS[model_error_budget(budget)]
    specs = list(dict.fromkeys(k for r in measured.values() for k in r["mismatch"]))
    ref = "lqr" if "lqr" in measured else None
    mfpt = "no MFPT" if not mb.mfpt_sigmas else f"MFPT at {len(mb.mfpt_sigmas)} slope sigmas"
    intro = (
        f"Each robot on its own plant (the spec's draws; the same plants for every column), "
        f"the controller on its nominal design. The model-error budget `{mb.name}`: hold on "
        f"{mb.plants} plants for {mb.hold_strides} strides from the nominal z*, r50 under error "
        f"on {len(mb.curve_sizes)} sizes ({mb.curve_strides} strides), {mfpt}; `default` is "
        "the best learned column's first seed, `adaptive` the learned adaptive controller's "
        "(`agents/policies/adaptive/s0`), `mpc-privileged` reads the robot's true plant "
        "(an upper reference, not a controller one could deploy). "
        "[docs/model-error.md](model-error.md) says how each measure is made.\n\n"
    )
    return "\n## Model error\n\n" + intro + mismatch_markdown(measured, specs=specs, reference=ref)


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
