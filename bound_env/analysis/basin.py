"""Basin atlas: which apex states on a 2-D slice return to the cycle, and how others fail.

`basin_map` starts the loop (passive, or a controller) at every point of a ``grid x grid``
slice through the gait's z* (the passive cycle), varying two apex components (``axes``, any
two of `Z_NAMES`) and holding the other four at z*, and iterates the apex-to-apex map up to
``max_strides`` times. Every controller's map has the same starts, so maps overlay. Each
start ends as one of

- ``returned``: the max-abs apex error to the cycle fell below ``tol`` (SI; 1e-4, as in
  `bound_env.analysis.margins`); ``strides`` = strides taken to get there;
- ``fell``: a stride failed; ``reason`` = its `bound_env.model.hybrid` failure, ``phase`` = the
  stance condition it failed in, ``strides`` = the stride that failed;
- ``undecided``: neither within ``max_strides`` (= ``strides``).

Two ways to run a batch of starts:

- **passive**: `passive_batch`, one compiled function that loops over the starts and over
  their strides with the fast back-end's `bound_env.model.fast.advance` (the same call
  `bound_env.model.hybrid.simulate_stride` makes);
- **a controller**: `controller_batch`, the one batched closed loop of the project
  (`bound_env.analysis.apex_loop`, which margins runs too): a stride controller's strides
  through the one stride map, any other controller (``batch(obs)``, or one copy per robot
  with its ``on_apex`` hook) through the native vector env's kernel, one controller call per
  control interval for the whole batch. Each stride restarts the control intervals at its
  apex (the robot is reset at the apex it reached), so the closed-loop apex map is the one
  `bound_env.analysis.margins` measures.

The grid is cut into chunks of ``chunk`` starts (row-major), one task each, through any
executor (`bound_env.sim.parallel`). A chunk's result depends only on its starts, so the map is
the same for every executor. Finished chunks are cached as ``<out>/chunks/<key>-<i>.npz``
(written atomically), so a killed run resumes with the missing chunks only.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..files.cache import atomic_write
from ..model.dynamics import jit, make_aux
from ..model.events import APEX, F_NO_APEX, FAIL_FIRST, FAILURES, N_FLAGS, PHASES, TIME_UP
from ..model.events import phase_index as _phase_index
from ..model.fast import EVENT_CAPACITY, Options, advance, event_log, recorder
from ..model.params import Z_IN_Y, Z_NAMES, Z_PAPER_UNITS, load_gait, z_to_paper, z_to_si
from ..model.stride import DEFAULT_T_MAX
from ..sim.stride_map import EVAL_RTOL, RETURN_TOL
from .apex_loop import FELL, RETURNED, UNDECIDED, apex_loop, empty_outputs  # noqa: F401
from .basin_defaults import (  # noqa: F401 - the command line reads them without numba
    DEFAULT_CHUNK,
    DEFAULT_GRID,
    DEFAULT_STRIDES,
    MAX_GRID,
    MAX_STRIDES,
)

OUTCOMES = ("returned", "fell", "undecided")
REASONS = ("",) + FAILURES  # reason code 0: none; k >= 1: FAILURES[k - 1]
# Default half-widths of the slice around the cycle, paper units [m, deg, deg, m/s, deg/s, deg/s]
DEFAULT_HALF_WIDTH = np.array([0.05, 10.0, 10.0, 0.6, 200.0, 200.0])
CYCLE_STRIDES = 400  # iterations to settle a controller's cycle
CYCLE_TOL = 1e-11  # successive apex states closer than this: settled (SI)


# --------------------------------------------------------------------------------------------
# Passive: one compiled loop over starts and strides
# --------------------------------------------------------------------------------------------


@jit
def passive_batch(
    Z, aux0, z_ref, max_strides, tol, rtol, t_max, outcome, reason, strides, phase, error, z_last
):
    """Iterate the passive map P (eq. 18) from each row of ``Z`` (SI apex states).

    Every stride starts like `bound_env.model.hybrid.simulate_stride`: y from z with x_g = 0,
    ydot_g = 0 (eq. 17), both legs in flight (``aux0``), t = 0. Fills ``outcome`` (RETURNED,
    FELL, UNDECIDED), ``reason`` (0 or 1 + failure index), ``strides``, ``phase`` (stance
    condition at the failure, -1 if none), ``error`` (last max-abs apex error to z_ref) and
    ``z_last`` (the last apex state reached).
    """
    n = Z.shape[0]
    y = np.empty(8)
    aux = np.empty(aux0.shape[0])
    flags = np.zeros(N_FLAGS, dtype=np.bool_)
    z = np.empty(6)
    log = event_log(EVENT_CAPACITY, np.empty((1, 8)))
    rec = recorder(1, 0.0)
    opts = Options(rtol, rtol, True)
    for k in range(n):
        z[:] = Z[k]
        z_last[k, :] = z
        outcome[k], reason[k], strides[k], phase[k] = UNDECIDED, 0, max_strides, -1
        error[k] = np.inf
        for s in range(1, max_strides + 1):
            y[0], y[5] = 0.0, 0.0
            for j in range(6):
                y[Z_IN_Y[j]] = z[j]
            aux[:] = aux0
            flags[:] = False
            status, _, _ = advance(y, aux, flags, 0.0, t_max, 0.0, opts, log, rec)
            if status == TIME_UP:
                status = F_NO_APEX
            if status != APEX:
                outcome[k], reason[k], strides[k] = FELL, status - FAIL_FIRST + 1, s
                phase[k] = _phase_index(aux)
                break
            err = 0.0
            for j in range(6):
                z[j] = y[Z_IN_Y[j]]
                err = max(err, abs(z[j] - z_ref[j]))
            error[k] = err
            z_last[k, :] = z
            if err < tol:
                outcome[k], strides[k] = RETURNED, s
                break


# --------------------------------------------------------------------------------------------
# A controller: the native vector env's kernel, one batched controller call per interval
# --------------------------------------------------------------------------------------------


_TASKS: dict = {}  # (controller fingerprint, gait, rtol) -> PassiveBoundTask, per process


def _task_for(controller, gait: str, rtol: float):
    from ..sim.task import PassiveBoundTask

    key = (controller.fingerprint(), gait, rtol)
    if key not in _TASKS:
        kwargs = dict(controller.env_kwargs)
        kwargs.pop("gait", None)
        overrides = kwargs.pop("gait_overrides", None)
        if len(_TASKS) > 16:
            _TASKS.clear()
        _TASKS[key] = PassiveBoundTask(
            gait=gait, gait_overrides=overrides or None, rtol=rtol, reset_noise_scale=0.0, **kwargs
        )
    return _TASKS[key]


def controller_batch(
    controller,
    Z,
    z_ref,
    gait: str = "default",
    max_strides=DEFAULT_STRIDES,
    tol=RETURN_TOL,
    rtol=EVAL_RTOL,
) -> dict:
    """Iterate the closed-loop apex map of ``controller`` from each row of ``Z`` (SI); the
    same outputs as `passive_batch`, as a dict of arrays: the one batched closed loop
    (`bound_env.analysis.apex_loop`), a stride controller's strides through the one stride
    map, any other controller through the task's batch kernel."""
    if callable(getattr(controller, "interval_actions", None)):
        sm = _map_for(controller, gait, rtol)

        def strides(Zs, kicks):
            return sm.run(Zs, controller.interval_actions(Zs))

        return apex_loop(Z, z_ref, max_strides, tol=tol, strides=strides)
    task = _task_for(controller, gait, rtol)
    return apex_loop(Z, z_ref, max_strides, tol=tol, task=task, controller=controller)


