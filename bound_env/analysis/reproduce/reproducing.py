"""Stage 1: the published gait under the reproducing reading."""

from __future__ import annotations

import math

import numpy as np

from ...model.params import Params, z_to_paper
from ..fixed_point import find_fixed_point
from ..poincare import apex_energy, stride
from ..stability import RECOVERY_REL, recovery, recovery_all, spine_oscillations
from .claims import CLAIMS, literal_gait, reproducing_gait
from .points import point_summary
from .settings import FP_TOL, Budget


def hip_margins(z, params: Params, record_dt: float = 1e-4) -> dict:
    """Each hip's height above its touchdown height l_bar cos(gamma_td) over one stride.

    The rule "a leg re-armed below its touchdown height waits until its hip has risen above
    it" can only matter where a leg is in flight with its hip below that height: at the
    start apex or right after liftoff. Reported per leg: the margin at the start apex, at
    liftoff (and the hip's vertical velocity there), the smallest margin while the leg is in
    flight, and at the final apex (metres; negative would trigger the rule).
    """
    from ...model.dynamics import body_points, make_aux, trig

    res = stride(z, params, record_dt=record_dt)
    if res.trajectory is None:
        return {"failure": res.failure}
    tr = res.trajectory
    aux = make_aux(params.to_array())
    hb = np.empty(len(tr.t))
    hf = np.empty(len(tr.t))
    for i in range(len(tr.t)):
        q = tr.q[i]
        pts = body_points(q, aux, *trig(q))
        hb[i], hf[i] = pts[1], pts[5]
    mb = hb - params.lb_bar * math.cos(params.gamma_b)
    mf = hf - params.lf_bar * math.cos(params.gamma_f)
    out = {"failure": res.failure}
    for leg, m, h, stance in (("back", mb, hb, ("bs", "ds")), ("front", mf, hf, ("fs", "ds"))):
        flight = np.array([ph not in stance for ph in tr.phase])
        ev_lo = [e for e in res.events if e.name == f"liftoff_{leg}"]
        i_lo = int(np.searchsorted(tr.t, ev_lo[0].t)) if ev_lo else None
        after = flight & (tr.t >= (ev_lo[0].t if ev_lo else math.inf))
        vy = np.gradient(h, tr.t)
        t_above = None  # how long a hip that lifts off below its touchdown height stays below
        if i_lo is not None and m[min(i_lo, len(m) - 1)] < 0.0:
            j = np.flatnonzero((m[:-1] < 0.0) & (m[1:] >= 0.0) & (np.arange(len(m) - 1) >= i_lo))
            if j.size:
                k = int(j[0])
                tc = tr.t[k] + (tr.t[k + 1] - tr.t[k]) * (-m[k]) / (m[k + 1] - m[k])
                t_above = float(tc - ev_lo[0].t)
        out[leg] = {
            "below_after_liftoff_s": t_above,
            "start_apex": float(m[0]),
            "liftoff": float(m[min(i_lo, len(m) - 1)]) if i_lo is not None else None,
            "liftoff_hip_vy": float(vy[min(i_lo, len(m) - 1)]) if i_lo is not None else None,
            "min_in_flight_after_liftoff": float(np.min(m[after])) if after.any() else None,
            "min_in_flight": float(np.min(m[flight])) if flight.any() else None,
            "end_apex": float(m[-1]),
        }
    return out


