"""Stage 5: the literal reading."""

from __future__ import annotations

import math

import numpy as np

from ...model.params import Params, z_to_paper, z_to_si
from ..fixed_point import find_fixed_point, slope_secant
from ..poincare import apex_energy, stride
from ..stability import spine_oscillations
from .claims import literal_gait, reproducing_gait
from .paths import arclength_path, natural_path, refine_emax_crossing
from .points import point_summary, rel_distance
from .reproducing import hip_margins
from .settings import (
    FP_TOL,
    HOMOTOPY_DS,
    HOMOTOPY_DS_MAX,
    LITERAL_ALPHA_DS,
    LITERAL_ALPHA_DS_MAX,
    LITERAL_PATH_STEP,
    LITERAL_RECORD_DT,
    MULTISTART_REL,
    MULTISTART_SEED,
    MULTISTART_WIDE,
    RELAXED_LEG_FRAC,
    Budget,
)
from .stiff import path_points


def min_leg_fraction(z, params: Params, hi=0.25) -> dict:
    """Bisect min_leg_frac: the shortest stance leg (fraction of l_bar) of the stride from z,
    and how the stride ends when legs may compress that far."""
    base = stride(z, params.with_values(min_leg_frac=hi))
    if base.failure not in ("leg_overcompressed_back", "leg_overcompressed_front"):
        return {"below": None, "failure_relaxed": base.failure}
    lo_f, hi_f = 1e-3, hi  # overcompressed at hi_f, not at lo_f (checked below)
    r_lo = stride(z, params.with_values(min_leg_frac=lo_f))
    if r_lo.failure in ("leg_overcompressed_back", "leg_overcompressed_front"):
        return {"below": lo_f, "failure_relaxed": r_lo.failure}
    for _ in range(30):
        mid = 0.5 * (lo_f + hi_f)
        r = stride(z, params.with_values(min_leg_frac=mid))
        if r.failure == base.failure:
            hi_f = mid
        else:
            lo_f = mid
    return {
        "min_leg_frac_reached": 0.5 * (lo_f + hi_f),
        "failure_relaxed": r_lo.failure,
        "phases_relaxed": r_lo.phases,
        "durations_relaxed": r_lo.durations,
    }


