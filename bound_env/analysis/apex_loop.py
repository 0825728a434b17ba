"""The one batched closed loop: many robots under one controller, all advanced together.

`interval_loop` is the one per-interval batched closed loop of `bound_env`: the margins'
step-level runs (`bound_env.analysis.margins.ClosedLoop.run_many`), the rough-terrain
episodes (`margins.closed_loop.rough_episodes`), the runs under model error
(`margins.mismatch_tasks.plant_runs`) and the basin atlas (`bound_env.analysis.basin`) all
step their robots here, through the task's batch kernel
(`bound_env.sim.task.PassiveBoundTask.step`), with one reset rule: **every robot starts with a
fresh controller state** (a stateful controller, e.g. `bound_env.control.offset_free.OffsetFree`,
runs as one reset copy per robot, so nothing it learned before, in this worker or in another
task, reaches a robot). A caller chooses what differs: restart at every apex (the apex map) or
one long episode (rough terrain, with its slope draws), per-robot plants, sensor noise,
actuation delay, kicks, a return test, effort bookkeeping (`interval_loop`'s docstring).

`apex_loop` iterates the closed-loop apex map from every start: every robot starts at its apex
state z (x_g = 0, both legs in flight, t = 0) and, at each apex it reached, is started again
there, as a single PassiveBound-v0 env is reset at the apex (``reset(options={"apex_state":
z})``), until

- it returns: the max-abs apex error to ``z_target`` falls below ``tol`` (SI);
- it falls: a stride fails (or reaches no apex within the step limit, `max_intervals`);
- ``max_strides`` strides pass (undecided).

Two ways to advance the batch, one per kind of controller:

- **a stride controller** (``interval_actions``): one batch of whole strides per stride count
  through the one stride map (``strides(Z, kicks)``, `bound_env.sim.stride_map.StrideMap.run`);
- **a step-level controller**: `interval_loop`, one controller call per control interval for
  the whole batch (``batch(obs)``) or one fresh copy per robot (with ``on_apex(z, 0.0)`` at
  each stride's start apex: a step-level residual over a stride controller, an offset-free
  controller). Each robot's intervals are its own, so its outcome is that of the single
  env's loop.

`CLOCK` records the wall time of every apex decision while it is on (margins' tasks turn it
on: the real-time yardstick, `bound_env.analysis.margins.decision_times`).
"""

from __future__ import annotations

import copy
import time

import numpy as np

from ..model.events import F_NO_APEX, FAIL_FIRST, FAILURES
from ..model.params import Z_IN_Y
from ..sim.stride_map import RETURN_TOL, max_intervals, to_next_apex
from ..sim.stride_protocol import StridePlans, reset_controller
from ..sim.task import S_NAPEX, S_PHASE, S_STATUS, S_STRIDES, S_T, S_T_APEX, S_TAU

RETURNED, FELL, UNDECIDED = 0, 1, 2  # a robot's outcome
NON_FINITE = FAILURES.index("non_finite") + FAIL_FIRST
_Z_IDX = np.array(Z_IN_Y)


class DecisionClock:
    """Wall times [s] of apex decisions, kept while ``on`` (per process)."""

    def __init__(self):
        self.on = False
        self.seconds: list = []

    def add(self, seconds) -> None:
        if self.on:
            self.seconds.extend(seconds)


CLOCK = DecisionClock()


def timed_interval_actions(controller, Z) -> np.ndarray:
    """``controller.interval_actions(Z)``, its apex decisions timed into `CLOCK`: the
    controller's own ``decision_seconds`` where it times each one, else the call's time
    shared equally by the robots; none for a controller with ``decides_at_apex`` false (the
    passive gait's zero torque)."""
    if not getattr(controller, "decides_at_apex", True):
        return controller.interval_actions(Z)
    own = getattr(controller, "decision_seconds", None)
    n0 = len(own) if own is not None else 0
    t0 = time.perf_counter()
    A = controller.interval_actions(Z)
    seconds = time.perf_counter() - t0
    if CLOCK.on:
        if own is not None and len(own) - n0 == len(Z):
            CLOCK.add(own[n0:])
        else:
            CLOCK.add([seconds / max(len(Z), 1)] * len(Z))
    return A


def timed_on_apex(on_apex, z, time_since_apex: float = 0.0) -> None:
    """``on_apex(z, time_since_apex)``, timed into `CLOCK`."""
    t0 = time.perf_counter()
    on_apex(z, time_since_apex)
    if CLOCK.on:
        CLOCK.add([time.perf_counter() - t0])


