"""Parameter sweeps the paper's way: e_max against alpha (Fig. 7) and against kc (Fig. 8).

From the gait's fixed point the parameter is stepped outwards, one direction at a time; at
each value 100 strides are run from the previous fixed point and the run counts as converged
iff max |z_99 - z_100| < 1e-5 (IV.B.3, steps 1-3). e_max is then taken at that point: z_100
is polished by Newton at the same parameters (``polish=True``, so the eigenvalues are those
of the fixed point itself rather than of a state within 1e-5 of it; the convergence verdict
is the paper's either way). Newton from z_100 also finds fixed points the 100-stride run did
not settle on (e_max near or above 1), which locates the stability boundary.

Two windows come out (each the contiguous range of values around the base value):

- ``converged_window``: where the 100-stride run converged (the paper's criterion; a slowly
  converging gait with e_max just below 1 falls outside it);
- ``stable_window``: where a fixed point exists and e_max < 1.

With ``refine`` > 0 each window edge is bisected that many times between the last value
inside and the first outside.
"""

from __future__ import annotations

import csv
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model.params import GAIT_KEYS, Params, z_to_paper
from .continuation import Z_COLUMNS
from .fixed_point import find_fixed_point
from .poincare import PAPER_CONV_TOL, PAPER_STRIDES, iterate, stride

STOP_AFTER = 3  # a direction ends after this many consecutive values outside both windows


@dataclass
class SweepPoint:
    value: float  # parameter value (gait units)
    converged: bool  # the paper's 100-stride criterion
    error: float  # max |z_99 - z_100| (SI); inf if the run fell
    failure: str | None  # why the 100-stride run fell, if it did
    z: np.ndarray | None  # the fixed point (polished) or z_100, SI
    found: bool  # Newton found a fixed point (with polish)
    emax: float
    eigenvalues: np.ndarray | None
    phases: list = field(default_factory=list)

    @property
    def has_ds(self) -> bool:
        return "ds" in self.phases

    @property
    def stable(self) -> bool:
        return self.found and self.emax < 1.0


@dataclass
class SweepResult:
    param: str
    base: float
    points: list  # SweepPoint, sorted by value

    def values(self) -> np.ndarray:
        return np.array([p.value for p in self.points])

    def emax(self) -> np.ndarray:
        return np.array([p.emax for p in self.points])

    def converged(self) -> np.ndarray:
        return np.array([p.converged for p in self.points], dtype=bool)

    def has_ds(self) -> np.ndarray:
        return np.array([p.has_ds for p in self.points], dtype=bool)

    def window(self, kind: str = "converged") -> tuple[float, float] | None:
        """The contiguous range around the base value where every point is ``converged``
        (the paper's criterion) or ``stable`` (fixed point found, e_max < 1)."""
        ok = [(p.converged if kind == "converged" else p.stable) for p in self.points]
        vals = self.values()
        i0 = int(np.argmin(np.abs(vals - self.base)))
        if not ok[i0]:
            return None
        lo = hi = i0
        while lo > 0 and ok[lo - 1]:
            lo -= 1
        while hi < len(ok) - 1 and ok[hi + 1]:
            hi += 1
        return float(vals[lo]), float(vals[hi])

    @property
    def converged_window(self):
        return self.window("converged")

    @property
    def stable_window(self):
        return self.window("stable")


