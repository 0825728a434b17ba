"""``bound-env reproduce``: every published number of the paper, measured again, with evidence.

The command regenerates the analogues of Figs. 3-8 (PNG with CSV beside them) and writes
``REPRODUCTION.md``: one row per published number (paper, ours, difference, verdict, evidence
and the most likely cause of a miss), both readings of Table II side by side, the stiff-spine
path of Figs. 3-4, the literal reading's periodic gait, and the edge case of a hip below its
touchdown height. Figures and the report are written by `bound_env.analysis.reproduce_report`.

Stages (each cached as JSON in ``DIR/cache/<stage>-<hash>.json``, the hash of the stage's
configuration: budget, gait files, inputs from earlier stages and `CACHE_VERSION`):

1. ``reproducing``: the published gait under the reproducing reading: one stride from the
   published z*, Newton's fixed point from it, eigenvalues, recovery (Fig. 6), the periodic
   stride (Fig. 5), spine bends, theta2 amplitude, hip margins, alpha = 1.93 vs 1.9343, c_c.
2. ``closest``: the alpha (kc fixed) and the kc (alpha fixed) whose fixed point lies closest
   to the published z* (bounded 1-D search along the branch), the sensitivity of z* to each
   published parameter within its printed rounding, and the paper's slope secant (eq. 27).
3. ``sweeps``: e_max against alpha and kc the paper's way (Figs. 7-8), windows, ds onset.
4. ``stiff``: the stiff-spine bound (kc = 20000, one-body-like) and the paths down to
   kc = 295 (Figs. 3-4): alpha chosen to hold the forward speed, alpha chosen to balance the
   energy (eq. 27, the paper's process, with its fallback ladder), and the energy level of
   the published gait followed upwards (pseudo-arclength in ln kc).
5. ``literal``: the literal reading: the stride from the published z*, Newton from there and
   nearby, the homotopy from the reproducing geometry, the fixed point at the published
   parameters with its eigenvalues, and the paper's path towards stiffer spines.

Units: z in SI inside, paper units [m, deg, deg, m/s, deg/s, deg/s] in the cache and report.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..cache import atomic_write, settings_hash
from ..params import GAITS_DIR, Params, load_gait, save_gait, z_to_paper, z_to_si
from .continuation import CORRECTOR_MAX_ITER, FixedPointPath, StepControl, arclength, natural
from .fixed_point import find_fixed_point, ladder, slope_secant
from .numerics import NEWTON_MAX_ITER, newton
from .poincare import StrideFailure, apex_energy, stride
from .stability import DZ, recovery, recovery_all, spine_oscillations, stability

CACHE_VERSION = 1
FP_TOL = 1e-11  # Newton tolerance for the fixed points reported (|P(z) - z|, SI)
RELAXED_LEG_FRAC = 0.05  # min_leg_frac used to explore the literal reading (diagnostic only)
Z_NAMES_PAPER = ("y_g [m]", "theta1 [deg]", "theta2 [deg]", "xdot_g [m/s]",
                 "theta1dot [deg/s]", "theta2dot [deg/s]")  # fmt: skip


@dataclass(frozen=True)
class Budget:
    """How much work each stage does. ``full`` is the committed report; ``quick`` the tests."""

    name: str = "full"
    alpha_sweep: tuple = (1.80, 2.10, 0.005)  # from, to, step [deg]
    kc_sweep: tuple = (280.0, 320.0, 0.5)  # [N m/rad]
    refine: int = 6  # bisections of each window edge
    coarse_sweeps: bool = True  # repeat the sweeps with twice the step (criterion vs. step)
    search_xatol: float = 1e-6  # closest-alpha search tolerance [deg]; kc uses x 100
    kc_stiff: float = 20000.0  # the stiff spine [N m/rad]
    path_step: float = 0.02  # first step of the natural paths in ln kc
    path_step_max: float = 0.02
    arc_step: float = 0.01  # pseudo-arclength step (ln kc units)
    family_step: float = 0.01  # forward-speed step of the stiff-family scan [m/s]
    family_max: int = 100  # points per direction in that scan
    literal_starts: int = 100  # multi-start Newton under the literal reading
    literal_kc_max: float = 20000.0  # the literal paper-path goes this stiff
    record_dt: float = 5e-4  # sampling of the periodic stride (Fig. 5) [s]


FULL = Budget()
QUICK = Budget(name="quick", alpha_sweep=(1.80, 2.10, 0.05), kc_sweep=(280.0, 320.0, 5.0),
               refine=1, coarse_sweeps=False, search_xatol=1e-3, kc_stiff=2000.0, path_step=0.3,
               path_step_max=0.5, arc_step=0.1, family_step=0.1, family_max=6,
               literal_starts=6, literal_kc_max=2000.0, record_dt=2e-3)  # fmt: skip


# --------------------------------------------------------------------------------------------
# Small helpers: progress, JSON, caching
# --------------------------------------------------------------------------------------------


class _Log:
    def __init__(self, enabled: bool):
        self.enabled, self.t0 = enabled, time.perf_counter()

    def __call__(self, msg: str):
        if self.enabled:
            dt = time.perf_counter() - self.t0
            print(f"[reproduce {dt:6.1f}s] {msg}", file=sys.stderr, flush=True)


def jsonable(x):
    """Plain JSON: arrays to lists, complex to [re, im], non-finite floats to None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (complex, np.complexfloating)):
        return [jsonable(float(x.real)), jsonable(float(x.imag))]
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, (np.integer, int)):
        return int(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    return x


def config_hash(config: dict) -> str:
    return settings_hash(jsonable(config), length=12)


class Cache:
    """One JSON file per stage, named by the hash of the stage's configuration."""

    def __init__(self, out_dir: Path, force: bool, log: _Log):
        self.dir = Path(out_dir) / "cache"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.force, self.log = force, log
        self.hits: list[str] = []
        self.misses: list[str] = []

    def get(self, stage: str, config: dict, compute):
        path = self.dir / f"{stage}-{config_hash({'stage': stage, **config})}.json"
        if path.is_file() and not self.force:
            try:
                data = json.loads(path.read_text())
                self.hits.append(stage)
                self.log(f"{stage}: cached ({path.name})")
                return data
            except json.JSONDecodeError:
                pass
        self.log(f"{stage}: computing")
        t0 = time.perf_counter()
        data = jsonable(compute())
        data["seconds"] = time.perf_counter() - t0
        atomic_write(path, json.dumps(data))
        self.misses.append(stage)
        self.log(f"{stage}: done in {data['seconds']:.1f} s")
        return data


def eig_list(lam) -> list | None:
    return None if lam is None else [[float(v.real), float(v.imag)] for v in lam]


def point_summary(params: Params, z, **extra) -> dict:
    """A fixed point's parameters, z (paper units), residual, eigenvalues, phases."""
    z = np.asarray(z, dtype=float)
    res = stride(z, params)
    resid = math.inf if res.z1 is None else float(np.max(np.abs(res.z1 - z)))
    try:
        st = stability(z, params)
        lam, emax = st.eigenvalues, st.emax
    except StrideFailure:
        lam, emax = None, math.nan
    gd = params.to_gait_dict()
    out = {k: gd[k] for k in ("kc", "alpha_deg", "gamma_b_deg", "gamma_f_deg", "kb", "kf")}
    out.update(z=z_to_paper(z), residual=resid, emax=emax, eigenvalues=eig_list(lam),
               phases=list(res.phases), durations=list(res.durations),
               energy=apex_energy(z, params), has_ds="ds" in res.phases, **extra)  # fmt: skip
    return out


def rel_distance(z_paper, z_ref_paper) -> float:
    """RMS over the six components of (z - z_ref) / |z_ref| (unit-free)."""
    z, r = np.asarray(z_paper, float), np.asarray(z_ref_paper, float)
    return float(np.sqrt(np.mean(((z - r) / np.abs(r)) ** 2)))


def reproducing_gait():
    return load_gait(GAITS_DIR / "paper.yaml")


def literal_gait():
    return load_gait(GAITS_DIR / "paper-literal.yaml")


def _gait_config(g) -> dict:
    return {"params": g.params.to_gait_dict(), "min_leg_frac": g.params.min_leg_frac,
            "z_published": z_to_paper(g.z_published)}  # fmt: skip


# --------------------------------------------------------------------------------------------
# Paths for `continuation.natural` (the paper's process, its fallback ladder as the on_stall
# hook) and `continuation.arclength` (to follow a branch round a fold)
# --------------------------------------------------------------------------------------------


def _fixed_path(params_of, free, pins) -> FixedPointPath:
    """Fixed points along s at the reproduction's tolerance (FP_TOL), default simulation."""
    return FixedPointPath(params_of, tuple(free), list(pins), {}, FP_TOL)


def _newton_at(params: Params, u0, free, pins, max_iter=CORRECTOR_MAX_ITER):
    """Newton for [z, freed values] at fixed parameters."""
    return _fixed_path(lambda _s: params, free, pins).correct(0.0, u0, max_iter=max_iter)


def natural_path(params: Params, u0, s_to: float, pins, free=("alpha_deg",), h0=0.1,
                 h_max=0.25, h_min=1e-3, use_ladder=True, max_points=300,
                 log=None) -> dict:  # fmt: skip
    """The paper's process (III.D.4 A-F) in s = ln kc: step kc, solve z* and the freed alpha
    with the pins (eq. 27's energy balance is the energy pin), halve the step when Newton
    fails, and below ``h_min`` walk the fallback ladder (touchdown angles +-0.5 deg up to
    +-4 deg, then kb = kf +-100 N/m), keeping the first change that converges. The
    continuation is `continuation.natural`; the ladder is its ``on_stall`` hook.

    ``params`` carries the start (kc, alpha); u0 = [z (SI), alpha]. Returns the points as
    (Params, z) pairs plus the ladder changes made and why the path stopped.
    """
    free = tuple(free)
    base = {"params": params}  # the ladder replaces it
    path = _fixed_path(lambda s: base["params"].with_values(kc=math.exp(s)), free, pins)
    s0 = math.log(params.kc)
    out = _newton_at(params, u0, free, pins, max_iter=NEWTON_MAX_ITER)
    if not out.converged:
        return {"points": [], "reason": f"no fixed point at the start: {out.reason}",
                "reached": False, "ladder": []}  # fmt: skip
    pts = [(params.with_values(**dict(zip(free, out.u[6:], strict=True))), out.u[:6].copy())]
    trail = [(s0, out.u.copy())]
    changes: list = []

    def on_point(s, u, iterations, step):
        cur = path.params_at(s, u)
        pts.append((cur, u[:6].copy()))
        if log:
            log(f"  kc = {cur.kc:9.2f}  alpha = {u[6]:.5f} deg")

    def ladder_hook(s, u, info, direction):  # steps E-F: touchdown angles, then leg stiffness
        cur = pts[-1][0]
        s_try = s + direction * 2.0 * h_min
        for ch in ladder(cur)[1:]:
            try:
                p_try = cur.with_values(kc=math.exp(s_try), **ch)
            except ValueError:
                continue
            o = _newton_at(p_try, u, free, pins)
            if o.converged:
                break
        else:
            return f"ladder exhausted at kc = {cur.kc:.6g}"
        changes.append({"kc": p_try.kc, "changes": ch})
        if log:
            log(f"  ladder at kc = {p_try.kc:.2f}: {ch}")
        base["params"] = p_try
        pts.append((p_try.with_values(**dict(zip(free, o.u[6:], strict=True))), o.u[:6].copy()))
        return s_try, o.u.copy()

    control = StepControl(h0, h_max, h_min, guard_first_step=True)
    stop = natural(path, trail, s_to, control, max_points, on_point=on_point,
                   on_stall=ladder_hook if use_ladder else None)  # fmt: skip
    if stop.kind == "reached":
        reason = "reached the target"
    elif stop.kind == "stalled":
        reason = f"step below {h_min} at kc = {pts[-1][0].kc:.6g}: {stop.info}"
    elif stop.kind == "max_points":
        reason = f"stopped after {max_points} points"
    else:
        reason = stop.kind  # the ladder's message
    return {"points": pts, "reason": reason, "reached": stop.reached, "ladder": changes}


def arclength_path(params_of, s0: float, s1: float, u0, free=(), pins=(), ds=0.05,
                   ds_max=0.2, ds_min=1e-5, max_points=300, stop_below_start=True,
                   log=None) -> dict:  # fmt: skip
    """Pseudo-arclength continuation of [z, freed values] in a scalar s (ln kc, a homotopy
    parameter, alpha, ...) by `continuation.arclength`: ``params_of(s)`` gives the
    parameters at s (freed values are applied on top); the second point by a natural step
    of ``ds``; a fold is where ds/d(arclength) changes sign.

    Returns {"points": [(s, u)], "folds": [s], "reason", "reached"}.
    """
    path = _fixed_path(params_of, free, pins)
    u0 = np.asarray(u0, float)
    steps_u = path.steps_of(u0)
    first = newton(path.residual_at(s0), u0, steps_u, tol=FP_TOL)
    if not first.converged:
        return {"points": [], "folds": [], "reason": f"start: {first.reason}",
                "reached": False}  # fmt: skip
    trail = [(s0, first.u)]
    first_step: list = []
    stop = natural(path, trail, s1, StepControl(ds, ds, ds_min), max_points=2,
                   on_point=lambda s, u, iterations, step: first_step.append(abs(step)))
    if len(trail) < 2:
        return {"points": [(float(s), u) for s, u in trail], "folds": [],
                "reason": f"no second point: {stop.info}", "reached": False}  # fmt: skip
    folds: list = []

    def on_point(s, u, iterations, step, turned):
        if turned:
            folds.append(float(trail[-2][0]))
        if log:
            log(f"  s = {s:.6g}")

    stop = arclength(path, trail, s1, first_step[0], ds_max, ds_min, np.append(steps_u, DZ),
                     max_points, stop_past_start=0 if stop_below_start else None,
                     on_point=on_point)  # fmt: skip
    reason = {"reached": "reached the target",
              "stalled": f"step below minimum at s = {stop.s:.6g}: {stop.info}",
              "turned_back": f"the branch turned back past the start (s = {stop.s:.6g})",
              "max_points": f"stopped after {max_points} points"}[stop.kind]  # fmt: skip
    return {"points": [(float(s), np.array(u, copy=True)) for s, u in trail], "folds": folds,
            "reason": reason, "reached": stop.reached}


# --------------------------------------------------------------------------------------------
# Stage 1: the published gait under the reproducing reading
# --------------------------------------------------------------------------------------------


def hip_margins(z, params: Params, record_dt: float = 1e-4) -> dict:
    """Each hip's height above its touchdown height l_bar cos(gamma_td) over one stride.

    The rule "a leg re-armed below its touchdown height waits until its hip has risen above
    it" can only matter where a leg is in flight with its hip below that height: at the
    start apex or right after liftoff. Reported per leg: the margin at the start apex, at
    liftoff (and the hip's vertical velocity there), the smallest margin while the leg is in
    flight, and at the final apex (metres; negative would trigger the rule).
    """
    from ..dynamics import body_points, make_aux, trig

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
    rec = [recovery(fp.z, p, 0, s * 0.01) for s in (+1.0, -1.0)]
    rec_all = recovery_all(fp.z, p)
    osc = spine_oscillations(fp.z, p)
    per = stride(fp.z, p, record_dt=b.record_dt)
    tr = per.trajectory
    th2 = np.degrees(tr.q[:, 3])
    fp193 = find_fixed_point(p.with_values(alpha_deg=1.93), fp.z, tol=FP_TOL, recover=True)
    if not fp193.converged:
        fp193 = find_fixed_point(p.with_values(alpha_deg=1.93), fp.z)
    mixed = p.with_values(I1=0.64, I2=0.64)  # geometry reproducing, inertia literal
    fp_mixed = find_fixed_point(mixed, zpub, recover=False)
    lit = literal_gait().params
    return {
        "params": p.to_gait_dict(),
        "z_published": z_to_paper(zpub),
        "stride_from_published": {
            "failure": s_pub.failure, "phases": s_pub.phases, "durations": s_pub.durations,
            "z1": None if s_pub.z1 is None else z_to_paper(s_pub.z1),
            "return_error_paper": None if s_pub.z1 is None
            else z_to_paper(s_pub.z1) - z_to_paper(zpub),
            "energy0": s_pub.energy0, "energy1": s_pub.energy1,
        },
        "fixed_point": {
            "converged": fp.converged, "reason": fp.reason, "iterations": fp.iterations,
            **point_summary(p, fp.z), "z_si": fp.z,
            "strides_to_converge": fp.strides_to_converge, "period": per.t_end,
        },
        "recovery": [{"rel": r.rel, "strides": r.strides, "strides_loose": r.strides_loose,
                      "failure": r.failure, "history": z_to_paper_rows(r.history),
                      "deviation": r.deviation} for r in rec],
        "recovery_all": [{"component": r.component, "rel": r.rel, "strides": r.strides,
                          "strides_loose": r.strides_loose, "failure": r.failure}
                         for r in rec_all],
        "spine": {"count": osc.count, "extrema_t": osc.extrema_t,
                  "extrema_theta2_deg": np.degrees(osc.extrema_theta2),
                  "extrema_phase": osc.extrema_phase, "minima": osc.minima,
                  "maxima": osc.maxima, "theta2_min_deg": float(th2.min()),
                  "theta2_max_deg": float(th2.max())},
        "trajectory": {"t": tr.t, "q": tr.q, "qd": tr.qd, "phase": tr.phase,
                       "events": [{"t": e.t, "name": e.name, "phase": e.phase}
                                  for e in per.events]},
        "trajectory_published": None if s_pub.trajectory is None else {
            "t": s_pub.trajectory.t, "q": s_pub.trajectory.q},
        "hip_margins": hip_margins(fp.z, p),
        "hip_margins_published": hip_margins(zpub, p),
        "alpha_193": {"converged": fp193.converged, **point_summary(fp193.params, fp193.z),
                      "strides_to_converge": fp193.strides_to_converge},
        "mixed_reading": {"converged": fp_mixed.converged, "reason": fp_mixed.reason,
                          "z": z_to_paper(fp_mixed.z), "phases": fp_mixed.phases,
                          "stride_failure": stride(zpub, mixed).failure},
        "damping": {"reproducing": {"c_c": p.c_c, "omega_n": p.omega_n,
                                    "I_joint": p.I1_joint},
                    "literal": {"c_c": lit.c_c, "omega_n": lit.omega_n,
                                "I_joint": lit.I1_joint}},
        "energy_published_z": apex_energy(zpub, p),
    }  # fmt: skip


def z_to_paper_rows(hist) -> np.ndarray:
    return np.array([z_to_paper(z) for z in np.asarray(hist)])


# --------------------------------------------------------------------------------------------
# Stage 2: the alpha and kc closest to the published z*; sensitivity; the paper's secant
# --------------------------------------------------------------------------------------------


def closest_on_branch(p: Params, key: str, bounds, z_start, z_ref_paper, xatol) -> dict:
    """Minimize rel_distance(z*(v), z_ref) over v in ``bounds`` (bounded Brent), each z*(v)
    by Newton from the nearest value solved so far."""
    from scipy.optimize import minimize_scalar

    solved: dict = {float(p.to_gait_dict()[key]): np.asarray(z_start, float)}

    def dist(v):
        near = min(solved, key=lambda w: abs(w - v))
        r = find_fixed_point(p.with_values(**{key: float(v)}), solved[near], tol=FP_TOL,
                             analyse=False)  # fmt: skip
        if not r.converged:
            return 1e3
        solved[float(v)] = r.z
        return rel_distance(z_to_paper(r.z), z_ref_paper)

    opt = minimize_scalar(dist, bounds=bounds, method="bounded",
                          options={"xatol": xatol})  # fmt: skip
    v = float(opt.x)
    near = min(solved, key=lambda w: abs(w - v))
    pv = p.with_values(**{key: v})
    r = find_fixed_point(pv, solved[near], tol=FP_TOL, recover=False)
    out = {"key": key, "value": v, "distance": rel_distance(z_to_paper(r.z), z_ref_paper),
           "evaluations": int(opt.nfev), "bounds": list(bounds), **point_summary(pv, r.z)}
    out["rel_diff"] = (np.asarray(out["z"]) - z_ref_paper) / np.abs(z_ref_paper)
    return out


# half a unit of the last printed digit of each published parameter (1.9343, 295, 46.7, ...)
ROUNDING = {"alpha_deg": 0.00005, "kc": 0.5, "gamma_b_deg": 0.05, "gamma_f_deg": 0.05,
            "kb": 5.0, "kf": 5.0}  # fmt: skip


def stage_closest(b: Budget, z_star_si, log) -> dict:
    g = reproducing_gait()
    p, zpub = g.params, z_to_paper(g.z_published)
    z_star_si = np.asarray(z_star_si, float)
    out = {"distance_at_published": rel_distance(z_to_paper(z_star_si), zpub)}
    out["alpha"] = closest_on_branch(p, "alpha_deg", (1.85, 2.00), z_star_si, zpub,
                                     b.search_xatol)  # fmt: skip
    log(f"  closest alpha = {out['alpha']['value']:.5f} deg, d = {out['alpha']['distance']:.4f}")
    out["kc"] = closest_on_branch(p, "kc", (286.0, 300.0), z_star_si, zpub,
                                  100 * b.search_xatol)  # fmt: skip
    log(f"  closest kc = {out['kc']['value']:.3f}, d = {out['kc']['distance']:.4f}")
    # how far z* moves when each published parameter moves by its printed rounding
    gd = p.to_gait_dict()
    sens = {}
    for key, half in {**ROUNDING, "alpha_deg_text": 0.005}.items():
        k = key.replace("_text", "")
        zs = []
        for sgn in (+1.0, -1.0):
            r = find_fixed_point(p.with_values(**{k: gd[k] + sgn * 0.1 * half}), z_star_si,
                                 tol=FP_TOL, analyse=False)  # fmt: skip
            zs.append(z_to_paper(r.z) if r.converged else np.full(6, np.nan))
        sens[key] = {"half_width": half, "dz_per_half_width": (zs[0] - zs[1]) / 0.2}
    out["sensitivity"] = sens
    out["needed"] = zpub - z_to_paper(z_star_si)  # published minus ours
    # the paper's slope secant (III.D.5, eq. 27) from the published z*
    sec = slope_secant(p, g.z_published)
    out["secant"] = {"alpha_deg": sec.alpha_deg, "converged": sec.converged,
                     "reason": sec.reason, "found": sec.fixed_point_found,
                     "evaluations": sec.iterations}  # fmt: skip
    if sec.fixed_point_found:
        pa = p.with_values(alpha_deg=sec.alpha_deg)
        r = find_fixed_point(pa, sec.run.z_last, tol=FP_TOL, recover=False)
        if r.converged:
            out["secant"].update(point_summary(pa, r.z))
    return out


# --------------------------------------------------------------------------------------------
# Stage 3: Figs. 7-8, e_max against alpha and kc the paper's way
# --------------------------------------------------------------------------------------------


def _sweep_dict(res) -> dict:
    pts = []
    for q in res.points:
        pts.append({"value": q.value, "converged": q.converged, "error": q.error,
                    "failure": q.failure, "found": q.found, "emax": q.emax,
                    "eigenvalues": eig_list(q.eigenvalues), "phases": q.phases,
                    "has_ds": q.has_ds,
                    "z": None if q.z is None else z_to_paper(q.z)})  # fmt: skip
    base = res.base
    found = [q for q in res.points if q.found]
    ds_up = [q.value for q in found if q.value >= base and q.has_ds]
    nods_up = [q.value for q in found if q.value >= base and not q.has_ds]
    ds_down = [q.value for q in found if q.value <= base and q.has_ds]
    return {"param": res.param, "base": base, "points": pts,
            "converged_window": res.converged_window, "stable_window": res.stable_window,
            "ds_from": min(ds_up) if ds_up else None,
            "no_ds_up_to": max([v for v in nods_up if not ds_up or v < min(ds_up)],
                               default=None),
            "ds_below_base": sorted(ds_down)}  # fmt: skip


def stage_sweeps(b: Budget, z_star_si, log) -> dict:
    from .sweeps import sweep

    g = reproducing_gait()
    out = {}
    for key, (lo, hi, st) in (("alpha_deg", b.alpha_sweep), ("kc", b.kc_sweep)):
        for factor in (1, 2) if b.coarse_sweeps else (1,):
            vals = np.round(np.arange(lo, hi + 0.5 * st * factor, st * factor), 12)
            res = sweep(g.params, np.asarray(z_star_si, float), key, vals, refine=b.refine)
            d = _sweep_dict(res)
            d["step"] = st * factor
            name = key if factor == 1 else f"{key}_coarse"
            out[name] = d
            log(f"  {key} (step {st * factor:g}): 100-stride window {d['converged_window']}, "
                f"e_max < 1 window {d['stable_window']}, ds from {d['ds_from']}")
    return out


# --------------------------------------------------------------------------------------------
# Stage 4: the stiff-spine bound and the paths to kc = 295 (Figs. 3-4)
# --------------------------------------------------------------------------------------------


def _path_points(res: dict, log=None) -> list:
    pts = []
    for p, z in res["points"]:
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
    p_s = p0.with_values(kc=kc_s, alpha_deg=0.01)
    st = find_fixed_point(p_s, g.z_published, free=("alpha_deg",), pin=[("xdot_g", v_star)],
                          tol=FP_TOL, recover=False)  # fmt: skip
    out = {"kc_stiff": kc_s, "energy_star": e_star, "xdot_star": v_star}
    if not st.converged:
        out["start"] = {"converged": False, "reason": st.reason}
        return out
    e_s = apex_energy(st.z, st.params)
    out["start"] = {"converged": True, **point_summary(st.params, st.z)}
    log(f"  stiff start kc = {kc_s:g}: alpha = {st.free['alpha_deg']:.6f} deg, "
        f"E = {e_s:.3f} J, e_max = {st.emax:.4f}")
    u_s = np.append(st.z, st.free["alpha_deg"])
    s_to = math.log(float(p0.kc))
    paths = {}
    for name, pins in (("speed", [("xdot_g", v_star)]), ("energy", [("energy", e_s)])):
        res = natural_path(st.params, u_s, s_to, pins, h0=b.path_step, h_max=b.path_step_max)
        paths[name] = {"pins": pins, "reason": res["reason"], "reached": res["reached"],
                       "ladder": res["ladder"], "points": _path_points(res)}
        end = paths[name]["points"][-1] if paths[name]["points"] else None
        if end:
            log(f"  path '{name}': {res['reason']}; at kc = {end['kc']:.2f} alpha = "
                f"{end['alpha_deg']:.5f} deg, e_max = {end['emax']:.4f}")
    # the energy level of the published gait followed upwards, round any fold
    p295 = p0

    def params_of(s):
        return p295.with_values(kc=math.exp(s))

    arc = arclength_path(params_of, math.log(p0.kc), math.log(kc_s),
                         np.append(z_star_si, p0.to_gait_dict()["alpha_deg"]),
                         free=("alpha_deg",), pins=[("energy", e_star)], ds=b.arc_step,
                         ds_max=4 * b.arc_step)  # fmt: skip
    apts = []
    for s, u in arc["points"]:
        pp = p295.with_values(kc=math.exp(s), alpha_deg=float(u[6]))
        apts.append(point_summary(pp, u[:6]))
    loss = None
    for q0, q1 in zip(apts, apts[1:], strict=False):
        if q0["emax"] is not None and q1["emax"] is not None and q0["emax"] < 1 <= q1["emax"]:
            loss = refine_emax_crossing(p295, q0, q1, [("energy", e_star)])
            break
    paths["energy_star"] = {"pins": [("energy", e_star)], "reason": arc["reason"],
                            "stability_loss_kc": loss,
                            "reached": arc["reached"], "ladder": [],
                            "folds_kc": [math.exp(s) for s in arc["folds"]],
                            "points": apts}  # fmt: skip
    log(f"  published energy level: {arc['reason']}; folds at kc = "
        f"{[round(math.exp(s), 2) for s in arc['folds']]}")
    out["paths"] = paths
    # the stiff family at kc_s: fixed points against the pinned forward speed
    fam = []
    for direction in (+1.0, -1.0):
        zp, z, a = None, st.z.copy(), st.free["alpha_deg"]
        for i in range(b.family_max):
            v = float(st.z[3]) + direction * b.family_step * i
            pred = z if zp is None else 2 * z - zp
            r = find_fixed_point(st.params.with_values(alpha_deg=a), pred, free=("alpha_deg",),
                                 pin=[("xdot_g", v)], tol=FP_TOL, recover=False,
                                 analyse=False)  # fmt: skip
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
        log(f"  stiff family: E from {m['energy']:.3f} J (xdot {m['xdot']:.3f}); "
            f"published gait's E = {e_star:.3f} J")
    return out


# --------------------------------------------------------------------------------------------
# Stage 5: the literal reading
# --------------------------------------------------------------------------------------------


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
    return {"min_leg_frac_reached": 0.5 * (lo_f + hi_f), "failure_relaxed": r_lo.failure,
            "phases_relaxed": r_lo.phases, "durations_relaxed": r_lo.durations}  # fmt: skip


def stage_literal(b: Budget, z_star_si, log) -> dict:
    gl, gr = literal_gait(), reproducing_gait()
    pl, zpub = gl.params, gl.z_published
    relaxed = pl.with_values(min_leg_frac=RELAXED_LEG_FRAC)
    out = {"params": pl.to_gait_dict()}
    s = stride(zpub, pl, record_dt=1e-3)
    out["stride_from_published"] = {"failure": s.failure, "phases": s.phases,
                                    "durations": s.durations, "t_end": s.t_end}  # fmt: skip
    out["leg_compression"] = min_leg_fraction(zpub, pl)
    nw = find_fixed_point(pl, zpub, recover=False)
    out["newton_from_published"] = {"converged": nw.converged, "reason": nw.reason}
    sec = slope_secant(pl, zpub, max_iter=3)
    out["secant_from_published"] = {"reason": sec.reason, "found": sec.fixed_point_found}
    # multi-start Newton around the published z* (legs may compress to 5 % while searching)
    rng = np.random.default_rng(0)
    rel = np.array([0.02, 0.05, 0.05, 0.1, 0.2, 0.3])
    wide = np.array([0.02, 4.0, 8.0, 0.5, 100.0, 150.0])
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
        analysed.append({"converged_default_leg_limit": r.converged, "reason": r.reason,
                         **(point_summary(pl, r.z) if r.converged else
                            {"z": z_to_paper(z)})})  # fmt: skip
    out["multistart"] = {"starts": b.literal_starts, "converged": n_conv,
                         "distinct": [z_to_paper(z) for z in found],
                         "analysed": analysed}  # fmt: skip
    log(f"  literal multi-start: {n_conv}/{b.literal_starts} converged, {len(found)} distinct")
    # homotopy: reproducing -> literal geometry, alpha freed, speed pinned at z*'s
    z_star_si = np.asarray(z_star_si, float)
    pr = gr.params

    def geom(lam):
        d = {k: getattr(pr, k) + lam * (getattr(pl, k) - getattr(pr, k))
             for k in ("l1", "l2", "I1", "I2")}  # fmt: skip
        return pr.with_values(**d, min_leg_frac=RELAXED_LEG_FRAC)

    hom = arclength_path(geom, 0.0, 1.0, np.append(z_star_si, pr.to_gait_dict()["alpha_deg"]),
                         free=("alpha_deg",), pins=[("xdot_g", float(z_star_si[3]))],
                         ds=0.02, ds_max=0.1)  # fmt: skip
    out["homotopy"] = {"reason": hom["reason"], "reached": hom["reached"],
                       "folds": hom["folds"],
                       "points": [{"lambda": s, "alpha_deg": float(u[6]),
                                   "z": z_to_paper(u[:6])} for s, u in hom["points"]]}  # fmt: skip
    z_lit = None
    if hom["reached"]:
        a_end, z_end = float(hom["points"][-1][1][6]), hom["points"][-1][1][:6]
        log(f"  homotopy reached the literal geometry at alpha = {a_end:.4f} deg")
        pa = relaxed

        def alpha_of(a):
            return pa.with_values(alpha_deg=a)

        arc = arclength_path(alpha_of, a_end, float(pl.to_gait_dict()["alpha_deg"]), z_end,
                             ds=0.1, ds_max=0.5)  # fmt: skip
        out["alpha_continuation"] = {"reason": arc["reason"], "reached": arc["reached"],
                                     "folds": arc["folds"],
                                     "points": [{"alpha_deg": s, "z": z_to_paper(u[:6])}
                                                for s, u in arc["points"]]}  # fmt: skip
        if arc["reached"]:
            z_lit = arc["points"][-1][1][:6]
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
    out["fixed_point"] = {**point_summary(pl, fp.z), "z_si": fp.z,
                          "strides_to_converge": fp.strides_to_converge,
                          "homotopy_agrees": bool(z_lit is not None
                                                  and np.max(np.abs(fp.z - z_lit)) < 1e-6),
                          "distance_to_published": rel_distance(z_to_paper(fp.z), zp)}  # fmt: skip
    log(f"  literal fixed point at the published parameters: e_max = {fp.emax:.4f}")
    osc = spine_oscillations(fp.z, pl)
    out["fixed_point"]["spine_count"] = osc.count
    out["fixed_point"]["hip_margins"] = hip_margins(fp.z, pl)
    # the paper's path towards stiffer spines: alpha balances the energy (pinned)
    e_l = apex_energy(fp.z, pl)
    res = natural_path(pl, np.append(fp.z, pl.to_gait_dict()["alpha_deg"]),
                       math.log(b.literal_kc_max), [("energy", e_l)], h0=0.05,
                       h_max=b.path_step_max)  # fmt: skip
    pts = _path_points(res)
    out["kc_path"] = {"reason": res["reason"], "reached": res["reached"],
                      "ladder": res["ladder"], "points": pts}  # fmt: skip
    stable = [q["kc"] for q in pts if q["emax"] is not None and q["emax"] < 1.0]
    out["kc_path"]["first_stable_kc"] = min(stable) if stable else None
    # every crossing of e_max = 1 along the path, bisected
    crossings = []
    for q0, q1 in zip(pts, pts[1:], strict=False):
        if q0["emax"] is None or q1["emax"] is None or (q0["emax"] >= 1) == (q1["emax"] >= 1):
            continue
        kcs = refine_emax_crossing(pl, q0, q1, [("energy", e_l)])
        crossings.append({"kc": 0.5 * (kcs[0] + kcs[1]), "bracket": kcs,
                          "becomes": "stable" if q1["emax"] < 1 else "unstable"})  # fmt: skip
    out["kc_path"]["crossings"] = crossings
    first = [c for c in crossings if c["becomes"] == "stable"]
    if first:
        out["kc_path"]["crossing"] = first[0]["bracket"]
    em = [q for q in pts if q["emax"] is not None]
    if em:
        low = min(em, key=lambda q: q["emax"])
        out["kc_path"]["min_emax"] = {"emax": low["emax"], "kc": low["kc"]}
    return out


def refine_emax_crossing(base: Params, q0: dict, q1: dict, pins, n: int = 12) -> list:
    """Bisect (in ln kc) between two path points on opposite sides of e_max = 1; each
    midpoint solved by Newton (alpha freed, ``pins``) from the interpolated neighbours.
    Returns [kc on the q0 side, kc on the q1 side]."""

    def u_of(q):
        return np.append(z_to_si(q["z"]), q["alpha_deg"])

    a = (math.log(q0["kc"]), u_of(q0), q0["emax"] >= 1.0)
    b = (math.log(q1["kc"]), u_of(q1), q1["emax"] >= 1.0)
    for _ in range(n):
        sm = 0.5 * (a[0] + b[0])
        o = _newton_at(base.with_values(kc=math.exp(sm)), 0.5 * (a[1] + b[1]), ("alpha_deg",),
                       pins)  # fmt: skip
        if not o.converged:
            break
        try:
            em = stability(o.u[:6], base.with_values(kc=math.exp(sm), alpha_deg=o.u[6])).emax
        except StrideFailure:
            break
        if (em >= 1.0) == a[2]:
            a = (sm, o.u, a[2])
        else:
            b = (sm, o.u, b[2])
    return [math.exp(a[0]), math.exp(b[0])]


# --------------------------------------------------------------------------------------------
# Gait files
# --------------------------------------------------------------------------------------------


def _kept_meta(gait) -> dict:
    """The source gait file's notes that a regenerated gait file carries over."""
    return {k: v for k, v in (gait.meta or {}).items()
            if k in ("h_b_unused", "h_f_unused", "reading")}  # fmt: skip


def write_gait_files(results: dict, gaits_dir: Path = GAITS_DIR) -> list[Path]:
    """default.yaml (the published gait's fixed point, reproducing reading) and
    literal-cycle.yaml (the literal reading's periodic gait at the published parameters)."""
    written = []
    gr = reproducing_gait()
    fp = results["reproducing"]["fixed_point"]
    written.append(save_gait(
        gaits_dir / "default.yaml", gr.params, z_star=np.asarray(fp["z_si"]),
        z_published=gr.z_published,
        found_by="bound-env reproduce: Newton-Raphson on P(z) = z (central-difference "
        "Jacobian, eq. 23) from z_published at the parameters of paper.yaml, rtol = atol = "
        "1e-12; eigenvalues of nabla P by eq. 23 (dz = 1e-6)",
        residual=float(fp["residual"]), eigenvalues=fp["eigenvalues"],
        emax=float(fp["emax"]), phases=fp["phases"],
        durations=[float(d) for d in fp["durations"]],
        strides_to_converge=fp["strides_to_converge"], **_kept_meta(gr),
    ))  # fmt: skip
    lit = results["literal"].get("fixed_point")
    if lit:
        gl = literal_gait()
        written.append(save_gait(
            gaits_dir / "literal-cycle.yaml", gl.params, z_star=np.asarray(lit["z_si"]),
            z_published=gl.z_published,
            found_by="bound-env reproduce: homotopy from the reproducing reading's fixed "
            "point to the literal geometry (alpha freed, forward speed pinned), alpha "
            "continued back to 1.9343 deg, Newton at the parameters of paper-literal.yaml; "
            "the same point as multi-start Newton around z_published. UNSTABLE: a real "
            "eigenvalue outside the unit circle",
            residual=float(lit["residual"]), eigenvalues=lit["eigenvalues"],
            emax=float(lit["emax"]), phases=lit["phases"],
            durations=[float(d) for d in lit["durations"]], **_kept_meta(gl),
        ))  # fmt: skip
    return written


# --------------------------------------------------------------------------------------------
# The command
# --------------------------------------------------------------------------------------------


def run(out_dir, quick: bool = False, force: bool = False, progress: bool = True,
        write_gaits: bool = False, docs_dir=None) -> dict:  # fmt: skip
    """Run every stage (or read it from the cache), write figures, CSVs and REPRODUCTION.md."""
    from . import reproduce_report

    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log = _Log(progress)
    b = QUICK if quick else FULL
    cache = Cache(out_dir, force, log)
    base_cfg = {"version": CACHE_VERSION, "budget": asdict(b),
                "paper": _gait_config(reproducing_gait()),
                "literal": _gait_config(literal_gait())}  # fmt: skip
    results: dict = {"budget": asdict(b)}
    results["reproducing"] = cache.get("reproducing", base_cfg,
                                       lambda: stage_reproducing(b, log))  # fmt: skip
    z_star = np.asarray(results["reproducing"]["fixed_point"]["z_si"], float)
    cfg = {**base_cfg, "z_star": z_star}
    results["closest"] = cache.get("closest", cfg, lambda: stage_closest(b, z_star, log))
    results["sweeps"] = cache.get("sweeps", cfg, lambda: stage_sweeps(b, z_star, log))
    results["stiff"] = cache.get("stiff", cfg, lambda: stage_stiff(b, z_star, log))
    results["literal"] = cache.get("literal", cfg, lambda: stage_literal(b, z_star, log))
    results["cache"] = {"hits": cache.hits, "misses": cache.misses}
    results["compute_seconds"] = {k: results[k].get("seconds") for k in
                                  ("reproducing", "closest", "sweeps", "stiff", "literal")}
    log("figures")
    figs = reproduce_report.write_figures(results, out_dir / "figures")
    results["figures"] = [str(p.relative_to(out_dir)) for p in figs]
    results["wall_seconds"] = time.perf_counter() - t0
    report = reproduce_report.write_report(results, out_dir / "REPRODUCTION.md")
    atomic_write(out_dir / "results.json", json.dumps(jsonable(
        {k: v for k, v in results.items() if k != "figures"} | {"figures": results["figures"]}
    )))  # fmt: skip
    if write_gaits:
        for pth in write_gait_files(results):
            log(f"wrote {pth}")
    if docs_dir is not None:
        docs_dir = Path(docs_dir)
        (docs_dir / "figures").mkdir(parents=True, exist_ok=True)
        shutil.copy(report, docs_dir / "REPRODUCTION.md")
        for pth in figs:
            if pth.suffix == ".png":
                shutil.copy(pth, docs_dir / "figures" / pth.name)
        log(f"copied the report and figures to {docs_dir}")
    log(f"done in {time.perf_counter() - t0:.1f} s; wrote {report}")
    results["report"] = str(report)
    return results
