"""The one stride map: a stride of the step env (PassiveBound-v0) from an apex state, batched.

Everything in the project that advances a stride under a torque profile uses this module: the
stride env (`PassiveBoundStride-v1`), the classical designs (`bound_env.control.design`), the
MPC's planning model, distillation and fine-tuning, and the margins' closed loop of a stride
controller. So a profile means the same thing everywhere, and a stride controller is measured
on the map it was designed and trained on.

The plant is the step env
-------------------------
A stride from the apex state z (eq. 17, t = 0 there) under the normalized **interval actions**
a[0], a[1], ... is the step env's own zero-order hold: interval k, [k dt, (k + 1) dt], holds
the torque tau_k = max_torque * clip(a_k, -1, 1), integrated event-accurately by the step
env's compiled kernel (`bound_env.sim.task.advance_interval`, the dynamics of every step of
PassiveBound-v0), until the step in which the next apex is passed; the apex state is located on the
integrator's dense output. The last action holds past the given ones. A stride-level profile
tau(t) = max_torque sum_i u_i phi_i(t) enters as its **interval averages**
a = W u (`interval_weights`), so each interval delivers the profile's impulse exactly.

So a stride here is bit-identical to the stride of a PassiveBound-v0 episode started at z with
``reset(options={"apex_state": z})`` and stepped with the same actions (tested), and zero
action is the passive Poincare map P of eq. 18 up to the integrator tolerance.

For planning only, ``StrideMap(segments=True)`` integrates each run of equal interval actions
as one segment and stops at the apex (`stride_segments`): the same piecewise-constant torque,
so the same stride to the integrator tolerance, but not bit for bit (the step env restarts
its integration at every interval); the MPC plans on it.

What it owns (one definition each): `EVAL_RTOL`, the integrator tolerance of every evaluation;
`RETURN_TOL`, "returned to the cycle"; `max_intervals`, the step limit of one stride; and the
failure names of the outcomes (`bound_env.sim.task.FAILURE_NAMES`, from `bound_env.model.events`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from ..model.dynamics import jit
from ..model.events import APEX, CONTINUE, F_NO_APEX, F_NON_FINITE, FAIL_FIRST, TIME_UP, phase_index
from ..model.fast import Options, advance, event_log, recorder
from ..model.params import P_TAU, Z_IN_Y
from ..model.terrain import change_slope, set_slope
from .task import (
    C_ATOL,
    C_DT,
    C_MAX_TORQUE,
    C_NO_APEX,
    C_RTOL,
    C_SLOPE_NOISE,
    DEFAULT_DT,
    DEFAULT_MAX_TORQUE,
    FAILURE_NAMES,
    NO_APEX_TIME,
    PassiveBoundTask,
    S,
    advance_interval,
    reset_at_apex,
    step_env,
    strict_jit,
)

EVAL_RTOL = 1e-10  # integrator tolerance of every evaluation (relative and absolute)
RETURN_TOL = 1e-4  # "returned to the cycle": max |z - z_target| below this (SI)
NO_KICK = -1  # kick_step of a stride without a push
# segments (planning only): consecutive interval actions that differ by at most this (normalized
# torque; 1e-12 x max_torque N m, far below any integrator tolerance) are one segment
SEGMENT_TOL = 1e-12
# intervals per segment at most with segments=True: no cap. (A cap keeps the integrator's
# steps shorter; at the planning tolerance 1e-8 longer steps very rarely step over a brief
# guard violation that the per-interval stride sees, or the reverse: 1 stride in ~1 000 of the
# tests' and validation's differs in outcome either way, see tests/test_stride_map.py)
MAX_SEGMENT = 1 << 30
_Z_IDX = np.array(Z_IN_Y, dtype=np.int64)


def max_intervals(dt: float) -> int:
    """The step limit of one stride: control intervals after which a stride without an apex
    has certainly failed (`NO_APEX_TIME` plus two intervals)."""
    return int(math.ceil(NO_APEX_TIME / dt)) + 2


def interval_weights(edges: np.ndarray, phi: np.ndarray, dt: float) -> np.ndarray:
    """W with a = W @ u: the interval averages over [k dt, (k + 1) dt] from the apex of the
    basis ``phi`` (sub-windows on ``edges``, the last holding past edges[-1]), for every
    interval that starts before the nominal period T, plus one last row, the last
    sub-window's value, held until the apex."""
    T = float(edges[-1])
    n = int(math.ceil(T / dt - 1e-12))
    t_edges = dt * np.arange(n + 1, dtype=float)
    W = np.zeros((n + 1, phi.shape[0]))  # on sub-windows, then mapped through phi
    hi_win = np.append(edges[1:-1], math.inf)
    for k in range(n):
        lo, hi = t_edges[k], t_edges[k + 1]
        W[k] = np.clip(np.minimum(hi_win, hi) - np.maximum(edges[:-1], lo), 0.0, None) / dt
    W[n, -1] = 1.0  # from n dt on: the last sub-window's value, held until the apex
    return W @ phi


