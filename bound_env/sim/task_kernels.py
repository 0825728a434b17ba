"""The compiled side of the PassiveBound task: the kernels every robot of the project steps with.

One control interval of one robot (`advance_interval`: the torque held, event-accurate
integration to the interval's end, every apex passed; `step_env`: with the reward terms and
the observation), starts at an apex (`reset_at_apex`, `start_at_state`) and whole batches
(`step_batch`, `step_batch_parallel`), with the flat layouts they read: the per-robot scalar
state (`STATE_LAYOUT`, columns ``S_*`` of ``Batch.s``), the task's constants (`CONFIG_LAYOUT`,
entries ``C_*`` of ``PassiveBoundTask.cfg``) and the observation (`OBS_NAMES`). The Python side
(settings, batches, start states, infos) is `bound_env.sim.task`, which re-exports all of this;
the one stride map (`bound_env.sim.stride_map`) runs these kernels too.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..files.layout import Layout
from ..model.dynamics import A_CB, A_CF, jit, leg_back, leg_front, total_energy
from ..model.events import (
    APEX,
    CONTINUE,
    F_NO_APEX,
    F_NON_FINITE,
    FAIL_FIRST,
    FL_TOUCHED_B,
    FL_TOUCHED_F,
    G_APEX,
    TIME_UP,
    phase_index,
    start_status,
)
from ..model.fast import EV_APEXES, EV_LOGGED, Options, advance, event_log, recorder
from ..model.params import P_ALPHA, P_GB, P_GF, P_LB, P_LF, P_TAU, Z_IN_Y
from ..model.terrain import change_slope

# Observation layout (x_g first only when it is included).
OBS_NAMES = (
    "x_g",
    "y_g",
    "theta1",
    "theta2",
    "xdot_g",
    "ydot_g",
    "theta1dot",
    "theta2dot",
    "contact_back",
    "contact_front",
    "leg_length_back",
    "leg_angle_back",
    "leg_length_front",
    "leg_angle_front",
    "touched_back",
    "touched_front",
    "time_since_apex",
)
OBS_UNITS = (
    "m",
    "m",
    "rad",
    "rad",
    "m/s",
    "m/s",
    "rad/s",
    "rad/s",
    "0/1",
    "0/1",
    "m",
    "rad",
    "m",
    "rad",
    "0/1",
    "0/1",
    "s",
)

# Per-robot scalar state, columns of `Batch.s` (float64; counts and codes are exact integers):
# S.T == S_T == 0, ..., N_S columns.
N_XI = 4  # slope draws kept per robot (rough terrain; refilled by `draw_slope_noise`)
STATE_LAYOUT = Layout(
    "S_",
    (
        "t",  # simulation time since reset [s]
        "h",  # integrator step to carry into the next interval [s] (0: choose)
        "t_apex",  # time of the last apex, or 0 [s]
        "steps",  # control intervals since reset
        "strides",  # strides completed since reset
        "status",  # CONTINUE or a failure code (bound_env.model.events)
        "napex",  # strides completed in the last interval
        "tau",  # spine torque of the last interval [N m]
        "energy",  # total energy after the last interval [J]
        "reward",  # reward of the last interval
        "alive",  # its terms: alive bonus, tracking (<= 0), control (<= 0)
        "tracking",
        "ctrl",
        "x",  # x_g after the last interval [m] (a copy, for the info)
        "phase",  # stance condition index after the last interval (PHASES)
        ("xi", N_XI),  # standard normal draws for the slope changes at the next apexes
    ),
    "N_S",
)
S = STATE_LAYOUT.ns
globals().update(STATE_LAYOUT.constants())  # S_T, ..., S_XI, N_S (imported by env, vector)

# Task constants, entries of the float64 vector `PassiveBoundTask.cfg` the kernel reads:
# C.DT == C_DT == 0, ..., N_CFG entries.
N_OBS_FULL = len(OBS_NAMES)
CONFIG_LAYOUT = Layout(
    "C_",
    (
        "dt",
        "max_torque",
        "rtol",
        "atol",
        "no_apex",
        "alive",
        "tracking",
        "ctrl",
        "include_x",
        ("zref", 6),  # the reference apex state z* (SI)
        ("zscale", 6),  # APEX_SCALES
        ("obs_low", N_OBS_FULL),  # lower bounds of the full observation (float32 values)
        ("obs_high", N_OBS_FULL),  # upper bounds
        "slope_noise",  # sigma of the slope at each apex [rad]
        "alpha_nominal",  # the nominal slope alpha [rad]
    ),
    "N_CFG",
)
C = CONFIG_LAYOUT.ns
globals().update(CONFIG_LAYOUT.constants())  # C_DT, ..., N_CFG

_Z_IDX = np.array(Z_IN_Y)  # z = y[_Z_IDX] at an apex (eq. 17)


# ---------------------------------------------------------------------------------------------
# Compiled kernels.
# ---------------------------------------------------------------------------------------------


@jit
def observe(y, aux, flags, time_since_apex, cfg, out):
    """Write the observation (layout `OBS_NAMES`, x_g only if included) into ``out``, clipped to
    the bounds in ``cfg``.

    A stance leg reports its length and its angle from the slope normal (toe ahead positive);
    a leg in flight is held at its rest length and touchdown angle, as the model assumes, so
    both are continuous at touchdown.
    """
    v = np.empty(N_OBS_FULL)
    v[0] = y[0]
    for j in range(1, 8):
        v[j] = y[j]
    v[8] = aux[A_CB]
    v[9] = aux[A_CF]
    # stance leg: length and angle from the slope normal, positive with the toe ahead of the
    # hip (unit vector (ux, uy) points toe -> hip)
    if aux[A_CB] > 0.5:
        lb, ux, uy = leg_back(y, aux)
        v[10] = lb
        v[11] = math.atan2(-ux, uy)
    else:
        v[10] = aux[P_LB]
        v[11] = aux[P_GB]
    if aux[A_CF] > 0.5:
        lf, ux, uy = leg_front(y, aux)
        v[12] = lf
        v[13] = math.atan2(-ux, uy)
    else:
        v[12] = aux[P_LF]
        v[13] = aux[P_GF]
    v[14] = 1.0 if flags[FL_TOUCHED_B] else 0.0
    v[15] = 1.0 if flags[FL_TOUCHED_F] else 0.0
    v[16] = time_since_apex
    k0 = 0 if cfg[C.INCLUDE_X] > 0.5 else 1
    for j in range(k0, N_OBS_FULL):
        lo, hi = cfg[C.OBS_LOW + j], cfg[C.OBS_HIGH + j]
        x = v[j]
        out[j - k0] = lo if not x >= lo else (hi if x > hi else x)  # NaN -> lo


# Kept as a name for its importers: every kernel now compiles without fast-math (`jit`), so the
# reward rounds the same in the serial and the threaded kernel, and from a cold or warm cache.
strict_jit = jit


@strict_jit
def tracking_cost(apex, n_apex, cfg):
    """sum over the first ``n_apex`` apex states of sum_i ((z_i - z*_i) / scale_i)^2
    (non-finite costs are skipped: they cannot arise from a located apex)."""
    total = 0.0
    for k in range(n_apex):
        c = 0.0
        for j in range(6):
            d = (apex[k, Z_IN_Y[j]] - cfg[C.ZREF + j]) / cfg[C.ZSCALE + j]
            c += d * d
        if math.isfinite(c):
            total += c
    return total


@strict_jit
def reward_terms(cfg, tracking, a, failed):
    """(alive, tracking, ctrl, reward): the reward terms of one interval and their sum."""
    alive = 0.0 if failed else cfg[C.ALIVE]
    r_tracking = -(cfg[C.TRACKING] * tracking) if tracking != 0.0 else 0.0  # (never -0.0)
    r_ctrl = -(cfg[C.CTRL] * (a * a)) if a != 0.0 else 0.0
    return alive, r_tracking, r_ctrl, (alive + r_tracking) + r_ctrl


@jit
def advance_rough(y, aux, flags, s, t_end, cfg, log, apex):
    """`bound_env.model.fast.advance` to t_end on rough terrain: at every apex the apex state is
    stored in ``apex`` (as the smooth path stores it), then the slope becomes
    alpha + sigma xi_k (alpha nominal, xi_k = s[S.XI + k] for the k-th apex of the interval):
    the ground tilts by the difference (`bound_env.model.terrain.change_slope`) and a new stride
    starts (`bound_env.model.events.apply_events` has cleared the touched-down flags).

    Returns (status, t, h_next, n_apex, t_last_apex or -1).
    """
    t, h = s[S.T], s[S.H]
    n_apex, t_apex = 0, -1.0
    opts = Options(cfg[C.RTOL], cfg[C.ATOL], True)
    rec = recorder(0, 0.0)
    for _ in range(apex.shape[0] + 8):
        status, t, h = advance(y, aux, flags, t, t_end, h, opts, log, rec)
        if status != APEX:
            return status, t, h, n_apex, t_apex
        if n_apex < apex.shape[0]:
            apex[n_apex, :] = y
        alpha_k = cfg[C.ALPHA_NOMINAL] + cfg[C.SLOPE_NOISE] * s[S.XI + min(n_apex, N_XI - 1)]
        change_slope(y, aux, alpha_k - aux[P_ALPHA])
        n_apex += 1
        t_apex = t
    return status, t, h, n_apex, t_apex


@jit
def advance_interval(y, aux, flags, s, apex, cfg, action):
    """The dynamics of one control interval of one robot: the torque held, integration to the
    interval's end (every apex passed on the way ends a stride: its full state goes to
    ``apex``, up to its capacity), status and time bookkeeping in ``s``. Returns (the clipped
    action, the tracking cost of the apexes passed); `step_env` adds rewards and the
    observation, the one stride map (`bound_env.sim.stride_map`) needs only this."""
    a = min(max(action, -1.0), 1.0)
    tau = cfg[C.MAX_TORQUE] * a
    aux[P_TAU] = tau
    y_start = y.copy()
    log = event_log(32, apex)
    steps = s[S.STEPS] + 1.0
    t_end = steps * cfg[C.DT]  # not accumulated, so no drift over long episodes
    if cfg[C.SLOPE_NOISE] > 0.0:  # rough terrain: stop at each apex and tilt the ground
        status, t, h, n_apex, t_apex = advance_rough(y, aux, flags, s, t_end, cfg, log, apex)
        n_ev = 0
    else:
        opts = Options(cfg[C.RTOL], cfg[C.ATOL], False)
        status, t, h = advance(y, aux, flags, s[S.T], t_end, s[S.H], opts, log, recorder(0, 0.0))
        n_ev, n_apex = log.count[EV_LOGGED], log.count[EV_APEXES]
        t_apex = t
    if status == TIME_UP:
        status = CONTINUE
    tracking = tracking_cost(apex, min(n_apex, apex.shape[0]), cfg)
    if n_apex > 0:
        for e in range(min(n_ev, log.t.shape[0])):
            if log.guard[e] == G_APEX:
                t_apex = log.t[e]
        s[S.T_APEX] = t_apex
    if status < FAIL_FIRST and t - s[S.T_APEX] >= cfg[C.NO_APEX]:
        status = F_NO_APEX
    finite = True
    for j in range(8):
        if not math.isfinite(y[j]):
            finite = False
    if not finite:  # report the last finite state
        y[:] = y_start
        if status < FAIL_FIRST:
            status = F_NON_FINITE
    s[S.T] = t
    s[S.H] = h
    s[S.STEPS] = steps
    s[S.STRIDES] += n_apex
    s[S.NAPEX] = n_apex
    s[S.STATUS] = status
    s[S.TAU] = tau
    s[S.PHASE] = phase_index(aux)
    return a, tracking


@jit
def step_env(y, aux, flags, s, apex, obs, cfg, action):
    """One control interval of one robot: torque, integration, reward terms, observation.

    ``action`` is the normalized torque (clipped here to [-1, 1]). Every apex passed on the
    way ends a stride: its full state goes to ``apex`` (up to its capacity) and its cost to
    the tracking term. Results go to ``s`` (columns ``S_*``) and ``obs``.
    """
    a, tracking = advance_interval(y, aux, flags, s, apex, cfg, action)
    status = s[S.STATUS]
    alive, r_tracking, r_ctrl, reward = reward_terms(cfg, tracking, a, status >= FAIL_FIRST)
    s[S.ENERGY] = total_energy(y, aux)
    s[S.X] = y[0]
    s[S.ALIVE] = alive
    s[S.TRACKING] = r_tracking
    s[S.CTRL] = r_ctrl
    s[S.REWARD] = reward
    observe(y, aux, flags, s[S.T] - s[S.T_APEX], cfg, obs)


@jit
def reset_at_apex(y, aux, flags, s, obs, aux0, z, cfg):
    """Put one robot at the apex state z (x_g = 0, both legs in flight, t = 0), with the
    parameters ``aux0``; an impossible start gets its failure status (it fails at the first
    step)."""
    y[:] = 0.0
    for i in range(6):
        y[_Z_IDX[i]] = z[i]
    aux[:] = aux0
    start_at_state(y, aux, flags, s, obs, cfg)


@jit
def start_at_state(y, aux, flags, s, obs, cfg):
    """Start one robot (t = 0, both legs in flight) at the full state y with the parameters
    in ``aux``, as set by the caller (`reset_at_apex`, or a slope change at the apex)."""
    flags[:] = False
    s[:] = 0.0
    s[S.STATUS] = start_status(y, aux)  # an impossible start fails at the first step
    s[S.ENERGY] = total_energy(y, aux)
    s[S.X] = y[0]
    s[S.PHASE] = 0  # df
    observe(y, aux, flags, 0.0, cfg, obs)


@jit
def step_batch(Y, AUX, FLAGS, S, APEX, OBS, cfg, actions, active):
    """`step_env` for every robot i with ``active[i]``, one after the other."""
    for i in range(Y.shape[0]):
        if active[i]:
            step_env(Y[i], AUX[i], FLAGS[i], S[i], APEX[i], OBS[i], cfg, actions[i])


@nb.njit(cache=True, parallel=True, error_model="numpy")
def step_batch_parallel(Y, AUX, FLAGS, S, APEX, OBS, cfg, actions, active):
    """`step_batch` with the robots spread over Numba's threads."""
    for i in nb.prange(Y.shape[0]):
        if active[i]:
            step_env(Y[i], AUX[i], FLAGS[i], S[i], APEX[i], OBS[i], cfg, actions[i])
