"""Continuation of fixed points in a parameter (kc, alpha_deg, ...), Figs. 3-4 and 7-8: the
branch (`continue_branch`), its analysis, files and plot. The stepping itself is the engine
of `bound_env.analysis.continuation_engine` (`natural`, `arclength`, `FixedPointPath`,
`StepControl`, `Stop`; re-exported here).

Two methods, both with a secant predictor and a Newton corrector (`fixed_point.newton`):

- ``"natural"``: step the parameter, predict z by linear extrapolation of the last two
  points, correct at the new parameter value (`find_fixed_point`). Cannot pass a fold.
- ``"arclength"`` (pseudo-arclength): unknowns v = [z, freed values, (p - p_0) / p_scale];
  predict v_k + ds t with t the unit chord of the last two points, correct with the extra
  condition t . (v - v_k) = ds. ``p_scale`` makes the first chord's parameter and state
  parts equally long, so ds starts out as the requested parameter step.

Along the branch each point records z, the residual, the eigenvalues of nabla P and e_max,
the phase sequence (with or without ds, the paper's squares and circles) and three flags
between it and the previous point: ``fold`` (the parameter's arclength derivative changes
sign, or a real eigenvalue crosses +1), ``pd`` (a real eigenvalue crosses -1: period
doubling) and ``ns`` (a complex pair crosses the unit circle: Neimark-Sacker).

Every loop is bounded (``max_points``; the step halves on a failed corrector down to
``min_step``). With ``out_dir`` the branch is written to ``branch.csv`` row by row next to
``branch.json`` (the configuration and status); a later call with the same configuration
reuses a finished branch and resumes an unfinished one.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..files.cache import append_line, atomic_write, read_lines
from ..model.params import GAIT_KEYS, Z_SI_UNITS, Params, z_labels, z_to_paper, z_to_si

# the engine (re-exported: ``from bound_env.analysis.continuation import natural`` keeps working)
from .continuation_engine import (  # noqa: F401
    CORRECTOR_MAX_ITER,
    EASY_ITER,
    GROW,
    JUMP_FACTOR,
    JUMP_FLOOR,
    MAX_POINTS,
    TARGET_TOL,
    FixedPointPath,
    StepControl,
    Stop,
    arclength,
    natural,
)
from .fixed_point import NEWTON_TOL, check_free, find_fixed_point, normalize_pins, param_step
from .poincare import stride
from .stability import DZ, eigen_counts, stability

Z_COLUMNS = z_labels("column")  # CSV columns of z in the paper's units
# the angular components of z again, in SI: deg -> rad does not round-trip exactly (about one
# value in seven changes in its last bit), so a resume reads z back from these columns
_Z_SI_INDEX = tuple(i for i, u in enumerate(Z_SI_UNITS) if "rad" in u)
Z_SI_COLUMNS = tuple(z_labels("si_column")[i] for i in _Z_SI_INDEX)  # theta1_rad, ...


@dataclass
class BranchPoint:
    value: float  # the continuation parameter (gait units, e.g. kc [N m/rad], alpha [deg])
    z: np.ndarray  # SI
    residual: float
    eigenvalues: np.ndarray | None
    emax: float
    phases: list
    period: float  # stride duration [s]
    free: dict = field(default_factory=dict)
    iterations: int = 0
    step: float = math.nan  # the step that reached this point (parameter or arclength)
    fold: bool = False
    pd: bool = False
    ns: bool = False

    @property
    def has_ds(self) -> bool:
        return "ds" in self.phases


@dataclass
class Branch:
    param: str
    method: str
    points: list  # BranchPoint
    reason: str  # why the continuation stopped
    reached: bool  # the target value was reached
    config: dict = field(default_factory=dict)

    def values(self) -> np.ndarray:
        return np.array([p.value for p in self.points])

    def z(self) -> np.ndarray:
        return np.array([p.z for p in self.points])

    def emax(self) -> np.ndarray:
        return np.array([p.emax for p in self.points])


def _params_at(base: Params, param: str, value: float, free_vals: dict) -> Params:
    return base.with_values(**{param: value}, **free_vals)


def analyse_point(
    base: Params, param: str, value: float, u, free, sim_kw, dz=DZ, jacobian_method="fd"
) -> BranchPoint:
    """A corrected point: eigenvalues, e_max, phases, period."""
    free_vals = dict(zip(free, (float(x) for x in u[6:]), strict=True))
    p = _params_at(base, param, value, free_vals)
    z = np.asarray(u[:6], dtype=float)
    res = stride(z, p, **sim_kw)
    r = math.inf if res.z1 is None else float(np.max(np.abs(res.z1 - z)))
    try:
        st = stability(z, p, method=jacobian_method, dz=dz, **sim_kw)
        lam, emax = st.eigenvalues, st.emax
    except Exception:  # noqa: BLE001 - a failed differentiation leaves the point unanalysed
        lam, emax = None, math.nan
    return BranchPoint(
        value=float(value),
        z=z.copy(),
        residual=r,
        eigenvalues=lam,
        emax=emax,
        phases=list(res.phases),
        period=float(res.t_end),
        free=free_vals,
    )


def mark_bifurcations(prev: BranchPoint, cur: BranchPoint, tangent_sign_changed=False):
    """Set the fold / pd / ns flags of ``cur`` from the eigenvalues of both points."""
    cur.fold = bool(tangent_sign_changed)
    if prev.eigenvalues is None or cur.eigenvalues is None:
        return cur
    a, b = eigen_counts(prev.eigenvalues), eigen_counts(cur.eigenvalues)
    cur.pd = a[0] != b[0]
    cur.fold = cur.fold or a[1] != b[1]
    cur.ns = a[2] != b[2]
    return cur


# --------------------------------------------------------------------------------------------
# CSV rows and the on-disk cache
# --------------------------------------------------------------------------------------------


def csv_header(param: str, free) -> list[str]:
    cols = ["index", param, *Z_COLUMNS, "residual", "emax"]
    cols += [f"abs_lambda{i}" for i in range(1, 7)]
    cols += [f"lambda{i}_{c}" for i in range(1, 7) for c in ("re", "im")]
    cols += list(free)
    cols += ["has_ds", "phases", "period_s", "iterations", "step", "fold", "pd", "ns"]
    return cols + list(Z_SI_COLUMNS)


def point_row(i: int, pt: BranchPoint, free) -> list:
    lam = pt.eigenvalues if pt.eigenvalues is not None else np.full(6, np.nan + 0j)
    row = [
        i,
        repr(pt.value),
        *(repr(float(v)) for v in z_to_paper(pt.z)),
        repr(pt.residual),
        repr(pt.emax),
    ]
    row += [repr(float(abs(v))) for v in lam]
    row += [repr(float(x)) for v in lam for x in (v.real, v.imag)]
    row += [repr(pt.free[k]) for k in free]
    return row + [
        int(pt.has_ds),
        "-".join(pt.phases),
        repr(pt.period),
        pt.iterations,
        repr(pt.step),
        int(pt.fold),
        int(pt.pd),
        int(pt.ns),
        *(repr(float(pt.z[i])) for i in _Z_SI_INDEX),
    ]


def csv_line(row) -> str:
    """One CSV row as `csv.writer` writes it (with its ``\r\n``)."""
    buf = io.StringIO()
    csv.writer(buf).writerow(row)
    return buf.getvalue()


def _z_of_row(r: dict) -> np.ndarray:
    """z (SI) of a branch.csv row: exactly as computed, from the SI columns (a file written
    before they existed: converted from the paper's units, exact to about 1e-16)."""
    z = z_to_si([float(r[c]) for c in Z_COLUMNS])
    if all(r.get(c) not in (None, "") for c in Z_SI_COLUMNS):
        z[list(_Z_SI_INDEX)] = [float(r[c]) for c in Z_SI_COLUMNS]
    return z


def read_branch_csv(path, param: str, free=()) -> list[BranchPoint]:
    """The points of a ``branch.csv`` written by `continue_branch` (a last row cut short by a
    kill is skipped with a warning)."""
    pts = []
    for r in csv.DictReader(read_lines(path)):
        lam = np.array(
            [float(r[f"lambda{i}_re"]) + 1j * float(r[f"lambda{i}_im"]) for i in range(1, 7)]
        )
        pts.append(
            BranchPoint(
                value=float(r[param]),
                z=_z_of_row(r),
                residual=float(r["residual"]),
                eigenvalues=None if np.isnan(lam).any() else lam,
                emax=float(r["emax"]),
                phases=r["phases"].split("-"),
                period=float(r["period_s"]),
                free={k: float(r[k]) for k in free},
                iterations=int(r["iterations"]),
                step=float(r["step"]),
                fold=r["fold"] == "1",
                pd=r["pd"] == "1",
                ns=r["ns"] == "1",
            )
        )
    return pts


class _Writer:
    """Appends rows to branch.csv and keeps branch.json's status current."""

    def __init__(self, out_dir, config, param, free, n_existing):
        self.dir = Path(out_dir) if out_dir is not None else None
        self.config, self.param, self.free = config, param, free
        self.i = n_existing
        self.state: dict = {}
        if self.dir is None:
            return
        self.dir.mkdir(parents=True, exist_ok=True)
        self.csv = self.dir / "branch.csv"
        if n_existing == 0:
            atomic_write(self.csv, csv_line(csv_header(param, free)))
        self.status("running")

    def add(self, pt: BranchPoint):
        if self.dir is not None:
            append_line(self.csv, csv_line(point_row(self.i, pt, self.free)), end="")
        self.i += 1

    def status(self, status, reason=None, reached=None):
        if self.dir is None:
            return
        data = {
            "config": self.config,
            "status": status,
            "reason": reason,
            "reached": reached,
            "state": self.state,
        }
        atomic_write(self.dir / "branch.json", json.dumps(data, indent=1))


def load_cached(out_dir, config) -> tuple[dict | None, list]:
    """(branch.json contents, points) if ``out_dir`` holds a branch of this configuration."""
    if out_dir is None:
        return None, []
    d = Path(out_dir)
    js, cs = d / "branch.json", d / "branch.csv"
    if not (js.is_file() and cs.is_file()):
        return None, []
    try:
        data = json.loads(js.read_text())
    except json.JSONDecodeError:
        return None, []
    if data.get("config") != json.loads(json.dumps(config)):
        return None, []
    try:
        pts = read_branch_csv(cs, config["param"], config["free"])
    except (KeyError, ValueError):
        return None, []
    return data, pts


# --------------------------------------------------------------------------------------------
# The continuation itself
# --------------------------------------------------------------------------------------------


@dataclass
class _Job:
    """Everything one continuation run needs besides the points found so far."""

    params: Params
    z0: np.ndarray
    param: str
    p0: float  # start value of the parameter
    to: float
    step: float
    min_step: float
    max_step: float
    free: tuple
    pins: list
    tol: float
    max_points: int
    writer: _Writer
    progress: bool
    dz: float
    jacobian_method: str
    sim_kw: dict

    @property
    def direction(self) -> float:
        return math.copysign(1.0, self.to - self.p0)

    def u(self, pt: BranchPoint) -> np.ndarray:
        """Newton unknowns of a point: z and the freed values."""
        return np.concatenate([pt.z, [pt.free[k] for k in self.free]])

    def analyse(self, value, u) -> BranchPoint:
        return analyse_point(
            self.params, self.param, value, u, self.free, self.sim_kw, self.dz, self.jacobian_method
        )

    def add(self, pts: list, pt: BranchPoint, prev: BranchPoint | None = None, turned=False):
        if prev is not None:
            mark_bifurcations(prev, pt, tangent_sign_changed=turned)
        pts.append(pt)
        self.writer.add(pt)
        _report(self.progress, self.param, pt)

    def path(self) -> FixedPointPath:
        """The engine's view: s is the parameter's value (gait units)."""
        return FixedPointPath(
            lambda value: self.params.with_values(**{self.param: value}),
            self.free,
            self.pins,
            self.sim_kw,
            self.tol,
            self.dz,
        )


def continue_branch(
    params: Params,
    z0,
    param: str,
    to: float,
    step: float | None = None,
    method: str = "natural",
    free=(),
    pin=None,
    tol: float = NEWTON_TOL,
    max_points: int = MAX_POINTS,
    min_step: float | None = None,
    max_step: float | None = None,
    out_dir=None,
    progress: bool = False,
    dz: float = DZ,
    jacobian_method: str = "fd",
    sim_kw: dict | None = None,
) -> Branch:
    """Follow the fixed point through z0 (SI) from the parameter's value in ``params`` to
    ``to`` (gait units). ``step`` defaults to 1/10 of the distance; ``free``/``pin`` as in
    `find_fixed_point` (e.g. free alpha_deg with the energy pinned: the paper's Fig. 4)."""
    if param not in GAIT_KEYS:
        raise ValueError(f"cannot continue in {param!r}: not a gait key")
    if method not in ("natural", "arclength"):
        raise ValueError(f"method must be 'natural' or 'arclength', got {method!r}")
    free = check_free(free)
    if param in free:
        raise ValueError(f"{param} cannot be both the continuation parameter and free")
    pins = normalize_pins(pin)
    sim_kw = dict(sim_kw or {})
    p0, to = float(params.to_gait_dict()[param]), float(to)
    if to == p0:
        raise ValueError(f"the target equals the start value {param} = {p0}")
    step = abs(float(step)) if step else abs(to - p0) / 10.0
    if not step > 0:
        raise ValueError(f"step must be positive, got {step}")
    config = {
        "params": params.to_gait_dict(),
        "z0": [float(v) for v in z_to_paper(z0)],
        "param": param,
        "to": to,
        "step": step,
        "method": method,
        "free": list(free),
        "pin": [list(p) for p in pins],
        "tol": tol,
        "max_points": max_points,
        "dz": dz,
        "jacobian_method": jacobian_method,
        "sim_kw": dict(sim_kw),
    }
    cached, pts = load_cached(out_dir, config)
    if cached is not None and cached.get("status") == "done":
        say(progress, f"reusing {len(pts)} points from {out_dir}")
        return Branch(
            param,
            method,
            pts,
            cached.get("reason") or "cached",
            bool(cached.get("reached")),
            config,
        )
    if cached is None:
        pts = []
    writer = _Writer(out_dir, config, param, free, len(pts))
    if cached is not None:
        writer.state = cached.get("state") or {}
        say(progress, f"resuming from {len(pts)} points in {out_dir}")
    job = _Job(
        params=params,
        z0=np.asarray(z0, dtype=float),
        param=param,
        p0=p0,
        to=to,
        step=step,
        min_step=abs(min_step) if min_step else step / 1024.0,
        max_step=abs(max_step) if max_step else step,
        free=free,
        pins=pins,
        tol=tol,
        max_points=max_points,
        writer=writer,
        progress=progress,
        dz=dz,
        jacobian_method=jacobian_method,
        sim_kw=sim_kw,
    )
    run = _natural if method == "natural" else _arclength
    reason, reached = run(job, pts)
    writer.status("done", reason, reached)
    return Branch(param, method, pts, reason, reached, config)


def say(progress, msg):
    if progress:
        print(f"[continue] {msg}", file=sys.stderr, flush=True)


def _report(progress, param, pt: BranchPoint):
    flags = "".join(f"  {n.upper()}" for n in ("fold", "pd", "ns") if getattr(pt, n))
    say(
        progress,
        f"{param} = {pt.value:.6g}  emax = {pt.emax:.4f}  residual = "
        f"{pt.residual:.1e}  iterations = {pt.iterations}  phases = {'-'.join(pt.phases)}"
        f"{flags}",
    )


def _first_point(job: _Job, pts: list) -> str | None:
    """Correct the start at p0; None on success, else why not."""
    res = find_fixed_point(
        job.params,
        job.z0,
        free=job.free,
        pin=job.pins,
        tol=job.tol,
        analyse=False,
        sim_kw=job.sim_kw,
    )
    if not res.converged:
        return f"no fixed point at the start: {res.reason}"
    pt = job.analyse(job.p0, np.concatenate([res.z, [res.free[k] for k in job.free]]))
    pt.iterations = res.iterations
    job.add(pts, pt)
    return None


def _natural(job: _Job, pts: list, max_points: int | None = None) -> tuple[str, bool]:
    """Natural-parameter continuation; returns (why it stopped, target reached)."""
    max_points = max_points or job.max_points
    if not pts and (why := _first_point(job, pts)) is not None:
        return why, False

    def on_point(value, u, iterations, step):
        pt = job.analyse(value, u)
        pt.iterations, pt.step = iterations, step
        job.add(pts, pt, prev=pts[-1])

    def on_reject(value, info, h):
        say(job.progress, f"{job.param} = {value:.6g}: corrector failed ({info}); step -> {h:.3g}")

    control = StepControl(
        job.step, job.max_step, job.min_step, target_tol=TARGET_TOL * max(1.0, abs(job.to))
    )
    trail = [(pt.value, job.u(pt)) for pt in pts[-2:]]  # the engine's points; pts gets analysed
    stop = natural(
        job.path(),
        trail,
        job.to,
        control,
        max_points - len(pts) + len(trail),
        on_point=on_point,
        on_reject=on_reject,
    )
    if stop.kind == "reached":
        return "reached the target", True
    if stop.kind == "stalled":
        return (
            f"step below {job.min_step:.3g} at {job.param} = {stop.s:.6g} "
            f"(fold or end of the branch? try --method arclength): {stop.info}"
        ), False
    return f"stopped after max_points = {max_points}", False


def _arclength(job: _Job, pts: list) -> tuple[str, bool]:
    """Pseudo-arclength continuation; returns (why it stopped, target reached)."""
    if len(pts) < 2:  # the first two points come from natural continuation
        why, reached = _natural(job, pts, max_points=2)
        if len(pts) < 2 or reached:
            return why, reached
    if "p_scale" not in job.writer.state:  # first chord: parameter part = state part
        dun = float(np.linalg.norm(job.u(pts[1]) - job.u(pts[0])))
        job.writer.state["p_scale"] = abs(pts[1].value - pts[0].value) / max(dun, 1e-12)
    p_scale = job.writer.state["p_scale"]
    job.writer.status("running")

    def v_of(pt):
        return np.append(job.u(pt), (pt.value - job.p0) / p_scale)

    ds = float(np.linalg.norm(v_of(pts[-1]) - v_of(pts[-2])))
    h_first = abs(pts[1].value - pts[0].value)
    steps = np.concatenate(
        [
            np.full(6, job.dz),
            [param_step(k, pts[-1].free[k], job.dz) for k in job.free],
            [param_step(job.param, job.p0, job.dz) / p_scale],
        ]
    )

    def on_point(value, u, iterations, step, turned):
        pt = job.analyse(value, u)
        pt.iterations, pt.step = iterations, step
        job.add(pts, pt, prev=pts[-1], turned=turned)

    def on_reject(value, info, ds_new):
        say(job.progress, f"arclength corrector failed ({info}); ds -> {ds_new:.3g}")

    trail = [(pt.value, job.u(pt)) for pt in pts]
    stop = arclength(
        job.path(),
        trail,
        job.to,
        ds,
        max(ds, job.max_step / h_first * ds),
        ds * job.min_step / job.step,
        steps,
        job.max_points,
        origin=job.p0,
        scale=p_scale,
        stop_past_start=3,
        on_point=on_point,
        on_reject=on_reject,
    )
    if stop.kind == "reached":
        return "reached the target", True
    if stop.kind == "stalled":
        return (f"arclength step below minimum at {job.param} = {stop.s:.6g}: {stop.info}"), False
    if stop.kind == "turned_back":
        return f"the branch turned back past the start ({job.param} = {stop.s:.6g})", False
    return f"stopped after max_points = {job.max_points}", False


# --------------------------------------------------------------------------------------------
# Plot
# --------------------------------------------------------------------------------------------

Z_LABELS = z_labels("tex")


def plot_branch(branch: Branch, path) -> Path:
    """z* components, e_max (and freed values) against the parameter; open circles without
    ds, open squares with ds (Figs. 3-4); bifurcation flags in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = branch.points
    x = branch.values()
    zp = np.array([z_to_paper(p.z) for p in pts]) if pts else np.empty((0, 6))
    free = list(pts[0].free) if pts else []
    series = [(Z_LABELS[i], zp[:, i]) for i in range(6)]
    series.append((r"$e_{max}$", branch.emax()))
    series += [(k, np.array([p.free[k] for p in pts])) for k in free]
    ncol = 4
    nrow = math.ceil(len(series) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4 * ncol, 3 * nrow), squeeze=False)
    ds = np.array([p.has_ds for p in pts], dtype=bool)
    flag = np.array([p.fold or p.pd or p.ns for p in pts], dtype=bool)
    for ax, (label, y) in zip(axes.flat, series, strict=False):
        ax.plot(x, y, "-", color="0.7", lw=0.8, zorder=1)
        ax.scatter(
            x[~ds],
            y[~ds],
            marker="o",
            facecolors="white",
            edgecolors="C0",
            label="without ds",
            zorder=2,
        )
        ax.scatter(
            x[ds], y[ds], marker="s", facecolors="white", edgecolors="C2", label="with ds", zorder=2
        )
        if flag.any():
            ax.scatter(x[flag], y[flag], marker="x", color="red", label="bifurcation", zorder=3)
        if label == r"$e_{max}$":
            ax.axhline(1.0, color="k", lw=0.6, ls="--")
        ax.set_xlabel(branch.param)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(series) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle(
        f"fixed points against {branch.param} ({branch.method}): {branch.reason}", fontsize=9
    )
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