@jit
def stride(y, aux, flags, s, apex, obs, cfg, actions, kick_step, kick_index, kick_delta, n_max):
    """One stride of the step env from the apex state in (y, aux, flags, s) (put there by
    `bound_env.sim.task.reset_at_apex`): interval k holds actions[min(k, len - 1)]; before interval
    ``kick_step`` the velocity y[kick_index] gets ``kick_delta``. At most ``n_max`` intervals.

    Returns (status, t, impulse, intervals, impulse_before, t_prev): `APEX` with t the apex
    time, else the failure code and the time reached; impulse = integral of |tau| dt up to t
    [N m s], impulse_before the same up to t_prev, the start of the last interval. At an apex
    the full state is ``apex[0]`` (and s[S.T] the end of that interval); after a failure,
    ``y`` is the last state."""
    if s[S.STATUS] >= FAIL_FIRST:  # an impossible start
        return int(s[S.STATUS]), 0.0, 0.0, 0, 0.0, 0.0
    n_a = actions.shape[0]
    t_prev = 0.0
    impulse = 0.0
    for k in range(n_max):
        if k == kick_step:
            y[kick_index] += kick_delta
        advance_interval(y, aux, flags, s, apex, cfg, actions[min(k, n_a - 1)])
        tau = abs(s[S.TAU])
        if s[S.NAPEX] > 0.0:
            t_apex = s[S.T_APEX]
            total = impulse + tau * max(0.0, t_apex - t_prev)
            return APEX, t_apex, total, k + 1, impulse, t_prev
        before = impulse
        impulse += tau * (s[S.T] - t_prev)
        if s[S.STATUS] >= FAIL_FIRST:
            return int(s[S.STATUS]), s[S.T], impulse, k + 1, before, t_prev
        t_prev = s[S.T]
    return F_NO_APEX, s[S.T], impulse, n_max, impulse, t_prev


@jit
def stride_segments(y, aux, flags, s, apex, cfg, actions, n_max, max_seg):
    """`stride` for planning: every run of equal consecutive interval actions (to
    `SEGMENT_TOL`) is integrated as one segment, and the integration stops at the apex. The
    torque is the same piecewise-constant function of time, but the integrator no longer
    restarts at every interval boundary inside a run, so the result agrees with `stride` to
    the integrator tolerance, not bit for bit (tested). No kicks, smooth ground only.

    Returns what `stride` returns (the apex state in ``apex[0]``)."""
    if s[S.STATUS] >= FAIL_FIRST:  # an impossible start
        return int(s[S.STATUS]), 0.0, 0.0, 0, 0.0, 0.0
    n_a = actions.shape[0]
    dt = cfg[C_DT]
    opts = Options(cfg[C_RTOL], cfg[C_ATOL], True)
    log = event_log(32, apex)
    rec = recorder(0, 0.0)
    y_start = np.empty(8)
    t, h, impulse, t_prev = 0.0, 0.0, 0.0, 0.0
    k = 0
    while k < n_max:
        a = actions[min(k, n_a - 1)]
        m = 1
        if k >= n_a - 1:  # the last action holds to the step limit
            m = n_max - k
        else:
            while k + m < n_a and m < max_seg and abs(actions[k + m] - a) <= SEGMENT_TOL:
                m += 1
            if k + m >= n_a:
                m = n_max - k
        m = min(m, max_seg)
        tau = cfg[C_MAX_TORQUE] * min(max(a, -1.0), 1.0)
        aux[P_TAU] = tau
        y_start[:] = y
        status, t1, h = advance(y, aux, flags, t, (k + m) * dt, h, opts, log, rec)
        finite = True
        for j in range(8):
            if not math.isfinite(y[j]):
                finite = False
        if not finite:
            y[:] = y_start
            if status < FAIL_FIRST:
                status = F_NON_FINITE
        t_prev = max(t, dt * math.floor(t1 / dt - 1e-9))  # start of the interval reached
        before = impulse + abs(tau) * (t_prev - t)
        s[S.T], s[S.TAU], s[S.PHASE] = t1, tau, phase_index(aux)
        if status == APEX:
            apex[0, :] = y
            steps = int(math.ceil(t1 / dt - 1e-9))
            return APEX, t1, impulse + abs(tau) * (t1 - t), steps, before, t_prev
        impulse += abs(tau) * (t1 - t)
        if status == TIME_UP or status == CONTINUE:
            status = F_NO_APEX if t1 >= cfg[C_NO_APEX] else CONTINUE
        if status >= FAIL_FIRST:
            s[S.STATUS] = status
            return status, t1, impulse, int(math.ceil(t1 / dt - 1e-9)), before, t_prev
        t = t1
        k += m
    s[S.STATUS] = F_NO_APEX
    return F_NO_APEX, t, impulse, n_max, impulse, t_prev


