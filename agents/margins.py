"""Stability margins of a closed loop, passive or learned, on the same yardsticks.

``bound-env margins --policy passive|PATH`` evaluates the zero action or a trained policy
(deterministic, with its ``VecNormalize`` observation normalization) on PassiveBound.

The closed-loop apex map
------------------------
Everything below is measured on the apex-to-apex map of the closed loop, P_pi: start an
episode at an apex state z with ``reset(options={"apex_state": z})``, step the policy until
the step in which a stride completes, and read ``info["apex_z"]``. Control intervals restart
at the apex (the reset puts t = 0 there and the observation's time-since-apex at 0), so P_pi
is a well defined function of z: the same z always meets the same sequence of control
instants. (Inside one long episode the dt grid drifts against the apex, and the apex
sequence is not exactly a map of z.) Iterating the map = chaining such one-stride episodes.
With zero action P_pi is the passive Poincare map P of the paper (eq. 18), up to the
integrator tolerance (rtol = 1e-10 here).

Measures (JSON keys)
--------------------
- ``emax``, ``eigenvalues``: the closed-loop fixed point z_cl (iteration, then Newton with
  central differences through the simulator with the policy in the loop) and the eigenvalues
  of the Jacobian of P_pi there (``[re, im]`` pairs, largest modulus first);
  ``fixed_point_shift`` = z_cl - z* (SI).
- ``basin``: for each apex component i and each sign, the largest relative perturbation s
  such that the loop started at z_cl + s z*_i e_i *returns*: max_j |z_j - z_cl_j| < 1e-4
  (SI) within a bounded number of strides, without a fall. Found by bisection on log(s)
  between 1e-3 and 1 (1 = 100 %: a direction that reaches it is reported as ``capped``).
  Each entry also has the absolute size |s z*_i| with its unit. ``basin_min`` is the
  smallest over the 12 directions (``basin_min_direction`` names it). The perturbations are
  relative to the *passive* z* for every controller, so the absolute sizes are identical.
- ``basin_curve``: the probability of returning against the size r of a perturbation in a
  random direction: z_cl + r |z*| * u with u uniform on the sphere and scaled to max |u_i| = 1
  (so r is the largest relative perturbation of any component, as in ``basin``); the same
  directions for every size and every controller.
- ``slope_window_deg``, ``kc_window``: the range of slope alpha (deg), and separately of
  spine stiffness k_c (N m/rad), containing the nominal value over which the loop started at
  z_cl survives ``window_strides`` strides (50) without a fall (``gait_overrides``); edges by
  an outward doubling scan, then bisection.
- ``push``: success rate (returns, as for the basin) against the size of a kick in forward
  speed (``xdot``, m/s) and in pitch rate (``th1dot``, rad/s) added to the state at a random
  control instant within a stride of the cycle, with a random sign; ``p50`` is the largest
  size up to which the rate stays >= 50 %.
- ``effort``: mean |tau| (N m, time average) over one stride of the closed-loop cycle, and
  ``effort_frac`` = effort / max_torque.

Evaluations run through a `concurrent.futures` executor (``--workers N`` processes; any
object with ``submit`` returning futures can be passed to `compute_margins`). Every task's
result is cached in ``<out>/cache.jsonl`` under a key of the controller, gait and budget, so
an interrupted run resumes.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import hashlib
import json
import math
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from bound_env.analysis.numerics import (  # noqa: F401 - bisect_threshold: re-exported
    bisect_threshold,
    fd_jacobian,
    map_fixed_point,
    sorted_eigenvalues,
)
from bound_env.cache import TaskCache

from .policy import MLPController, ZeroController, load_controller

ENV_ID = "PassiveBound-v0"
Z_LABELS = ("y_g", "theta1", "theta2", "xdot_g", "theta1dot", "theta2dot")
Z_UNITS = ("m", "rad", "rad", "m/s", "rad/s", "rad/s")
RETURN_TOL = 1e-4  # "returned to the cycle": max-abs apex error below this (SI)
EVAL_RTOL = 1e-10  # integrator tolerance of every evaluation (training uses the env's 1e-8)
BASIN_LO, BASIN_HI = 1e-3, 1.0  # bracket of the relative basin bisection
FD_REL = 1e-4  # central-difference step, relative to max(|z*_i|, FD_FLOOR_i)
FD_FLOOR = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1])  # SI floors of the FD step scale
Y_XDOT, Y_TH1DOT = 4, 6  # indices in the full state y = [x, y, th1, th2, xd, yd, th1d, th2d]


@dataclass(frozen=True)
class Budget:
    """How hard to look (iterations, strides, samples)."""

    name: str
    basin_iters: int  # bisection steps on log(s) per direction
    basin_strides: int  # strides allowed to return
    curve_sizes: tuple  # relative sizes r of random-direction perturbations
    curve_dirs: int  # random directions per size
    window_iters: int  # bisection steps per window edge
    window_strides: int  # strides to survive
    push_xdot: tuple  # kick sizes in xdot [m/s]
    push_th1dot: tuple  # kick sizes in th1dot [rad/s]
    push_samples: int  # random phases/signs per size
    newton_iters: int = 8
    settle_strides: int = 60  # map iterations before Newton


_CURVE_FULL = tuple(float(x) for x in np.round(np.geomspace(0.005, 0.5, 16), 5))
BUDGETS = {
    "test": Budget("test", 3, 40, (0.01, 0.1), 2, 2, 10, (0.1, 0.4), (0.5, 2.0), 2,
                   newton_iters=3, settle_strides=10),
    "quick": Budget("quick", 7, 100, (0.01, 0.02, 0.04, 0.06, 0.1, 0.15, 0.25, 0.4), 12,
                    5, 50, (0.05, 0.1, 0.2, 0.3, 0.4, 0.6, 0.8), (0.25, 0.5, 1.0, 2.0, 3.0, 4.0,
                                                                 6.0), 8),
    "full": Budget("full", 14, 300, _CURVE_FULL, 128, 10, 50,
                   (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5, 0.6, 0.8, 1.0),
                   (0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0), 64),
}
# Window scans: first offset from nominal, doubling up to the limit.
WINDOW_SCAN = {"alpha_deg": (0.005, 4.0), "kc": (0.5, 256.0)}


# --------------------------------------------------------------------------------------------
# Numerics: `bound_env.analysis.numerics` (the names below were defined here and stay importable)
# --------------------------------------------------------------------------------------------


def central_jacobian(f, z, steps) -> np.ndarray:
    """Jacobian of f at z by central differences with per-component ``steps`` (no one-sided
    fallback: a failing side raises). Alias of `numerics.fd_jacobian` with ``one_sided=False``."""
    return fd_jacobian(f, z, steps, one_sided=False)


def find_fixed_point(f, z0, steps, settle: int = 60, newton_iters: int = 8, tol: float = 1e-11):
    """Old name of `bound_env.analysis.numerics.map_fixed_point` (returns (z, residual,
    Jacobian)); `bound_env.analysis.find_fixed_point` is the Poincare map's."""
    return tuple(map_fixed_point(f, z0, steps, settle=settle, newton_iters=newton_iters, tol=tol))


