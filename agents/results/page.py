"""The results page, ``docs/MARGINS.md``, as Markdown (`render_markdown`).

One function per section, in the page's order: the title (`title_section`: the command, the
budget and the seed), the headline, all columns (`agents.results.page_tables`), the paired
differences (`bound_env.analysis.paired_text`), how each column was made
(`agents.results.provenance`), the yardsticks, the per-direction tables, the basin maps and the
training curves. `COLUMN_STYLES` gives each column the same colour in every figure.
"""

from __future__ import annotations

from pathlib import Path

from bound_env.analysis.margins import DEFAULT_SEED
from bound_env.analysis.paired_text import paired_text

from .formatting import fmt_list, rel
from .headline import HEADLINE_FILE, headline_numbers, headline_table
from .page_tables import (
    ceiling_table,
    columns_table,
    direction_table,
    failure_table,
    seed_details,
)
from .provenance import provenance

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


# What a budget other than the full one leaves out, said in the page's first sentence
BUDGET_FIELDS = (
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
)


def budget_note(budget: str) -> str:
    """The budget in words; one other than the full one with what it has fewer of."""
    from bound_env.analysis.margins import BUDGETS

    b = BUDGETS.get(budget)
    full = BUDGETS["full"]
    if budget == "full":
        return "the **full** budget"
    if b is None:
        return f"the `{budget}` budget"
    diffs = []
    for field, what in BUDGET_FIELDS:
        mine, theirs = getattr(b, field), getattr(full, field)
        if mine != theirs:
            n = len(mine) if isinstance(mine, tuple) else mine
            m = len(theirs) if isinstance(theirs, tuple) else theirs
            diffs.append(f"{n} {what} instead of {m}")
    return f"the **{budget}** budget, NOT the full one (" + "; ".join(diffs) + ")"


def run_text(run: dict | None) -> str:
    """How long the run that made the page took (`agents.results.headline.run_record`)."""
    if not run:
        return ""
    t = run.get("tasks") or {}
    load = run.get("load_average_before") or ["?"]
    commit = (run.get("commit") or "?")[:12] + (" with local changes" if run.get("dirty") else "")
    return (
        f" This run took {run['wall_seconds'] / 60:.1f} min of wall time with "
        f"{run['workers']} worker(s) on {run.get('cores', '?')} cores (load average "
        f"{load[0]} before), computing {t.get('computed', '?')} tasks and taking "
        f"{t.get('cached', '?')} from the cache, at commit {commit} (`columns.json`)."
    )


def title_section(budget: str, r0: dict, note: str = "", run: dict | None = None) -> str:
    """The title, how the page was generated (budget, seed, the run: `run_text`) and
    ``note``."""
    para_note = ("\n\n" + note + "\n") if note else ""
    seed = r0.get("seed", DEFAULT_SEED)
    seed_note = (
        f"seed {seed}, the **test set**"
        if seed == DEFAULT_SEED
        else f"seed {seed}, a **held-out validation set** (the test set is seed {DEFAULT_SEED})"
    )
    budget_text = budget_note(budget)
    return f"""# Stability margins: passive, classical and learned spine control

Generated by `bound-env compare --budget {budget} --seed {seed}` (agents/results/compare.py) with
{budget_text}; random samples of {seed_note}; do not edit by hand.{run_text(run)}{para_note}

"""


def headline_section(head: dict, own: bool = True) -> str:
    """The headline table (`agents.results.headline`) and what its numbers mean; ``own``: the
    project's page (its reproducibility measured across machines), not a user's."""
    headline = headline_table(head) if head["rows"] else "(none of the headline's columns)"
    repro = REPRODUCIBILITY if own else ""
    return f"""## Headline

{headline}

r50: the perturbation size (units of |z*_i|, a random direction) from which half the starts
return to the cycle; σ: the rough terrain's slope noise at which the mean first-passage time
falls to 100 strides. Larger is better for both. Numbers in `{HEADLINE_FILE}` beside this page;
every column, every measure and how each was made follow.

{repro}"""


