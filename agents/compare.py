"""Passive vs learned margins side by side: ``docs/MARGINS.md`` (``bound-env compare``).

Runs `agents.margins.compute_margins` (the front of `bound_env.analysis.margins`) for the
passive gait and for each shipped policy (results cached under ``out/margins/<label>/``, so a
second run only rewrites the page), then writes the table and the plots
(``docs/margins_*.png``) and copies each policy's training curve.

Every column is scored on the same random samples (``--seed``), so two columns are compared
*paired* (`paired_comparisons`, `bound_env.analysis.paired`): each column against the
``lqr`` column (and a trained column against an ``mpc`` column, when there is one) on the
same directions, with McNemar's exact test per size and a bootstrap interval of Delta r50;
the page says which differences stand out of the noise, and ``paired.json`` beside the page
holds the numbers.
"""

from __future__ import annotations

import contextlib
import json
import math
import shutil
from pathlib import Path

from bound_env.analysis.margins import DEFAULT_SEED, Z_LABELS, check_seed, plot_margins
from bound_env.analysis.margins.stats import t_interval
from bound_env.cache import atomic_write
from bound_env.parallel import open_pool

from .margins import compute_margins
from .policy import SHIPPED_DIR

POLICIES_DIR = SHIPPED_DIR
ROOT = Path(__file__).resolve().parent.parent
DEFAULT_DOCS = ROOT / "docs"
DEFAULT_OUT = Path("out") / "margins"
CLASSICAL = ("lqr", "deadbeat", "damping", "mpc")  # controller specs in configs/controllers/
# How each shipped classical design was chosen (docs/controllers.md, "Design table"): first on
# the quick budget with the test seed (its 32 random directions are the first 32 of the test
# set's: a selection on the test set), then re-chosen by the same criterion on the validation
# seed 777 (scripts/control_table.py): the same designs.
CLASSICAL_SELECTION = {
    "lqr": "its design (8 windows, Q = I, R = 0.1) was **first chosen on the quick budget with "
    "the test seed** (criterion: largest basin_min, then r50, the slope window, push recovery; "
    "its 32 random directions are the first 32 of this page's 256, so that choice saw part of "
    "the test set), then **re-chosen on the validation seed 777** (seed 777's random "
    "directions, terrain and push samples, held out from this page's test set) among the 9 "
    "designs of the design table (docs/controllers.md): the same design, by a tie-break on r50 "
    "(0.1465 against 0.1462 for the other 8-window designs, which tie it on basin_min)",
    "deadbeat": "8 windows over 6: **first chosen on the quick budget with the test seed**, "
    "then **confirmed on the validation seed 777** by the same criterion (basin_min 4.8x "
    "against 3.9x the passive's on both; docs/controllers.md's design table)",
    "damping": "c is the spine's own damper c_c (the trivial baseline), not tuned on these "
    "yardsticks: no selection",
    "mpc": "**chosen on the validation seed 777**: its search settings (configs/controllers/"
    "mpc.yaml) were set before any measurement and kept against 4 variants (a longer horizon, "
    "a larger library, more cross-entropy rounds, a wider safe radius) on 96 random directions "
    "of seed 777 at r = 0.15-0.35 (docs/learned.md); its LQR is `lqr`'s design",
}
# How a learned recipe was chosen (docs/learned.md, "Selection, on held-out directions only"),
# said under its column's provenance
LEARNED_SELECTION = {
    "finetuned": "recipe **chosen on the validation seed 777** (96 random directions, r = "
    "0.15-0.35), never on this page's test set: each seed is PPO (1.5e6 strides) from the "
    "student distilled by DAgger from `mpc` with the same seed (`agents/policies/distilled/sS`);"
    " fine-tuning was chosen over the distilled students and 1.5e6 strides over 3e5 there; "
    "`agents/policies/default` is seed 0 (no choice among seeds)",
    "step-ppo": "recipe (configs/ppo-residual.yaml) **chosen on the validation seed 777** "
    "(agents/residual.py `validation_curve`: 64 random directions, r = 0.2-0.4), never on this "
    "page's test set: step-level PPO on PassiveBound-v0 (`bound-env train --config "
    "ppo-residual`), a residual on `default`'s interval torques active past its safe radius; "
    "final models, one per seed",
    "warm-started": "ppo-v1's recipe (configs/ppo.yaml, 3e6 steps) unchanged, but the actor "
    "first clones the torques of the shipped `default` (fine-tuned/s0) in the training env "
    "(`train --init-from default`, agents/warmstart.py); final models, nothing chosen on any "
    "yardstick",
    "ppo-v1-final": "ppo-v1's recipe (configs/ppo.yaml) unchanged, its final models (the "
    "shipped `agents/policies/ppo-v1` is a checkpoint selected on axis basins, left out here)",
}
# One colour and line style per column of the page, the same in every figure
# (`bound_env.analysis.margins.plot_margins`); the literal reading's columns dashed. A column
# not listed gets a colour none of these uses (`column_styles`).
COLUMN_STYLES = {
    "passive": {"color": "black", "ls": "-"},
    "fine-tuned": {"color": "tab:blue", "ls": "-"},
    "warm-started": {"color": "tab:cyan", "ls": "-"},
    "ppo-v1": {"color": "tab:purple", "ls": "-"},
    "lqr": {"color": "tab:orange", "ls": "-"},
    "deadbeat": {"color": "tab:brown", "ls": "-"},
    "damping": {"color": "tab:pink", "ls": "-"},
    "mpc": {"color": "tab:red", "ls": "-"},
    "passive literal": {"color": "tab:gray", "ls": "--"},
    "learned literal": {"color": "tab:green", "ls": "--"},
    "lqr literal": {"color": "tab:olive", "ls": "--"},
}
# The headline table (the page's first table and the README's): (role, column label, what it
# is). The step-level PPO row is the shipped step-level recipe's column (`step-ppo`: residual
# PPO on PassiveBound-v0; ppo-v1's plain recipe is the `ppo-v1` column of the full table).
HEADLINE = (
    ("passive", "passive", "zero spine torque"),
    ("lqr", "lqr", "stride-to-stride LQR (classical)"),
    ("mpc", "mpc", "model-predictive search over the next stride (classical, the teacher)"),
    (
        "best learned",
        "fine-tuned",
        "`default`: distilled from `mpc`, fine-tuned by PPO (3 seeds; `default` = s0)",
    ),
    (
        "step-level PPO",
        "step-ppo",
        "PPO on PassiveBound-v0: a residual on `default`'s torques past its safe radius "
        "(configs/ppo-residual.yaml, 3 final-model seeds)",
    ),
)
HEADLINE_FILE = "headline.json"  # beside MARGINS.md and paired.json