def random_directions(n: int, seed: int = 12345) -> np.ndarray:
    """n directions uniform on the 6-sphere, each scaled to max |u_i| = 1."""
    u = np.random.default_rng(seed).standard_normal((n, 6))
    return u / np.max(np.abs(u), axis=1, keepdims=True)


# --------------------------------------------------------------------------------------------
# The closed loop
# --------------------------------------------------------------------------------------------


@dataclass
class StrideOut:
    """One stride of the closed-loop map."""

    z1: np.ndarray | None
    failure: str | None
    effort: float = math.nan  # time-averaged |tau| [N m]
    period: float = math.nan  # [s]
    steps: int = 0  # control intervals started


class ClosedLoop:
    """A controller in the loop of one PassiveBound environment (no wrappers).

    ``stride(z)`` is the closed-loop apex map (see the module docstring); ``kick`` adds
    ``delta`` to one entry of the simulator state just before control interval ``step``.
    """

    def __init__(self, controller, gait: str = "default", gait_overrides: dict | None = None):
        import gymnasium as gym

        import bound_env

        gym.register_envs(bound_env)
        kwargs = dict(controller.env_kwargs)
        kwargs["gait"] = gait
        overrides = {**(kwargs.get("gait_overrides") or {}), **(gait_overrides or {})}
        kwargs["gait_overrides"] = overrides or None
        kwargs["rtol"] = EVAL_RTOL
        kwargs["reset_noise_scale"] = 0.0
        self.env = gym.make(ENV_ID, **kwargs).unwrapped
        self.controller = controller
        self.max_torque = float(self.env.task.max_torque)
        self.dt = float(self.env.task.dt)
        from bound_env.task import NO_APEX_TIME

        self.max_steps = int(math.ceil(NO_APEX_TIME / self.dt)) + 2
        self.i_since_apex = list(self.env.task.obs_names).index("time_since_apex")

    def stride(self, z, kick: tuple | None = None) -> StrideOut:
        env, ctrl = self.env, self.controller
        obs, info = env.reset(options={"apex_state": np.asarray(z, dtype=float)})
        if info["failure"] is not None:
            return StrideOut(None, info["failure"])
        t_prev, impulse = 0.0, 0.0
        for k in range(self.max_steps):
            if kick is not None and k == kick[0]:
                apply_kick(env, kick[1], kick[2])
            obs, _, terminated, _, info = env.step(np.array([ctrl(obs)]))
            tau = abs(info["tau"])
            if "apex_z" in info:
                t_apex = info["time"] - float(obs[self.i_since_apex])
                impulse += tau * max(0.0, t_apex - t_prev)
                return StrideOut(np.array(info["apex_z"], dtype=float), None,
                                 impulse / t_apex, t_apex, k + 1)
            impulse += tau * (info["time"] - t_prev)
            t_prev = info["time"]
            if terminated:
                return StrideOut(None, info["failure"], steps=k + 1)
        return StrideOut(None, "no_apex", steps=self.max_steps)

    def map(self, z) -> np.ndarray | None:
        return self.stride(z).z1

    def run(self, z0, z_target, max_strides: int, kick: tuple | None = None,
            survive_only: bool = False) -> tuple[bool, int, str | None]:
        """Iterate the map from z0 (the first stride kicked if ``kick``). Returns (success,
        strides, failure): success = returned within RETURN_TOL of ``z_target`` within
        ``max_strides`` (or, with ``survive_only``, did not fall in ``max_strides``)."""
        z = np.asarray(z0, dtype=float)
        for n in range(1, max_strides + 1):
            out = self.stride(z, kick if n == 1 else None)
            if out.z1 is None:
                return False, n, out.failure
            z = out.z1
            if not np.all(np.isfinite(z)):
                return False, n, "non_finite"
            if not survive_only and np.max(np.abs(z - z_target)) < RETURN_TOL:
                return True, n, None
        return survive_only, max_strides, None


