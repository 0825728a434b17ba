"""Passive vs learned margins side by side: ``docs/MARGINS.md`` (``bound-env compare``).

Runs `agents.results.margins.compute_margins` (the front of `bound_env.analysis.margins`) for the
passive gait and for each shipped policy (results cached under ``out/margins/<label>/``, so a
second run only rewrites the page), then writes the table and the plots
(``docs/margins_*.png``) and copies each policy's training curve.

Every column is scored on the same random samples (``--seed``), so two columns are compared
*paired* (`paired_comparisons`, `bound_env.analysis.paired`): each column against the
``lqr`` column (and a trained column against an ``mpc`` column, when there is one) on the
same directions, with McNemar's exact test per size and a bootstrap interval of Delta r50;
the page says which differences stand out of the noise, and ``paired.json`` beside the page
holds the numbers.

The page is written by `agents.results.page` (its tables: `agents.results.page_tables`; each
column's provenance: `agents.results.provenance`; its first table: `agents.results.headline`; the
paired comparisons in words: `bound_env.analysis.paired_text`); this module chooses the columns
(entries), runs them and writes the page and its JSON. The names those modules define are importable
from here too.
"""

from __future__ import annotations

import contextlib
import json
import shutil
from pathlib import Path

from bound_env.analysis.margins import DEFAULT_SEED, check_seed, plot_margins
from bound_env.analysis.paired_text import paired_text as paired_text
from bound_env.commands.cli_args import strict_json
from bound_env.files.cache import atomic_write
from bound_env.files.schema import load_json_strict
from bound_env.sim.parallel import open_pool

from ..runtime.policy import SHIPPED_DIR

# `X as X`: re-exported, the names the page's modules define stay importable from here
from .formatting import ROOT, rel, slug
from .headline import (
    COLUMNS_FILE,
    HEADLINE_FILE,
    MODEL_ERROR_FILE,
    PageProgress,
    add_held,
    columns_json,
    headline_numbers,
    held_at,
    model_error_json,
    run_record,
    time_rows,
)
from .headline import HEADLINE as HEADLINE
from .headline import headline_table as headline_table
from .headline import mfpt_sigma_100_interval as mfpt_sigma_100_interval
from .margins import compute_margins
from .page import BASIN_MAPS as BASIN_MAPS
from .page import BASIN_SLICES as BASIN_SLICES
from .page import COLUMN_STYLES, basin_maps, model_error_section, render_markdown
from .page_inputs import load_model_error, read_decision_times
from .page_inputs import load_result as load_result
from .page_tables import MEASURES as MEASURES
from .provenance import CLASSICAL_SELECTION as CLASSICAL_SELECTION
from .provenance import LEARNED_SELECTION as LEARNED_SELECTION
from .provenance import provenance as _provenance  # noqa: F401 (tests/test_margins_v3.py)
from .provenance import provenance as provenance
from .provenance import trained as _trained

POLICIES_DIR = SHIPPED_DIR
DEFAULT_DOCS = ROOT / "docs"
DEFAULT_OUT = Path("out") / "margins"
# The page's classical columns (configs/controllers/; `damping`, the trivial baseline, is a
# name still: add it with --entry damping)
CLASSICAL = ("lqr", "deadbeat", "mpc")

# Learned columns with one folder per training seed, shipped in agents/policies/<group>/s<k>:
# the page's (SEED_GROUPS), and the archived ones a user can add with --entry (EXTRA_GROUPS,
# in agents/policies/archive/: agents.runtime.policy_table.ARCHIVED says why each left the page)
SEED_GROUPS = (
    # agents/experts/finetune.py: PPO from the distilled (`default`: s0)
    ("fine-tuned", "finetuned"),
    ("step-ppo", "step-ppo"),  # agents/runtime/residual.py: step-level residual PPO over `default`
    ("ppo-v1", "ppo-v1-final"),  # plain PPO: ppo-v1's recipe (step-level PPO), final models
)
EXTRA_GROUPS = (
    # agents/experts/distill.py: DAgger from mpc, before fine-tuning
    ("distilled", "archive/distilled"),
    # agents/runtime/stride.py: PPO residual on the LQR
    ("stride-residual", "archive/stride-residual"),
    ("warm-started", "archive/warm-started"),  # step-level PPO cloned from `default` first
)