# Learned columns with one folder per training seed, shipped in agents/policies/<group>/s<k>:
# the page's (SEED_GROUPS), and the ablations a user can add with --entry (EXTRA_GROUPS)
SEED_GROUPS = (
    ("fine-tuned", "finetuned"),  # agents/finetune.py: PPO from the distilled (`default`: s0)
    ("step-ppo", "step-ppo"),  # agents/residual.py: step-level residual PPO over `default`
    ("warm-started", "warm-started"),  # step-level PPO cloned from `default` first
    ("ppo-v1", "ppo-v1-final"),  # ppo-v1's recipe (step-level PPO), final models
)
EXTRA_GROUPS = (
    ("distilled", "distilled"),  # agents/distill.py: DAgger from mpc, before fine-tuning
    ("stride-residual", "stride-residual"),  # agents/stride.py: PPO residual on the LQR
)


def seed_group(group: str) -> list[str]:
    """The shipped seed folders of a group (``agents/policies/<group>/s*``)."""
    return [str(p) for p in sorted((POLICIES_DIR / group).glob("s*")) if p.is_dir()]


def default_entries() -> list[tuple[str, list[str], str]]:
    """(label, policies, gait) for the passive gait and every shipped policy."""
    entries = [("passive", ["passive"], "default")]
    # learned columns, one policy per seed (the shipped `default` is fine-tuned/s0; the
    # selected checkpoint `agents/policies/ppo-v1` is left out: its final-model seeds are in)
    for label, group in SEED_GROUPS:
        if seed_group(group):
            entries.append((label, seed_group(group), "default"))
    # the classical stride-level controllers (bound_env.control, configs/controllers/)
    entries += [(name, [name], "default") for name in CLASSICAL]
    if (POLICIES_DIR / "literal-cycle" / "model.zip").is_file():
        entries.append(("passive literal", ["passive"], "literal-cycle"))
        entries.append(("learned literal", [str(POLICIES_DIR / "literal-cycle")], "literal-cycle"))
        entries.append(("lqr literal", ["lqr"], "literal-cycle"))
    return entries


def parse_entry(text: str) -> tuple[str, list[str], str]:
    """``LABEL=PATH[,PATH...]`` or ``LABEL=PATH[,PATH...]@GAIT``: one controller made several
    times (e.g. one policy per training seed), or ``passive``, or a controller name; a bare
    classical controller name ``NAME`` or ``NAME@GAIT`` (``lqr``) is its own label."""
    from bound_env.control import is_controller

    name, _, gait = text.partition("@")
    if "=" not in text and is_controller(name.strip()):
        # a gait file's path names the column by its stem
        g = gait.strip() if not any(c in gait for c in "/\\.") else Path(gait.strip()).stem
        label = name.strip() if not gait.strip() else f"{name.strip()} {g}"
        return label, [name.strip()], (gait.strip() or "default")
    if "=" not in text:
        raise ValueError(f"--entry {text!r} must look like LABEL=PATH[,PATH...][@GAIT]")
    label, rest = text.split("=", 1)
    paths, _, gait = rest.rpartition("@") if "@" in rest else (rest, "", "")
    policies = [p.strip() for p in paths.split(",") if p.strip()]
    if not label.strip() or not policies:
        raise ValueError(f"--entry {text!r} needs a label and at least one policy")
    return label.strip(), policies, (gait.strip() or "default")


def check_entries(entries) -> None:
    """ValueError (one line, naming ``--entry``) for entries that would be written wrongly or
    not run at all, before any column is computed: a label that is not a name (`check_name`:
    no path, no ``|``), two labels that share a folder or a column name, two policies of one
    entry that share a folder, and a policy or gait that does not load (`load_controller`,
    with its checks, as `compute_margins` loads it)."""
    from bound_env.cli_args import check_name, name_key

    from .margins import as_controller

    seen: dict[str, str] = {}
    for label, policies, _gait in entries:
        check_name(label, "--entry", spaces=True)
        key = name_key(label)
        if key in seen:
            raise ValueError(
                f"--entry {label!r}: the column {seen[key]!r} has the same name or folder "
                f"({key}); give each column its own label"
            )
        seen[key] = label
        subs: dict[str, str] = {}
        for policy in policies:
            sub = name_key(_slug(Path(policy).name))
            if len(policies) > 1 and sub in subs:
                raise ValueError(
                    f"--entry {label!r}: policies {subs[sub]} and {policy} would share the "
                    f"folder {sub}; give folders of different names"
                )
            subs[sub] = policy
    for label, policies, gait in entries:  # the names first (cheap), then the loads
        for policy in policies:
            try:
                as_controller(policy, gait)  # as compute_margins loads it
            except (ValueError, FileNotFoundError, OSError) as e:
                raise ValueError(f"--entry {label!r}: {e}") from None


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