def _map_for(controller, gait: str, rtol: float):
    """The one stride map of ``controller``'s task settings (kept per process)."""
    from ..sim.stride_map import StrideMap
    from ..sim.task import DEFAULT_DT, DEFAULT_MAX_TORQUE

    kwargs = controller.env_kwargs  # the env's defaults where the controller names none
    key = ("map", controller.fingerprint(), gait, rtol)
    if key not in _TASKS:
        if len(_TASKS) > 16:
            _TASKS.clear()
        _TASKS[key] = StrideMap(
            gait, kwargs.get("gait_overrides") or None, kwargs.get("dt", DEFAULT_DT),
            kwargs.get("max_torque", DEFAULT_MAX_TORQUE), rtol,
        )  # fmt: skip
    return _TASKS[key]


def controller_cycle(
    controller, z0, gait: str = "default", rtol=EVAL_RTOL, strides=CYCLE_STRIDES
) -> tuple[np.ndarray, float]:
    """The closed loop's cycle apex state by iterating its map from ``z0`` (one robot of the
    batch kernel): (z_cl, last successive difference, SI). Iterates until the difference is
    below `CYCLE_TOL` or ``strides`` strides; raises RuntimeError if the loop falls."""
    z = np.asarray(z0, dtype=float)
    diff = math.inf
    for _ in range(strides):
        r = controller_batch(controller, z[None], z + 1e9, gait, max_strides=1, rtol=rtol)
        if r["outcome"][0] == FELL:
            raise RuntimeError(
                f"the closed loop falls from its start ({REASONS[r['reason'][0]]})"
                " while settling on its cycle"
            )
        z1 = r["z_last"][0]
        diff = float(np.max(np.abs(z1 - z)))
        z = z1
        if diff < CYCLE_TOL:
            break
    return z, diff