# What reproduces bit for bit, and what does not (docs/developers.md, "Same commit, same numbers")
REPRODUCIBILITY = """\
**Reproducibility.** The compiled kernels round in source order (no fast-math), so every
number on this page except the wall-clock times reproduces bit for bit from the same commit on
the same kind of machine: from a cold or a warm Numba cache and on 1 or 2 workers
(`tests/test_same_numbers.py`), whichever worker runs a task after whichever other tasks
(`tests/test_worker_history.py`: a worker's cached closed loop once kept the stride period
that scores the ceiling search from the task that built it, and a controller run as one copy
per robot lost decisions from its counts). Before, fast-math made a function compiled with
its callers round otherwise than one loaded from the cache, and `mpc`, which seeds its random
candidates with the bytes of z, and the chaotic rough-terrain runs turned those last bits into
other outcomes: a fresh clone of the same commit regenerated another `mpc` r50. Across CPUs or
math libraries (glibc's FMA variants, BLAS kernels) last bits can still differ, and a start
near a basin edge can then go either way. Decision times are the CPU time of one process
over fixed states, the minimum of repeats, so a rerun on an idle machine reproduces them
closely but not bit for bit (with another process busy on the other core, the learned
students' microsecond decisions came out up to half again as long); run times are wall time
and move with the load.

"""


def columns_section(groups) -> str:
    """Every column and every measure, with the names and the statistics explained."""
    settings = groups[0]["runs"][0]["settings"]
    main = columns_table(groups)
    details = seed_details(groups)
    return f"""## All columns

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

"""


def paired_section(pairs) -> str:
    """The paired differences against lqr (and mpc) on the same directions."""
    pairs_md = paired_text(pairs or [])
    return f"""## Paired differences (the same directions)

Each column against `lqr` (and a trained column against `mpc`, when there is one), on the same
random directions. Per size r, the difference of P(return) and McNemar's exact test: a
two-sided sign test on the directions where the two differ (`scipy.stats.binomtest`; a
column with several seeds contributes, per direction, the mean of its seeds' outcomes). Δr50
with a 95 % percentile bootstrap interval (2000 resamples of the directions, the same draw for
both columns, and of the seeds). A difference **stands out of the noise** when the interval of
Δr50 excludes 0 *and* McNemar's p < 0.05 at a grid size around the reference's r50, with the
same sign. Numbers in `paired.json` beside this page (`bound_env/analysis/paired.py`).

{pairs_md}

"""


def provenance_section(groups) -> str:
    """How each column was made (`agents.results.provenance`)."""
    prov = []
    for g in groups:
        prov.append(f"- **{g['label']}** (gait `{g['gait']}`):")
        prov += [f"  - {line}" for line in provenance(g)]
    return f"""## How each column was made

{chr(10).join(prov)}

"""


def yardsticks_section(r0: dict) -> str:
    """What each yardstick measures, with the settings of the first column's first run."""
    settings = r0["settings"]
    ceil = settings.get("ceiling", {})
    terrain = r0.get("terrain", {})
    mset = r0.get("mfpt_settings") or {}
    return f"""## The yardsticks

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
- **Random directions** (basin stability). {r0["basin_curve"]["directions"]}
  directions (seed {r0["basin_curve"].get("direction_seed", "?")}) uniform on the
  sphere, scaled to max
  |u_i| = 1, sizes in the zstar scale; 95 % Wilson intervals per point. r50 is where P(return)
  first falls below 0.5, interpolated linearly in log r between the two sizes around the
  crossing (the JSON keeps the grid value as `r50_grid`).
- **Rough terrain.** The slope becomes α_k = α + σ ξ_k at every apex (ξ_k standard normal
  from the env's RNG; `slope_noise_deg`), the ground tilting under the robot in flight about
  the point below its centre of mass (`bound_env/model/terrain.py`). σ50 = the σ at which the
  fraction of {terrain.get("runs", "?")} runs (env seeds {terrain.get("seeds", ["?"])[0]}…) that
  survive {terrain.get("strides", "?")} strides first falls below one half (log-interpolated
  like r50; the JSON keeps the largest grid σ with survival ≥ 1/2 as
  `terrain_sigma50_grid_deg`).
- **MFPT.** At each σ of {fmt_list(mset.get("sigmas_deg"))}°, {mset.get("robots", "?")}
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

"""