def compare(
    entries=None,
    budget: str = "full",
    workers: int = 2,
    out: str | Path = DEFAULT_OUT,
    docs: str | Path = DEFAULT_DOCS,
    progress: bool = True,
    executor=None,
    note: str = "",
    scheduler: str | None = None,
    seed: int = DEFAULT_SEED,
    render_only: bool = False,
) -> Path:
    """Compute (or reuse) every entry's margins and write ``docs/MARGINS.md``; returns its path.

    ``render_only`` computes nothing: it reads each column's ``margins.json`` under ``out``
    (as an earlier run of the same budget and seed left it; `load_result`) and rewrites the
    page, its plots, ``paired.json`` and ``headline.json`` from them (seconds), e.g. after a
    change of the page's text or styles, which changes the margins' cache key.

    ``seed`` picks the random samples of every column
    (`bound_env.analysis.margins.sample_seeds`): the default is the test set; another seed's
    results go under ``out/seed-<seed>/``. The paired comparisons go to ``paired.json`` beside
    the page.

    An entry is (label, policies, gait); an old-style (label, policy, gait) is accepted. Each
    policy of an entry is one seed of the same recipe: the page reports per measure the mean
    and a 95 % Student-t interval over them, and every seed's value in a collapsible detail.
    One executor (``executor``, else `bound_env.parallel.open_pool` of ``scheduler`` and
    ``workers``) serves every entry.
    """
    entries = [
        (lab, [pol] if isinstance(pol, str) else list(pol), gait)
        for lab, pol, gait in (entries or default_entries())
    ]
    seed = check_seed(seed)
    check_entries(entries)  # every column before the first is computed
    out, docs = Path(out), Path(docs)
    if seed != DEFAULT_SEED:
        out = out / f"seed-{seed}"
    docs.mkdir(parents=True, exist_ok=True)
    groups = []
    with contextlib.ExitStack() as stack:
        if executor is None and not render_only:
            executor = stack.enter_context(open_pool(scheduler, workers)).executor
        for label, policies, gait in entries:
            runs = []
            for policy in policies:
                sub = (
                    out / _slug(label)
                    if len(policies) == 1
                    else out / _slug(label) / _slug(Path(policy).name)
                )
                if render_only:
                    r = load_result(sub / "margins.json", budget, seed)
                else:
                    r = compute_margins(
                        policy,
                        budget=budget,
                        gait=gait,
                        workers=workers,
                        executor=executor,
                        out=sub,
                        progress=progress,
                        seed=seed,
                    )
                r["label"] = label
                r["source"] = policy
                runs.append(r)
            groups.append({"label": label, "gait": gait, "policies": policies, "runs": runs})
    firsts = [g["runs"][0] for g in groups]
    plots = plot_margins(firsts, docs, prefix="margins_", styles=COLUMN_STYLES)
    curves = []
    for g in groups:
        src = Path(g["policies"][0]) / "eval.png"
        if src.is_file():
            dst = docs / f"training_{g['label'].replace(' ', '_')}.png"
            shutil.copyfile(src, dst)
            curves.append((g["label"], g["policies"][0], dst))
    pairs = paired_comparisons(groups)
    head = headline_numbers(groups, budget, seed)
    path = docs / "MARGINS.md"
    from .decisions import decisions_text, fair_decision_times
    from .policy import load_controller

    old = path.with_name("paired.json")
    if render_only and old.is_file():  # measured by the run that computed the columns
        times = json.loads(old.read_text()).get("decision_times")
    else:
        times = fair_decision_times(groups, load_controller, seed)  # the workers are done
    page = render_markdown(groups, plots, curves, budget, note, pairs, basin_maps(docs), head)
    page += decisions_text(times, groups)
    body = {"budget": budget, "seed": seed, "pairs": pairs, "decision_times": times}
    atomic_write(path.with_name("paired.json"), json.dumps(body, indent=2) + "\n")
    atomic_write(path.with_name(HEADLINE_FILE), json.dumps(head, indent=2) + "\n")
    atomic_write(path, page)
    return path


