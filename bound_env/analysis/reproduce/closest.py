"""Stage 2: the alpha and kc closest to the published z*; sensitivity; the paper's secant."""

from __future__ import annotations

import numpy as np

from ...model.params import Params, z_to_paper
from ..fixed_point import find_fixed_point, slope_secant
from .claims import CLAIMS, reproducing_gait
from .points import point_summary, rel_distance
from .settings import CLOSEST_BOUNDS, CLOSEST_KC_XATOL, FP_TOL, Budget


def closest_on_branch(p: Params, key: str, bounds, z_start, z_ref_paper, xatol) -> dict:
    """Minimize rel_distance(z*(v), z_ref) over v in ``bounds`` (bounded Brent), each z*(v)
    by Newton from the nearest value solved so far."""
    from scipy.optimize import minimize_scalar

    solved: dict = {float(p.to_gait_dict()[key]): np.asarray(z_start, float)}

    def dist(v):
        near = min(solved, key=lambda w: abs(w - v))
        r = find_fixed_point(
            p.with_values(**{key: float(v)}), solved[near], tol=FP_TOL, analyse=False
        )
        if not r.converged:
            return 1e3
        solved[float(v)] = r.z
        return rel_distance(z_to_paper(r.z), z_ref_paper)

    opt = minimize_scalar(dist, bounds=bounds, method="bounded", options={"xatol": xatol})
    v = float(opt.x)
    near = min(solved, key=lambda w: abs(w - v))
    pv = p.with_values(**{key: v})
    r = find_fixed_point(pv, solved[near], tol=FP_TOL, recover=False)
    out = {
        "key": key,
        "value": v,
        "distance": rel_distance(z_to_paper(r.z), z_ref_paper),
        "evaluations": int(opt.nfev),
        "bounds": list(bounds),
        **point_summary(pv, r.z),
    }
    out["rel_diff"] = (np.asarray(out["z"]) - z_ref_paper) / np.abs(z_ref_paper)
    return out


def stage_closest(b: Budget, z_star_si, log) -> dict:
    g = reproducing_gait()
    p, zpub = g.params, z_to_paper(g.z_published)
    z_star_si = np.asarray(z_star_si, float)
    out = {"distance_at_published": rel_distance(z_to_paper(z_star_si), zpub)}
    out["alpha"] = closest_on_branch(
        p, "alpha_deg", CLOSEST_BOUNDS["alpha_deg"], z_star_si, zpub, b.search_xatol
    )
    log(f"  closest alpha = {out['alpha']['value']:.5f} deg, d = {out['alpha']['distance']:.4f}")
    out["kc"] = closest_on_branch(
        p, "kc", CLOSEST_BOUNDS["kc"], z_star_si, zpub, CLOSEST_KC_XATOL * b.search_xatol
    )
    log(f"  closest kc = {out['kc']['value']:.3f}, d = {out['kc']['distance']:.4f}")
    # how far z* moves when each published parameter moves by its printed rounding
    gd = p.to_gait_dict()
    sens = {}
    for key, half in {
        **CLAIMS.param_half_digit,
        "alpha_deg_text": CLAIMS.alpha_text_half_digit,
    }.items():
        k = key.replace("_text", "")
        zs = []
        for sgn in (+1.0, -1.0):
            r = find_fixed_point(
                p.with_values(**{k: gd[k] + sgn * 0.1 * half}), z_star_si, tol=FP_TOL, analyse=False
            )
            zs.append(z_to_paper(r.z) if r.converged else np.full(6, np.nan))
        sens[key] = {"half_width": half, "dz_per_half_width": (zs[0] - zs[1]) / 0.2}
    out["sensitivity"] = sens
    out["needed"] = zpub - z_to_paper(z_star_si)  # published minus ours
    # the paper's slope secant (III.D.5, eq. 27) from the published z*
    sec = slope_secant(p, g.z_published)
    out["secant"] = {
        "alpha_deg": sec.alpha_deg,
        "converged": sec.converged,
        "reason": sec.reason,
        "found": sec.fixed_point_found,
        "evaluations": sec.iterations,
    }
    if sec.fixed_point_found:
        pa = p.with_values(alpha_deg=sec.alpha_deg)
        r = find_fixed_point(pa, sec.run.z_last, tol=FP_TOL, recover=False)
        if r.converged:
            out["secant"].update(point_summary(pa, r.z))
    return out