def seed_group(group: str) -> list[str]:
    """The shipped seed folders of a group (``agents/policies/<group>/s*``)."""
    return [str(p) for p in sorted((POLICIES_DIR / group).glob("s*")) if p.is_dir()]


def default_entries() -> list[tuple[str, list[str], str]]:
    """(label, policies, gait) for the passive gait and every shipped policy."""
    entries = [("passive", ["passive"], "default")]
    # learned columns, one policy per seed (the name `default` is fine-tuned/s0; the archived
    # checkpoint `ppo-v1` is left out: its recipe's final-model seeds are in)
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
        from ..runtime.policy_table import archived_message

        gone = archived_message(name.strip())  # an archived name: where it went
        where = f" ({gone})" if gone else ""
        raise ValueError(f"--entry {text!r} must look like LABEL=PATH[,PATH...][@GAIT]{where}")
    label, rest = text.split("=", 1)
    paths, _, gait = rest.rpartition("@") if "@" in rest else (rest, "", "")
    policies = [p.strip() for p in paths.split(",") if p.strip()]
    if not label.strip() or not policies:
        raise ValueError(f"--entry {text!r} needs a label and at least one policy")
    return label.strip(), policies, (gait.strip() or "default")


def chosen_entries(parsed, keep_defaults: bool = False) -> list[tuple[str, list[str], str]]:
    """The columns of ``compare --entry ...``: the default passive column (unless an entry is
    the default-gait passive) and the ``parsed`` entries; with ``keep_defaults`` every default
    column (`default_entries`) stays, and an entry of the same label (or folder) replaces the
    default column of that name. No entries: the default columns."""
    from bound_env.files.values import name_key

    defaults = default_entries()
    if not parsed:
        return defaults
    mine = {name_key(e[0]) for e in parsed}
    if keep_defaults:
        kept = [e for e in defaults if name_key(e[0]) not in mine]
    elif any(e[1] == ["passive"] and e[2] == "default" for e in parsed):
        kept = []
    else:
        kept = [defaults[0]]
    return kept + list(parsed)


def check_entries(entries) -> None:
    """ValueError (one line, naming ``--entry``) for entries that would be written wrongly or
    not run at all, before any column is computed: a label that is not a name (`check_name`:
    no path, no ``|``), two labels that share a folder or a column name, two policies of one
    entry that share a folder, and a policy or gait that does not load (`load_controller`,
    with its checks, as `compute_margins` loads it)."""
    from bound_env.files.values import check_name, name_key

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


