"""Running a margins evaluation: the task table (`TASKS`, `run_task`, run in worker processes)
and the core entry `compute_margins`, which takes a loaded controller. The task cache's keys
(`setup_key`: `SETTINGS`, the gait file, the controller's fingerprint and code closure, and
`source_hash`) are `keys`', importable from here."""

from __future__ import annotations

import contextlib
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bound_env.files.cache import TaskCache, atomic_write
from bound_env.sim.parallel import TasksFailed, open_pool, run_tasks

from ..apex_loop import CLOCK
from .assemble import assemble, controller_name
from .basin import BASIN_GROUPS, task_basin, task_basins
from .budget import (
    DEFAULT_SEED,
    MFPT_CHUNK,
    Budget,
    as_budget,
    check_seed,
)
from .ceiling import task_ceiling
from .closed_loop import EVAL_RTOL, Setup
from .curve import task_curve
from .cycle import task_cycle
from .decision_times import histogram
from .model_error.mismatch_tasks import (
    MISMATCH_BUDGETS,
    assemble_mismatch,
    mismatch_jobs,
    task_mm_curve,
    task_mm_hold,
    task_mm_mfpt,
)
from .provenance.fingerprint import column_fingerprint
from .provenance.keys import (  # noqa: F401 - the cache key's parts, importable from here as before
    CYCLE_RECORD_DT,
    MISMATCH_SETTINGS,
    SETTINGS,
    gait_key,
    mismatch_key,
    setup_key,
    source_files,
    source_hash,
)
from .push import task_push
from .report import Z_LABELS, Z_UNITS, write_outputs
from .terrain import task_mfpt, task_terrain
from .windows import task_window

TASKS = {
    "cycle": task_cycle,
    "basin": task_basin,
    "basins": task_basins,
    "curve": task_curve,
    "window": task_window,
    "push": task_push,
    "ceiling": task_ceiling,
    "terrain": task_terrain,
    "mfpt": task_mfpt,
    "mm_hold": task_mm_hold,
    "mm_curve": task_mm_curve,
    "mm_mfpt": task_mm_mfpt,
}


def run_task(setup: Setup, name: str, args: tuple) -> dict:
    """Worker entry point: one named task (its wall ``seconds`` and the worker's
    ``cpu_seconds``, `time.process_time`, go into its result)."""
    t0, c0 = time.perf_counter(), time.process_time()
    CLOCK.seconds.clear()
    CLOCK.on = True  # every apex decision of the task is timed (the real-time yardstick)
    try:
        result = TASKS[name](setup, *args)
    except RuntimeError as e:
        result = {"error": str(e)}
    finally:
        CLOCK.on = False
    if CLOCK.seconds:
        result["decision_hist"] = histogram(CLOCK.seconds)
        CLOCK.seconds.clear()
    result["seconds"] = time.perf_counter() - t0
    result["cpu_seconds"] = time.process_time() - c0
    return result


def basin_results(res: dict) -> dict:
    """{("basin", (i, sign)): result} of every direction of the ``basins`` tasks in ``res``
    (a task's error for each of its directions)."""
    out = {}
    for (name, args), r in res.items():
        if name == "basins":
            each = r["basins"] if "basins" in r else [r] * len(args)
            for (i, sign), b in zip(args, each, strict=True):
                out[("basin", (int(i), int(sign)))] = b
    return out


# --------------------------------------------------------------------------------------------
# Orchestration
# --------------------------------------------------------------------------------------------


def task_key(setup_key: str, name: str, args: tuple) -> str:
    """Cache key of one task: the setup's settings hash, the task name and its arguments."""
    return f"{setup_key}/{name}/{json.dumps(list(args))}"


def _run_all(
    executor, setup: Setup, jobs: list, cache: TaskCache, progress: bool, desc: str, counts=None
) -> dict:
    """Run (name, args) jobs through the executor, using and filling the cache. A task that
    raises is reported (key and arguments) without stopping the others; then `TasksFailed`.
    ``counts`` (a dict) adds up the tasks taken from the cache and those computed, and the
    CPU time of those computed (``cpu_seconds``: the workers' process time)."""
    results, tasks = {}, {}
    for name, args in jobs:
        key = task_key(setup.key, name, args)
        hit = cache.get(key)
        if hit is not None:
            results[(name, args)] = hit
        else:
            tasks[key] = (run_task, (setup, name, args), (name, args))
    if counts is not None:
        counts["cached"] = counts.get("cached", 0) + len(results)
        counts["computed"] = counts.get("computed", 0) + len(tasks)

    def keep(key, res):
        if "error" not in res:
            cache.put(key, res)

    done, failures = run_tasks(
        executor, tasks, progress and bool(tasks), desc, keep, done_before=len(results)
    )
    for key, res in done.items():
        results[tasks[key][2]] = res
        if counts is not None:
            counts["cpu_seconds"] = counts.get("cpu_seconds", 0.0) + float(
                res.get("cpu_seconds") or 0.0
            )
    if failures:
        raise TasksFailed(
            failures,
            len(jobs),
            "; the others are cached: rerun to retry" if cache.path is not None else "",
        )
    return results


