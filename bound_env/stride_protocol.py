"""The stride protocol: what a stride controller and a loop over PassiveBound-v0 share.

Beside `bound_env.stride_map` (the one stride map) and below both `bound_env.control` (the
controllers) and `bound_env.analysis` (the loops that measure them), so that analysis never
imports control:

- where a stride controller reads the apex state and the time since the apex in the
  observation (`OBS_Z`, `OBS_TIME`, `OBS_TH2DOT`), and the times it reads on each control
  interval (`observed_times`, `grid_times`);
- a profile's interval actions (`interval_averages`, `interval_actions_of`: bit for bit what a
  stride controller's ``__call__`` outputs; `ProfileActions`: the stride map's a = W u), the
  plans of n robots under one controller (`StridePlans`) and the loop side of ``on_apex``
  (`notify_apex`);
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
    from the apex (`bound_env.stride_map.interval_weights` of the ``basis`` at ``dt``): the
    stride map's input for a planned profile (the MPC's planning model, the rescue env's
    plant). Rows of U in, rows of actions out."""

    def __init__(self, basis: TorqueBasis, dt: float):
        self.W = interval_weights(basis.edges, basis.phi, dt)

    def __call__(self, U) -> np.ndarray:
        return np.atleast_2d(U) @ self.W.T


class StridePlans:
    """The stride plans of n robots under one stride controller, for loops that step many
    robots through the step env at once (long episodes, `bound_env.stride_map.to_next_apex`):
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