def empty_outputs(n: int, max_strides: int) -> dict:
    """The outputs of `apex_loop` before any stride: every robot undecided."""
    return {
        "outcome": np.full(n, UNDECIDED, dtype=np.int8),
        "reason": np.zeros(n, np.int8),  # 0, or 1 + the failure's index in FAILURES
        "strides": np.full(n, max_strides, dtype=np.int32),
        "phase": np.full(n, -1, dtype=np.int8),
        "error": np.full(n, np.inf),
        "z_last": np.zeros((n, 6)),
        "apexes": 0,  # strides completed by all robots together
    }


def fell(out: dict, i: int, code: int, stride: int, phase: int) -> None:
    """Robot i fell with status ``code`` in its stride ``stride`` (stance condition ``phase``)."""
    out["outcome"][i], out["reason"][i] = FELL, code - FAIL_FIRST + 1
    out["strides"][i], out["phase"][i] = stride, phase


def apex_loop(
    Z,
    z_target,
    max_strides: int,
    *,
    tol: float = RETURN_TOL,
    strides=None,
    task=None,
    controller=None,
    kicks=None,
) -> dict:
    """Iterate the closed-loop apex map from every row of ``Z`` (SI), all robots together
    (module docstring): ``strides(Z, kicks) -> Strides`` for a stride controller, else the
    ``task``'s batch kernel stepping ``controller``. ``kicks[i]``: robot i's first-stride
    push (interval, state index 4..7, delta) or None.

    Returns a dict of arrays per robot: ``outcome`` (RETURNED, FELL, UNDECIDED), ``reason``
    (0 or 1 + failure index in `bound_env.model.events.FAILURES`), ``strides`` (strides to the
    return, the stride that failed, or ``max_strides``), ``phase`` (stance condition index at
    the failure, -1 if none), ``error`` (last max-abs apex error to ``z_target``), ``z_last``
    (the last apex reached); and ``apexes``, the strides completed in all."""
    Z = np.array(np.atleast_2d(Z), dtype=float)
    n = len(Z)
    kicks = list(kicks) if kicks is not None else [None] * n
    if len(kicks) != n:
        raise ValueError(f"kicks must have one entry per start ({n}), got {len(kicks)}")
    for k in kicks:
        if k is not None and not 4 <= int(k[1]) <= 7:
            raise ValueError(f"a kick changes a velocity (state index 4..7), got {k[1]}")
    out = empty_outputs(n, max_strides)
    out["z_last"][:] = Z
    if strides is not None:
        _through_map(out, Z, np.asarray(z_target, float), max_strides, tol, strides, kicks)
    else:
        _through_task(
            out, Z, np.asarray(z_target, float), max_strides, tol, task, controller, kicks
        )
    return out


def _apex_reached(out: dict, i: int, z1, stride: int, z_target, tol: float) -> bool:
    """Book robot i's apex z1 after ``stride`` strides; True if it goes on."""
    out["apexes"] += 1
    if not np.all(np.isfinite(z1)):
        fell(out, i, NON_FINITE, stride, -1)
        return False
    err = float(np.max(np.abs(z1 - z_target)))
    out["error"][i] = err
    out["z_last"][i] = z1
    if err < tol:
        out["outcome"][i], out["strides"][i] = RETURNED, stride
        return False
    return True


def _through_map(out, Z, z_target, max_strides, tol, strides, kicks) -> None:
    live = np.arange(len(Z))
    for stride in range(1, max_strides + 1):
        r = strides(Z[live], [kicks[i] for i in live] if stride == 1 else None)
        keep = []
        for j, i in enumerate(live):
            if not r.ok[j]:
                fell(out, i, int(r.status[j]), stride, int(r.phase[j]))
            elif _apex_reached(out, i, r.z1[j], stride, z_target, tol):
                Z[i] = r.z1[j]
                keep.append(i)
        live = np.array(keep, dtype=np.int64)
        if not len(live):
            break


def _through_task(out, Z, z_target, max_strides, tol, task, controller, kicks) -> None:
    r = interval_loop(task, controller, Z, max_strides, kicks=kicks, z_target=z_target, tol=tol)
    for i in range(len(Z)):
        if r["returned"][i]:
            out["outcome"][i], out["strides"][i] = RETURNED, r["strides"][i]
        elif r["status"][i]:  # the stride that failed: one past the completed ones
            fell(out, i, int(r["status"][i]), int(r["strides"][i]) + 1, int(r["phase"][i]))
    out["error"][:], out["z_last"][:] = r["error"], r["z_last"]
    out["apexes"] += r["apexes"]


# --------------------------------------------------------------------------------------------
# The one per-interval batched closed loop
# --------------------------------------------------------------------------------------------