def evaluate(
    params: Params, z_start, n_strides=PAPER_STRIDES, tol=PAPER_CONV_TOL, polish=True, sim_kw=None
) -> SweepPoint:
    """One sweep value: 100 strides from z_start, the convergence verdict, e_max."""
    sim_kw = dict(sim_kw or {})
    value = math.nan
    run = iterate(z_start, params, n_strides, tol=tol, **sim_kw)
    z = run.z_last if run.failure is None else None
    err = run.error if run.failure is None else math.inf
    found, emax, lam, phases = False, math.nan, None, []
    starts = [z] if z is not None else []
    if polish:
        starts.append(np.asarray(z_start, dtype=float))
    for z0 in starts:
        fp = find_fixed_point(params, z0, recover=False, sim_kw=sim_kw)
        if fp.converged and fp.eigenvalues is not None:
            found, z, emax, lam, phases = True, fp.z, fp.emax, fp.eigenvalues, fp.phases
            break
    if not polish and z is not None and run.converged:
        from .stability import stability

        st = stability(z, params, **sim_kw)
        found, emax, lam = True, st.emax, st.eigenvalues
        phases = stride(z, params, **sim_kw).phases
    return SweepPoint(
        value=value,
        converged=run.converged,
        error=err,
        failure=run.failure,
        z=z,
        found=found,
        emax=emax,
        eigenvalues=lam,
        phases=list(phases),
    )


def sweep(
    params: Params,
    z_star,
    param: str,
    values,
    n_strides: int = PAPER_STRIDES,
    tol: float = PAPER_CONV_TOL,
    polish: bool = True,
    stop_after: int = STOP_AFTER,
    refine: int = 0,
    progress: bool = False,
    sim_kw: dict | None = None,
    executor=None,
) -> SweepResult:
    """e_max against ``param`` (gait key, gait units) over ``values``, the paper's way.

    The base value is the parameter's value in ``params`` (z_star its fixed point, SI).
    Values above it are visited upwards, values below downwards, each starting from the
    previous value's fixed point (or z_100 where Newton did not polish, else the last start).
    The two directions are independent after the base value: with an ``executor``
    (`bound_env.sim.parallel`) they run as two tasks, with the same result.
    """
    if param not in GAIT_KEYS:
        raise ValueError(f"cannot sweep {param!r}: not a gait key")
    base = float(params.to_gait_dict()[param])
    vals = np.unique(np.append(np.asarray(values, dtype=float), base))
    z0 = np.asarray(z_star, dtype=float)
    args = (params, param, n_strides, tol, polish, sim_kw, stop_after, progress)
    (base_pt,) = _chain(*args, [base], z0, 0)
    ok = base_pt.converged or base_pt.stable
    z_up = base_pt.z if base_pt.z is not None and (base_pt.found or base_pt.converged) else z0
    z_down = base_pt.z if base_pt.z is not None else z0
    chains = [(vals[vals > base], z_up, 0 if ok else 1), (vals[vals < base][::-1], z_down, 0)]
    if executor is None:
        ends = [_chain(*args, list(c), z, m) for c, z, m in chains]
    else:
        futs = [executor.submit(_chain, *args, list(c), z, m) for c, z, m in chains]
        ends = [f.result() for f in futs]
    pts = {p.value: p for p in [base_pt, *ends[0], *ends[1]]}
    res = SweepResult(param, base, [pts[v] for v in sorted(pts)])
    for kind in ("converged", "stable") if refine else ():
        _refine(res, params, param, kind, refine, n_strides, tol, polish, sim_kw, progress)
    return res


def _chain(
    params, param, n_strides, tol, polish, sim_kw, stop_after, progress, chain, z, misses
) -> list:
    """Evaluate ``chain`` in order, each value from the previous one's fixed point; stop
    after ``stop_after`` consecutive values outside both windows (``misses`` so far)."""
    pts = []
    if misses >= stop_after:
        return pts
    for v in chain:
        pt = _evaluate_at(params, param, v, z, n_strides, tol, polish, sim_kw)
        pts.append(pt)
        _say(progress, param, pt)
        if pt.z is not None and (pt.found or pt.converged):
            z = pt.z  # the next value starts from this fixed point
        misses = 0 if (pt.converged or pt.stable) else misses + 1
        if misses >= stop_after:
            break
    return pts


def _evaluate_at(params, param, v, z, n_strides, tol, polish, sim_kw) -> SweepPoint:
    try:
        p = params.with_values(**{param: float(v)})
    except ValueError as e:
        return SweepPoint(float(v), False, math.inf, f"invalid: {e}", None, False, math.nan, None)
    pt = evaluate(p, z, n_strides, tol, polish, sim_kw)
    pt.value = float(v)
    return pt