@jit
def reset_rows(Y, AUX, FLAGS, SS, OBS, aux0, Z, cfg):
    """`bound_env.sim.task.reset_at_apex` of robot i at Z[i] for every row i (one compiled call)."""
    for i in range(Y.shape[0]):
        reset_at_apex(Y[i], AUX[i], FLAGS[i], SS[i], OBS[i], aux0, Z[i], cfg)


@jit
def open_loop(y, aux, flags, s, apex, obs, cfg, actions, seg, n_max, max_strides):
    """Open loop over whole strides from the apex state in (y, aux, flags, s), as one episode
    of the step env: interval k holds actions[k // seg] (zero after the last), the control
    grid running on across apexes. Stops when ``max_strides`` strides are completed, at a
    failure, or after ``n_max`` intervals.

    Returns (code, strides, t_step, t_apex, t): code 1 when ``max_strides`` were reached, 0
    on a failure (status in ``s``), -1 after ``n_max`` intervals; t_step, t_apex: the end of
    the interval in which the last apex was passed and that apex's time (0 before any)."""
    t_step, t_apex = 0.0, 0.0
    n_a = actions.shape[0]
    for k in range(n_max):
        j = k // seg
        advance_interval(y, aux, flags, s, apex, cfg, actions[j] if j < n_a else 0.0)
        if s[S.NAPEX] > 0.0:
            t_step, t_apex = s[S.T], s[S.T_APEX]
            if s[S.STRIDES] >= max_strides:
                return 1, int(s[S.STRIDES]), t_step, t_apex, s[S.T]
        if s[S.STATUS] >= FAIL_FIRST:
            return 0, int(s[S.STRIDES]), t_step, t_apex, s[S.T]
    return -1, int(s[S.STRIDES]), t_step, t_apex, s[S.T]


@strict_jit
def profile_action(taus, edges, t, t0, snap, dt, max_torque):
    """clip(average of the sub-window torques ``taus`` (on ``edges``, the last one held past
    edges[-1]) over [t, t + dt] / max_torque, -1, 1): a stride controller's action on the
    interval that starts t after its apex (with ``snap``: t snapped to the grid t0 + k dt), as
    `bound_env.sim.stride_task.TorqueBasis.average` computes it (compiled without fast-math, so
    it rounds as NumPy does)."""
    if snap:
        t = t0 + dt * round((t - t0) / dt)
    t1 = t + dt
    n = taus.shape[0]
    acc = 0.0
    for j in range(n):
        lo = min(max(edges[j], t), t1)
        hi = min(max(edges[j + 1] if j < n - 1 else math.inf, t), t1)
        acc += taus[j] * (hi - lo)
    return min(max(acc / (t1 - t) / max_torque, -1.0), 1.0)