class SensorNoise:
    """What the controller sees under sensor noise: its observation plus sigma_obs N(0, 1)
    (clipped to the observation's bounds), and the apex state handed to ``on_apex`` plus
    sigma_z N(0, 1), robot i's draws from its own generator ``rngs[i]``."""

    def __init__(self, obs_sigma, z_sigma, rngs, low, high):
        self.obs_sigma = np.asarray(obs_sigma, dtype=np.float32)
        self.z_sigma = np.asarray(z_sigma, dtype=float)
        self.rngs, self.low, self.high = rngs, low, high

    def obs(self, obs, rows) -> np.ndarray:
        seen = obs.copy()
        for i in rows:
            draw = self.rngs[i].standard_normal(len(self.obs_sigma))
            seen[i] = np.clip(obs[i] + self.obs_sigma * draw, self.low, self.high)
        return seen

    def z(self, i: int, z) -> np.ndarray:
        return z + self.z_sigma * self.rngs[i].standard_normal(6)


class _Controllers:
    """The controller side of `interval_loop`, one rule for every caller: every robot starts
    with a fresh controller state.

    - a memoryless controller with ``batch(obs)`` (no ``on_apex``, not ``stateful``): one call
      for the whole batch per control interval;
    - a memoryless stride controller with ``apex_torques`` on the nominal plant with nothing
      between its plan and the torque (no per-robot plant, sensor noise, delay, kick or
      effort bookkeeping): every robot's plan in one array (`StridePlans`), stepped from
      apex to apex by a compiled loop (`bound_env.sim.stride_map.to_next_apex`: the copies'
      intervals and actions, to rounding);
    - any other controller: one copy per robot, reset (`reset_controller`: a stateful one,
      e.g. `OffsetFree`, forgets whatever it learned before), called row by row, with
      ``on_apex`` at the start and at every apex, as a single env calls it; a controller
      with ``act_rows(copies, obs)`` acts for all its live copies in one call (a step-level
      residual policy: one forward pass of its network for every robot).

    Every ``on_apex`` is timed into `CLOCK`; the copies' ``decision_kinds`` go, robot by
    robot, into the controller's own record at the end (`close`)."""

    def __init__(self, controller, n: int, compiled: bool, plants=None):
        self.controller = controller
        hook = callable(getattr(controller, "on_apex", None))
        # a privileged controller (`bound_env.control.privileged`) is handed its robot's true
        # plant, so it runs as one copy per robot
        privileged = plants is not None and getattr(controller, "privileged", False) is True
        memoryless = not getattr(controller, "stateful", False) and not privileged
        self.batched = callable(getattr(controller, "batch", None)) and not hook and memoryless
        self.plans = None
        if not self.batched and compiled and memoryless:
            if callable(getattr(controller, "apex_torques", None)):
                self.plans = StridePlans(controller, n)
        self.copies = None
        self.kinds = getattr(controller, "decision_kinds", None)
        self.rows = None
        if not self.batched and self.plans is None:
            self.copies = [copy.deepcopy(controller) for _ in range(n)]
            for i, c in enumerate(self.copies):
                reset_controller(c)
                if privileged:
                    c.set_plant(plants[i])
            # where each copy's own record starts: a copy may start with the controller's whole
            # record or (a controller that pickles without it, `MPCController.__getstate__`) none
            self.k0 = [len(getattr(c, "decision_kinds", None) or ()) for c in self.copies]
            # the copies' actions in one call (``act_rows(copies, obs)``: as each copy's
            # ``__call__`` on its row, to rounding), where the controller offers it
            rows = getattr(controller, "act_rows", None)
            self.rows = rows if callable(rows) else None
        self.hook = self.plans is not None or (self.copies is not None and hook)

    def apex(self, i: int, z, time_since_apex: float, noise) -> None:
        """Robot i is at the apex z (its stride's start): the controller's ``on_apex``, with
        the apex state it sees."""
        if not self.hook:
            return
        z = np.asarray(z, dtype=float)
        seen = noise.z(i, z) if noise is not None else z
        if self.plans is not None:
            timed_on_apex(lambda z, t: self.plans.apex(i, z, t), seen, time_since_apex)
        else:
            timed_on_apex(self.copies[i].on_apex, seen, time_since_apex)

    def __call__(self, obs, live) -> np.ndarray:
        if self.batched:
            return self.controller.batch(obs)
        a = np.zeros(len(obs))
        idx = np.flatnonzero(live)
        if self.rows is not None:
            if idx.size:
                a[idx] = self.rows([self.copies[i] for i in idx], obs[idx])
            return a
        for i in idx:
            a[i] = self.copies[i](obs[i])
        return a

    def close(self) -> None:
        if self.copies is not None and self.kinds is not None:
            for c, k0 in zip(self.copies, self.k0, strict=True):
                self.kinds.extend(c.decision_kinds[k0:])