def check_controller(controller):
    """``controller`` if it has the controller protocol (``__call__`` and ``fingerprint()``,
    see the package docstring), else ValueError. Names and paths are loaded by the caller."""
    if callable(controller) and callable(getattr(controller, "fingerprint", None)):
        return controller
    raise ValueError(
        f"the controller must be an object with __call__(obs) and fingerprint(), got "
        f"{type(controller).__name__} (a name or a path is loaded first)"
    )


def cycle_scale(gait: str) -> np.ndarray:
    """Peak-to-peak range of each apex component [y_g, th1, th2, xdot_g, th1dot, th2dot]
    over one passive stride from the gait's z* (SI): the ``cycle`` yardstick."""
    from bound_env.model.hybrid import simulate_stride
    from bound_env.model.params import load_gait

    g = load_gait(gait)
    res = simulate_stride(
        g.z0, g.params, backend="fast", rtol=EVAL_RTOL, atol=EVAL_RTOL, record_dt=CYCLE_RECORD_DT
    )
    tr = res.trajectory
    full = np.hstack([tr.q, tr.qd])[:, [1, 2, 3, 4, 6, 7]]
    return full.max(axis=0) - full.min(axis=0)


def compute_margins(
    controller,
    budget: str | Budget = "quick",
    gait: str = "default",
    workers: int = 1,
    executor=None,
    out: str | Path | None = None,
    progress: bool = False,
    use_cache: bool = True,
    scheduler: str | None = None,
    seed: int = DEFAULT_SEED,
    extra_sources=(),
    mismatch=None,
    files: str | None = None,
    mismatch_budget: str | None = None,
    nominal: bool = True,
) -> dict:
    """All margins of ``controller`` (an object with the controller protocol, package
    docstring) as a JSON-able dict.

    ``seed`` picks the random directions, the rough-terrain runs, the push trials and the
    MFPT robots (`sample_seeds`): the default is the test set of docs/MARGINS.md, any other
    a held-out (validation) set.
    ``executor``: any `concurrent.futures.Executor`-like object; default: the one
    `bound_env.sim.parallel.open_pool` builds from ``scheduler`` and ``workers`` (a process pool
    of ``workers`` processes, in-process when ``workers == 1``, or Dask). ``out``: directory
    for the CSV/PNG outputs and the task cache. ``extra_sources``: files of the controller's
    code outside bound_env/ (e.g. a learned policy's modules), hashed into the cache key with
    bound_env/'s own sources (`setup_key`), so that a change of that code never returns a stale
    result; the controller's ``fingerprint()`` covers its data (weights, gains, settings).
    ``mismatch``: a model-error spec (`bound_env.model.mismatch.as_spec`: a preset, a YAML file or
    a `MismatchSpec`) or a list of them: the result then has the key ``mismatch`` too,
    {spec name: its block} (`mismatch_tasks`), each spec's tasks cached under `mismatch_key`.
    ``files``: the sha256 of the controller's files (its spec, a policy's weights), recorded
    in the result's ``fingerprint`` (`fingerprint.column_fingerprint`) by the caller that
    resolved its name.
    ``mismatch_budget``: the name of the model-error budget (`MISMATCH_BUDGETS`; default: the
    one of ``budget``'s name, e.g. ``page``: the results page's model-error section).
    ``nominal`` False: the model-error measures only (with the closed-loop cycle they start
    from): the result holds the run's keys (controller, gait, budget, seed, fingerprint,
    seconds, tasks), ``mismatch`` and ``"nominal": false``, and only ``margins.json`` is
    written.
    """
    from bound_env.model.mismatch import as_spec, check_distinct
    from bound_env.model.params import load_gait

    budget = as_budget(budget)
    many = mismatch if isinstance(mismatch, (list, tuple)) else [mismatch]
    specs = check_distinct([as_spec(m) for m in many if m is not None])
    mb_name = budget.name if mismatch_budget is None else mismatch_budget
    if specs and mb_name not in MISMATCH_BUDGETS:
        raise ValueError(f"--mismatch has budgets {sorted(MISMATCH_BUDGETS)}, got {mb_name!r}")
    if not nominal and not specs:
        raise ValueError("nominal=False measures the model error only: give --mismatch specs")
    if workers < 1:
        raise ValueError(f"--workers must be at least 1, got {workers}")
    seed = check_seed(seed)
    controller = check_controller(controller)
    g = load_gait(gait)
    z_star = np.asarray(g.z0, dtype=float)
    scale = {
        "names": list(Z_LABELS),
        "units": list(Z_UNITS),
        "zstar": np.abs(z_star).tolist(),
        "cycle": cycle_scale(gait).tolist(),
    }
    out_dir = Path(out) if out is not None else None
    setup = Setup(
        controller=controller,
        gait=gait,
        budget=budget,
        z_star=z_star,
        key=setup_key(controller, gait, budget, seed, extra_sources),
        seed=seed,
    )
    fingerprint = column_fingerprint(
        controller,
        gait=gait,
        budget=budget,
        seed=seed,
        extra_sources=extra_sources,
        files=files,
    )
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if executor is None:
            executor = stack.enter_context(open_pool(scheduler, workers)).executor
        if out_dir is not None:  # once the pool is up: a refused --scheduler leaves nothing
            out_dir.mkdir(parents=True, exist_ok=True)
        cache = TaskCache(out_dir / "cache.jsonl" if (out_dir is not None and use_cache) else None)
        counts: dict = {}
        cyc = _run_all(executor, setup, [("cycle", ())], cache, False, "cycle", counts)
        cyc = cyc[("cycle", ())]
        if "error" in cyc:
            raise RuntimeError(f"no closed-loop cycle: {cyc['error']}")
        setup = replace(
            setup,
            z_cl=np.array(cyc["z_cl"]),
            cycle_steps=int(cyc["cycle_steps"]),
            period=float(cyc["period"]),
        )
        jobs = [("basins", group) for group in BASIN_GROUPS]  # bisections in lockstep
        jobs += [("ceiling", (i, s)) for i in range(6) for s in (1, -1)]
        jobs += [("curve", (r,)) for r in budget.curve_sizes]
        jobs += [("terrain", (v,)) for v in budget.terrain_sigmas]
        chunks = range(math.ceil(budget.mfpt_robots / MFPT_CHUNK))
        jobs += [("mfpt", (v, c)) for v in budget.mfpt_sigmas for c in chunks]
        jobs += [("window", (k, s)) for k in ("alpha_deg", "kc") for s in (-1, 1)]
        jobs += [("push", ("xdot", v, j)) for j, v in enumerate(budget.push_xdot)]
        jobs += [("push", ("th1dot", v, j)) for j, v in enumerate(budget.push_th1dot)]
        if not nominal:
            jobs = []  # the model-error measures only
        res = _run_all(
            executor, setup, jobs, cache, progress, f"margins {controller_name(controller)}", counts
        )
        res.update(basin_results(res))
        mm = {}
        for spec in specs:
            mb = MISMATCH_BUDGETS[mb_name]
            mm_setup = replace(
                setup,
                key=mismatch_key(setup.key, spec, budget, mb_name),
                mismatch=spec,
                mismatch_budget=mb,
            )
            mm_res = _run_all(
                executor,
                mm_setup,
                mismatch_jobs(mb),
                cache,
                progress,
                f"mismatch {spec.name} {controller_name(controller)}",
                counts,
            )
            mm[spec.name] = assemble_mismatch(mm_setup, mm_res)
    if not nominal:
        result = {
            "controller": controller_name(controller),
            "gait": gait,
            "budget": budget.name,
            "seed": seed,
            "nominal": False,
        }
    else:
        result = assemble(controller, gait, budget, z_star, cyc, res, scale, seed)
    result["fingerprint"] = fingerprint  # what decided these numbers, before they were made
    if mm:
        result["mismatch"] = mm
    result["seconds"] = time.perf_counter() - t0
    # the CPU time of the tasks this run computed (in its workers; a cached task's: none)
    result["cpu_seconds"] = counts.pop("cpu_seconds", 0.0)
    result["tasks"] = counts  # taken from the cache, computed: the seconds' meaning
    if out_dir is not None and not nominal:
        atomic_write(out_dir / "margins.json", json.dumps(result, indent=2) + "\n")
    elif out_dir is not None:
        write_outputs(result, out_dir)
    return result