def apply_kick(env, index: int, delta: float) -> None:
    """Add ``delta`` to velocity entry ``index`` (4..7) of the simulator state y between two
    control intervals (`bound_env.env.PassiveBoundEnv.kick`). The controller sees it in the
    next observation (a push is sensed one control interval later, like a sampled sensor)."""
    if not 4 <= index <= 7:
        raise ValueError(f"a kick changes a velocity (state index 4..7), got index {index}")
    d = np.zeros(4)
    d[index - 4] = delta
    env.kick(d)


# --------------------------------------------------------------------------------------------
# Tasks (run in worker processes)
# --------------------------------------------------------------------------------------------


@dataclass
class Setup:
    """Everything a worker needs; picklable."""

    controller: object
    gait: str
    budget: Budget
    z_star: np.ndarray
    z_cl: np.ndarray | None = None
    cycle_steps: int = 0
    key: str = ""


_LOOPS: dict = {}


def _loop(setup: Setup, overrides: dict | None = None) -> ClosedLoop:
    k = (setup.key, tuple(sorted((overrides or {}).items())))
    if k not in _LOOPS:
        if len(_LOOPS) > 64:
            _LOOPS.clear()
        _LOOPS[k] = ClosedLoop(setup.controller, setup.gait, overrides)
    return _LOOPS[k]


