"""The margins' JSON result from the tasks' results (`assemble`): per-direction entries, the
rate curves with their Wilson intervals and crossings, and the MFPT per slope noise."""

from __future__ import annotations

import math

import numpy as np

from .basin import BASIN_CAP, BASIN_HI, BASIN_LO
from .budget import DEFAULT_SEED, MFPT_CHUNK, MFPT_LEVEL, Budget, sample_seeds
from .closed_loop import EVAL_RTOL, PROFILE_SEG, RETURN_TOL
from .curve import decision_shares, decision_summary
from .decision_times import summary as decision_times
from .report import Z_LABELS, Z_UNITS
from .stats import (
    crossing_on_grid,
    mfpt_crossing,
    mfpt_estimate,
    threshold_on_grid,
    wilson_interval,
)


def controller_name(controller) -> str:
    return str(getattr(controller, "name", None) or type(controller).__name__)


def _direction_entry(r: dict, i: int, scale: dict) -> dict:
    e = {k: r.get(k) for k in ("rel", "abs", "capped", "cap", "cap_reason", "beyond")}
    e["rel_cycle"] = r["abs"] / scale["cycle"][i] if scale["cycle"][i] > 0 else math.nan
    for k in ("mechanism", "geometric", "hip_below_touchdown_from"):
        if k in r:
            e[k] = r[k]
    return e


def _rate_curve(xs, items) -> dict:
    k = [int(c["k"]) for c in items]
    n = [int(c["n"]) for c in items]
    rates = [c["success"] for c in items]
    ci = [wilson_interval(a, b) for a, b in zip(k, n, strict=True)]
    lo, hi = [c[0] for c in ci], [c[1] for c in ci]
    x50 = crossing_on_grid(xs, rates)
    return {
        "success": rates,
        "k": k,
        "n": n,
        "ci_low": lo,
        "ci_high": hi,
        "x50": x50,
        "x50_ci": [min(x50, crossing_on_grid(xs, lo)), max(x50, crossing_on_grid(xs, hi))],
        "x50_grid": threshold_on_grid(xs, rates),
        "x50_at_grid_end": bool(rates and rates[-1] >= 0.5),
    }


def mfpt_curve(budget: Budget, res: dict) -> list[dict]:
    """The MFPT per sigma from the chunks' results (`stats.mfpt_estimate`)."""
    out = []
    chunks = range(math.ceil(budget.mfpt_robots / MFPT_CHUNK))
    for v in budget.mfpt_sigmas:
        parts = [res[("mfpt", (v, c))] for c in chunks]
        completed = sum(sum(p["strides"]) for p in parts)
        fell = sum(sum(p["fell"]) for p in parts)
        reasons: dict = {}
        for p in parts:
            for name, n in p["failures"].items():
                reasons[name] = reasons.get(name, 0) + n
        total = completed + fell  # strides attempted: the failing ones count
        est = mfpt_estimate(total, fell)
        out.append(
            {
                "sigma_deg": v,
                "robots": budget.mfpt_robots,
                "horizon": budget.mfpt_strides,
                "strides_total": int(total),
                "failures": int(fell),
                "mfpt": est["mfpt"],
                "lower_bound": est["lower_bound"],
                "ci": est["ci"],
                "failure_reasons": reasons,
            }
        )
    return out


