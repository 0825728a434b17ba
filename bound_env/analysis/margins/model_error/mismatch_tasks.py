"""Margins under model error (JSON ``mismatch``; ``bound-env margins --mismatch SPEC``).

The controller keeps its nominal design (model, gains, network); robot i runs on its own
plant, drawn from the spec (`bound_env.model.mismatch`: relative parameter ranges, sensor noise,
actuation delay) with the seed's plant seed (`mismatch_seeds`), so every controller meets the
same plants in the same order (paired comparisons: `mismatch_report`). Every run steps the
step env interval by interval (`plant_runs`, through the one batched loop
`bound_env.analysis.apex_loop.interval_loop`, every robot with a fresh controller state); on
smooth ground each stride restarts at its apex (the nominal apex map's convention), on rough
terrain a run is one long episode (the nominal MFPT's); delayed actions stay in flight across
apexes.

Measures
--------
- ``hold``: robot i starts on the *nominal* z* on plant i; held = no fall in
  ``hold_strides`` strides (100 in the quick and full budgets). ``k``, ``n``, ``fraction``,
  ``ci`` (Wilson 95 %), ``outcomes`` (per plant, for McNemar's test) and ``effort``: mean
  |tau| [N m] over the last ``effort_strides`` (10) strides of each held plant, with
  ``effort_median`` and its distribution-free 95 % interval (``effort_median_ci``: order
  statistics of the binomial).
- ``curve`` / ``r50``: robot i starts at z* + r |z*| xi_i on plant i (xi_i: direction i of
  `random_directions` of the seed's directions, the nominal curve's first directions);
  success = no fall in ``curve_strides`` (50) strides *and* the apex settled: the last two
  apexes within the return tolerance of each other, max_j |z_j(N) - z_j(N - 1)| < tol_j with
  tol_j = `RETURN_TOL` (SI, unscaled, as the nominal return test) plus 4 sigma_j of the
  sensor noise on that component (none without noise). Not "returned to the nominal z*",
  which the plant may not have. Per size: Wilson intervals; ``r50`` (log-interpolated
  crossing of 1/2, as the nominal curve) and ``r50_ci`` from the intervals' bounds.
- ``mfpt``: the nominal MFPT's runs (the seed's MFPT env seeds, slope noise sigma) from z*,
  robot k on plant k mod ``plants``; MFPT = strides attempted / falls with the exact Poisson
  interval; ``mfpt_sigma_100_deg``. On rough terrain the mean slope is the gait's (the
  terrain's draws replace a plant's slope error after the first apex).

Noise and delay act on what the controller sees and does: its observation (and the apex
state handed to ``on_apex``) gets the spec's noise from a per-robot generator; the action it
returns acts ``delay`` control intervals later (zero torque before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ....model.dynamics import make_aux
from ....model.mismatch import MismatchSpec, sample_plant_params
from ....model.params import Z_NAMES
from ....sim.stride_map import RETURN_TOL
from ....sim.task import FAILURE_NAMES
from ...apex_loop import SensorNoise, interval_loop
from ..budget import DEFAULT_SEED, random_directions, sample_seeds
from ..closed_loop import STRIDES, Setup, loop_for

MISMATCH_SEED = 40_000  # the plants of the default (test) seed; any other seed derives its own
SETTLE_NOISE = 4.0  # settle tolerance: RETURN_TOL + this many noise sigmas per component


@dataclass(frozen=True)
class MismatchBudget:
    """How hard the model-error measures look."""

    name: str
    plants: int  # plants (robots) of hold and of each curve size
    hold_strides: int
    effort_strides: int  # hold's effort: mean |tau| over the last this many strides
    curve_sizes: tuple
    curve_strides: int
    mfpt_sigmas: tuple
    mfpt_robots: int
    mfpt_strides: int


MISMATCH_BUDGETS = {
    "test": MismatchBudget("test", 8, 20, 5, (0.01, 0.1), 20, (0.5,), 8, 10),
    "quick": MismatchBudget(
        "quick",
        32,
        100,
        10,
        (0.01, 0.02, 0.04, 0.07, 0.1, 0.15, 0.25, 0.4),
        50,
        (0.2, 0.5, 1.0),
        32,
        100,
    ),
    "full": MismatchBudget(
        "full",
        32,
        100,
        10,
        (0.005, 0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.25, 0.4, 0.7),
        50,
        (0.1, 0.2, 0.35, 0.5, 0.75, 1.0),
        64,
        200,
    ),
}
MISMATCH_BUDGETS["standard"] = MISMATCH_BUDGETS["full"]
# The results page's model-error section (`bound-env compare`, docs/model-error.md): hold (32
# plants, 100 strides) and r50 under error on five sizes, no MFPT (its runs cost more than the
# rest together: the page's nominal MFPT stands for it)
MISMATCH_BUDGETS["page"] = MismatchBudget(
    "page", 32, 100, 10, (0.05, 0.1, 0.2, 0.3, 0.4), 50, (), 0, 0
)


def mismatch_seeds(seed: int = DEFAULT_SEED) -> dict:
    """Seeds of the plants and of the sensor noise (``noise`` + robot index) of ``--seed``:
    fixed ones for the default (test) seed, derived ones (`numpy.random.SeedSequence`) for
    any other."""
    if seed == DEFAULT_SEED:
        return {"plants": MISMATCH_SEED, "noise": MISMATCH_SEED + 1000}
    plants, noise = (int(v) for v in np.random.SeedSequence([seed, 3]).generate_state(2) >> 2)
    return {"plants": plants, "noise": noise}


def plants_of(setup: Setup, n: int) -> list:
    """The first ``n`` plants (`bound_env.model.params.Params`) of ``setup``'s spec and seed."""
    from ....model.params import load_gait

    nominal = load_gait(setup.gait).params
    return sample_plant_params(setup.mismatch, n, mismatch_seeds(setup.seed)["plants"], nominal)