def fd_steps(z_star) -> np.ndarray:
    return FD_REL * np.maximum(np.abs(np.asarray(z_star)), FD_FLOOR)


def task_cycle(setup: Setup) -> dict:
    """Closed-loop fixed point, multipliers, effort on the cycle."""
    loop = _loop(setup)
    b = setup.budget
    z_cl, res, jac = map_fixed_point(loop.map, setup.z_star, fd_steps(setup.z_star),
                                     settle=b.settle_strides, newton_iters=b.newton_iters)
    lam = sorted_eigenvalues(jac)
    out = loop.stride(z_cl)
    return {
        "z_cl": z_cl.tolist(), "residual": res, "jacobian": jac.tolist(),
        "eigenvalues": [[float(v.real), float(v.imag)] for v in lam],
        "emax": float(np.abs(lam[0])), "effort": out.effort, "period": out.period,
        "cycle_steps": out.steps, "max_torque": loop.max_torque,
    }


def task_basin(setup: Setup, i: int, sign: int) -> dict:
    loop = _loop(setup)
    zs, zc = setup.z_star, setup.z_cl

    def ok(s):
        z = zc.copy()
        z[i] += sign * s * zs[i]
        return loop.run(z, zc, setup.budget.basin_strides)[0]

    s, capped = bisect_threshold(ok, BASIN_LO, BASIN_HI, setup.budget.basin_iters)
    return {"rel": s, "abs": abs(s * zs[i]), "capped": capped}


def task_curve(setup: Setup, size: float) -> dict:
    loop = _loop(setup)
    zs, zc = setup.z_star, setup.z_cl
    wins = 0
    dirs = random_directions(setup.budget.curve_dirs)
    for u in dirs:
        wins += loop.run(zc + size * np.abs(zs) * u, zc, setup.budget.basin_strides)[0]
    return {"size": size, "success": wins / len(dirs), "n": len(dirs)}


def task_window(setup: Setup, key: str, side: int) -> dict:
    """Edge of the survival window of gait parameter ``key`` on one side of nominal."""
    from bound_env.params import load_gait

    nominal = load_gait(setup.gait).params.to_gait_dict()[key]
    overrides0 = dict(setup.controller.env_kwargs.get("gait_overrides") or {})
    nominal = float(overrides0.get(key, nominal))
    first, limit = WINDOW_SCAN[key]
    b = setup.budget

    def survives(offset: float) -> bool:
        value = nominal + side * offset
        if key == "kc" and value <= 0:
            return False
        try:
            loop = _loop(setup, {key: value})
        except ValueError:  # invalid parameter value
            return False
        return loop.run(setup.z_cl, setup.z_cl, b.window_strides, survive_only=True)[0]

    good, bad, d = 0.0, None, first
    while d <= limit:
        if survives(d):
            good, d = d, 2 * d
        else:
            bad = d
            break
    if bad is None:
        return {"edge": nominal + side * good, "capped": True, "nominal": nominal}
    if good == 0.0 and not survives(0.0):
        return {"edge": math.nan, "capped": False, "nominal": nominal}
    for _ in range(b.window_iters):
        mid = 0.5 * (good + bad)
        if survives(mid):
            good = mid
        else:
            bad = mid
    return {"edge": nominal + side * good, "capped": False, "nominal": nominal}


def task_push(setup: Setup, kind: str, size: float, index: int) -> dict:
    loop = _loop(setup)
    y_index = {"xdot": Y_XDOT, "th1dot": Y_TH1DOT}[kind]
    rng = np.random.default_rng([index, 0 if kind == "xdot" else 1, 2024])
    wins = 0
    n = setup.budget.push_samples
    steps = max(1, setup.cycle_steps - 1)
    for _ in range(n):
        k = int(rng.integers(0, steps))
        sign = 1.0 if rng.random() < 0.5 else -1.0
        wins += loop.run(setup.z_cl, setup.z_cl, setup.budget.basin_strides,
                         kick=(k, y_index, sign * size))[0]
    return {"kind": kind, "size": size, "success": wins / n, "n": n}


TASKS = {"cycle": task_cycle, "basin": task_basin, "curve": task_curve, "window": task_window,
         "push": task_push}