def assemble(controller, gait, budget, z_star, cyc, res, scale=None, seed=DEFAULT_SEED) -> dict:
    scale = scale or {
        "names": list(Z_LABELS),
        "units": list(Z_UNITS),
        "zstar": np.abs(z_star).tolist(),
        "cycle": [math.nan] * 6,
    }
    basin, ceiling = {}, {}
    worst = (math.inf, None, math.nan)
    worst_cycle = (math.inf, None)
    worst_share = (math.inf, None)
    for i, label in enumerate(Z_LABELS):
        entry = {"unit": Z_UNITS[i], "z_star": float(z_star[i])}
        centry = dict(entry)
        for sign, sym in ((1, "+"), (-1, "-")):
            r = res[("basin", (i, sign))]
            entry[sym] = _direction_entry(r, i, scale)
            c = res.get(("ceiling", (i, sign)))
            if c is not None:
                centry[sym] = _direction_entry(c, i, scale)
                share = r["abs"] / c["abs"] if c["abs"] > 0 else math.nan
                entry[sym]["share"] = share
                if share < worst_share[0]:
                    worst_share = (share, f"{label}{sym}")
            if r.get("rel") is not None and r["rel"] < worst[0]:
                worst = (r["rel"], f"{label}{sym}", r["abs"])
            if entry[sym]["rel_cycle"] < worst_cycle[0]:
                worst_cycle = (entry[sym]["rel_cycle"], f"{label}{sym}")
        basin[label] = entry
        ceiling[label] = centry
    curve = [res[("curve", (r,))] for r in budget.curve_sizes]
    for c in curve:  # results cached before the success counts were kept
        c.setdefault("k", int(round(c["success"] * c["n"])))
    ccurve = _rate_curve(list(budget.curve_sizes), curve)
    terr = [res[("terrain", (v,))] for v in budget.terrain_sigmas]
    tcurve = _rate_curve(list(budget.terrain_sigmas), terr)
    samples = sample_seeds(seed)
    mfpt = (
        mfpt_curve(budget, res) if all(("mfpt", (v, 0)) in res for v in budget.mfpt_sigmas) else []
    )
    push = {}
    for kind, sizes in (("xdot", budget.push_xdot), ("th1dot", budget.push_th1dot)):
        rates = [res[("push", (kind, v, j))]["success"] for j, v in enumerate(sizes)]
        push[kind] = {
            "unit": "m/s" if kind == "xdot" else "rad/s",
            "sizes": list(sizes),
            "success": rates,
            "p50": threshold_on_grid(sizes, rates),
        }
    win = {(k, s): res[("window", (k, s))] for k in ("alpha_deg", "kc") for s in (-1, 1)}
    z_cl = np.array(cyc["z_cl"])
    curve_sizes = [c["size"] for c in curve]
    return {
        "policy": controller_name(controller),
        # it reads the robot's true plant (bound_env.control.privileged): a reference only
        "privileged": getattr(controller, "privileged", False) is True,
        "gait": gait,
        "budget": budget.name,
        "seed": seed,
        "seed_role": "test" if seed == DEFAULT_SEED else "validation (held out)",
        "basin_scale": scale,
        "basin": basin,
        "basin_min": worst[0],
        "basin_min_direction": worst[1],
        "basin_min_abs": worst[2],
        "basin_min_cycle": worst_cycle[0],
        "basin_min_cycle_direction": worst_cycle[1],
        "basin_ceiling": ceiling,
        "basin_share_min": worst_share[0] if worst_share[1] else None,
        "basin_share_min_direction": worst_share[1],
        "basin_curve": {
            "sizes": curve_sizes,
            "success": ccurve["success"],
            "k": ccurve["k"],
            "n": ccurve["n"],
            "ci_low": ccurve["ci_low"],
            "ci_high": ccurve["ci_high"],
            "interval": "95% Wilson",
            "r50": ccurve["x50"],
            "r50_ci": ccurve["x50_ci"],
            "r50_grid": ccurve["x50_grid"],
            "r50_at_grid_end": ccurve["x50_at_grid_end"],
            "directions": budget.curve_dirs,
            "direction_seed": samples["directions"],
            "scale": "zstar",
            # per size, the outcome from each direction (1: returned), directions in the
            # order of random_directions(directions, direction_seed): for paired comparisons
            "outcomes": [c["outcomes"] for c in curve]
            if all("outcomes" in c for c in curve)
            else None,
        },
        "terrain": {
            "sigmas_deg": list(budget.terrain_sigmas),
            "survival": tcurve["success"],
            "k": tcurve["k"],
            "n": tcurve["n"],
            "ci_low": tcurve["ci_low"],
            "ci_high": tcurve["ci_high"],
            "interval": "95% Wilson",
            "runs": budget.terrain_runs,
            "strides": budget.terrain_strides,
            "seeds": [samples["terrain"], samples["terrain"] + budget.terrain_runs - 1],
            "mean_strides": [t["mean_strides"] for t in terr],
            "failures": [t["failures"] for t in terr],
        },
        "terrain_sigma50_deg": tcurve["x50"],
        "terrain_sigma50_grid_deg": tcurve["x50_grid"],
        "terrain_sigma50_ci_deg": tcurve["x50_ci"],
        "terrain_sigma50_at_grid_end": tcurve["x50_at_grid_end"],
        "mfpt": mfpt,
        "mfpt_sigma_100_deg": mfpt_crossing(
            [m["sigma_deg"] for m in mfpt],
            [m["mfpt"] for m in mfpt],
            [m["lower_bound"] for m in mfpt],
            MFPT_LEVEL,
        )
        if mfpt
        else None,
        "mfpt_settings": {
            "robots": budget.mfpt_robots,
            "horizon": budget.mfpt_strides,
            "sigmas_deg": list(budget.mfpt_sigmas),
            "seeds": [samples["mfpt"], samples["mfpt"] + budget.mfpt_robots - 1],
            "level": MFPT_LEVEL,
            "estimator": "strides_total / failures (constant-hazard MLE; censored at the "
            "horizon); no failure: lower bound strides_total; ci: exact Poisson",
        },
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
        "decision_seconds": decision_summary(curve),
        # every apex decision of the controller's own measures (the real-time yardstick)
        "decision_times": decision_times(res.values()),
        # who decided at the apexes of a gated controller (gate / the LQR's plan / override)
        "decision_shares": {
            "curve": decision_shares(curve),
            "terrain": decision_shares(terr + [r for key, r in res.items() if key[0] == "mfpt"]),
        },
        "max_torque": cyc["max_torque"],
        "period": cyc["period"],
        "settings": {
            "return_tol": RETURN_TOL,
            "rtol": EVAL_RTOL,
            "basin_strides": budget.basin_strides,
            "basin_iters": budget.basin_iters,
            "basin_first_bracket": [BASIN_LO, BASIN_HI],
            "basin_cap": BASIN_CAP,
            "window_strides": budget.window_strides,
            "push_samples": budget.push_samples,
            "ceiling": {
                "strides": budget.ceiling_strides,
                "iters": budget.ceiling_iters,
                "random_profiles": budget.ceiling_random,
                "optimizer_iters": budget.ceiling_opt,
                "piece_intervals": PROFILE_SEG,
            },
            "terrain_runs": budget.terrain_runs,
            "terrain_strides": budget.terrain_strides,
            "seed": seed,
            "samples": samples,
            "mfpt_robots": budget.mfpt_robots,
            "mfpt_strides": budget.mfpt_strides,
        },
    }
