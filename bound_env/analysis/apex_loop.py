"""The one batched closed loop: many robots under one controller, each restarted at its apex,
all advanced together (`apex_loop`). `bound_env.analysis.margins` (its closed loop's
``run_many``) and the basin atlas (`bound_env.analysis.basin`) both run their batches here.

Every robot starts at its apex state z (x_g = 0, both legs in flight, t = 0) and iterates the
closed-loop apex map: at each apex it reached it is started again there, as a single
PassiveBound-v0 env is reset at the apex (``reset(options={"apex_state": z})``), until

- it returns: the max-abs apex error to ``z_target`` falls below ``tol`` (SI);
- it falls: a stride fails (or reaches no apex within the step limit, `max_intervals`);
- ``max_strides`` strides pass (undecided).

Two ways to advance a batch, one per kind of controller:

- **a stride controller** (``interval_actions``): one batch of whole strides per stride count
  through the one stride map (``strides(Z, kicks)``, `bound_env.stride_map.StrideMap.run`);
- **a step-level controller**: the task's batch kernel (`bound_env.task.PassiveBoundTask.step`),
  one controller call per control interval for the whole batch: ``batch(obs)`` if it has one
  (and no ``on_apex``), else one copy per robot, called row by row, with ``on_apex(z, 0.0)``
  at each stride's start apex (a step-level residual over a stride controller). Each robot's
  intervals are its own, so its outcome is that of the single env's loop.

`CLOCK` records the wall time of every apex decision while it is on (margins' tasks turn it
on: the real-time yardstick, `bound_env.analysis.margins.decision_times`).
"""

from __future__ import annotations

import copy
import time

import numpy as np

from ..events import F_NO_APEX, FAIL_FIRST, FAILURES
from ..params import Z_IN_Y
from ..stride_map import RETURN_TOL, max_intervals
from ..task import S_NAPEX, S_PHASE, S_STATUS

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
    (0 or 1 + failure index in `bound_env.events.FAILURES`), ``strides`` (strides to the
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


class _Actions:
    """One call per control interval for the whole batch: ``controller.batch(obs)`` if it has
    one (and no ``on_apex``); else one copy of the controller per robot, called row by row,
    with ``on_apex(z, 0.0)`` at each stride's start apex when it has that hook."""

    def __init__(self, controller, Z):
        self.controller = controller
        self.batched = callable(getattr(controller, "batch", None)) and not callable(
            getattr(controller, "on_apex", None)
        )
        if not self.batched:
            self.kinds = getattr(controller, "decision_kinds", None)
            self.n0 = len(self.kinds) if self.kinds is not None else 0
            self.copies = [copy.deepcopy(controller) for _ in range(len(Z))]
            for i, z in enumerate(Z):
                self.restart(i, z)

    def restart(self, i: int, z) -> None:
        if not self.batched and hasattr(self.copies[i], "on_apex"):
            timed_on_apex(self.copies[i].on_apex, np.asarray(z, dtype=float), 0.0)

    def __call__(self, obs, live) -> np.ndarray:
        if self.batched:
            return self.controller.batch(obs)
        a = np.zeros(len(obs))
        for i in np.flatnonzero(live):
            a[i] = self.copies[i](obs[i])
        return a

    def close(self) -> None:
        """The copies' decisions, robot by robot, into the controller's own record."""
        if not self.batched and self.kinds is not None:
            for c in self.copies:
                self.kinds.extend(c.decision_kinds[self.n0 :])


def _through_task(out, Z, z_target, max_strides, tol, task, controller, kicks) -> None:
    n = len(Z)
    b = task.new_batch(n)
    for i in range(n):
        task.reset_robot(b, i, Z[i])
    live = np.ones(n, dtype=np.bool_)
    for i in np.flatnonzero(b.s[:, S_STATUS] >= FAIL_FIRST):  # impossible starts
        fell(out, i, int(b.s[i, S_STATUS]), 1, 0)
        live[i] = False
    act = _Actions(controller, Z)
    stride = np.zeros(n, dtype=np.int64)  # strides completed
    steps = np.zeros(n, dtype=np.int64)  # control intervals in the current stride
    max_steps = max_intervals(task.dt)
    kick_at = np.array([-1 if k is None else int(k[0]) for k in kicks], dtype=np.int64)
    while live.any():
        for i in np.flatnonzero(live & (stride == 0) & (steps == kick_at)):
            b.y[i, int(kicks[i][1])] += float(kicks[i][2])
        b.actions[:] = act(b.obs, live)
        b.active[:] = live
        task.step(b)
        steps[live] += 1
        s = b.s
        napex = s[:, S_NAPEX].astype(np.int64)
        done = live & (napex > 0)
        failed = live & ~done & ((s[:, S_STATUS] >= FAIL_FIRST) | (steps >= max_steps))
        for i in np.flatnonzero(failed):
            code = int(s[i, S_STATUS]) if s[i, S_STATUS] >= FAIL_FIRST else F_NO_APEX
            fell(out, i, code, int(stride[i]) + 1, int(s[i, S_PHASE]))
        live &= ~failed
        for i in np.flatnonzero(done):
            z1 = np.array(b.apex[i, min(napex[i], b.apex.shape[1]) - 1][_Z_IDX], dtype=float)
            stride[i] += 1
            if not _apex_reached(out, i, z1, int(stride[i]), z_target, tol):
                live[i] = False
            elif stride[i] >= max_strides:
                live[i] = False
            else:
                task.reset_robot(b, i, z1)
                act.restart(i, z1)
                steps[i] = 0
    act.close()