def run_task(setup: Setup, name: str, args: tuple) -> dict:
    """Worker entry point: one named task."""
    t0 = time.perf_counter()
    try:
        result = TASKS[name](setup, *args)
    except RuntimeError as e:
        result = {"error": str(e)}
    result["seconds"] = time.perf_counter() - t0
    return result


# --------------------------------------------------------------------------------------------
# Orchestration
# --------------------------------------------------------------------------------------------


class SerialExecutor(cf.Executor):
    """Runs each task at submit time, in this process (``--workers 1``)."""

    def submit(self, fn, /, *args, **kwargs):
        fut = cf.Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as e:  # noqa: BLE001 - delivered through the future
            fut.set_exception(e)
        return fut


def task_key(setup_key: str, name: str, args: tuple) -> str:
    """Cache key of one task: the setup's settings hash, the task name and its arguments."""
    return f"{setup_key}/{name}/{json.dumps(list(args))}"


def _run_all(executor, setup: Setup, jobs: list, cache: TaskCache, progress: bool,
             desc: str) -> dict:
    """Run (name, args) jobs through the executor, using and filling the cache."""
    results, pending = {}, {}
    for name, args in jobs:
        key = task_key(setup.key, name, args)
        hit = cache.get(key)
        if hit is not None:
            results[(name, args)] = hit
        else:
            pending[executor.submit(run_task, setup, name, args)] = (name, args, key)
    bar = None
    if progress and pending:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(jobs), initial=len(results), desc=desc, file=sys.stderr)
    for fut in cf.as_completed(pending):
        name, args, key = pending[fut]
        res = fut.result()
        if "error" not in res:
            cache.put(key, res)
        results[(name, args)] = res
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return results


def setup_key(controller, gait: str, budget: Budget) -> str:
    h = hashlib.sha256(f"{controller.fingerprint()}|{gait}|{asdict(budget)}|{EVAL_RTOL}|"
                       f"{RETURN_TOL}".encode())
    return h.hexdigest()[:16]


def compute_margins(policy="passive", budget: str | Budget = "quick", gait: str = "default",
                    workers: int = 1, executor=None, out: str | Path | None = None,
                    progress: bool = False, use_cache: bool = True) -> dict:
    """All margins of ``policy`` (``"passive"``, a path, or a controller) as a JSON-able dict.

    ``executor``: any `concurrent.futures.Executor`-like object; default: a process pool of
    ``workers`` processes (in-process when ``workers == 1``). ``out``: directory for the
    CSV/PNG outputs and the task cache.
    """
    from bound_env.params import load_gait

    if isinstance(budget, str):
        if budget not in BUDGETS:
            raise ValueError(f"budget must be one of {sorted(BUDGETS)}, got {budget!r}")
        budget = BUDGETS[budget]
    if workers < 1:
        raise ValueError(f"--workers must be at least 1, got {workers}")
    controller = policy if isinstance(policy, (MLPController, ZeroController)) else \
        load_controller(policy)
    g = load_gait(gait)
    z_star = np.asarray(g.z0, dtype=float)
    out_dir = Path(out) if out is not None else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    cache = TaskCache(out_dir / "cache.jsonl" if (out_dir is not None and use_cache) else None)
    setup = Setup(controller=controller, gait=gait, budget=budget, z_star=z_star,
                  key=setup_key(controller, gait, budget))
    own = executor is None
    if own:
        executor = SerialExecutor() if workers == 1 else cf.ProcessPoolExecutor(workers)
    t0 = time.perf_counter()
    try:
        cyc = _run_all(executor, setup, [("cycle", ())], cache, False, "cycle")[("cycle", ())]
        if "error" in cyc:
            raise RuntimeError(f"no closed-loop cycle: {cyc['error']}")
        setup = replace(setup, z_cl=np.array(cyc["z_cl"]), cycle_steps=int(cyc["cycle_steps"]))
        jobs = [("basin", (i, s)) for i in range(6) for s in (1, -1)]
        jobs += [("curve", (r,)) for r in budget.curve_sizes]
        jobs += [("window", (k, s)) for k in ("alpha_deg", "kc") for s in (-1, 1)]
        jobs += [("push", ("xdot", v, j)) for j, v in enumerate(budget.push_xdot)]
        jobs += [("push", ("th1dot", v, j)) for j, v in enumerate(budget.push_th1dot)]
        res = _run_all(executor, setup, jobs, cache, progress, f"margins {controller.name}")
    finally:
        if own:
            executor.shutdown()
    result = assemble(controller, gait, budget, z_star, cyc, res)
    result["seconds"] = time.perf_counter() - t0
    if out_dir is not None:
        write_outputs(result, out_dir)
    return result


