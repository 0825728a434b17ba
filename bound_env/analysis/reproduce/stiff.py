"""Stage 4: the stiff-spine bound and the paths down to the published kc (Figs. 3-4)."""

from __future__ import annotations

import math

import numpy as np

from ..fixed_point import find_fixed_point
from ..poincare import apex_energy
from .claims import reproducing_gait
from .paths import arclength_path, natural_path, refine_emax_crossing
from .points import point_summary
from .settings import ARC_STEP_MAX, FP_TOL, STIFF_ALPHA0_DEG, Budget


def path_points(res, log=None) -> list:
    """`point_summary` of every point of a continuation path."""
    pts = []
    for p, z in res.points:
        pts.append(point_summary(p, z))
    return pts


def stage_stiff(b: Budget, z_star_si, log) -> dict:
    g = reproducing_gait()
    p0 = g.params
    z_star_si = np.asarray(z_star_si, float)
    e_star = apex_energy(z_star_si, p0)
    v_star = float(z_star_si[3])
    kc_s = b.kc_stiff
    # the stiff-spine start: published gamma, k; alpha freed, forward speed pinned at z*'s
    p_s = p0.with_values(kc=kc_s, alpha_deg=STIFF_ALPHA0_DEG)
    st = find_fixed_point(
        p_s, g.z_published, free=("alpha_deg",), pin=[("xdot_g", v_star)], tol=FP_TOL, recover=False
    )
    out = {"kc_stiff": kc_s, "energy_star": e_star, "xdot_star": v_star}
    if not st.converged:
        out["start"] = {"converged": False, "reason": st.reason}
        return out
    e_s = apex_energy(st.z, st.params)
    out["start"] = {"converged": True, **point_summary(st.params, st.z)}
    log(
        f"  stiff start kc = {kc_s:g}: alpha = {st.free['alpha_deg']:.6f} deg, "
        f"E = {e_s:.3f} J, e_max = {st.emax:.4f}"
    )
    u_s = np.append(st.z, st.free["alpha_deg"])
    s_to = math.log(float(p0.kc))
    paths = {}
    for name, pins in (("speed", [("xdot_g", v_star)]), ("energy", [("energy", e_s)])):
        res = natural_path(st.params, u_s, s_to, pins, h0=b.path_step, h_max=b.path_step_max)
        paths[name] = {
            "pins": pins,
            "reason": res.reason,
            "reached": res.reached,
            "ladder": res.ladder,
            "points": path_points(res),
        }
        end = paths[name]["points"][-1] if paths[name]["points"] else None
        if end:
            log(
                f"  path '{name}': {res.reason}; at kc = {end['kc']:.2f} alpha = "
                f"{end['alpha_deg']:.5f} deg, e_max = {end['emax']:.4f}"
            )
    # the energy level of the published gait followed upwards, round any fold
    p_pub = p0

    def params_of(s):
        return p_pub.with_values(kc=math.exp(s))

    arc = arclength_path(
        params_of,
        math.log(p0.kc),
        math.log(kc_s),
        np.append(z_star_si, p0.to_gait_dict()["alpha_deg"]),
        free=("alpha_deg",),
        pins=[("energy", e_star)],
        ds=b.arc_step,
        ds_max=ARC_STEP_MAX * b.arc_step,
    )
    apts = []
    for s, u in arc.points:
        pp = p_pub.with_values(kc=math.exp(s), alpha_deg=float(u[6]))
        apts.append(point_summary(pp, u[:6]))
    loss = None
    for q0, q1 in zip(apts, apts[1:], strict=False):
        if q0["emax"] is not None and q1["emax"] is not None and q0["emax"] < 1 <= q1["emax"]:
            loss = refine_emax_crossing(p_pub, q0, q1, [("energy", e_star)])
            break
    paths["energy_star"] = {
        "pins": [("energy", e_star)],
        "reason": arc.reason,
        "stability_loss_kc": loss,
        "reached": arc.reached,
        "ladder": [],
        "folds_kc": [math.exp(s) for s in arc.folds],
        "points": apts,
    }
    log(
        f"  published energy level: {arc.reason}; folds at kc = "
        f"{[round(math.exp(s), 2) for s in arc.folds]}"
    )
    out["paths"] = paths
    # the stiff family at kc_s: fixed points against the pinned forward speed
    fam = []
    for direction in (+1.0, -1.0):
        zp, z, a = None, st.z.copy(), st.free["alpha_deg"]
        for i in range(b.family_max):
            v = float(st.z[3]) + direction * b.family_step * i
            pred = z if zp is None else 2 * z - zp
            r = find_fixed_point(
                st.params.with_values(alpha_deg=a),
                pred,
                free=("alpha_deg",),
                pin=[("xdot_g", v)],
                tol=FP_TOL,
                recover=False,
                analyse=False,
            )
            if not r.converged:
                break
            zp, z, a = z, r.z, r.free["alpha_deg"]
            if i > 0 or direction > 0:
                fam.append(point_summary(r.params, r.z, xdot=v))
    fam.sort(key=lambda q: q["xdot"])
    out["family"] = fam
    if fam:
        m = min(fam, key=lambda q: q["energy"])
        out["family_min_energy"] = {"energy": m["energy"], "xdot": m["xdot"]}
        log(
            f"  stiff family: E from {m['energy']:.3f} J (xdot {m['xdot']:.3f}); "
            f"published gait's E = {e_star:.3f} J"
        )
    return out