def interval_loop(
    task,
    controller,
    Z0,
    max_strides: int,
    *,
    restart: bool = True,
    aux=None,
    terrain=None,
    noise: SensorNoise | None = None,
    delay: int = 0,
    kicks=None,
    z_target=None,
    tol: float = RETURN_TOL,
    effort_strides: int | None = None,
    plants=None,
) -> dict:
    """The one per-interval batched closed loop: robot i starts at the apex state Z0[i] and
    is stepped with ``controller`` through the ``task``'s batch kernel
    (`bound_env.sim.task.PassiveBoundTask.step`), all robots together, one control interval at
    a time, each robot's intervals its own (so its outcome is that of a single env), until
    it falls, returns (``z_target``) or completes ``max_strides`` strides. The controller
    side (batch, compiled plans or one fresh copy per robot) is `_Controllers`: every robot
    starts with a fresh controller state.

    - ``restart``: the closed-loop apex map: at every apex the robot starts again there
      (t = 0, the observation's time since the apex 0), as the stride map and
      ``reset(options={"apex_state": z})`` do; an interval that reaches an apex ends the
      stride there. False: one long episode per robot (the env's loop: a failure in the
      interval of an apex ends it; the stride count is the env's, ``info["stride"]``).
    - ``aux``: per-robot parameters (n, N_AUX) (model error), else the task's; ``plants``:
      the same robots' `bound_env.model.params.Params`, handed (``set_plant``) only to a
      controller that declares itself ``privileged`` (the privileged reference).
    - ``terrain``: per-robot generators of the slope draws (rough terrain: the task's
      ``slope_noise_deg``; long episodes only), drawn at the start and after each apex as
      the env draws them.
    - ``noise`` (`SensorNoise`): what the controller sees; ``delay``: the action decided on
      interval k acts on interval k + delay (zero torque before; in flight across apexes).
    - ``kicks[i]``: (interval, state index 4..7, delta) added to robot i's state before that
      interval of its first stride (sensed one interval later), or None.
    - ``z_target``, ``tol``: a robot *returns* (and stops) at the first apex with max-abs
      error to ``z_target`` below ``tol``.
    - ``effort_strides``: record each robot's mean |tau| [N m] over its last this many
      strides when it completes ``max_strides``.

    A robot also falls when a stride reaches no apex within `max_intervals` (``no_apex``)
    or reaches a non-finite apex (``non_finite``, stance condition -1). Returns per robot
    (arrays, lists): ``strides`` (completed), ``status`` (0, or the failure code),
    ``phase`` (stance condition index at the failure; 0 for an impossible start),
    ``returned``, ``error`` (the last apex's max-abs error to ``z_target``), ``z_last``
    (the last apex reached, Z0 before any), ``settle`` (per component |z(N) - z(N - 1)| of
    the last two apexes, None before two), ``effort`` (None unless recorded); and
    ``apexes``, the apexes reached in all."""
    if restart and terrain is not None:
        raise ValueError("rough terrain runs long episodes (restart=False)")
    Z0 = np.array(np.atleast_2d(Z0), dtype=float)
    n = len(Z0)
    b = task.new_batch(n)

    def start(i, z):
        task.reset_robot(b, i, z)
        if aux is not None:
            b.aux[i] = aux[i]
            task.restart_robot(b, i)

    for i in range(n):
        start(i, Z0[i])
        if terrain is not None:
            task.draw_slope_noise(b, i, terrain[i])
    out = {
        "strides": np.zeros(n, dtype=np.int64),
        "status": np.zeros(n, dtype=np.int64),
        "phase": np.full(n, -1, dtype=np.int64),
        "returned": np.zeros(n, dtype=np.bool_),
        "error": np.full(n, np.inf),
        "z_last": Z0.copy(),
        "settle": [None] * n,
        "effort": [None] * n,
        "apexes": 0,
    }
    live = b.s[:, S_STATUS] < FAIL_FIRST
    for i in np.flatnonzero(~live):  # impossible starts
        out["status"][i], out["phase"][i] = int(b.s[i, S_STATUS]), 0
    nominal = aux is None and noise is None and delay == 0 and kicks is None
    ctl = _Controllers(controller, n, compiled=nominal and effort_strides is None, plants=plants)
    for i in range(n):
        ctl.apex(i, Z0[i].copy(), 0.0, noise)
    kick_at = np.full(n, -1, dtype=np.int64)
    if kicks is not None:
        kick_at[:] = [-1 if k is None else int(k[0]) for k in kicks]
    queue = [np.zeros(n) for _ in range(delay)]
    dt, n_max = task.dt, max_intervals(task.dt)
    i_time = list(task.obs_names).index("time_since_apex")
    steps = np.zeros(n, dtype=np.int64)  # control intervals since the stride's start
    done = out["strides"]
    seen_apex = np.zeros(n, dtype=np.bool_)
    if effort_strides is not None:
        imp = np.zeros(n)  # integral of |tau| dt since the last apex [N m s]
        t_start = np.zeros(n)  # time of the last apex [s]
        per_stride = [[] for _ in range(n)]  # (impulse, duration) of each stride
    while live.any():
        if ctl.plans is not None:  # every live robot to its next apex (or fall), compiled
            c = ctl.controller
            to_next_apex(
                b.y, b.aux, b.flags, b.s, b.apex, b.obs, task.cfg, live, ctl.plans.taus,
                ctl.plans.t0, bool(c.snaps_time), c.basis.edges, c.dt, i_time, n_max,
            )  # fmt: skip
        else:
            for i in np.flatnonzero(live & (done == 0) & (steps == kick_at)):
                b.y[i, int(kicks[i][1])] += float(kicks[i][2])
            obs = b.obs if noise is None else noise.obs(b.obs, np.flatnonzero(live))
            decided = ctl(obs, live)
            if queue:
                queue.append(decided)
                decided = queue.pop(0)
            b.actions[:] = decided
            b.active[:] = live
            task.step(b)
            steps[live] += 1
        s = b.s
        napex = s[:, S_NAPEX].astype(np.int64)
        reached = live & (napex > 0)
        failed = live & (s[:, S_STATUS] >= FAIL_FIRST)
        if restart:  # the stride ended at its apex: what follows in the interval is not run
            failed &= ~reached
        apex = reached & ~failed
        timeout = live & ~apex & ~failed & (steps >= n_max)
        if effort_strides is not None:
            tau = np.abs(s[:, S_TAU])
            imp[live & ~reached] += tau[live & ~reached] * dt
        if terrain is not None:
            for i in np.flatnonzero(reached):
                task.draw_slope_noise(b, i, terrain[i])
        for i in np.flatnonzero(failed | timeout):
            out["status"][i] = int(s[i, S_STATUS]) if failed[i] else F_NO_APEX
            out["phase"][i] = int(s[i, S_PHASE])
            if not restart:
                done[i] = int(s[i, S_STRIDES])
        live &= ~(failed | timeout)
        for i in np.flatnonzero(apex):
            out["apexes"] += 1
            z1 = np.array(b.apex[i, min(napex[i], b.apex.shape[1]) - 1][_Z_IDX], dtype=float)
            if not np.all(np.isfinite(z1)):
                out["status"][i] = NON_FINITE
                live[i] = False
                continue
            done[i] = done[i] + 1 if restart else int(s[i, S_STRIDES])
            steps[i] = 0
            if effort_strides is not None:
                t_apex, t_end = float(s[i, S_T_APEX]), float(s[i, S_T])
                last = imp[i] + tau[i] * (t_apex - (t_end - dt))
                per_stride[i].append((last, t_apex - t_start[i]))
            if seen_apex[i]:
                out["settle"][i] = np.abs(z1 - out["z_last"][i]).tolist()
            seen_apex[i] = True
            out["z_last"][i] = z1
            if z_target is not None:
                out["error"][i] = float(np.max(np.abs(z1 - z_target)))
                if out["error"][i] < tol:
                    out["returned"][i], live[i] = True, False
                    continue
            if done[i] >= max_strides:
                live[i] = False
                if effort_strides is not None:
                    tail = per_stride[i][-effort_strides:]
                    dur = sum(d for _, d in tail)
                    if len(tail) == effort_strides and dur > 0:
                        out["effort"][i] = sum(m for m, _ in tail) / dur
                continue
            if restart:  # the apex map: the next stride from z1 at t = 0
                start(i, z1)
                t_seen = 0.0
                if effort_strides is not None:
                    imp[i], t_start[i] = 0.0, 0.0
            else:
                t_seen = float(b.obs[i, i_time])
                if effort_strides is not None:
                    imp[i], t_start[i] = tau[i] * (t_end - t_apex), t_apex
            ctl.apex(i, z1, t_seen, noise)
    ctl.close()
    return out