# --------------------------------------------------------------------------------------------
# The grid, its chunks, the tasks
# --------------------------------------------------------------------------------------------


@dataclass
class BasinSpec:
    """Everything a chunk task needs (picklable)."""

    axes: tuple  # two indices into Z_NAMES
    values: tuple  # (values along axis 0, values along axis 1), SI
    z_slice: np.ndarray  # the slice's centre (SI): the other four components are held here
    z_target: np.ndarray  # the loop's cycle (SI): "returned" = within tol of it
    controller: object = None  # None: passive (compiled); else batch(obs), env_kwargs
    gait: str = "default"
    max_strides: int = DEFAULT_STRIDES
    tol: float = RETURN_TOL
    rtol: float = EVAL_RTOL
    chunk: int = DEFAULT_CHUNK
    label: str = "passive"
    extra: dict = field(default_factory=dict)

    @property
    def n_starts(self) -> int:
        return len(self.values[0]) * len(self.values[1])

    @property
    def n_chunks(self) -> int:
        return -(-self.n_starts // self.chunk)

    def starts(self, i: int | None = None) -> np.ndarray:
        """Start apex states (SI), row-major: row r of the grid is ``values[1][r]``, column c
        is ``values[0][c]``; chunk ``i`` only if given."""
        vx, vy = (np.asarray(v, dtype=float) for v in self.values)
        gx, gy = np.meshgrid(vx, vy)
        Z = np.tile(np.asarray(self.z_slice, dtype=float), (gx.size, 1))
        Z[:, self.axes[0]] = gx.ravel()
        Z[:, self.axes[1]] = gy.ravel()
        if i is None:
            return Z
        return Z[i * self.chunk : (i + 1) * self.chunk]

    def key(self) -> str:
        fp = "passive" if self.controller is None else self.controller.fingerprint()
        text = json.dumps(
            [
                fp,
                self.gait,
                list(self.axes),
                [list(map(float, v)) for v in self.values],
                list(map(float, self.z_slice)),
                list(map(float, self.z_target)),
                self.max_strides,
                self.tol,
                self.rtol,
                self.chunk,
            ]
        )
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def run_chunk(spec: BasinSpec, i: int) -> dict:
    """One task: the starts of chunk ``i``."""
    Z = spec.starts(i)
    t0 = time.perf_counter()
    if spec.controller is None:
        gait = load_gait(spec.gait)
        out = empty_outputs(len(Z), spec.max_strides)
        passive_batch(
            Z,
            make_aux(gait.params.to_array()),
            np.asarray(spec.z_target, float),
            int(spec.max_strides),
            float(spec.tol),
            float(spec.rtol),
            float(DEFAULT_T_MAX),
            out["outcome"],
            out["reason"],
            out["strides"],
            out["phase"],
            out["error"],
            out["z_last"],
        )
    else:
        out = controller_batch(
            spec.controller,
            Z,
            np.asarray(spec.z_target, float),
            spec.gait,
            spec.max_strides,
            spec.tol,
            spec.rtol,
        )
    out.pop("apexes")
    out["seconds"] = time.perf_counter() - t0
    return out


def _save_npz(path: Path, **arrays) -> None:
    """Atomic (`bound_env.files.cache.atomic_write`): complete, or not there."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write(path, buf.getvalue())


def run_grid(
    spec: BasinSpec,
    executor,
    out_dir: Path | None = None,
    progress: bool = False,
    desc: str = "basin",
) -> dict:
    """All chunks of ``spec`` through ``executor`` (cached per chunk under ``out_dir``);
    returns the outputs reshaped to the grid (rows: axis 1, columns: axis 0)."""
    from ..sim.parallel import TasksFailed, run_tasks

    key = spec.key()
    cache_dir = out_dir / "chunks" if out_dir is not None else None
    if cache_dir is not None:
        cache_dir.mkdir(parents=True, exist_ok=True)
    parts, tasks = {}, {}
    for i in range(spec.n_chunks):
        path = cache_dir / f"{key}-{i}.npz" if cache_dir is not None else None
        if path is not None and path.is_file():
            try:
                with np.load(path) as d:
                    parts[i] = {k: d[k] for k in d.files}
                continue
            except (OSError, ValueError):  # a damaged file: run the chunk again
                pass
        tasks[f"{key}-{i}"] = (run_chunk, (spec, i), (spec.label, f"chunk {i}"))

    def keep(k, res):
        if cache_dir is not None:
            _save_npz(cache_dir / f"{k}.npz", **res)

    done, failures = run_tasks(executor, tasks, progress, desc, keep, done_before=len(parts))
    if failures:
        raise TasksFailed(
            failures,
            spec.n_chunks,
            "; the others are cached: rerun to retry" if cache_dir is not None else "",
        )
    for k, res in done.items():
        parts[int(k.rsplit("-", 1)[1])] = res
    shape = (len(spec.values[1]), len(spec.values[0]))
    grid = {}
    for name in ("outcome", "reason", "strides", "phase", "error", "z_last"):
        cat = np.concatenate([parts[i][name] for i in range(spec.n_chunks)])
        grid[name] = cat.reshape(shape + cat.shape[1:])
    grid["task_seconds"] = float(sum(float(parts[i]["seconds"]) for i in parts))
    return grid


# --------------------------------------------------------------------------------------------
# The map: axes, ranges, outputs
# --------------------------------------------------------------------------------------------


def parse_axes(text: str | tuple) -> tuple[int, int]:
    """``"xdot_g,y_g"`` -> indices into `Z_NAMES` (two different apex components)."""
    names = [t.strip() for t in text.split(",")] if isinstance(text, str) else list(text)
    if len(names) != 2 or names[0] == names[1] or not all(n in Z_NAMES for n in names):
        raise ValueError(
            f"--axes must be two different apex components from {Z_NAMES}, "
            f"e.g. xdot_g,y_g; got {text!r}"
        )
    return Z_NAMES.index(names[0]), Z_NAMES.index(names[1])


def parse_range(text: str | None, axes: tuple, z_center) -> np.ndarray:
    """``"LO,HI,LO,HI"`` (paper units of the two axes) -> array of 4; default: the centre
    (SI) plus or minus `DEFAULT_HALF_WIDTH` on each axis."""
    zc = z_to_paper(z_center)
    if text is None:
        return np.array([zc[a] + s * DEFAULT_HALF_WIDTH[a] for a in axes for s in (-1, 1)])
    try:
        r = np.array([float(v) for v in text.split(",")])
    except ValueError:
        r = np.array([])
    if r.shape != (4,) or not np.all(np.isfinite(r)) or r[0] >= r[1] or r[2] >= r[3]:
        units = ", ".join(f"{Z_NAMES[a]} [{Z_PAPER_UNITS[a]}]" for a in axes)
        raise ValueError(f"--range must be LO,HI,LO,HI with LO < HI ({units}), got {text!r}")
    return r


def axis_values(axes: tuple, ranges_paper, grid: int) -> tuple[np.ndarray, np.ndarray]:
    """The grid values along both axes, SI (``grid`` points from LO to HI)."""
    vals = []
    for k, a in enumerate(axes):
        v = np.linspace(ranges_paper[2 * k], ranges_paper[2 * k + 1], grid)
        z = np.zeros((grid, 6))
        z[:, a] = v
        vals.append(np.array([z_to_si(row)[a] for row in z]))
    return vals[0], vals[1]


def basin_map(
    controller=None,
    label: str = "passive",
    axes="xdot_g,y_g",
    grid: int = DEFAULT_GRID,
    ranges: str | None = None,
    gait: str = "default",
    max_strides: int = DEFAULT_STRIDES,
    chunk: int = DEFAULT_CHUNK,
    executor=None,
    scheduler: str | None = None,
    workers: int = 1,
    out: str | Path | None = None,
    progress: bool = False,
    overlay_passive: bool = True,
) -> dict:
    """The basin map of the passive gait (``controller=None``) or of a controller on a
    ``grid x grid`` slice (see the module docstring). The slice passes through the gait's
    z* for every controller (so maps of different controllers share their starts); a
    controller's "returned" means to its own closed-loop cycle. With ``out``: writes
    ``basin.npz`` and ``basin.png`` there (and caches chunks). Returns a summary dict."""
    import contextlib

    from ..sim.parallel import open_pool

    ax = parse_axes(axes)
    if not 2 <= int(grid) <= MAX_GRID:
        raise ValueError(f"--grid must be from 2 to {MAX_GRID}, got {grid}")
    if not 1 <= int(max_strides) <= MAX_STRIDES:
        raise ValueError(f"--strides must be from 1 to {MAX_STRIDES}, got {max_strides}")
    if int(chunk) < 1:
        raise ValueError(f"--chunk must be at least 1, got {chunk}")
    z_star = np.asarray(load_gait(gait).z0, dtype=float)
    rng = parse_range(ranges, ax, z_star)
    values = axis_values(ax, rng, int(grid))
    t0 = time.perf_counter()
    cycle_diff = 0.0
    z_target = z_star
    if controller is not None:
        z_target, cycle_diff = controller_cycle(controller, z_star, gait)
    spec = BasinSpec(
        axes=ax,
        values=values,
        z_slice=z_star,
        z_target=z_target,
        controller=controller,
        gait=gait,
        max_strides=int(max_strides),
        chunk=int(chunk),
        label=label,
    )
    out_dir = Path(out) if out is not None else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    passive = None
    with contextlib.ExitStack() as stack:
        if executor is None:
            executor = stack.enter_context(open_pool(scheduler, workers)).executor
        res = run_grid(spec, executor, out_dir, progress, f"basin {label}")
        seconds = time.perf_counter() - t0
        if controller is not None and overlay_passive:
            pspec = BasinSpec(
                axes=ax,
                values=values,
                z_slice=z_star,
                z_target=z_star,
                gait=gait,
                max_strides=int(max_strides),
                chunk=int(chunk),
            )
            passive = run_grid(pspec, executor, out_dir, progress, "basin passive (overlay)")
    summary = {
        "policy": label,
        "gait": gait,
        "axes": [Z_NAMES[a] for a in ax],
        "units": [Z_PAPER_UNITS[a] for a in ax],
        "range": rng.tolist(),
        "grid": int(grid),
        "max_strides": int(max_strides),
        "return_tol": RETURN_TOL,
        "rtol": EVAL_RTOL,
        "chunk": int(chunk),
        "z_slice": z_star.tolist(),
        "z_target": z_target.tolist(),
        "cycle_settle_diff": cycle_diff,
        "starts": spec.n_starts,
        "fraction": {name: float(np.mean(res["outcome"] == k)) for k, name in enumerate(OUTCOMES)},
        "seconds": seconds,
        "starts_per_s": spec.n_starts / seconds,
    }
    if out_dir is not None:
        write_basin(out_dir, summary, values, res, passive)
    return summary


def write_basin(out_dir: Path, summary: dict, values, res: dict, passive: dict | None) -> None:
    """``basin.npz`` (every array of the map, plus the passive map when overlaid) and
    ``basin.png``; both written atomically."""
    arrays = {
        "axes": np.array(summary["axes"]),
        "units": np.array(summary["units"]),
        "x": values[0],
        "y": values[1],  # SI, columns / rows
        "x_paper": np.linspace(*summary["range"][:2], len(values[0])),
        "y_paper": np.linspace(*summary["range"][2:], len(values[1])),
        "outcome": res["outcome"],
        "outcome_names": np.array(OUTCOMES),
        "reason": res["reason"],
        "reason_names": np.array(REASONS),
        "strides": res["strides"],
        "phase": res["phase"],
        "phase_names": np.array(PHASES),
        "error": res["error"],
        "z_last": res["z_last"],
        "z_slice": np.array(summary["z_slice"]),
        "z_target": np.array(summary["z_target"]),
        "settings": np.array(
            json.dumps({k: v for k, v in summary.items() if k not in ("seconds", "starts_per_s")})
        ),
    }
    if passive is not None:
        arrays["passive_outcome"] = passive["outcome"]
        arrays["passive_strides"] = passive["strides"]
    _save_npz(out_dir / "basin.npz", **arrays)
    plot_basin(out_dir / "basin.png", summary, arrays)


def return_scale(strides, max_strides: int) -> int:
    """The top of the strides-to-return colour scale: the 99th percentile of the starts that
    returned, rounded up to a multiple of 5 (at least 5, at most ``max_strides``), so the
    colours spread over the range the returns use; ``max_strides`` when none returned."""
    s = np.asarray(strides, dtype=float)
    s = s[np.isfinite(s)]
    if s.size == 0:
        return int(max_strides)
    top = int(5 * np.ceil(np.percentile(s, 99) / 5))
    return int(min(max(top, 5), max_strides))


def _legend_below(ax) -> None:
    """A map's legend under its axes, outside the data."""
    ax.legend(
        fontsize=7,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.13),
        ncol=2,
        frameon=False,
    )