def plant_runs(
    loop,
    Z0,
    plants,
    max_strides: int,
    spec: MismatchSpec,
    noise_seeds,
    terrain_seeds=None,
    effort_strides: int | None = 10,
) -> dict:
    """One run per robot i from the apex state Z0[i] on the plant ``plants[i]`` (`Params`),
    all stepped together through ``loop``'s task by the one batched loop
    (`bound_env.analysis.apex_loop.interval_loop`: each robot with a fresh controller
    state), with the spec's sensor noise (robot i's generator seeded ``noise_seeds[i]``) and
    actuation delay, until ``max_strides`` strides or a fall. On smooth ground every stride
    restarts at its apex (t = 0 there, as the nominal apex map `ClosedLoop.stride`; delayed
    actions stay in flight); ``terrain_seeds`` (env seeds of the slope draws, rough terrain:
    the loop's ``slope_noise_deg``) runs one long episode per robot instead, as the nominal
    MFPT.

    Returns per robot: ``strides``, ``fell`` (0/1), ``failure`` (name or None), ``settle``
    (per component |z(N) - z(N - 1)| of the last two apexes, None before two), ``effort``
    (mean |tau| [N m] over the last ``effort_strides`` strides, None before as many or with
    ``effort_strides`` None)."""
    from gymnasium.utils import seeding

    task = loop.env.task
    terrain = None
    if terrain_seeds is not None:
        terrain = [seeding.np_random(int(s))[0] for s in terrain_seeds]
    sig_obs = spec.obs_sigma(task.obs_names)
    noise = None
    if np.any(sig_obs > 0):
        rngs = [np.random.default_rng(int(s)) for s in noise_seeds]
        noise = SensorNoise(sig_obs, spec.obs_sigma(Z_NAMES), rngs, *task.obs_bounds())
    r = interval_loop(
        task,
        loop.controller,
        Z0,
        max_strides,
        restart=terrain is None,
        aux=[make_aux(p.to_array()) for p in plants],
        terrain=terrain,
        noise=noise,
        delay=spec.delay,
        effort_strides=effort_strides,
        plants=plants,
    )
    STRIDES[0] += int(r["strides"].sum())
    return {
        "strides": r["strides"].tolist(),
        "fell": (r["status"] > 0).astype(np.int64).tolist(),
        "failure": [FAILURE_NAMES[int(c)] if c else None for c in r["status"]],
        "settle": r["settle"],
        "effort": r["effort"],
    }