def _p50(sizes, success) -> float:
    """Largest size up to which the success rate stays >= 0.5 (0 if the first is below)."""
    best = 0.0
    for s, p in zip(sizes, success, strict=True):
        if p < 0.5:
            break
        best = s
    return best


def assemble(controller, gait, budget, z_star, cyc, res) -> dict:
    basin = {}
    worst = (math.inf, None, math.nan)
    for i, label in enumerate(Z_LABELS):
        entry = {"unit": Z_UNITS[i], "z_star": float(z_star[i])}
        for sign, sym in ((1, "+"), (-1, "-")):
            r = res[("basin", (i, sign))]
            entry[sym] = {k: r.get(k) for k in ("rel", "abs", "capped")}
            if r.get("rel") is not None and r["rel"] < worst[0]:
                worst = (r["rel"], f"{label}{sym}", r["abs"])
        basin[label] = entry
    curve = [res[("curve", (r,))] for r in budget.curve_sizes]
    push = {}
    for kind, sizes in (("xdot", budget.push_xdot), ("th1dot", budget.push_th1dot)):
        rates = [res[("push", (kind, v, j))]["success"] for j, v in enumerate(sizes)]
        push[kind] = {"unit": "m/s" if kind == "xdot" else "rad/s", "sizes": list(sizes),
                      "success": rates, "p50": _p50(sizes, rates)}
    win = {(k, s): res[("window", (k, s))] for k in ("alpha_deg", "kc") for s in (-1, 1)}
    z_cl = np.array(cyc["z_cl"])
    curve_sizes = [c["size"] for c in curve]
    curve_rates = [c["success"] for c in curve]
    return {
        "policy": controller.name,
        "gait": gait,
        "budget": budget.name,
        "basin": basin,
        "basin_min": worst[0],
        "basin_min_direction": worst[1],
        "basin_min_abs": worst[2],
        "basin_curve": {"sizes": curve_sizes, "success": curve_rates,
                        "r50": _p50(curve_sizes, curve_rates),
                        "directions": budget.curve_dirs},
        "emax": cyc["emax"],
        "eigenvalues": cyc["eigenvalues"],
        "z_star": z_star.tolist(),
        "z_cl": z_cl.tolist(),
        "fixed_point_shift": (z_cl - z_star).tolist(),
        "fixed_point_residual": cyc["residual"],
        "slope_window_deg": [win[("alpha_deg", -1)]["edge"], win[("alpha_deg", 1)]["edge"]],
        "slope_window_capped": [win[("alpha_deg", -1)]["capped"], win[("alpha_deg", 1)]["capped"]],
        "slope_nominal_deg": win[("alpha_deg", 1)]["nominal"],
        "kc_window": [win[("kc", -1)]["edge"], win[("kc", 1)]["edge"]],
        "kc_window_capped": [win[("kc", -1)]["capped"], win[("kc", 1)]["capped"]],
        "kc_nominal": win[("kc", 1)]["nominal"],
        "push": push,
        "effort": cyc["effort"],
        "effort_frac": cyc["effort"] / cyc["max_torque"],
        "max_torque": cyc["max_torque"],
        "period": cyc["period"],
        "settings": {"return_tol": RETURN_TOL, "rtol": EVAL_RTOL,
                     "basin_strides": budget.basin_strides, "basin_iters": budget.basin_iters,
                     "window_strides": budget.window_strides,
                     "push_samples": budget.push_samples},
    }


# --------------------------------------------------------------------------------------------
# Outputs
# --------------------------------------------------------------------------------------------