def stage_reproducing(b: Budget, log) -> dict:
    g = reproducing_gait()
    p, zpub = g.params, g.z_published
    s_pub = stride(zpub, p, record_dt=b.record_dt)
    fp = find_fixed_point(p, zpub, tol=FP_TOL)
    if not fp.converged:  # the integrator's floor: accept the default tolerance
        fp = find_fixed_point(p, zpub)
    log(f"  z* = {np.round(z_to_paper(fp.z), 6).tolist()}  e_max = {fp.emax:.4f}")
    rec = [recovery(fp.z, p, 0, s * RECOVERY_REL) for s in (+1.0, -1.0)]
    rec_all = recovery_all(fp.z, p)
    osc = spine_oscillations(fp.z, p)
    per = stride(fp.z, p, record_dt=b.record_dt)
    tr = per.trajectory
    th2 = np.degrees(tr.q[:, 3])
    p_text = p.with_values(alpha_deg=CLAIMS.alpha_text_deg)  # the slope as the text prints it
    fp_text = find_fixed_point(p_text, fp.z, tol=FP_TOL, recover=True)
    if not fp_text.converged:
        fp_text = find_fixed_point(p_text, fp.z)
    mixed = p.with_values(I1=0.64, I2=0.64)  # geometry reproducing, inertia literal
    fp_mixed = find_fixed_point(mixed, zpub, recover=False)
    lit = literal_gait().params
    return {
        "params": p.to_gait_dict(),
        "z_published": z_to_paper(zpub),
        "stride_from_published": {
            "failure": s_pub.failure,
            "phases": s_pub.phases,
            "durations": s_pub.durations,
            "z1": None if s_pub.z1 is None else z_to_paper(s_pub.z1),
            "return_error_paper": None
            if s_pub.z1 is None
            else z_to_paper(s_pub.z1) - z_to_paper(zpub),
            "energy0": s_pub.energy0,
            "energy1": s_pub.energy1,
        },
        "fixed_point": {
            "converged": fp.converged,
            "reason": fp.reason,
            "iterations": fp.iterations,
            **point_summary(p, fp.z),
            "z_si": fp.z,
            "strides_to_converge": fp.strides_to_converge,
            "period": per.t_end,
        },
        "recovery": [
            {
                "rel": r.rel,
                "strides": r.strides,
                "strides_loose": r.strides_loose,
                "failure": r.failure,
                "history": z_to_paper_rows(r.history),
                "deviation": r.deviation,
            }
            for r in rec
        ],
        "recovery_all": [
            {
                "component": r.component,
                "rel": r.rel,
                "strides": r.strides,
                "strides_loose": r.strides_loose,
                "failure": r.failure,
            }
            for r in rec_all
        ],
        "spine": {
            "count": osc.count,
            "extrema_t": osc.extrema_t,
            "extrema_theta2_deg": np.degrees(osc.extrema_theta2),
            "extrema_phase": osc.extrema_phase,
            "minima": osc.minima,
            "maxima": osc.maxima,
            "theta2_min_deg": float(th2.min()),
            "theta2_max_deg": float(th2.max()),
        },
        "trajectory": {
            "t": tr.t,
            "q": tr.q,
            "qd": tr.qd,
            "phase": tr.phase,
            "events": [{"t": e.t, "name": e.name, "phase": e.phase} for e in per.events],
        },
        "trajectory_published": None
        if s_pub.trajectory is None
        else {"t": s_pub.trajectory.t, "q": s_pub.trajectory.q},
        "hip_margins": hip_margins(fp.z, p),
        "hip_margins_published": hip_margins(zpub, p),
        "alpha_193": {
            "converged": fp_text.converged,
            **point_summary(fp_text.params, fp_text.z),
            "strides_to_converge": fp_text.strides_to_converge,
        },
        "mixed_reading": {
            "converged": fp_mixed.converged,
            "reason": fp_mixed.reason,
            "z": z_to_paper(fp_mixed.z),
            "phases": fp_mixed.phases,
            "stride_failure": stride(zpub, mixed).failure,
        },
        "damping": {
            "reproducing": {"c_c": p.c_c, "omega_n": p.omega_n, "I_joint": p.I1_joint},
            "literal": {"c_c": lit.c_c, "omega_n": lit.omega_n, "I_joint": lit.I1_joint},
        },
        "energy_published_z": apex_energy(zpub, p),
    }


def z_to_paper_rows(hist) -> np.ndarray:
    return np.array([z_to_paper(z) for z in np.asarray(hist)])