def load_result(path: Path, budget: str, seed: int) -> dict:
    """A column's ``margins.json`` as `compute_margins` wrote it, for ``render_only``: it must
    exist and be of ``budget`` and ``seed`` (else a ValueError naming the file)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no margins.json to render (run compare without --render-only)")
    try:
        r = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a margins result ({e})") from None
    if not isinstance(r, dict) or "basin_curve" not in r:
        raise ValueError(f"{path}: not a margins result (no basin_curve)")
    if r.get("budget") != budget or r.get("seed", DEFAULT_SEED) != seed:
        raise ValueError(
            f"{path}: budget {r.get('budget')!r}, seed {r.get('seed')!r}; "
            f"the page asks for budget {budget!r}, seed {seed}"
        )
    return r


def mfpt_sigma_100_interval(r: dict) -> list:
    """The Poisson-based interval of one run's ``mfpt_sigma_100_deg``: where the lower and the
    upper ends of the MFPT's exact Poisson intervals cross 100 strides (log-log interpolated,
    as the estimate; an unbounded upper end counts as above). The analogue of r50's
    Wilson-based interval: the sampling error of the robots' runs. None where a bound does not
    cross on the grid."""
    from bound_env.analysis.margins.budget import MFPT_LEVEL
    from bound_env.analysis.margins.stats import mfpt_crossing

    m = r.get("mfpt") or []
    if not m:
        return [None, None]
    sig = [e["sigma_deg"] for e in m]
    lo = [e["ci"][0] for e in m]
    hi = [math.inf if e["ci"][1] is None else e["ci"][1] for e in m]
    # an infinite upper end is "above" for mfpt_crossing only as a huge finite number
    hi = [1e300 if math.isinf(v) else v for v in hi]
    no = [False] * len(m)
    return [mfpt_crossing(sig, lo, no, MFPT_LEVEL), mfpt_crossing(sig, hi, no, MFPT_LEVEL)]


def _headline_measure(runs, fn, single_interval, single_method) -> dict:
    vals = [_value(fn, r) for r in runs]
    if len(runs) > 1:
        ti = t_interval(vals)
        return {
            "value": ti["mean"],
            "low": ti["low"],
            "high": ti["high"],
            "interval": f"Student-t over {ti['n']} seeds",
            "per_seed": vals,
        }
    lo, hi = single_interval(runs[0])
    return {"value": vals[0], "low": lo, "high": hi, "interval": single_method}


def headline_numbers(groups, budget: str, seed: int) -> dict:
    """The headline (`HEADLINE`): per row present among the default-gait columns, r50 and the
    sigma at which the MFPT falls to 100 strides, each with its 95 % interval (Student-t over
    seeds; one run: Wilson-based for r50, Poisson-based for the sigma). What docs/headline.json
    holds and `headline_table` renders."""
    rows = []
    for role, label, what in HEADLINE:
        g = next((g for g in groups if g["label"] == label and g["gait"] == "default"), None)
        if g is None:
            continue
        runs = g["runs"]
        rows.append(
            {
                "role": role,
                "label": label,
                "what": what,
                "policies": [_rel(p) for p in g["policies"]],
                "r50": _headline_measure(
                    runs,
                    lambda r: r["basin_curve"]["r50"],
                    lambda r: r["basin_curve"].get("r50_ci", [None, None]),
                    "Wilson-based (the directions' sampling error)",
                ),
                "mfpt_sigma_100_deg": _headline_measure(
                    runs,
                    lambda r: r.get("mfpt_sigma_100_deg"),
                    mfpt_sigma_100_interval,
                    "Poisson-based (the robots' sampling error)",
                ),
            }
        )
    return {"budget": budget, "seed": seed, "rows": rows}


def _num3(v) -> str:
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.3g}"


def headline_table(head: dict) -> str:
    """The headline table in Markdown (five columns; one row per `HEADLINE` row present), from
    the numbers `headline_numbers` made (docs/headline.json): the page's first table and the
    README's results table are this text."""
    lines = [
        "| controller | what it is | r50 [95 % interval] | σ (deg) where MFPT = 100 "
        "strides [95 % interval] | interval |",
        "| --- | --- | --- | --- | --- |",
    ]
    for row in head["rows"]:
        cells = []
        for key in ("r50", "mfpt_sigma_100_deg"):
            m = row[key]
            cells.append(f"{_num3(m['value'])} [{_num3(m['low'])}, {_num3(m['high'])}]")
        kinds = {row["r50"]["interval"], row["mfpt_sigma_100_deg"]["interval"]}
        kind = (
            kinds.pop()
            if len(kinds) == 1
            else "r50: Wilson-based; σ: Poisson-based (one run's sampling error)"
        )
        name = row["role"] if row["role"] == row["label"] else f"{row['role']} ({row['label']})"
        lines.append(f"| **{name}** | {row['what']} | {cells[0]} | {cells[1]} | {kind} |")
    return "\n".join(lines)


def _trained(g) -> bool:
    return all((Path(p) / "run.json").is_file() for p in g["policies"])


def _reference(groups, name: str, gait: str):
    """The column of controller ``name`` (its label or its only policy) on ``gait``."""
    for g in groups:
        if g["gait"] == gait and (g["label"] == name or g["policies"] == [name]):
            return g
    return None


def paired_comparisons(groups, n_boot: int = 2000) -> list[dict]:
    """Each column against the ``lqr`` column of its gait, and each trained column against the
    ``mpc`` column of its gait if there is one, on the same random directions: per size the
    difference of the success rates with McNemar's exact test (a sign test on the directions
    where the two differ; several seeds: the mean outcome over them), and Delta r50 with a
    bootstrap interval over the directions (and seeds); `bound_env.analysis.paired`. A pair
    that cannot be made (no per-direction outcomes, other directions) has a ``skipped``
    reason instead."""
    import numpy as np

    from bound_env.analysis.paired import compare_paired

    out = []
    for g in groups:
        if _reference(groups, "lqr", g["gait"]) is None:
            out.append(
                {
                    "column": g["label"],
                    "reference": "lqr",
                    "gait": g["gait"],
                    "skipped": f"no lqr column on its gait ({g['gait']})",
                }
            )
        for ref_name in ("lqr", "mpc"):
            ref = _reference(groups, ref_name, g["gait"])
            if ref is None or ref is g or (ref_name == "mpc" and not _trained(g)):
                continue
            entry = {"column": g["label"], "reference": ref["label"], "gait": g["gait"]}
            curves = [r["basin_curve"] for r in g["runs"] + ref["runs"]]
            keys = {
                (tuple(c["sizes"]), c.get("directions"), c.get("direction_seed")) for c in curves
            }
            if any(c.get("outcomes") is None for c in curves):
                entry["skipped"] = "no per-direction outcomes (results from before margins v3)"
            elif len(keys) != 1:
                entry["skipped"] = "not measured on the same directions and sizes"
            else:
                sizes, n_dirs, dseed = keys.pop()
                a = np.array([r["basin_curve"]["outcomes"] for r in g["runs"]], dtype=float)
                b = np.array([r["basin_curve"]["outcomes"] for r in ref["runs"]], dtype=float)
                entry.update(
                    {"directions": n_dirs, "direction_seed": dseed, "seeds": [len(a), len(b)]}
                )
                entry.update(compare_paired(list(sizes), a, b, n_boot=n_boot))
            out.append(entry)
    return out


def _fmt(v, digits=4) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.{digits}g}"


def _dir_label(r, key) -> str:
    return r.get(key) or "—"


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


def _value(fn, r):
    try:
        v = fn(r)
    except (KeyError, TypeError, IndexError):
        return math.nan
    return math.nan if v is None else float(v)


def _agg(values, digits) -> str:
    """One value as it is; several (seeds) as mean [95 % t interval]."""
    vals = [v for v in values if not math.isnan(v)]
    if not vals:
        return "—"
    if len(values) == 1:
        return _fmt(vals[0], digits)
    ti = t_interval(vals)
    return f"{_fmt(ti['mean'], digits)} [{_fmt(ti['low'], digits)}, {_fmt(ti['high'], digits)}]"