# --------------------------------------------------------------------------------------------
# Tasks (run in worker processes; ``setup.mismatch`` is the spec)
# --------------------------------------------------------------------------------------------


def settle_tol(spec: MismatchSpec) -> np.ndarray:
    """Per apex component: the settle test's tolerance (SI), `RETURN_TOL` plus `SETTLE_NOISE`
    sigmas of the sensor noise on it."""
    return RETURN_TOL + SETTLE_NOISE * spec.obs_sigma(Z_NAMES)


def task_mm_hold(setup: Setup) -> dict:
    """hold: every plant from the nominal z* for ``hold_strides`` strides."""
    mb = setup.mismatch_budget
    loop = loop_for(setup)
    plants = plants_of(setup, mb.plants)
    base = mismatch_seeds(setup.seed)["noise"]
    Z0 = np.tile(setup.z_star, (mb.plants, 1))
    r = plant_runs(
        loop,
        Z0,
        plants,
        mb.hold_strides,
        setup.mismatch,
        [base + i for i in range(mb.plants)],
        effort_strides=mb.effort_strides,
    )
    outcomes = [int(not f) for f in r["fell"]]
    return {"outcomes": outcomes, **r}


def task_mm_curve(setup: Setup, size: float) -> dict:
    """r50 under error at one size: robot i from z* + size |z*| xi_i on plant i."""
    mb = setup.mismatch_budget
    loop = loop_for(setup)
    plants = plants_of(setup, mb.plants)
    dirs = random_directions(mb.plants, sample_seeds(setup.seed)["directions"])
    zs = setup.z_star
    base = mismatch_seeds(setup.seed)["noise"] + 10_000  # robot i: the same stream at every size
    r = plant_runs(
        loop,
        zs + size * np.abs(zs) * dirs,
        plants,
        mb.curve_strides,
        setup.mismatch,
        [base + i for i in range(mb.plants)],
        effort_strides=None,
    )
    tol = settle_tol(setup.mismatch)
    outcomes = [
        int(not f and st is not None and bool(np.all(np.array(st) < tol)))
        for f, st in zip(r["fell"], r["settle"], strict=True)
    ]
    return {
        "size": size,
        "n": mb.plants,
        "k": int(sum(outcomes)),
        "outcomes": outcomes,
        "survived": int(mb.plants - sum(r["fell"])),
        "failures": _count(r["failure"]),
    }


def task_mm_mfpt(setup: Setup, sigma: float) -> dict:
    """MFPT under error at slope noise sigma [deg]: robot k on plant k mod ``plants``."""
    mb = setup.mismatch_budget
    loop = loop_for(setup, env_extra={"slope_noise_deg": float(sigma)})
    plants = plants_of(setup, mb.plants)
    robots = range(mb.mfpt_robots)
    base = sample_seeds(setup.seed)["mfpt"]
    nbase = mismatch_seeds(setup.seed)["noise"] + 50_000
    Z0 = np.tile(setup.z_star, (len(robots), 1))
    r = plant_runs(
        loop,
        Z0,
        [plants[k % mb.plants] for k in robots],
        mb.mfpt_strides,
        setup.mismatch,
        [nbase + k for k in robots],
        terrain_seeds=[base + k for k in robots],
        effort_strides=None,
    )
    return {
        "sigma_deg": sigma,
        "robots": len(robots),
        "strides": r["strides"],
        "fell": r["fell"],
        "failures": _count(r["failure"]),
    }


def _count(names) -> dict:
    out: dict = {}
    for f in names:
        if f is not None:
            out[f] = out.get(f, 0) + 1
    return out


def mismatch_jobs(mb: MismatchBudget) -> list:
    """The (task name, args) of one evaluation under error."""
    jobs = [("mm_hold", ())]
    jobs += [("mm_curve", (r,)) for r in mb.curve_sizes]
    jobs += [("mm_mfpt", (v,)) for v in mb.mfpt_sigmas]
    return jobs