@jit
def to_next_apex(
    Y, AUX, FLAGS, SS, APEXES, OBS, cfg, live, taus, t0, snap, edges, dt, i_time, n_max
):
    """Long episodes of a stride controller in the step env (rough terrain, MFPT): every live
    robot i steps its own plan, the profile ``taus[i]`` it chose at its last apex, read at the
    observed (float32) time since that apex (snapped to the grid ``t0[i]`` + k dt with
    ``snap``), until an interval in which it passes an apex or fails (at most ``n_max``
    intervals). The caller re-plans at the apex; robots are independent, so each one's
    intervals are exactly those of stepping the whole batch one interval at a time."""
    max_torque = cfg[C_MAX_TORQUE]
    for i in range(Y.shape[0]):
        if not live[i]:
            continue
        for _ in range(n_max):
            t = np.float64(OBS[i, i_time])
            a = profile_action(taus[i], edges, t, t0[i], snap, dt, max_torque)
            step_env(Y[i], AUX[i], FLAGS[i], SS[i], APEXES[i], OBS[i], cfg, a)
            if SS[i, S.NAPEX] > 0.0 or SS[i, S.STATUS] >= FAIL_FIRST:
                break


@jit
def strides(Y, AUX, FLAGS, SS, APEXES, OBS, cfg, A, kick_step, kick_index, kick_delta, n_max, out):
    """`stride` for every robot i of a batch (row i of each array); ``out[i]`` = its six
    returns."""
    for i in range(Y.shape[0]):
        st, t, imp, k, before, t_prev = stride(
            Y[i],
            AUX[i],
            FLAGS[i],
            SS[i],
            APEXES[i],
            OBS[i],
            cfg,
            A[i],
            kick_step[i],
            kick_index[i],
            kick_delta[i],
            n_max,
        )
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = st, t, imp, k
        out[i, 4], out[i, 5] = before, t_prev


@jit
def strides_segments(Y, AUX, FLAGS, SS, APEXES, cfg, A, n_max, max_seg, out):
    """`stride_segments` for every robot i of a batch; ``out[i]`` = its six returns."""
    for i in range(Y.shape[0]):
        st, t, imp, k, before, t_prev = stride_segments(
            Y[i], AUX[i], FLAGS[i], SS[i], APEXES[i], cfg, A[i], n_max, max_seg
        )
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = st, t, imp, k
        out[i, 4], out[i, 5] = before, t_prev


@dataclass
class Strides:
    """The outcome of n strides (row i: robot i)."""

    z1: np.ndarray  # (n, 6) next apex state (SI); NaN where the stride failed
    status: np.ndarray  # (n,) int: APEX or a failure code (`bound_env.model.events`)
    period: np.ndarray  # (n,) apex time [s] (time of the failure if one)
    effort: np.ndarray  # (n,) mean |tau| over the stride [N m]
    intervals: np.ndarray  # (n,) control intervals stepped
    y_end: np.ndarray  # (n, 8) full state at the end (the apex, or the last state)
    phase: np.ndarray  # (n,) stance condition index at the end (`bound_env.model.events.PHASES`)
    t_step: np.ndarray  # (n,) end of the last interval stepped [s]
    t_prev: np.ndarray  # (n,) its start [s]
    tau_last: np.ndarray  # (n,) |tau| held over it [N m]
    impulse_before: np.ndarray  # (n,) integral of |tau| dt up to t_prev [N m s]

    @property
    def ok(self) -> np.ndarray:
        return self.status == APEX

    def failure(self, i: int) -> str | None:
        """The failure name of robot i's stride, None if it reached its apex."""
        return None if self.status[i] == APEX else FAILURE_NAMES[int(self.status[i])]