def _cell(g, base, name, fn, digits, ratio) -> str:
    runs = g["runs"]
    vals = [_value(fn, r) for r in runs]
    text = _agg(vals, digits)
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
        text += f" (Wilson-based [{_fmt(lo, 3)}, {_fmt(hi, 3)}])"
    elif name == "terrain_sigma50_deg" and len(runs) == 1:
        lo, hi = runs[0].get("terrain_sigma50_ci_deg", [math.nan, math.nan])
        text += f" (Wilson-based [{_fmt(lo, 3)}, {_fmt(hi, 3)}])"
    elif name == "effort" and runs[0]["policy"] == "passive":
        text = "0 (zero action)"
    if ratio and g is not base:
        b = _value(fn, base["runs"][0])
        ratios = [v / b if b and not math.isnan(v) else math.nan for v in vals]
        if not all(math.isnan(x) for x in ratios):
            text += f", **{_agg(ratios, 3)}×**"
    return text


def _basin_cell(runs, label, sym, key, field="rel", digits=3) -> str:
    vals = [r[key][label][sym][field] if r[key].get(label, {}).get(sym) else math.nan for r in runs]
    vals = [math.nan if v is None else float(v) for v in vals]
    text = _agg(vals, digits)
    capped = sum(
        bool(r[key][label][sym].get("capped")) for r in runs if r[key].get(label, {}).get(sym)
    )
    if capped:
        text = ("≥" if capped == len(runs) else f"({capped}/{len(runs)} capped) ") + text
    return text


def _provenance(g) -> list[str]:
    """How each controller of a column was made."""
    lines = []
    for policy in g["policies"]:
        if policy == "passive":
            lines.append("zero spine torque (no controller)")
            continue
        p = Path(policy)
        info_path = p / "run.json"
        if not info_path.is_file():
            from .policy import CONTROLLERS

            what = CONTROLLERS.get(policy, (None, None))[1]
            spec = ROOT / "configs" / "controllers" / f"{policy}.yaml"
            lines.append(
                f"controller `{policy}`"
                + (f": {what}" if what else "")
                + (f"; spec `{_rel(str(spec))}`" if spec.is_file() else "")
                + "; designed, not trained: no seeds; "
                + CLASSICAL_SELECTION.get(
                    policy, "whether its spec was tuned on these yardsticks is not recorded here"
                )
            )
            continue
        info = json.loads(info_path.read_text())
        t = info.get("wall_time_s")
        exp_path = p / "exported.json"
        exp = json.loads(exp_path.read_text()) if exp_path.is_file() else {}
        if "timesteps" in exp:
            sel = (
                f"**selected**: the checkpoint with the best basin validation at "
                f"{exp['timesteps']} timesteps"
            )
        else:
            sel = "final model, **no selection**"
        made = info.get("timesteps_done", "?")
        made = made if isinstance(made, str) else f"{made} timesteps"  # or said in words
        lines.append(
            f"`{_rel(policy)}`: seed {info.get('seed', '?')}, {made}, "
            f"{'%.1f min' % (t / 60) if t else '?'} of training on "
            f"{info.get('machine', '?')}; {sel}; command `{_command(info.get('command', '?'))}`"
            + (f" ({info['note']})" if info.get("note") else "")
        )
    group = Path(g["policies"][0]).parent.name if g["policies"] else ""
    if group in LEARNED_SELECTION:
        lines.append(LEARNED_SELECTION[group])
    return lines


def _pvals(ps) -> str:
    return ", ".join(f"{p:.2g}" for p in ps) or "—"


def paired_text(pairs) -> str:
    """The paired comparisons in words and as a table (see `paired_comparisons`)."""
    if not pairs:
        return "(no lqr column to compare against)"
    words, rows, details = [], [], []
    for e in pairs:
        name = f"**{e['column']}** vs {e['reference']}"
        if "skipped" in e:
            words.append(f"- {name}: not compared ({e['skipped']}).")
            continue
        d = e["delta_r50"]
        around = ", ".join(f"{r:g}" for r in e["around_r50"])
        ci_zero = d["low"] <= 0 <= d["high"]
        small_p = [p for p in e["p_around_r50"] if p < e["alpha"]]
        if e["stands_out"]:
            verdict = (
                f"**stands out of the noise** ({'better' if d['delta'] > 0 else 'worse'}): "
                f"the interval of Δr50 excludes 0 and McNemar's p < {e['alpha']:g} at "
                f"r = {around}"
            )
        else:
            why = []
            if ci_zero:
                why.append("the interval of Δr50 contains 0")
            if not small_p:
                why.append(f"McNemar's p ≥ {e['alpha']:g} at r = {around}")
            elif not ci_zero:
                why.append("the per-size tests disagree in sign with Δr50")
            verdict = "within the noise (" + "; ".join(why) + ")"
        words.append(
            f"- {name}: Δr50 = {d['delta']:+.3g} [{d['low']:+.3g}, {d['high']:+.3g}]; {verdict}."
        )
        near = [c for c in e["curve"] if c["size"] in e["around_r50"]]
        rows.append(
            f"| {e['column']} | {e['reference']} | {d['delta']:+.3g} "
            f"[{d['low']:+.3g}, {d['high']:+.3g}] ({d['resampled']}) | "
            + "; ".join(
                f"r = {c['size']:g}: {c['delta']:+.3f} ({c['n_better']}/{c['n_worse']}, "
                f"p = {c['p']:.2g})"
                for c in near
            )
            + f" | {'**yes**' if e['stands_out'] else 'no'} |"
        )
        drows = [
            f"| {c['size']:g} | {c['success']:.3f} | {c['success_ref']:.3f} | "
            f"{c['delta']:+.3f} | {c['n_better']} | {c['n_worse']} | {c['p']:.2g} |"
            for c in e["curve"]
        ]
        details.append(
            f"<details><summary>per size: {e['column']} vs {e['reference']}</summary>\n\n"
            "| r | P(return) | P(return), reference | Δ | directions better | "
            "directions worse | McNemar p |\n| --- | --- | --- | --- | --- | --- | --- |\n"
            + "\n".join(drows)
            + "\n\n</details>"
        )
    table = "\n".join(
        [
            "| column | reference | Δr50 [95 % bootstrap] | around the reference's r50: Δ "
            "P(return) (directions better/worse, McNemar p) | stands out |",
            "| --- | --- | --- | --- | --- |",
            *rows,
        ]
    )
    return "\n".join(words) + "\n\n" + table + "\n\n" + "\n\n".join(details)