def _refine(
    res: SweepResult, params, param, kind, n_bisect, n_strides, tol, polish, sim_kw, progress
):
    """Bisect both edges of a window, adding the evaluated points to ``res``."""
    w = res.window(kind)
    if w is None:
        return

    def ok(pt):
        return pt.converged if kind == "converged" else pt.stable

    for edge, outward in ((w[0], -1), (w[1], +1)):
        pts = res.points
        vals = res.values()
        i = int(np.flatnonzero(vals == edge)[0])
        j = i + outward
        if not 0 <= j < len(pts):
            continue
        inside, outside = pts[i], pts[j]
        for _ in range(n_bisect):
            v = 0.5 * (inside.value + outside.value)
            pt = _evaluate_at(params, param, v, inside.z, n_strides, tol, polish, sim_kw)
            _say(progress, param, pt)
            res.points.append(pt)
            if ok(pt):
                inside = pt
            else:
                outside = pt
        res.points.sort(key=lambda p: p.value)


def _say(progress, param, pt: SweepPoint):
    if progress:
        print(
            f"[sweep] {param} = {pt.value:.6g}  converged = {pt.converged}  error = "
            f"{pt.error:.1e}  emax = {pt.emax:.4f}  phases = {'-'.join(pt.phases)}"
            + (f"  fell: {pt.failure}" if pt.failure else ""),
            file=sys.stderr,
            flush=True,
        )


def write_sweep_csv(res: SweepResult, path) -> Path:
    """One row per value: parameter, verdict, error, e_max, |lambda|, z* (paper units)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            [
                res.param,
                "converged",
                "error",
                "failure",
                "found",
                "emax",
                *(f"abs_lambda{i}" for i in range(1, 7)),
                *Z_COLUMNS,
                "has_ds",
                "phases",
            ]
        )
        for p in res.points:
            lam = np.abs(p.eigenvalues) if p.eigenvalues is not None else np.full(6, np.nan)
            z = z_to_paper(p.z) if p.z is not None else np.full(6, np.nan)
            w.writerow(
                [
                    repr(p.value),
                    int(p.converged),
                    repr(p.error),
                    p.failure or "",
                    int(p.found),
                    repr(p.emax),
                    *(repr(float(x)) for x in lam),
                    *(repr(float(x)) for x in z),
                    int(p.has_ds),
                    "-".join(p.phases),
                ]
            )
    return path


def plot_sweep(res: SweepResult, path) -> Path:
    """e_max against the parameter (Figs. 7-8): circles without ds, squares with ds, filled
    where the 100-stride run converged, open where it did not."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x, e = res.values(), res.emax()
    conv, ds = res.converged(), res.has_ds()
    fig, ax = plt.subplots(figsize=(6, 4))
    for mask_ds, marker, color, label in (
        (~ds, "o", "C0", "without ds"),
        (ds, "s", "C2", "with ds"),
    ):
        m = mask_ds & conv
        ax.scatter(x[m], e[m], marker=marker, color=color, label=f"{label}, converged")
        m = mask_ds & ~conv
        ax.scatter(
            x[m],
            e[m],
            marker=marker,
            facecolors="none",
            edgecolors=color,
            label=f"{label}, not converged in 100 strides",
        )
    ax.axhline(1.0, color="k", lw=0.6, ls="--")
    ax.axvline(res.base, color="0.6", lw=0.6, ls=":")
    for kind, color in (("converged", "C0"), ("stable", "C3")):
        w = res.window(kind)
        if w is not None:
            ax.axvspan(w[0], w[1], color=color, alpha=0.08, label=f"{kind} window")
    ax.set_xlabel(res.param)
    ax.set_ylabel(r"$e_{max}$")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper center", framealpha=0.95)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