def write_outputs(result: dict, out_dir: Path) -> None:
    """margins.json, basin.csv, curve.csv, push.csv and PNG plots."""
    (out_dir / "margins.json").write_text(json.dumps(result, indent=2) + "\n")
    with (out_dir / "basin.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["component", "unit", "sign", "rel", "abs", "capped"])
        for label, e in result["basin"].items():
            for sym in ("+", "-"):
                w.writerow([label, e["unit"], sym, e[sym]["rel"], e[sym]["abs"], e[sym]["capped"]])
    with (out_dir / "curve.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["size_rel", "success"])
        for s, p in zip(result["basin_curve"]["sizes"], result["basin_curve"]["success"],
                        strict=True):
            w.writerow([s, p])
    with (out_dir / "push.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["kind", "unit", "size", "success"])
        for kind, e in result["push"].items():
            for s, p in zip(e["sizes"], e["success"], strict=True):
                w.writerow([kind, e["unit"], s, p])
    plot_margins([result], out_dir)


def plot_margins(results: list[dict], out_dir: Path, prefix: str = "") -> list[Path]:
    """basin, curve and push plots of one or more results (one colour each)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    paths = []
    labels = [r.get("label") or r["policy"] for r in results]

    fig, ax = plt.subplots(figsize=(7.0, 3.6), dpi=100)
    names = [f"{lab}{s}" for lab in Z_LABELS for s in ("+", "-")]
    x = np.arange(len(names))
    wbar = 0.8 / len(results)
    for k, (r, lab) in enumerate(zip(results, labels, strict=True)):
        vals = [r["basin"][c][s]["rel"] for c in Z_LABELS for s in ("+", "-")]
        ax.bar(x + (k - (len(results) - 1) / 2) * wbar, vals, wbar, label=lab)
    if any(r["basin"][c][s]["rel"] > 0 for r in results for c in Z_LABELS for s in "+-"):
        ax.set_yscale("log")  # an empty basin (all zero) has nothing to put on a log axis
    ax.set_xticks(x, names, rotation=45, ha="right")
    ax.set_ylabel("largest relative perturbation")
    ax.set_title("Basin along each apex component (capped at 1)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}basin.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.0, 3.4), dpi=100)
    for r, lab in zip(results, labels, strict=True):
        ax.plot(r["basin_curve"]["sizes"], r["basin_curve"]["success"], "o-", label=lab)
    ax.set_xscale("log")
    ax.set_xlabel("relative perturbation size r (random direction)")
    ax.set_ylabel("P(return)")
    ax.set_ylim(-0.05, 1.05)
    ax.legend(fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}curve.png")
    fig.savefig(paths[-1])
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.4), dpi=100)
    for ax, kind, unit in ((axes[0], "xdot", "m/s"), (axes[1], "th1dot", "rad/s")):
        for r, lab in zip(results, labels, strict=True):
            ax.plot(r["push"][kind]["sizes"], r["push"][kind]["success"], "o-", label=lab)
        ax.set_xlabel(f"kick in {kind} [{unit}]")
        ax.set_ylabel("success rate")
        ax.set_ylim(-0.05, 1.05)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}push.png")
    fig.savefig(paths[-1])
    plt.close(fig)
    return paths


def summary_text(r: dict) -> str:
    """A few human-readable lines."""
    lines = [
        f"policy {r['policy']}  gait {r['gait']}  budget {r['budget']}  ({r['seconds']:.1f} s)",
        f"basin_min {r['basin_min']:.4g} ({r['basin_min_direction']}, "
        f"abs {r['basin_min_abs']:.4g})",
        f"emax {r['emax']:.4f}   fixed-point shift max |dz| "
        f"{np.max(np.abs(r['fixed_point_shift'])):.3g}",
        f"slope window {r['slope_window_deg'][0]:.4f} .. {r['slope_window_deg'][1]:.4f} deg   "
        f"kc window {r['kc_window'][0]:.2f} .. {r['kc_window'][1]:.2f} N m/rad",
        f"push p50: xdot {r['push']['xdot']['p50']:g} m/s, th1dot {r['push']['th1dot']['p50']:g}"
        f" rad/s   effort {r['effort']:.3g} N m ({100 * r['effort_frac']:.2f} % of max torque)",
    ]
    return "\n".join(lines)