# Basin maps the page shows when they are in its folder (`bound-env basin-map --png
# DIR/basin_<name>_<slice>.png`; docs/analysis.md, "Basin maps", has the commands)
BASIN_MAPS = ("passive", "lqr", "mpc", "default")
BASIN_SLICES = (("xdot_y", "ẋ_g × y_g"), ("th1_th1dot", "θ1 × θ̇1"))


def basin_maps(docs: Path) -> str:
    """Markdown of the basin-map PNGs present in ``docs`` (empty if none)."""
    rows = []
    for key, title in BASIN_SLICES:
        cells = [
            f"![{name}, {title}](basin_{name}_{key}.png)"
            for name in BASIN_MAPS
            if (Path(docs) / f"basin_{name}_{key}.png").is_file()
        ]
        if cells:
            rows.append(
                f"**{title}** ({', '.join(BASIN_MAPS)}, where made):\n\n" + "\n".join(cells)
            )
    return "\n\n".join(rows)


def render_markdown(
    groups, plots, curves, budget, note: str = "", pairs=None, maps: str = "", head=None
) -> str:
    from bound_env.analysis.margins import BUDGETS

    if head is None:
        r0 = groups[0]["runs"][0]
        head = headline_numbers(groups, budget, r0.get("seed", DEFAULT_SEED))
    headline = headline_table(head) if head["rows"] else "(none of the headline's columns)"

    labels = [g["label"] for g in groups]
    base = groups[0]
    trained = _trained

    head = (
        "| measure | "
        + " | ".join(
            f"{g['label']} ({len(g['runs'])} seed{'s' if len(g['runs']) > 1 else ''})"
            if trained(g)
            else g["label"]
            for g in groups
        )
        + " |"
    )
    sep = "| --- |" + " --- |" * len(groups)
    rows = ["| gait | " + " | ".join(f"`{g['gait']}`" for g in groups) + " |"]
    for name, title, fn, digits, ratio in MEASURES:
        rows.append(
            f"| {title} | "
            + " | ".join(_cell(g, base, name, fn, digits, ratio) for g in groups)
            + " |"
        )
    main = "\n".join([head, sep, *rows])

    def direction_table(key, field="rel", digits=3, unit=True):
        bhead = "| direction | " + " | ".join(labels) + " |"
        brows = []
        for c in Z_LABELS:
            for sym in ("+", "-"):
                cells = [_basin_cell(g["runs"], c, sym, key, field, digits) for g in groups]
                brows.append(f"| {c}{sym} | " + " | ".join(cells) + " |")
        return "\n".join([bhead, sep.replace("| --- |", "| --- |", 1), *brows])

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
                    f"| {g['label']} | {c}{sym} | {_fmt(e['rel'], 3)} | "
                    f"{'yes' if e.get('geometric') else 'no'} | {e.get('mechanism') or '—'} | "
                    f"{_fmt(bey.get('rel'), 3)} |"
                )
    mech = "\n".join(
        [
            "| column (first seed) | direction | ceiling (zstar) | geometric | "
            "what stops it | first failing size |",
            "| --- | --- | --- | --- | --- | --- |",
            *mech_rows,
        ]
    )

    fail_rows = []
    for g in groups:
        r = g["runs"][0]
        for c in Z_LABELS:
            for sym in ("+", "-"):
                bey = r["basin"][c][sym].get("beyond") or {}
                if not bey:
                    continue
                fail_rows.append(
                    f"| {g['label']} | {c}{sym} | {_fmt(bey.get('rel'), 3)} | "
                    f"{bey.get('reason')} | {bey.get('stride')} | {bey.get('phase') or '—'} | "
                    f"{'; '.join(bey.get('mechanisms') or []) or '—'} |"
                )
    fails = "\n".join(
        [
            "| column (first seed) | direction | size | failure | stride | phase | "
            "start geometry |",
            "| --- | --- | --- | --- | --- | --- | --- |",
            *fail_rows,
        ]
    )

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
                f"| {name} | " + " | ".join(_fmt(_value(fn, r), digits) for r in g["runs"]) + " |"
            )
        drows.append(
            "| basin_min direction | "
            + " | ".join(_dir_label(r, "basin_min_direction") for r in g["runs"])
            + " |"
        )
        details.append(
            f"<details><summary>per-seed values: {g['label']}</summary>\n\n"
            + "\n".join([dh, ds, *drows])
            + "\n\n</details>"
        )

    prov = []
    for g in groups:
        prov.append(f"- **{g['label']}** (gait `{g['gait']}`):")
        prov += [f"  - {line}" for line in _provenance(g)]

    train_lines = [
        f"- **{label}** (`{_rel(policy)}`)\n\n  ![training curve {label}]({png.name})"
        for label, policy, png in curves
    ]
    settings = base["runs"][0]["settings"]
    b = BUDGETS.get(budget)
    full = BUDGETS["full"]
    if budget == "full":
        budget_note = "the **full** budget"
    elif b is None:
        budget_note = f"the `{budget}` budget"
    else:
        diffs = []
        for field, what in (
            ("curve_dirs", "random directions"),
            ("curve_sizes", "curve sizes"),
            ("basin_strides", "strides to return"),
            ("basin_iters", "basin bisection steps"),
            ("push_samples", "push samples per size"),
            ("terrain_sigmas", "rough-terrain levels"),
            ("terrain_runs", "rough-terrain runs per level"),
            ("terrain_strides", "rough-terrain strides"),
            ("ceiling_random", "random ceiling profiles"),
            ("ceiling_opt", "ceiling optimizer iterations"),
            ("mfpt_sigmas", "MFPT levels"),
            ("mfpt_robots", "MFPT robots per level"),
            ("mfpt_strides", "MFPT horizon [strides]"),
        ):
            mine, theirs = getattr(b, field), getattr(full, field)
            if mine != theirs:
                n = len(mine) if isinstance(mine, tuple) else mine
                m = len(theirs) if isinstance(theirs, tuple) else theirs
                diffs.append(f"{n} {what} instead of {m}")
        budget_note = f"the **{budget}** budget, NOT the full one (" + "; ".join(diffs) + ")"
    terrain = base["runs"][0].get("terrain", {})
    ceil = settings.get("ceiling", {})
    r0 = base["runs"][0]
    para_note = ("\n\n" + note + "\n") if note else ""
    seed = r0.get("seed", DEFAULT_SEED)
    seed_note = (
        f"seed {seed}, the **test set**"
        if seed == DEFAULT_SEED
        else f"seed {seed}, a **held-out validation set** (the test set is seed {DEFAULT_SEED})"
    )
    mset = r0.get("mfpt_settings") or {}
    pairs_md = paired_text(pairs or [])
    return f"""# Stability margins: passive, classical and learned spine control

Generated by `bound-env compare --budget {budget} --seed {seed}` (agents/compare.py) with
{budget_note}; random samples of {seed_note}; do not edit by hand.{para_note}

## Headline

{headline}

r50: the perturbation size (units of |z*_i|, a random direction) from which half the starts
return to the cycle; σ: the rough terrain's slope noise at which the mean first-passage time
falls to 100 strides. Larger is better for both. Numbers in `{HEADLINE_FILE}` beside this page;
every column, every measure and how each was made follow.

**Reproducibility.** Every number reproduces bit for bit on one machine (the same build of
NumPy and Numba, the same Numba cache state), and across machines to its statistical
precision: the controllers' own round-off differs from one CPU to another, `mpc` seeds its
random candidates with the bytes of z, and rough terrain is chaotic, so a start near a basin
edge can go either way. Measured: on another 2-core machine, from an empty cache, an earlier
version of this page's code gave for `mpc` r50 0.294, σ50 0.757° and the MFPT's σ 0.791°
(that version's page on this machine: 0.289, 0.697° and 0.802°), and for `default` r50
0.2636 and 0.777° (that page: 0.264 and 0.774°).

## All columns

**Names.** The random-direction success curve P(return | r) is a **basin stability**
estimate (Menck et al. 2013: the probability that a random perturbation of size r returns to
the cycle; JSON `basin_curve`, its 1/2 crossing `r50`). The per-axis basin is a **minimal
fatal shock** along each axis (the smallest perturbation of one apex component, each sign,
that no longer returns; JSON `basin`, `basin_min`). On rough terrain, the **mean
first-passage time** (MFPT, Byl & Tedrake 2009, "Metastable walking machines") is the
expected number of strides before a fall (JSON `mfpt`, `mfpt_sigma_100_deg`); σ50 (JSON
`terrain_sigma50_deg`) is the older survival-over-a-fixed-horizon yardstick.

Every column is measured on the same yardsticks by `bound-env margins` (bound_env/analysis/margins):
the closed-loop apex-to-apex map, each stride an episode started at an apex with
`reset(options={{"apex_state": z}})` so the control intervals restart at the apex,
integrator tolerance {settings["rtol"]:g}, "returned" = max-abs apex error below
{settings["return_tol"]:g} (SI) within {settings["basin_strides"]} strides.

**Statistics.** Three different intervals, for three different questions. A column with
several seeds shows the **mean [95 % Student-t interval] over its seeds**: the
*seed-to-seed spread* of the training recipe (t with n − 1 degrees of freedom; with 3 seeds
it is wide), which does not include the sampling error of the directions, since every seed
is scored on the same ones; the per-seed values are in the collapsible details below the
table. A single-seed or passive column shows its value; for r50 and σ50 it adds the
*Wilson-based* interval: the crossing of the 95 % Wilson bounds of the success rates, the
*sampling error of the random directions (or terrain runs)* of one run. Neither says whether
two columns differ: they share the same directions, so the comparison is **paired** (next
section). Ratios (×) are each seed's value over the default-gait passive value, averaged the
same way. No column was selected on these yardsticks unless its provenance below says so.

{main}

{chr(10).join(details)}

## Paired differences (the same directions)

Each column against `lqr` (and a trained column against `mpc`, when there is one), on the same
random directions. Per size r, the difference of P(return) and McNemar's exact test: a
two-sided sign test on the directions where the two differ (`scipy.stats.binomtest`; a
column with several seeds contributes, per direction, the mean of its seeds' outcomes). Δr50
with a 95 % percentile bootstrap interval (2000 resamples of the directions, the same draw for
both columns, and of the seeds). A difference **stands out of the noise** when the interval of
Δr50 excludes 0 *and* McNemar's p < 0.05 at a grid size around the reference's r50, with the
same sign. Numbers in `paired.json` beside this page (`bound_env/analysis/paired.py`).

{pairs_md}

## How each column was made

{chr(10).join(prov)}

## The yardsticks

- **Basin, uncapped** (a minimal fatal shock per axis). Along each apex component and
  sign, the largest s such that the loop
  started at z_cl + s z*_i e_i returns (z* the passive fixed point, the same absolute sizes
  for every column). s = 1e-3 and 1 are tried first; while the loop returns, the bracket
  doubles from the last success up to the direction's physical cap (the size at which the
  start state itself is invalid: a hip or the spine joint in the ground, or ẋ ≤ 0; else
  {settings.get("basin_cap", 64):g} |z*_i|), then bisection on log s ({settings["basin_iters"]}
  steps). ≥ marks an edge at the cap.
- **Two scales.** `zstar`: units of |z*_i| (the paper-style scale; basin_min keeps this
  meaning, now uncapped). `cycle`: units of the component's peak-to-peak range over one
  passive stride (y_g 0.032 m, θ1 0.59 rad, θ2 0.20 rad, ẋ_g 0.42 m/s, θ̇1 9.5 rad/s, θ̇2
  6.4 rad/s on the default gait), so that a step in θ1 means as much as a step in ẋ_g.
- **Ceiling.** For each direction, the largest perturbation from which *some* admissible
  open-loop torque profile (|τ| ≤ the column's max_torque, piecewise constant over
  {ceil.get("piece_intervals", "?")} control intervals) completes the first
  {ceil.get("strides", "?")} strides without a fall. At each tested size the search tries
  the zero profile, ±max, bang-bang profiles with one switch, {ceil.get("random_profiles", "?")}
  random piecewise-constant profiles and {ceil.get("optimizer_iters", "?")} iterations of a
  (1+1) evolution-strategy shooting optimizer from the best; sizes are grown and bisected
  like the basin ({ceil.get("iters", "?")} steps). A search finds profiles, it cannot prove
  there is none: the ceiling is a lower bound, and a share slightly above 1 means the
  controller's edge lies within the bisection's resolution of it. basin_share = basin /
  ceiling.
- **Random directions** (basin stability). {base["runs"][0]["basin_curve"]["directions"]}
  directions (seed {base["runs"][0]["basin_curve"].get("direction_seed", "?")}) uniform on the
  sphere, scaled to max
  |u_i| = 1, sizes in the zstar scale; 95 % Wilson intervals per point. r50 is where P(return)
  first falls below 0.5, interpolated linearly in log r between the two sizes around the
  crossing (the JSON keeps the grid value as `r50_grid`).
- **Rough terrain.** The slope becomes α_k = α + σ ξ_k at every apex (ξ_k standard normal
  from the env's RNG; `slope_noise_deg`), the ground tilting under the robot in flight about
  the point below its centre of mass (`bound_env/terrain.py`). σ50 = the σ at which the
  fraction of {terrain.get("runs", "?")} runs (env seeds {terrain.get("seeds", ["?"])[0]}…) that
  survive {terrain.get("strides", "?")} strides first falls below one half (log-interpolated
  like r50; the JSON keeps the largest grid σ with survival ≥ 1/2 as
  `terrain_sigma50_grid_deg`).
- **MFPT.** At each σ of {_fmt_list(mset.get("sigmas_deg"))}°, {mset.get("robots", "?")}
  robots (env seeds {(mset.get("seeds") or ["?"])[0]}…) run from the cycle for up to
  {mset.get("horizon", "?")} strides each, batched. With a constant per-stride hazard, the
  maximum-likelihood hazard is falls / strides (strides attempted, runs censored at the
  horizon), so MFPT = strides / falls; with no fall only a lower bound (the strides run)
  exists, drawn as ▲ and flagged `lower_bound` in the JSON; bars: exact Poisson 95 %
  intervals. The MFPT = 100 σ is log-log interpolated between the grid points around it
  (none if the curve does not cross 100 on the grid).

Windows: the connected range around the nominal value (α = {r0["slope_nominal_deg"]:.4f}°,
k_c = {r0["kc_nominal"]:g} N m/rad) in which the loop started at z_cl survives 50
strides. The paper's passive windows (1.92–2.05°, 294–308 N m/rad) come from its own
criterion (a stable fixed point that the gait converges to); survival for 50 strides is a
looser test. Push: a kick of the given size, random sign, at a random control instant of a
cycle stride; p50 = the largest size up to which at least half of the
{settings["push_samples"]} trials return.

## Basin along each apex component (zstar scale)

{direction_table("basin")}

## Basin in the cycle scale

{direction_table("basin", "rel_cycle")}

## Ceilings and each controller's share of them

Ceiling (zstar scale) per direction:

{direction_table("basin_ceiling")}

Basin / ceiling:

{direction_table("basin", "share")}

What stops the ceiling (first seed of each column):

{mech}

## Where the loop fails beyond each basin edge

The first failing perturbation found beyond each edge (first seed of each column): the failure
reason (`no_return`: no fall, but not back within the stride limit), the stride (1 = the
first) and the stance phase in which it happened, and what the start state itself rules out.

{fails}

![basin per direction](margins_basin.png)

![success probability against the size of a random-direction perturbation](margins_curve.png)

![survival on rough terrain](margins_terrain.png)

![mean first-passage time on rough terrain](margins_mfpt.png)

![push recovery](margins_push.png)

## Basin maps

Slices through z* (64 × 64 starts, 100 strides; `bound-env basin-map`; `default` is the
fine-tuned seed 0), each outlining the passive basin in red; the right panel of each says why
the falls fell.

{maps or "(no basin maps in this folder)"}

## Training curves

{chr(10).join(train_lines) if train_lines else "(no trained policy)"}

The literal reading of Table II (`PassiveBoundLiteral-v0`, section of `configs/ppo.yaml`):
its published apex state falls within the first stride, so its task starts on the literal
reading's own periodic gait at the published parameters (`configs/gaits/literal-cycle.yaml`),
a saddle with e_max 1.364: its passive basin is empty. The literal columns' ratios are
against the default gait's passive column, since the literal passive values are zero.
"""


def _fmt_list(values) -> str:
    return ", ".join(f"{v:g}" for v in values) if values else "?"


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
    from bound_env.analysis.margins import Z_UNITS

    return Z_UNITS[Z_LABELS.index(direction[:-1])]