def plot_basin(path: Path, summary: dict, a: dict) -> Path:
    """Left: strides to return (colour, scaled to the range the returns use: `return_scale`),
    fell (light grey), undecided (dark grey), with the passive basin's boundary (red) on a
    controller's map. Right: why and where starts fell. Legends under the maps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    x, y = a["x_paper"], a["y_paper"]
    ext = [x[0], x[-1], y[0], y[-1]]
    lab = [f"{n} [{u}]" for n, u in zip(summary["axes"], summary["units"], strict=True)]
    zt = z_to_paper(a["z_target"])
    ix, iy = (Z_NAMES.index(n) for n in summary["axes"])
    fig, axs = plt.subplots(1, 2, figsize=(12.0, 5.4), dpi=100, layout="constrained")
    ax = axs[0]
    bg = np.where(a["outcome"] == FELL, 0.85, np.where(a["outcome"] == UNDECIDED, 0.45, np.nan))
    ax.imshow(bg, origin="lower", extent=ext, aspect="auto", cmap="gray", vmin=0, vmax=1)
    ret = np.where(a["outcome"] == RETURNED, a["strides"], np.nan).astype(float)
    top = return_scale(ret, summary["max_strides"])
    im = ax.imshow(
        ret,
        origin="lower",
        extent=ext,
        aspect="auto",
        cmap="viridis",
        vmin=1,
        vmax=top,
    )
    over = bool(np.nanmax(ret, initial=0) > top) if np.isfinite(ret).any() else False
    fig.colorbar(im, ax=ax, label="strides to return", extend="max" if over else "neither")
    if "passive_outcome" in a:
        ax.contour(
            x,
            y,
            (a["passive_outcome"] == RETURNED).astype(float),
            levels=[0.5],
            colors="red",
            linewidths=1.2,
        )
        ax.plot([], [], "r-", label="passive basin boundary")
    ax.plot(zt[ix], zt[iy], "X", ms=9, mfc="white", mec="black", mew=1, label="cycle")
    _legend_below(ax)
    f = summary["fraction"]
    ax.set_title(
        f"{summary['policy']}: returned {100 * f['returned']:.1f} %, fell "
        f"{100 * f['fell']:.1f} %, undecided {100 * f['undecided']:.1f} %",
        fontsize=9,
    )
    ax.set_xlabel(lab[0])
    ax.set_ylabel(lab[1])
    ax = axs[1]
    used = sorted(int(r) for r in np.unique(a["reason"][a["outcome"] == FELL]))
    if used:
        codes = np.full(a["reason"].shape, np.nan)
        for k, r in enumerate(used):
            codes[(a["reason"] == r) & (a["outcome"] == FELL)] = k
        cmap = ListedColormap(plt.get_cmap("tab10").colors[: len(used)])
        ax.imshow(
            codes,
            origin="lower",
            extent=ext,
            aspect="auto",
            cmap=cmap,
            vmin=-0.5,
            vmax=len(used) - 0.5,
            interpolation="nearest",
        )
        for k, r in enumerate(used):
            phases = a["phase"][(a["reason"] == r) & (a["outcome"] == FELL)]
            ph = ", ".join(f"{PHASES[p]}" for p in sorted(set(int(v) for v in phases)) if p >= 0)
            ax.plot([], [], "s", color=cmap(k), label=f"{REASONS[r]} (in {ph or '?'})")
        _legend_below(ax)
    ax.set_title("fell: reason (stance condition)", fontsize=9)
    ax.set_xlabel(lab[0])
    ax.set_ylabel(lab[1])
    fig.suptitle(
        f"basin on the {summary['axes'][0]} x {summary['axes'][1]} slice through z* "
        f"(gait {summary['gait']}; returned = within {summary['return_tol']:g} of the "
        f"cycle in {summary['max_strides']} strides)",
        fontsize=9,
    )
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic_write(path, buf.getvalue())
    return path


def summary_text(s: dict) -> str:
    f = s["fraction"]
    return (
        f"basin {s['policy']} on {s['axes'][0]} x {s['axes'][1]} ({s['grid']}x{s['grid']}, "
        f"{s['starts']} starts): returned {100 * f['returned']:.1f} %, fell "
        f"{100 * f['fell']:.1f} %, undecided {100 * f['undecided']:.1f} %  "
        f"({s['seconds']:.1f} s, {s['starts_per_s']:.0f} starts/s)"
    )


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)