def direction_sections(groups) -> str:
    """The basin per apex direction (two scales), the ceilings and the failures beyond."""
    mech = ceiling_table(groups)
    fails = failure_table(groups)
    return f"""## Basin along each apex component (zstar scale)

{direction_table(groups, "basin")}

## Basin in the cycle scale

{direction_table(groups, "basin", "rel_cycle")}

## Ceilings and each controller's share of them

Ceiling (zstar scale) per direction:

{direction_table(groups, "basin_ceiling")}

Basin / ceiling:

{direction_table(groups, "basin", "share")}

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

"""


def basin_maps_section(maps: str) -> str:
    """The basin-map figures present (`basin_maps`)."""
    return f"""## Basin maps

Slices through z* (64 × 64 starts, 100 strides; `bound-env basin-map`; `default` is the
fine-tuned seed 0), each outlining the passive basin in red; the right panel of each says why
the falls fell.

{maps or "(no basin maps in this folder)"}

"""


def training_section(curves, literal: bool = True) -> str:
    """Each trained column's training curve, and the literal reading's note when the page has
    its columns (``literal``)."""
    train_lines = [
        f"- **{label}** (`{rel(policy)}`)\n\n  ![training curve {label}]({png.name})"
        for label, policy, png in curves
    ]
    note = LITERAL_NOTE if literal else ""
    return f"""## Training curves

{(chr(10) * 2).join(train_lines) if train_lines else "(no trained policy)"}
{note}"""


LITERAL_NOTE = """
The literal reading of Table II (`PassiveBoundLiteral-v0`, section of `configs/ppo.yaml`):
its published apex state falls within the first stride, so its task starts on the literal
reading's own periodic gait at the published parameters (`configs/gaits/literal-cycle.yaml`),
a saddle with e_max 1.364: its passive basin is empty. The literal columns' ratios are
against the default gait's passive column, since the literal passive values are zero.
"""


def render_markdown(
    groups,
    plots,
    curves,
    budget,
    note: str = "",
    pairs=None,
    maps: str = "",
    head=None,
    run: dict | None = None,
    own: bool = True,
) -> str:
    """The page (without the decision times, which `agents.results.decisions` appends): ``groups``
    the columns (label, gait, policies, runs), ``curves`` the training curves copied beside
    it, ``pairs`` the paired comparisons, ``maps`` the basin maps' Markdown, ``head`` the
    headline numbers (made from ``groups`` if None), ``run`` the run that made it
    (`run_text`). ``own``: the project's page; a user's (``compare --entry``) says nothing of
    the project's own measurements, and has basin maps and the literal reading's note only
    when it has them. ``plots`` is not used (the figures have fixed names)."""
    r0 = groups[0]["runs"][0]
    if head is None:
        head = headline_numbers(groups, budget, r0.get("seed", DEFAULT_SEED))
    literal = any(g["gait"] != "default" and "literal" in g["gait"] for g in groups)
    return "".join(
        [
            title_section(budget, r0, note, run),
            headline_section(head, own),
            columns_section(groups),
            paired_section(pairs),
            provenance_section(groups),
            yardsticks_section(r0),
            direction_sections(groups),
            basin_maps_section(maps) if (maps or own) else "",
            training_section(curves, literal or own),
        ]
    )


def model_error_section(groups) -> str:
    """The page's "Model error" section of the columns
    `agents.results.compare.run_model_error` made: how they were measured (the model-error
    budget their blocks record), then one table per spec, paired against lqr
    (`bound_env.analysis.margins.model_error.mismatch_report.mismatch_markdown`)."""
    from types import SimpleNamespace

    from bound_env.analysis.margins.model_error.mismatch_report import mismatch_markdown

    measured = {g["label"]: g["runs"][0] for g in groups if g["runs"][0].get("mismatch")}
    if not measured:
        return ""
    first = next(iter(next(iter(measured.values()))["mismatch"].values()))
    mb = SimpleNamespace(**first["budget"])
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
