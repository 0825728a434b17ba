"""The stride protocol: what a stride controller and a loop over PassiveBound-v0 share.

Beside `bound_env.sim.stride_map` (the one stride map) and below both `bound_env.control` (the
controllers) and `bound_env.analysis` (the loops that measure them), so that analysis never
imports control:

- where a stride controller reads the apex state and the time since the apex in the
  observation (`OBS_Z`, `OBS_TIME`, `OBS_TH2DOT`), and the times it reads on each control
  interval (`observed_times`, `grid_times`);
- a profile's interval actions (`interval_averages`, `interval_actions_of`: bit for bit what a
  stride controller's ``__call__`` outputs; `ProfileActions`: the stride map's a = W u), the
  plans of n robots under one controller (`StridePlans`) and the loop side of ``on_apex``
  (`notify_apex`);
- the interval actions of n copies of one stride controller at once, each told its own
  apexes (`profile_rows`: bit for bit each copy's ``__call__``);
- who made an apex decision (`DECISION_KINDS`; a gated planner's ``decision_kinds``).

The controller side of the protocol is described in `bound_env.control.controllers`.
"""

from __future__ import annotations

import numpy as np

from .stride_map import interval_weights, max_intervals
from .stride_task import TorqueBasis
from .task import OBS_NAMES

# Who made a decision (``decision_kinds``): "gate" (within ``safe``: the LQR alone), "lqr"
# (past it, the LQR's own plan kept: it returns on the planning model, or a learned chooser
# picked it) and "override" (a searched or chosen profile instead of the LQR's plan).
DECISION_KINDS = ("gate", "lqr", "override")

# indices in the default (x_g excluded) PassiveBound-v0 observation
OBS_TIME = OBS_NAMES[1:].index("time_since_apex")
OBS_TH2DOT = OBS_NAMES[1:].index("theta2dot")
OBS_Z = tuple(
    OBS_NAMES[1:].index(n) for n in ("y_g", "theta1", "theta2", "xdot_g", "theta1dot", "theta2dot")
)


def observed_times(dt: float) -> np.ndarray:
    """The time since the apex a stride controller reads on control interval k of a stride
    (the observation's, rounded to float32), k < `max_intervals` (dt)."""
    return np.float32(dt * np.arange(max_intervals(dt))).astype(float)


def grid_times(dt: float) -> np.ndarray:
    """The start k dt of control interval k of a stride (the MPC snaps the observed time
    to it), k < `max_intervals` (dt)."""
    return dt * np.arange(max_intervals(dt))


def interval_averages(basis: TorqueBasis, taus, t0, dt: float) -> np.ndarray:
    """basis.average(taus[i], t0[i, j], t0[i, j] + dt) for each row of ``taus`` (n, n_sub)
    and each time of row i of ``t0`` (broadcast to (n, m)), bit for bit as the scalar path
    (elementwise products, and at most two non-zero terms per interval for sub-windows wider
    than dt, so the order of the sums cannot matter)."""
    taus = np.atleast_2d(np.asarray(taus, dtype=float))
    t0 = np.atleast_2d(np.asarray(t0, dtype=float))
    t1 = t0 + dt
    lo = np.clip(basis.edges[:-1], t0[..., None], t1[..., None])
    hi = np.clip(np.append(basis.edges[1:-1], np.inf), t0[..., None], t1[..., None])
    return (taus[:, None, :] * (hi - lo)).sum(axis=-1) / (t1 - t0)


def interval_actions_of(basis: TorqueBasis, max_torque: float, U, times, dt: float) -> np.ndarray:
    """(n, len(times)): clip(basis.average(tau_i, t, t + dt) / max_torque, -1, 1) for the
    profile tau_i = basis.torques(U[i], max_torque) of each row of U and each t of ``times``,
    bit for bit as a stride controller's ``__call__`` computes it (`interval_averages`)."""
    taus = np.array([basis.torques(u, max_torque) for u in np.atleast_2d(U)])
    avg = interval_averages(basis, taus, np.asarray(times, dtype=float)[None, :], dt)
    return np.clip(avg / max_torque, -1.0, 1.0)


class ProfileActions:
    """A profile's coefficients -> its interval actions a = W u on the step env's control grid
    from the apex (`bound_env.sim.stride_map.interval_weights` of the ``basis`` at ``dt``): the
    stride map's input for a planned profile (the MPC's planning model, the rescue env's
    plant). Rows of U in, rows of actions out."""

    def __init__(self, basis: TorqueBasis, dt: float):
        self.W = interval_weights(basis.edges, basis.phi, dt)

    def __call__(self, U) -> np.ndarray:
        return np.atleast_2d(U) @ self.W.T


