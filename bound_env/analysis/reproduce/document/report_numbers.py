"""The numbers REPRODUCTION.md reads: the stage results and every number computed from them.

`derive` computes what the text needs that a stage did not store (differences to the paper,
windows' shifts, predicted strides, selections) into one `Derived`; `window_edges` reads what
happens at a sweep window's edges. Nothing here formats or simulates. The paper's numbers come
from `claims` (the gait files and the one claims table).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...stability import RECOVERY_REL, RECOVERY_TOL
from ..claims import CLAIMS, published

VISUAL_FRACTION = 0.01  # "by eye": every component within 1 % of its own peak deviation
KC_MATCH = 1e-6  # a path's last point is at the published kc within this [N m/rad]
GAP_PHASES = ["df", "bs", "df", "fs"]  # the stride's start with the short bs -> fs flight


@dataclass
class Derived:
    """The stage results the text reads, and every number computed from them."""

    R: dict  # stage results: reproducing, closest, sweeps, stiff, literal
    C: dict
    S: dict
    T: dict
    L: dict
    quick: bool
    refine: int  # bisections of each window edge
    fp: dict  # our fixed point at the published parameters
    z: list  # its z (paper units)
    zp: tuple  # the published z*
    diff: list  # z - zp per component
    rel: list  # diff / |zp|
    emax: float
    sp: dict  # the stride from the published z*
    ca: dict  # the closest alpha and kc
    ck: dict
    gap_star: float | None  # the short bs -> fs flight [s]: at z*, from the published z*, ...
    gap_pub: float | None
    gap_ca: float | None  # ... at the closest alpha
    rec_p: dict  # recovery after +1 % and -1 % on y_g
    rec_m: dict
    vis: list  # strides until within VISUAL_FRACTION of the peak, for +1 %, -1 %
    n_pred: float | None  # strides of a linear decay e_max^n from 1 % of y_g to the tolerance
    n_pred_paper: float  # ... at the paper's e_max
    all_ok: bool  # all 12 perturbations recover
    max_rec: int | None
    sa: dict  # the sweeps in alpha and kc
    sk: dict
    alpha_shift: tuple | None  # our 100-stride window minus the paper's (lower, upper)
    kc_shift: tuple | None
    d_alpha_closest: float  # closest alpha minus the published one
    d_kc_closest: float
    ds_from_alpha: float | None  # ds onset minus the published value
    ds_from_kc: float | None
    gap_star_diff: float | None  # gap at z* minus the paper's [s]
    spn: dict  # spine oscillations
    th2min: float
    th2max: float
    th2_pp: float  # peak-to-peak
    amp_half: float
    amp_peak: float
    swings: list
    a_text: dict  # the fixed point at the text's alpha
    d_text: float  # its distance to the published z*
    d_pub: float
    zdiff_text: float  # max |dz*| between the two slopes
    dmp: dict
    paths: dict
    psp: dict | None  # the three stiff-spine paths
    pen: dict | None
    pes: dict | None
    end_sp: dict | None
    end_en: dict | None
    zdiff_speed_end: float | None  # the speed path's end against our z*
    emx_speed: list  # e_max along the speed path
    st0: dict
    fam_min: dict | None
    loss_kc: float | None  # the published energy level loses stability here
    max_kc_pes: float | None  # ... and folds here
    lf: dict | None  # the literal reading's fixed point and path
    kp: dict
    ms_ok: list
    ms_all_unstable: bool
    ds_stable: bool
    crossing_kc: float | None
    need_y: float  # published minus ours in y_g
    y_max_move: float  # largest move of y_g* within any parameter's printed rounding
    energy_gap: float  # apex energy of the published z* minus ours [J]
    hip_min: float  # smallest hip margin of the two reproducing strides [m]
    hip_liftoff_angles: dict  # leg -> leg angle at a liftoff below the touchdown height [deg]
    cs: dict  # compute seconds per stage
    cs_total: float
    path_ends: dict  # path name -> its last point if that is at the published kc, else None
    y_half_digits: float  # half-digits of rounding needed to move y_g* by need_y


def _gap(q) -> float | None:
    return q["durations"][2] if q["phases"][:4] == GAP_PHASES else None


def derive(results: dict) -> Derived:
    pub = published()
    R, C, S = results["reproducing"], results["closest"], results["sweeps"]
    T, L = results["stiff"], results["literal"]
    fp = R["fixed_point"]
    z, zp = fp["z"], pub.z
    diff = [z[i] - zp[i] for i in range(6)]
    emax = fp["emax"]
    ca, ck = C["alpha"], C["kc"]
    sa, sk = S["alpha_deg"], S["kc"]
    all_rec = R["recovery_all"]
    spn = R["spine"]
    th2min, th2max = spn["theta2_min_deg"], spn["theta2_max_deg"]
    ext = spn["extrema_theta2_deg"]
    a_text = R["alpha_193"]
    paths = T.get("paths") or {}
    psp, pen, pes = paths.get("speed"), paths.get("energy"), paths.get("energy_star")
    end_sp = psp["points"][-1] if psp and psp["points"] else None
    lf = L.get("fixed_point")
    kp = L.get("kc_path") or {}
    ms_ok = [q for q in L["multistart"].get("analysed", []) if q.get("converged_default_leg_limit")]
    sens = C["sensitivity"]
    hm, hp = R["hip_margins"], R["hip_margins_published"]
    cs = results["compute_seconds"]
    y_start = RECOVERY_REL * z[0]
    return Derived(
        R=R,
        C=C,
        S=S,
        T=T,
        L=L,
        quick=results["budget"]["name"] != "full",
        refine=results["budget"]["refine"],
        fp=fp,
        z=z,
        zp=zp,
        diff=diff,
        rel=[diff[i] / abs(zp[i]) for i in range(6)],
        emax=emax,
        sp=R["stride_from_published"],
        ca=ca,
        ck=ck,
        gap_star=_gap(fp),
        gap_pub=_gap(R["stride_from_published"]),
        gap_ca=_gap(ca),
        rec_p=R["recovery"][0],
        rec_m=R["recovery"][1],
        vis=[_visual_strides(r, z) for r in R["recovery"]],
        n_pred=math.log(RECOVERY_TOL / y_start) / math.log(emax) if emax and emax < 1 else None,
        n_pred_paper=math.log(RECOVERY_TOL / y_start) / math.log(CLAIMS.emax),
        all_ok=all(r["strides"] is not None for r in all_rec),
        max_rec=max((r["strides"] for r in all_rec if r["strides"] is not None), default=None),
        sa=sa,
        sk=sk,
        alpha_shift=_shift(sa["converged_window"], CLAIMS.alpha_window),
        kc_shift=_shift(sk["converged_window"], CLAIMS.kc_window),
        d_alpha_closest=ca["value"] - pub.alpha_deg,
        d_kc_closest=ck["value"] - pub.kc,
        ds_from_alpha=sa["ds_from"] and sa["ds_from"] - pub.alpha_deg,
        ds_from_kc=sk["ds_from"] and sk["ds_from"] - pub.kc,
        gap_star_diff=_gap(fp) and _gap(fp) - CLAIMS.gap_s,
        spn=spn,
        th2min=th2min,
        th2max=th2max,
        th2_pp=th2max - th2min,
        amp_half=0.5 * (th2max - th2min),
        amp_peak=max(abs(th2min), abs(th2max)),
        swings=[abs(b - a) for a, b in zip(ext, ext[1:], strict=False)],
        a_text=a_text,
        d_text=_rel_dist(a_text["z"], zp),
        d_pub=C["distance_at_published"],
        zdiff_text=_zdiff(a_text, fp),
        dmp=R["damping"],
        paths=paths,
        psp=psp,
        pen=pen,
        pes=pes,
        end_sp=end_sp,
        end_en=pen["points"][-1] if pen and pen["points"] else None,
        zdiff_speed_end=_zdiff(end_sp, fp) if end_sp else None,
        emx_speed=[q["emax"] for q in psp["points"] if q["emax"] is not None] if psp else [],
        st0=T.get("start") or {},
        fam_min=T.get("family_min_energy"),
        loss_kc=_loss(pes),
        max_kc_pes=_max_kc(pes),
        lf=lf,
        kp=kp,
        ms_ok=ms_ok,
        ms_all_unstable=all(q["emax"] > 1 for q in ms_ok),
        ds_stable=any(
            q["has_ds"] for q in kp.get("points", []) if q["emax"] is not None and q["emax"] < 1
        ),
        crossing_kc=0.5 * (kp["crossing"][0] + kp["crossing"][1]) if kp.get("crossing") else None,
        need_y=C["needed"][0],
        y_max_move=max(abs(s["dz_per_half_width"][0]) for s in sens.values()),
        energy_gap=R["energy_published_z"] - fp["energy"],
        hip_min=min((_min_margin(m) for m in (hm, hp) if m), default=math.nan),
        hip_liftoff_angles=_liftoff_angles(hm, R["params"]),
        cs=cs,
        cs_total=sum(v for v in cs.values() if v),
        path_ends={name: _end_at(pth, pub.kc) for name, pth in paths.items()},
        y_half_digits=abs(C["needed"][0])
        / max(abs(s["dz_per_half_width"][0]) for s in sens.values()),
    )


def _visual_strides(rec, zstar) -> int | None:
    """First stride after which every component stays below 1 % of its own peak |Δz_i|."""
    h = np.abs(np.asarray(rec["history"]) - np.asarray(zstar))
    peak = h.max(axis=0)
    ok = np.all(h <= VISUAL_FRACTION * np.where(peak > 0, peak, 1.0), axis=1)
    for n in range(len(ok)):
        if ok[n:].all():
            return int(n)
    return None


def _rel_dist(zq, zr):
    zq, zr = np.asarray(zq, float), np.asarray(zr, float)
    return float(np.sqrt(np.mean(((zq - zr) / np.abs(zr)) ** 2)))


def _zdiff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a["z"]) - np.asarray(b["z"]))))


def _end_at(path, kc) -> dict | None:
    e = path["points"][-1] if path["points"] else None
    return None if e is None or abs(e["kc"] - kc) > KC_MATCH else e


def _shift(ours, paper) -> tuple | None:
    return None if not ours else (ours[0] - paper[0], ours[1] - paper[1])


def _max_kc(path) -> float | None:
    if not path or not path["points"]:
        return None
    return max(q["kc"] for q in path["points"])


def _loss(path):
    c = (path or {}).get("stability_loss_kc")
    return None if not c else 0.5 * (c[0] + c[1])


def _min_margin(m) -> float:
    vals = []
    for leg in ("back", "front"):
        x = m.get(leg) or {}
        for k in ("start_apex", "liftoff", "min_in_flight_after_liftoff", "end_apex"):
            if x.get(k) is not None:
                vals.append(x[k])
    return min(vals) if vals else math.nan


def _liftoff_angles(hm, gd) -> dict:
    """Leg angle from the normal at a liftoff with the hip below its touchdown height [deg]."""
    out = {}
    for leg in ("back", "front"):
        x = hm.get(leg)
        if x and x.get("liftoff") is not None and x["liftoff"] < 0:
            lbar, gtd = gd[f"l{leg[0]}_bar"], gd[f"gamma_{leg[0]}_deg"]
            out[leg] = math.degrees(
                math.acos((lbar * math.cos(math.radians(gtd)) + x["liftoff"]) / lbar)
            )
    return out


def window_edges(sw) -> dict:
    """What happens at the edges of a window, from the sweep's own points."""
    pts = sorted((q for q in sw["points"]), key=lambda q: q["value"])
    cw, stw = sw["converged_window"], sw["stable_window"]
    if not cw or not stw:
        return {}
    lo = [q for q in pts if q["value"] == cw[0]]
    hi = [q for q in pts if q["value"] == cw[1]]
    beyond = [q for q in pts if q["value"] > stw[1]]
    return {
        "lo": lo[0] if lo else None,
        "hi": hi[0] if hi else None,
        "stable_lo": stw[0],
        "next": beyond[0] if beyond else None,
    }