class StrideMap:
    """z1 = P(z, a): strides of the step env of one task setting, batched (module docstring).

    ``gait``, ``gait_overrides``, ``dt``, ``max_torque`` and ``rtol`` are PassiveBound-v0's
    settings of the same name (``rtol`` defaults to `EVAL_RTOL`). ``segments``: a planning
    map, each run of equal interval actions integrated as one segment, stopping at the apex
    (`stride_segments`: the same strides to the integrator tolerance, not bit for bit; no
    kicks, no slopes).

    ``task``: a `bound_env.sim.task.PassiveBoundTask` (without slope noise) to run on instead of
    building one from the settings above (which are then ignored): an env's own task, so
    that the env's plant has one holder. The map keeps no copy of the plant: every run reads
    its task's parameters (``task.aux0``), so `PassiveBoundTask.set_params` (model error,
    `bound_env.envs.randomized.RandomizedPlant`) reaches the next stride."""

    def __init__(
        self,
        gait="default",
        gait_overrides: dict | None = None,
        dt: float = DEFAULT_DT,
        max_torque: float = DEFAULT_MAX_TORQUE,
        rtol: float = EVAL_RTOL,
        segments: bool | int = False,
        task: PassiveBoundTask | None = None,
    ):
        if task is None:
            task = PassiveBoundTask(
                gait=gait,
                gait_overrides=gait_overrides,
                dt=dt,
                max_torque=max_torque,
                rtol=rtol,
                reset_noise_scale=0.0,
            )
        elif not isinstance(task, PassiveBoundTask):
            raise ValueError(f"task must be a PassiveBoundTask, got {type(task).__name__}")
        else:
            rtol = float(task.cfg[C_RTOL])
        self.task = task
        # the task's constants as the stride kernels read them: a stride map draws no slopes
        # of its own (rough terrain comes per stride, ``run(slopes=...)``), so a task with
        # slope noise (the stride env's) runs here on smooth ground. Not the plant: that is
        # read from the task at every run.
        self.cfg = task.cfg
        if task.cfg[C_SLOPE_NOISE] != 0.0:
            self.cfg = task.cfg.copy()
            self.cfg[C_SLOPE_NOISE] = 0.0
        self.dt = self.task.dt
        self.max_torque = self.task.max_torque
        self.rtol = float(rtol)
        self.n_max = max_intervals(self.dt)
        # intervals per segment at most (0: off; True: `MAX_SEGMENT`)
        self.segments = MAX_SEGMENT if segments is True else int(segments)
        self._batches: dict = {}

    @property
    def params(self):
        return self.task.params

    @property
    def z_ref(self) -> np.ndarray:
        return self.task.z_ref

    def _batch(self, n: int):
        """The first n robots of one batch kept for every size (grown to the largest n asked;
        the caller resets the robots it runs)."""
        b = self._batches.get("all")
        if b is None or b.n < n:
            self._batches.clear()
            b = self._batches["all"] = self.task.new_batch(max(n, 8))
        if n not in self._batches:
            self._batches[n] = replace(b, **{f.name: getattr(b, f.name)[:n] for f in fields(b)})
        return self._batches[n]

    def run(self, Z, A, *, aux=None, kicks=None, slopes=None) -> Strides:
        """One stride from each apex state Z[i] (SI) with the interval actions A[i] (or one
        row A for all), from the start.

        ``aux``: per-robot parameter vectors (n, N_AUX) in place of the task's (parameter
        overrides); ``kicks``: per robot (interval, state index 4..7, delta) or None, a push
        added to that velocity before that interval; ``slopes``: per robot (alpha_from,
        alpha_to) [rad] or None, rough terrain: Z[i] is an apex state on a ground at
        alpha_from that tilts to alpha_to at that apex (`bound_env.model.terrain.change_slope`)."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        n = Z.shape[0]
        A = np.asarray(A, dtype=float)
        A = np.broadcast_to(A, (n, A.shape[-1])) if A.ndim == 1 else A
        if Z.shape[1] != 6 or A.shape[0] != n:
            raise ValueError(f"Z must be (n, 6) and A (n, K) or (K,), got {Z.shape}, {A.shape}")
        if not (np.isfinite(Z).all() and np.isfinite(A).all()):
            raise ValueError("Z and A must be finite (no NaN or inf)")
        for kick in kicks if kicks is not None else ():
            if kick is not None and not 4 <= int(kick[1]) <= 7:
                raise ValueError(f"a kick changes a velocity (state index 4..7), got {kick[1]}")
        if self.segments and (kicks is not None or slopes is not None):
            raise ValueError("a StrideMap with segments=True (planning) takes no kicks or slopes")
        b = self._batch(n)
        reset_rows(b.y, b.aux, b.flags, b.s, b.obs, self.task.aux0, Z, self.cfg)
        for i in range(n) if aux is not None or slopes is not None else ():
            if aux is not None:
                b.aux[i] = aux[i]
            if slopes is not None and slopes[i] is not None:
                a0, a1 = slopes[i]
                set_slope(b.aux[i], a0)
                change_slope(b.y[i], b.aux[i], a1 - a0)
            if aux is not None or (slopes is not None and slopes[i] is not None):
                self.task.restart_robot(b, i)
        ks = np.full(n, NO_KICK, dtype=np.int64)
        ki = np.zeros(n, dtype=np.int64)
        kd = np.zeros(n)
        for i, kick in enumerate(kicks if kicks is not None else ()):
            if kick is not None:
                ks[i], ki[i], kd[i] = int(kick[0]), int(kick[1]), float(kick[2])
        out = np.zeros((n, 6))
        if self.segments:
            strides_segments(
                b.y, b.aux, b.flags, b.s, b.apex, self.cfg, np.ascontiguousarray(A),
                self.n_max, self.segments, out,
            )  # fmt: skip
        else:
            strides(
                b.y, b.aux, b.flags, b.s, b.apex, b.obs, self.cfg,
                np.ascontiguousarray(A), ks, ki, kd, self.n_max, out,
            )  # fmt: skip
        status = out[:, 0].astype(np.int64)
        ok = status == APEX
        y_end = np.where(ok[:, None], b.apex[:, 0], b.y)
        z1 = np.where(ok[:, None], y_end[:, _Z_IDX], np.nan)
        t = out[:, 1]
        effort = np.divide(out[:, 2], t, out=np.zeros(n), where=t > 0.0)
        return Strides(
            z1=z1,
            status=status,
            period=t,
            effort=effort,
            intervals=out[:, 3].astype(np.int64),
            y_end=y_end,
            phase=b.s[:, S.PHASE].astype(np.int64),
            t_step=b.s[:, S.T].copy(),
            t_prev=out[:, 5].copy(),
            tau_last=np.abs(b.s[:, S.TAU]),
            impulse_before=out[:, 4].copy(),
        )

    def apexes(self, Z, A) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lean core of `run` for a planner's inner loop (no kicks, slopes or parameter
        overrides, no checks: Z (n, 6) and A (n, K) finite float arrays): (status, apex time
        or time of the failure, next apex state z1 (NaN where it failed)) per robot, the
        same strides as `run`'s."""
        n = Z.shape[0]
        b = self._batch(n)
        reset_rows(b.y, b.aux, b.flags, b.s, b.obs, self.task.aux0, Z, self.cfg)
        out = np.zeros((n, 6))
        A = np.ascontiguousarray(A)
        if self.segments:
            strides_segments(
                b.y, b.aux, b.flags, b.s, b.apex, self.cfg, A, self.n_max, self.segments,
                out,
            )  # fmt: skip
        else:
            ks, zero = np.full(n, NO_KICK, dtype=np.int64), np.zeros(n, dtype=np.int64)
            strides(
                b.y, b.aux, b.flags, b.s, b.apex, b.obs, self.cfg, A, ks, zero,
                np.zeros(n), self.n_max, out,
            )  # fmt: skip
        status = out[:, 0].astype(np.int64)
        z1 = b.apex[:, 0][:, _Z_IDX]
        z1[status != APEX] = np.nan
        return status, out[:, 1], z1

    def open_loop(self, z, actions, seg: int, max_strides: int) -> tuple:
        """`open_loop` from the apex state z: (code, strides, t_step, t_apex, t, status,
        phase index); code -2 for a start that is already impossible."""
        b = self._batch(1)
        self.task.reset_robot(b, 0, np.asarray(z, dtype=float))
        s = b.s[0]
        if s[S.STATUS] >= FAIL_FIRST:
            return -2, 0, 0.0, 0.0, 0.0, int(s[S.STATUS]), 0
        code, n, t_step, t_apex, t = open_loop(
            b.y[0], b.aux[0], b.flags[0], s, b.apex[0], b.obs[0], self.cfg,
            np.asarray(actions, dtype=float), int(seg), self.n_max * max_strides, max_strides,
        )  # fmt: skip
        return code, n, t_step, t_apex, t, int(s[S.STATUS]), int(s[S.PHASE])

    def map(self, z, a) -> np.ndarray | None:
        """z1 of one stride from z with the interval actions a, None on a failure."""
        r = self.run(np.asarray(z, dtype=float)[None], np.asarray(a, dtype=float)[None])
        return r.z1[0] if r.ok[0] else None