def stage_literal(b: Budget, z_star_si, log) -> dict:
    gl, gr = literal_gait(), reproducing_gait()
    pl, zpub = gl.params, gl.z_published
    relaxed = pl.with_values(min_leg_frac=RELAXED_LEG_FRAC)
    out = {"params": pl.to_gait_dict()}
    s = stride(zpub, pl, record_dt=LITERAL_RECORD_DT)
    out["stride_from_published"] = {
        "failure": s.failure,
        "phases": s.phases,
        "durations": s.durations,
        "t_end": s.t_end,
    }
    out["leg_compression"] = min_leg_fraction(zpub, pl)
    nw = find_fixed_point(pl, zpub, recover=False)
    out["newton_from_published"] = {"converged": nw.converged, "reason": nw.reason}
    sec = slope_secant(pl, zpub, max_iter=3)
    out["secant_from_published"] = {"reason": sec.reason, "found": sec.fixed_point_found}
    # multi-start Newton around the published z* (legs may compress to 5 % while searching)
    rng = np.random.default_rng(MULTISTART_SEED)
    rel = np.array(MULTISTART_REL)
    wide = np.array(MULTISTART_WIDE)
    found, n_conv = [], 0
    zp = z_to_paper(zpub)
    for i in range(b.literal_starts):
        if i < b.literal_starts // 2:
            z0 = zpub * (1.0 + rel * rng.uniform(-1, 1, 6)) if i else zpub.copy()
        else:
            z0 = z_to_si(zp + wide * rng.uniform(-1, 1, 6))
        r = find_fixed_point(relaxed, z0, recover=False, analyse=False, max_iter=30)
        if not r.converged:
            continue
        n_conv += 1
        if not any(np.max(np.abs(r.z - q)) < 1e-6 for q in found):
            found.append(r.z)
    analysed = []
    for z in found:  # each one again at the default leg limit, with its eigenvalues
        r = find_fixed_point(pl, z, tol=FP_TOL, recover=False)
        if not r.converged:
            r = find_fixed_point(pl, z, recover=False)
        analysed.append(
            {
                "converged_default_leg_limit": r.converged,
                "reason": r.reason,
                **(point_summary(pl, r.z) if r.converged else {"z": z_to_paper(z)}),
            }
        )
    out["multistart"] = {
        "starts": b.literal_starts,
        "converged": n_conv,
        "distinct": [z_to_paper(z) for z in found],
        "analysed": analysed,
    }
    log(f"  literal multi-start: {n_conv}/{b.literal_starts} converged, {len(found)} distinct")
    # homotopy: reproducing -> literal geometry, alpha freed, speed pinned at z*'s
    z_star_si = np.asarray(z_star_si, float)
    pr = gr.params

    def geom(lam):
        d = {
            k: getattr(pr, k) + lam * (getattr(pl, k) - getattr(pr, k))
            for k in ("l1", "l2", "I1", "I2")
        }
        return pr.with_values(**d, min_leg_frac=RELAXED_LEG_FRAC)

    hom = arclength_path(
        geom,
        0.0,
        1.0,
        np.append(z_star_si, pr.to_gait_dict()["alpha_deg"]),
        free=("alpha_deg",),
        pins=[("xdot_g", float(z_star_si[3]))],
        ds=HOMOTOPY_DS,
        ds_max=HOMOTOPY_DS_MAX,
    )
    out["homotopy"] = {
        "reason": hom.reason,
        "reached": hom.reached,
        "folds": hom.folds,
        "points": [
            {"lambda": s, "alpha_deg": float(u[6]), "z": z_to_paper(u[:6])} for s, u in hom.points
        ],
    }
    z_lit = None
    if hom.reached:
        a_end, z_end = float(hom.points[-1][1][6]), hom.points[-1][1][:6]
        log(f"  homotopy reached the literal geometry at alpha = {a_end:.4f} deg")
        pa = relaxed

        def alpha_of(a):
            return pa.with_values(alpha_deg=a)

        arc = arclength_path(
            alpha_of,
            a_end,
            float(pl.to_gait_dict()["alpha_deg"]),
            z_end,
            ds=LITERAL_ALPHA_DS,
            ds_max=LITERAL_ALPHA_DS_MAX,
        )
        out["alpha_continuation"] = {
            "reason": arc.reason,
            "reached": arc.reached,
            "folds": arc.folds,
            "points": [{"alpha_deg": s, "z": z_to_paper(u[:6])} for s, u in arc.points],
        }
        if arc.reached:
            z_lit = arc.points[-1][1][:6]
    cands = ([z_lit] if z_lit is not None else []) + found
    fp = None
    for z0 in cands:  # at the published parameters with the default leg limit
        r = find_fixed_point(pl, z0, tol=FP_TOL)
        if not r.converged:
            r = find_fixed_point(pl, z0)
        if r.converged:
            fp = r
            break
    if fp is None:
        out["fixed_point"] = None
        return out
    out["fixed_point"] = {
        **point_summary(pl, fp.z),
        "z_si": fp.z,
        "strides_to_converge": fp.strides_to_converge,
        "homotopy_agrees": bool(z_lit is not None and np.max(np.abs(fp.z - z_lit)) < 1e-6),
        "distance_to_published": rel_distance(z_to_paper(fp.z), zp),
    }
    log(f"  literal fixed point at the published parameters: e_max = {fp.emax:.4f}")
    osc = spine_oscillations(fp.z, pl)
    out["fixed_point"]["spine_count"] = osc.count
    out["fixed_point"]["hip_margins"] = hip_margins(fp.z, pl)
    # the paper's path towards stiffer spines: alpha balances the energy (pinned)
    e_l = apex_energy(fp.z, pl)
    res = natural_path(
        pl,
        np.append(fp.z, pl.to_gait_dict()["alpha_deg"]),
        math.log(b.literal_kc_max),
        [("energy", e_l)],
        h0=LITERAL_PATH_STEP,
        h_max=b.path_step_max,
    )
    pts = path_points(res)
    out["kc_path"] = {
        "reason": res.reason,
        "reached": res.reached,
        "ladder": res.ladder,
        "points": pts,
    }
    stable = [q["kc"] for q in pts if q["emax"] is not None and q["emax"] < 1.0]
    out["kc_path"]["first_stable_kc"] = min(stable) if stable else None
    # every crossing of e_max = 1 along the path, bisected
    crossings = []
    for q0, q1 in zip(pts, pts[1:], strict=False):
        if q0["emax"] is None or q1["emax"] is None or (q0["emax"] >= 1) == (q1["emax"] >= 1):
            continue
        kcs = refine_emax_crossing(pl, q0, q1, [("energy", e_l)])
        crossings.append(
            {
                "kc": 0.5 * (kcs[0] + kcs[1]),
                "bracket": kcs,
                "becomes": "stable" if q1["emax"] < 1 else "unstable",
            }
        )
    out["kc_path"]["crossings"] = crossings
    first = [c for c in crossings if c["becomes"] == "stable"]
    if first:
        out["kc_path"]["crossing"] = first[0]["bracket"]
    em = [q for q in pts if q["emax"] is not None]
    if em:
        low = min(em, key=lambda q: q["emax"])
        out["kc_path"]["min_emax"] = {"emax": low["emax"], "kc": low["kc"]}
    return out