def median_interval(values, level: float = 0.95) -> list:
    """Distribution-free interval of the median: the narrowest symmetric pair of order
    statistics [x_(j+1), x_(n-j)] with P(j < B < n - j) >= level for B ~ Binomial(n, 1/2)
    (n = 32: the 10th and 23rd); [nan, nan] for no value, the whole range when n is too
    small."""
    from scipy.stats import binom

    x = np.sort(np.asarray([v for v in values if v is not None], dtype=float))
    n = len(x)
    if n == 0:
        return [math.nan, math.nan]
    for j in range(n // 2, -1, -1):  # [x_(j+1), x_(n-j)] (1-based order statistics)
        cover = binom.cdf(n - j - 1, n, 0.5) - binom.cdf(j, n, 0.5)  # P(j < B < n - j)
        if cover >= level:
            return [float(x[j]), float(x[n - j - 1])]
    return [float(x[0]), float(x[-1])]


def assemble_mismatch(setup: Setup, res: dict) -> dict:
    """The JSON ``mismatch`` block from the tasks' results (module docstring)."""
    from ..decision_times import summary as decision_summary
    from ..stats import crossing_on_grid, mfpt_crossing, mfpt_estimate, wilson_interval

    mb, spec = setup.mismatch_budget, setup.mismatch
    from dataclasses import asdict

    from ....model.mismatch import plant_values

    hold = res[("mm_hold", ())]
    k = int(sum(hold["outcomes"]))
    efforts = [
        e for e, o in zip(hold["effort"], hold["outcomes"], strict=True) if o and e is not None
    ]
    out = {
        "spec": spec.to_dict(),
        "privileged": getattr(setup.controller, "privileged", False) is True,
        "budget": asdict(mb),
        "seeds": mismatch_seeds(setup.seed),
        "plants": [
            {key: plant_values(p)[key] for key, d in spec.ranges if d > 0}
            for p in plants_of(setup, mb.plants)
        ],
        "start": "nominal z* (hold, MFPT); z* + r |z*| xi_i (curve)",
        "hold": {
            "strides": mb.hold_strides,
            "k": k,
            "n": mb.plants,
            "fraction": k / mb.plants,
            "ci": list(wilson_interval(k, mb.plants)),
            "outcomes": hold["outcomes"],
            "strides_reached": hold["strides"],
            "failures": _count(hold["failure"]),
            "effort": hold["effort"],
            "effort_strides": mb.effort_strides,
            "effort_median": float(np.median(efforts)) if efforts else None,
            "effort_median_ci": median_interval(efforts) if efforts else None,
        },
    }
    curve = []
    for r in mb.curve_sizes:
        c = res[("mm_curve", (r,))]
        lo, hi = wilson_interval(c["k"], c["n"])
        curve.append(
            {
                **{x: c[x] for x in ("size", "n", "k", "outcomes", "survived", "failures")},
                "success": c["k"] / c["n"],
                "ci_low": lo,
                "ci_high": hi,
            }
        )
    sizes = [c["size"] for c in curve]
    out["curve"] = curve
    out["curve_strides"] = mb.curve_strides
    out["settle_tol"] = settle_tol(spec).tolist()
    out["r50"] = crossing_on_grid(sizes, [c["success"] for c in curve])
    out["r50_ci"] = [
        crossing_on_grid(sizes, [c["ci_low"] for c in curve]),
        crossing_on_grid(sizes, [c["ci_high"] for c in curve]),
    ]
    mfpt = []
    for v in mb.mfpt_sigmas:
        m = res[("mm_mfpt", (v,))]
        falls = int(sum(m["fell"]))
        total = int(sum(m["strides"])) + falls  # strides attempted
        mfpt.append(
            {
                "sigma_deg": v,
                "robots": m["robots"],
                "strides_total": total,
                "failures": falls,
                "fail_reasons": m["failures"],
                **mfpt_estimate(total, falls),
            }
        )
    out["mfpt"] = mfpt
    out["mfpt_strides"] = mb.mfpt_strides
    # every apex decision of the robots under error (an adaptive controller identifies here)
    out["decision_times"] = decision_summary(res[j] for j in mismatch_jobs(mb))
    out["mfpt_sigma_100_deg"] = mfpt_crossing(
        [m["sigma_deg"] for m in mfpt],
        [m["mfpt"] for m in mfpt],
        [m["lower_bound"] for m in mfpt],
    )
    return out