_slug = slug  # a label's or a policy's folder name under ``out``


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
    mismatch=None,
    command: str = "",
    model_error: bool = False,
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
    One executor (``executor``, else `bound_env.sim.parallel.open_pool` of ``scheduler`` and
    ``workers``) serves every entry.

    ``mismatch`` (specs of `bound_env.model.mismatch`, e.g. ``["pm5", "pm10"]``) measures every
    column under model error too, and the page gets a "Model error" section
    (`bound_env.analysis.margins.model_error.mismatch_report.mismatch_markdown`, paired against
    lqr).

    ``model_error`` (what ``bound-env compare`` asks for the page's own columns, unless
    ``--no-mismatch``; ignored with ``mismatch``): the page's "Model error" section, its own
    columns measured under model error at the model-error budget
    (`run_model_error`, `model_error_entries`), their hold at ±10 % and ±15 % in the headline.

    Beside the page go ``columns.json`` (every column's fingerprint and headline measures,
    and the run: `agents.results.headline`, ``command`` recorded there) and, with
    ``mismatch``, ``model_error.json``. The entries that are not default columns
    (`default_entries`) are the user's: they get headline rows, and the page then says
    nothing of the project's own measurements. Each trained column's training curve is
    plotted from its ``eval.csv``; a ``training_*.png`` of the folder that no column drew is
    removed.
    """
    import os
    import time

    t0, load0 = time.perf_counter(), [round(v, 2) for v in os.getloadavg()]
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
    defaults = {(lab, tuple(pols), gait) for lab, pols, gait in default_entries()}
    yours = [lab for lab, pols, gait in entries if (lab, tuple(pols), gait) not in defaults]
    groups, me_groups = [], []
    model_error = bool(model_error) and not mismatch
    me_todo = [(f"model error {lab}", [pol], "default") for lab, pol in model_error_entries()]
    if model_error and not render_only:
        check_entries(me_todo)  # the section's columns load, before the first column runs
    eta = PageProgress(
        entries + (me_todo if model_error else []),
        docs / COLUMNS_FILE,
        enabled=progress and not render_only,
    )
    with contextlib.ExitStack() as stack:
        if executor is None and not render_only:
            executor = stack.enter_context(open_pool(scheduler, workers)).executor
        for label, policies, gait in entries:
            runs = []
            for policy in policies:
                eta.start()
                sub = (
                    out / _slug(label)
                    if len(policies) == 1
                    else out / _slug(label) / _slug(Path(policy).name)
                )
                if render_only:
                    r = load_result(sub / "margins.json", budget, seed, mismatch)
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
                        mismatch=mismatch,
                    )
                r["label"] = label
                r["source"] = policy
                runs.append(r)
                eta.done(label, policy, r)
            groups.append({"label": label, "gait": gait, "policies": policies, "runs": runs})
        if model_error:  # the section's own columns, on the same executor
            me_groups = run_model_error(
                budget,
                out,
                seed,
                executor=executor,
                workers=workers,
                progress=progress,
                render_only=render_only,
                on_column=lambda lab, pol, r: eta.done(f"model error {lab}", pol, r),
            )
    old = docs / "paired.json"
    # render_only: the decision times measured by the run that computed the columns, checked
    # (one line naming the file and the key) before any figure is drawn
    times = read_decision_times(old) if render_only and old.is_file() else None
    firsts = [g["runs"][0] for g in groups]
    plots = plot_margins(firsts, docs, prefix="margins_", styles=COLUMN_STYLES)
    curves = training_curves(groups, docs)
    pairs = paired_comparisons(groups)
    head = headline_numbers(groups, budget, seed, yours)
    if me_groups:
        add_held(head, held_at(me_groups), model_error_budget(budget))
    path = docs / "MARGINS.md"
    from ..runtime.policy import load_controller
    from .decisions import decisions_text, fair_decision_times, real_time_text

    if times is None:
        times = fair_decision_times(groups, load_controller, seed)  # the workers are done
    cols_path = path.with_name(COLUMNS_FILE)
    if not render_only:
        run = run_record(t0, workers, scheduler, load0, groups + me_groups, command)
    elif cols_path.is_file():  # the run that computed the columns, not this rewrite
        run = load_json_strict(cols_path, {"run": (dict, None)})["run"]
    else:
        run = None  # not known: the columns were computed by a run that left no record
    page = render_markdown(
        groups, plots, curves, budget, note, pairs, basin_maps(docs), head, run, not yours
    )
    page += decisions_text(times, groups)
    page += real_time_text(groups, times)  # fixed-state CPU times, else its measures' wall times
    page += model_error_text(groups)  # --mismatch: every column under its specs
    page += model_error_section(me_groups)  # the page's own section
    body = {"budget": budget, "seed": seed, "pairs": pairs, "decision_times": times}
    atomic_write(path.with_name("paired.json"), json.dumps(body, indent=2) + "\n")
    # strict JSON: a measure that could not be made is null (and listed under "nonfinite")
    atomic_write(path.with_name(HEADLINE_FILE), strict_json(head, indent=2) + "\n")
    cols = columns_json(groups, budget, seed, run)
    if me_groups:  # where the section's time went, column by column
        cols["model_error"] = time_rows(me_groups)
    atomic_write(cols_path, strict_json(cols, indent=2) + "\n")
    me = model_error_json(me_groups or groups, budget, seed, run)
    if me is not None and me_groups:
        me["mismatch_budget"] = model_error_budget(budget)
    if me is not None:
        atomic_write(path.with_name(MODEL_ERROR_FILE), strict_json(me, indent=2) + "\n")
    atomic_write(path, page)
    return path


# --------------------------------------------------------------------------------------------
# The results page's model-error section (``bound-env compare``, on by default for the page's
# own columns; ``--no-mismatch`` leaves it out): which controller holds a robot that is not its
# model, beside which one has the widest basin.
#
# The section's columns (`model_error_entries`): passive, lqr, mpc, `default` (the fine-tuned
# student's first seed, the best learned column's s0), `mpc-adaptive` (the MPC that identifies
# its plant online), the learned adaptive controller (`agents/policies/adaptive/s0`, where it is
# shipped) and `mpc-privileged` (re-designed on each robot's true plant: **privileged**, an
# upper reference, never a deployable controller; the tables label it). Each is measured under
# `MODEL_ERROR_SPECS` (pm10, pm15, pm10+noise) on the model-error budget `model_error_budget`
# (``page``: hold on 32 plants for 100 strides and r50 under error on five sizes, no MFPT;
# ``test`` for ``--budget test``), the model-error measures only (`compute_margins` with
# ``nominal=False``): its nominal margins are the page's other columns. Results under
# ``<out>/model-error/<label>/``; the paired comparisons are against lqr. The section's text:
# `agents.results.page.model_error_section`; its held column in the headline and its columns'
# times: `agents.results.headline`; its inputs for ``--render-only``:
# `agents.results.page_inputs.load_model_error`.
# --------------------------------------------------------------------------------------------
MODEL_ERROR_SPECS = ("pm10", "pm15", "pm10+noise")
ADAPTIVE = SHIPPED_DIR / "adaptive" / "s0"  # the learned adaptive controller's first seed


def model_error_budget(budget: str) -> str:
    """The model-error budget
    (`bound_env.analysis.margins.model_error.mismatch_tasks.MISMATCH_BUDGETS`) of the page's
    ``budget``: ``test`` for the test budget, else ``page``."""
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
    from bound_env.model.mismatch import parse_specs

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


def training_curves(groups, docs: Path) -> list:
    """Each trained column's training curve in ``docs`` (``training_<label>.png``), plotted
    from its first policy's ``eval.csv`` (`agents.common.run_files.plot_eval`: the selected
    checkpoint marked where one was selected, else the final model), or its ``eval.png`` when
    it has no CSV; a ``training_*.png`` in ``docs`` that no column drew is removed (it would
    be a figure of a column the page no longer has). [(label, policy, png)]."""
    from ..common.run_files import plot_eval

    curves = []
    for g in groups:
        folder = Path(g["policies"][0])
        dst = docs / f"training_{g['label'].replace(' ', '_')}.png"
        if (folder / "eval.csv").is_file():
            exp = folder / "exported.json"
            selected = exp.is_file() and "timesteps" in json.loads(exp.read_text())
            plot_eval(
                folder / "eval.csv",
                dst,
                title=f"training of {g['label']} ({rel(str(folder))})",
                kept="best" if selected else "final",
            )
        elif (folder / "eval.png").is_file():
            shutil.copyfile(folder / "eval.png", dst)
        else:
            continue
        curves.append((g["label"], g["policies"][0], dst))
    drawn = {c[2].name for c in curves}
    for old in docs.glob("training_*.png"):
        if old.name not in drawn:
            old.unlink()
    return curves


def model_error_text(groups) -> str:
    """The page's "Model error" section from the columns measured under model error (their
    first seed), paired against the lqr column where it is one of them; empty without any."""
    measured = {g["label"]: g["runs"][0] for g in groups if g["runs"][0].get("mismatch")}
    if not measured:
        return ""
    from bound_env.analysis.margins.model_error.mismatch_report import mismatch_markdown

    specs = list(dict.fromkeys(k for r in measured.values() for k in r["mismatch"]))
    ref = "lqr" if "lqr" in measured else None
    return "\n## Model error\n\n" + mismatch_markdown(measured, specs=specs, reference=ref)


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


if __name__ == "__main__":  # python -m agents.results.compare ARGS is bound-env compare ARGS
    import sys

    from bound_env.commands.cli import main

    sys.exit(main(["compare", *sys.argv[1:]]))