class StridePlans:
    """The stride plans of n robots under one stride controller, for loops that step many
    robots through the step env at once (long episodes, `bound_env.sim.stride_map.to_next_apex`):
    each robot's profile, chosen at its last apex (``apex``), and the time since that apex it
    was announced at. The controller provides ``apex_torques(z)`` (the profile it plans at z,
    as ``on_apex`` stores it), ``snaps_time`` (whether it reads its profile at the observed
    time or snaps it to the apex's interval grid), ``basis``, ``max_torque`` and ``dt``."""

    def __init__(self, controller, n: int):
        self.ctrl = controller
        self.taus = np.zeros((n, controller.basis.phi.shape[0]))
        self.t0 = np.zeros(n)

    def apex(self, i: int, z, time_since_apex: float = 0.0) -> None:
        self.taus[i] = self.ctrl.apex_torques(np.asarray(z, dtype=float))
        self.t0[i] = time_since_apex


def _owner(cls, name: str):
    """The class in ``cls``'s MRO that defines ``name`` (None: none does)."""
    return next((k for k in cls.__mro__ if name in vars(k)), None)


def profile_rows(copies, obs) -> np.ndarray | None:
    """Each copy's ``__call__(obs[k])`` (copies of one stride controller, one per robot, each
    told its own apexes) in one array, bit for bit, or None where they do not offer it (the
    caller then calls them row by row).

    A stride controller offers it with ``planned_profile()``: (taus [N m], t0), the profile it
    planned at its last apex and the time since the apex it was announced at (None before
    the first apex), defined by the same class as the ``__call__`` it stands for (a subclass
    that overrides ``__call__`` alone is called row by row). Its interval action is then
    clip(basis.average(taus, t, t + dt) / max_torque, -1, 1) at the observed time t, snapped
    to the grid t0 + k dt where ``snaps_time`` (as its ``__call__``: the windows' weights
    in one array, each row's dot product as the scalar path's, bit for bit)."""
    if not len(copies):
        return np.zeros(0)
    c0 = copies[0]
    cls = type(c0)
    if _owner(cls, "planned_profile") is None or _owner(cls, "planned_profile") is not _owner(
        cls, "__call__"
    ):
        return None
    plans = [c.planned_profile() for c in copies]
    if any(p is None for p in plans):  # no apex announced yet: the copy's own call decides
        return None
    taus = np.array([p[0] for p in plans], dtype=float)
    t = np.asarray(obs)[:, OBS_TIME].astype(float)
    if c0.snaps_time:
        t0 = np.array([p[1] for p in plans], dtype=float)
        t = t0 + c0.dt * np.round((t - t0) / c0.dt)  # round half to even, as Python's round
    basis, t1 = c0.basis, t + c0.dt
    lo = np.clip(basis.edges[:-1], t[:, None], t1[:, None])
    hi = np.clip(np.append(basis.edges[1:-1], np.inf), t[:, None], t1[:, None])
    w = hi - lo
    # each row's dot product as `TorqueBasis.average` makes it (np.dot: BLAS may fuse a
    # multiply and an add, so elementwise products summed can differ in the last bit)
    avg = np.fromiter((np.dot(taus[k], w[k]) for k in range(len(t))), float, len(t)) / (t1 - t)
    return np.clip(avg / c0.max_torque, -1.0, 1.0)


def reset_controller(controller) -> None:
    """Forget a stateful controller's episode (``reset()``, e.g. `OffsetFree`'s estimate): the
    loops call it at the start of each episode; memoryless controllers are left alone."""
    reset = getattr(controller, "reset", None)
    if getattr(controller, "stateful", False) and callable(reset):
        reset()


def notify_apex(controller, obs, info) -> None:
    """The loop side of the ``on_apex`` protocol, for any rollout of PassiveBound-v0: call it
    after ``reset`` and after every ``step`` with that call's observation and info. It calls
    ``controller.on_apex`` when the info marks an apex (``start_z`` after a reset, ``apex_z``
    after a step); controllers without ``on_apex`` are left alone."""
    on_apex = getattr(controller, "on_apex", None)
    if on_apex is None:
        return
    if "apex_z" in info:
        on_apex(_apex_state(info, "apex_z"), float(obs[OBS_TIME]))
    elif "start_z" in info:
        on_apex(_apex_state(info, "start_z"), 0.0)


def _apex_state(info, key: str) -> np.ndarray:
    """``info[key]`` as six finite numbers (a stride controller plans from it); ValueError
    naming the key otherwise (a NaN apex state would become a NaN torque)."""
    try:
        z = np.asarray(info[key], dtype=float)
    except (TypeError, ValueError):
        z = None
    if z is None or z.shape != (6,) or not np.all(np.isfinite(z)):
        got = " ".join(repr(info[key]).split())  # one line
        raise ValueError(
            f"info[{key!r}] must be the apex state, six finite numbers, got {got[:160]}; "
            "pass the info the env returned"
        )
    return z
