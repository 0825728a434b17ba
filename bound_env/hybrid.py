"""Hybrid simulation: stance conditions, guards, resets, failures and the apex-to-apex stride.

This is the one place where touchdown, liftoff, apex and failure are decided (paper Sec.
III.B.2, III.D.1). The guards and resets are compiled functions shared by both integrator
back-ends: the *reference* back-end below (``scipy.integrate.solve_ivp``, DOP853, event
functions) and the *fast* one in `bound_env.fast` (the whole loop compiled).

Guards (a transition fires when its guard crosses zero in its direction):

=============  ==================================================  =========  =========
guard          value                                               direction  active in
=============  ==================================================  =========  =========
TD_B / TD_F    hip height - l_bar cos(gamma_td)  (III.B.2, 1 & 3)  falling    leg flight
LO_B / LO_F    l - l_bar                          (III.B.2, 2 & 4) rising     leg stance
SHORT_B / _F   l - min_leg_frac * l_bar           (failure)        falling    leg stance
GROUND_*       height of back hip, spine joint, front hip (fail)   falling    always
BACKWARD       xdot_g                             (failure)        falling    always
APEX           ydot_g  (eq. 17)                                    falling    df, armed
=============  ==================================================  =========  =========

A leg whose hip is below its touchdown height when it lifts off (or at the start) stays in
flight until its hip has risen above that height and falls through it again: the toe cannot
be placed at gamma_td without reaching into the ground, so the leg keeps swinging.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .dynamics import (
    A_CB,
    A_CF,
    A_XB,
    A_XF,
    back_hip,
    body_points,
    front_hip,
    hip_velocities,
    jit,
    make_aux,
    rhs,
    spine_joint,
    total_energy,
    trig,
)  # fmt: skip
from .params import P_GB, P_GF, P_LB, P_LF, P_MINLEG, Params

G_TD_B, G_TD_F, G_LO_B, G_LO_F, G_SHORT_B, G_SHORT_F = range(6)
G_GROUND_B, G_GROUND_J, G_GROUND_F, G_BACKWARD, G_APEX = range(6, 11)
N_GUARDS = 11
GUARD_DIRECTION = np.array([-1, -1, 1, 1, -1, -1, -1, -1, -1, -1, -1], dtype=np.int64)
GUARD_NAMES = (
    "touchdown_back", "touchdown_front", "liftoff_back", "liftoff_front",
    "short_back", "short_front", "ground_back_hip", "ground_spine_joint",
    "ground_front_hip", "backward", "apex",
)  # fmt: skip

# Status codes returned by `apply_events` and the fast loop; failures are >= FAIL_FIRST.
CONTINUE, APEX, TIME_UP = 0, 1, 2
FAIL_FIRST = 3
FAILURES = (
    "ground_contact_back_hip",
    "ground_contact_spine_joint",
    "ground_contact_front_hip",
    "moving_backwards",
    "leg_overcompressed_back",
    "leg_overcompressed_front",
    "leg_extending_at_touchdown_back",
    "leg_extending_at_touchdown_front",
    "no_apex",
    "non_finite",
    "integration_failed",
)
(F_GROUND_B, F_GROUND_J, F_GROUND_F, F_BACKWARD, F_SHORT_B, F_SHORT_F, F_EXT_B, F_EXT_F,
 F_NO_APEX, F_NON_FINITE, F_INTEGRATION) = range(FAIL_FIRST, FAIL_FIRST + len(FAILURES))

# Flags carried along a stride: has each leg touched down since the start?
FL_TOUCHED_B, FL_TOUCHED_F, FL_STRICT = range(3)
N_FLAGS = 3

EVENT_COINCIDENCE = 1e-10  # guards within this of their zero at an event fire together [m, m/s]
PHASES = ("df", "bs", "fs", "ds")  # indexed by back_stance + 2 * front_stance
DEFAULT_T_MAX = 2.0  # a stride with no apex within this time [s] fails with "no_apex"


def failure_name(code: int) -> str | None:
    """Status code -> failure reason (None for a success)."""
    return FAILURES[code - FAIL_FIRST] if code >= FAIL_FIRST else None


@jit
def phase_index(aux):
    """0 df, 1 bs, 2 fs, 3 ds (Fig. 2)."""
    return int(aux[A_CB] > 0.5) + 2 * int(aux[A_CF] > 0.5)


@jit
def apex_armed(aux, flags):
    """The apex ends a stride only in df, and only once both legs have been in stance
    (or, with the strict rule, once any leg has)."""
    if aux[A_CB] > 0.5 or aux[A_CF] > 0.5:
        return False
    if flags[FL_STRICT]:
        return flags[FL_TOUCHED_B] or flags[FL_TOUCHED_F]
    return flags[FL_TOUCHED_B] and flags[FL_TOUCHED_F]


@jit
def guard_values(y, aux, flags, out):
    """All guards at state y; an inactive guard holds a constant on its non-firing side."""
    for i in range(N_GUARDS):
        out[i] = -GUARD_DIRECTION[i]  # inactive: never crosses
    hbx, hby, _, jy, hfx, hfy = body_points(y, aux, *trig(y))
    if aux[A_CB] > 0.5:
        lb = math.sqrt((hbx - aux[A_XB]) ** 2 + hby * hby)
        out[G_LO_B] = lb - aux[P_LB]
        out[G_SHORT_B] = lb - aux[P_MINLEG] * aux[P_LB]
    else:
        out[G_TD_B] = hby - aux[P_LB] * math.cos(aux[P_GB])
    if aux[A_CF] > 0.5:
        lf = math.sqrt((hfx - aux[A_XF]) ** 2 + hfy * hfy)
        out[G_LO_F] = lf - aux[P_LF]
        out[G_SHORT_F] = lf - aux[P_MINLEG] * aux[P_LF]
    else:
        out[G_TD_F] = hfy - aux[P_LF] * math.cos(aux[P_GF])
    out[G_GROUND_B] = hby
    out[G_GROUND_J] = jy
    out[G_GROUND_F] = hfy
    out[G_BACKWARD] = y[4]
    if apex_armed(aux, flags):
        out[G_APEX] = y[5]


@jit
def coincident(g_before, g_event, fired):
    """Mark every guard that was on its non-firing side at the start of the integrator step
    (``g_before``) and is at, past or within EVENT_COINCIDENCE of its zero at the event."""
    for i in range(N_GUARDS):
        d = GUARD_DIRECTION[i]
        if d * g_before[i] < 0.0 and d * g_event[i] >= -EVENT_COINCIDENCE:
            fired[i] = True


@jit
def apply_events(y, aux, flags, fired):
    """Resets for the guards that fired at state y; updates aux (contacts, toes) and flags.

    Returns CONTINUE, APEX or a failure code. Failures take precedence, then liftoffs, then
    touchdowns (which place the toe at x_hip + l_bar sin(gamma_td)), then the apex.
    """
    if fired[G_GROUND_B]:
        return F_GROUND_B
    if fired[G_GROUND_J]:
        return F_GROUND_J
    if fired[G_GROUND_F]:
        return F_GROUND_F
    if fired[G_BACKWARD]:
        return F_BACKWARD
    if fired[G_SHORT_B]:
        return F_SHORT_B
    if fired[G_SHORT_F]:
        return F_SHORT_F
    # liftoff: the massless leg snaps back to its touchdown angle (III.D.1)
    if fired[G_LO_B]:
        aux[A_CB] = 0.0
    if fired[G_LO_F]:
        aux[A_CF] = 0.0
    vbx, vby, vfx, vfy = hip_velocities(y, aux)
    if fired[G_TD_B]:
        hx, _ = back_hip(y, aux)
        gb = aux[P_GB]
        # leg rate dl/dt = u . v_hip with u = (-sin gamma, cos gamma) pointing toe -> hip
        if -math.sin(gb) * vbx + math.cos(gb) * vby > 0.0:
            return F_EXT_B
        aux[A_XB] = hx + aux[P_LB] * math.sin(gb)
        aux[A_CB] = 1.0
        flags[FL_TOUCHED_B] = True
    if fired[G_TD_F]:
        hx, _ = front_hip(y, aux)
        gf = aux[P_GF]
        if -math.sin(gf) * vfx + math.cos(gf) * vfy > 0.0:
            return F_EXT_F
        aux[A_XF] = hx + aux[P_LF] * math.sin(gf)
        aux[A_CF] = 1.0
        flags[FL_TOUCHED_F] = True
    if fired[G_APEX] and apex_armed(aux, flags):
        return APEX
    return CONTINUE


@jit
def start_status(y, aux):
    """Failure code of an impossible start state, else CONTINUE."""
    for i in range(8):
        if not math.isfinite(y[i]):
            return F_NON_FINITE
    for i in range(aux.shape[0]):
        if not math.isfinite(aux[i]):
            return F_NON_FINITE
    if back_hip(y, aux)[1] <= 0.0:
        return F_GROUND_B
    if spine_joint(y, aux)[1] <= 0.0:
        return F_GROUND_J
    if front_hip(y, aux)[1] <= 0.0:
        return F_GROUND_F
    if y[4] <= 0.0:
        return F_BACKWARD
    return CONTINUE


def state_from_z(z) -> np.ndarray:
    """Full state y = [q, qdot] at an apex z (SI) with x_g = 0, ydot_g = 0 (eq. 17)."""
    z = np.asarray(z, dtype=float)
    return np.array([0.0, z[0], z[1], z[2], z[3], 0.0, z[4], z[5]])


def z_from_state(y) -> np.ndarray:
    """Apex coordinates z = [y_g, th1, th2, xdot_g, th1dot, th2dot] of a full state."""
    y = np.asarray(y, dtype=float)
    return y[[1, 2, 3, 4, 6, 7]].copy()


@dataclass
class Event:
    """A transition: time [s], guard name, phase after it."""

    t: float
    name: str
    phase: str


@dataclass
class Trajectory:
    """A sampled stride: t [s], q, qdot (SI), stance condition name, total energy [J]."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    phase: list
    energy: np.ndarray


@dataclass
class StrideResult:
    """One apex-to-apex stride (the Poincare map P, eq. 18) or how it failed."""

    z0: np.ndarray
    z1: np.ndarray | None
    failure: str | None
    phases: list = field(default_factory=list)
    durations: list = field(default_factory=list)
    events: list = field(default_factory=list)
    energy0: float = math.nan
    energy1: float = math.nan
    t_end: float = math.nan
    y_end: np.ndarray | None = None
    trajectory: Trajectory | None = None

    @property
    def ok(self) -> bool:
        return self.failure is None

    def summary(self) -> dict:
        """Plain-JSON summary (z in paper units), as ``bound-env stride --json`` prints it."""
        from .params import z_to_paper

        return {
            "z0": [float(v) for v in z_to_paper(self.z0)],
            "z1": None if self.z1 is None else [float(v) for v in z_to_paper(self.z1)],
            "phases": list(self.phases),
            "durations": [float(d) for d in self.durations],
            "failure": self.failure,
            "energy": {"start": float(self.energy0), "end": float(self.energy1)},
            "period": float(self.t_end),
            "events": [{"t": e.t, "name": e.name, "phase": e.phase} for e in self.events],
        }


def phases_from_events(events: list, t_end: float) -> tuple[list, list]:
    """Phase names in order and their durations, merging events that did not change phase."""
    phases, starts = ["df"], [0.0]
    for e in events:
        if e.phase != phases[-1]:
            phases.append(e.phase)
            starts.append(e.t)
    durations = [b - a for a, b in zip(starts, starts[1:] + [t_end], strict=True)]
    return phases, durations


# --------------------------------------------------------------------------------------------
# Reference back-end: scipy.integrate.solve_ivp (DOP853) with event functions.
# --------------------------------------------------------------------------------------------


def _events_for(aux, flags):
    """solve_ivp event functions for the guards of the current condition (all terminal)."""
    buf = np.empty(N_GUARDS)
    evs = []
    for i in range(N_GUARDS):

        def ev(t, y, i=i):
            guard_values(y, aux, flags, buf)
            return buf[i]

        ev.terminal = True
        ev.direction = float(GUARD_DIRECTION[i])
        evs.append(ev)
    return evs


def simulate_reference(
    y0, aux, flags, t0=0.0, t_end=DEFAULT_T_MAX, stop_at_apex=True,
    rtol=1e-12, atol=1e-12, record_dt=None,
):  # fmt: skip
    """Integrate the hybrid system from (t0, y0) until the apex (or t_end) with solve_ivp.

    ``aux`` and ``flags`` are updated in place. Returns (status, t, y, events, samples) where
    samples is a list of (t, y, phase) when ``record_dt`` is given.
    """
    from scipy.integrate import solve_ivp

    y = np.array(y0, dtype=float)
    t = float(t0)
    events, samples = [], []
    g, g_before = np.empty(N_GUARDS), np.empty(N_GUARDS)
    status = start_status(y, aux)
    if status != CONTINUE:
        return status, t, y, events, samples
    if record_dt is not None:
        samples.append((t, y.copy(), PHASES[phase_index(aux)], total_energy(y, aux)))
    out = np.empty(8)

    def f(t, y):
        rhs(t, y, aux, out)
        return out.copy()

    for _ in range(10_000):  # bound on the number of transitions
        evs = _events_for(aux, flags)
        y0_seg = y
        sol = solve_ivp(
            f, (t, t_end), y, method="DOP853", rtol=rtol, atol=atol, events=evs,
            dense_output=record_dt is not None,
        )  # fmt: skip
        if sol.status < 0:
            return F_INTEGRATION, t, y, events, samples
        t_new, y_new = float(sol.t[-1]), sol.y[:, -1].copy()
        if record_dt is not None:
            ts = np.arange(t + record_dt, t_new, record_dt)
            ph = PHASES[phase_index(aux)]
            for ti in ts:
                yi = sol.sol(ti)
                samples.append((float(ti), yi, ph, total_energy(yi, aux)))
        t, y = t_new, y_new
        if not np.all(np.isfinite(y)):
            return F_NON_FINITE, t, y, events, samples
        if sol.status == 0:  # reached t_end
            return TIME_UP, t, y, events, samples
        fired = np.zeros(N_GUARDS, dtype=np.bool_)
        for i, te in enumerate(sol.t_events):
            if len(te):
                fired[i] = True
        guard_values(sol.y[:, -2] if sol.y.shape[1] > 1 else y0_seg, aux, flags, g_before)
        guard_values(y, aux, flags, g)
        coincident(g_before, g, fired)
        if not stop_at_apex:
            fired[G_APEX] = False
        status = apply_events(y, aux, flags, fired)
        ph = PHASES[phase_index(aux)]
        for i in np.flatnonzero(fired):
            events.append(Event(t, GUARD_NAMES[i], ph))
        if record_dt is not None:
            samples.append((t, y.copy(), ph, total_energy(y, aux)))
        if status != CONTINUE:
            return status, t, y, events, samples
    return F_INTEGRATION, t, y, events, samples


def simulate_stride(
    z0, params: Params, *, backend="fast", tau=0.0, strict=False, rtol=None, atol=None,
    t_max=DEFAULT_T_MAX, record_dt=None,
) -> StrideResult:  # fmt: skip
    """One stride of the Poincare map P (eq. 18) from the apex state ``z0`` (SI).

    ``backend`` is ``"fast"`` (compiled, default tolerances 1e-10) or ``"reference"``
    (solve_ivp DOP853, default tolerances 1e-12). ``strict=True`` ends the stride at the first
    apex after any touchdown instead of after both legs have been in stance. ``record_dt``
    (s) returns a sampled `Trajectory` plus every event state.
    """
    z0 = np.asarray(z0, dtype=float).reshape(6)
    y0 = state_from_z(z0)
    aux = make_aux(params.to_array(tau))
    flags = np.zeros(N_FLAGS, dtype=np.bool_)
    flags[FL_STRICT] = strict
    e0 = total_energy(y0, aux) if np.all(np.isfinite(y0)) else math.nan
    if backend == "reference":
        status, t, y, events, samples = simulate_reference(
            y0, aux, flags, t_end=t_max, rtol=rtol or 1e-12, atol=atol or 1e-12,
            record_dt=record_dt,
        )  # fmt: skip
    elif backend == "fast":
        from .fast import simulate_fast

        status, t, y, events, samples = simulate_fast(
            y0, aux, flags, t_end=t_max, rtol=rtol or 1e-10, atol=atol or 1e-10,
            record_dt=record_dt,
        )  # fmt: skip
    else:
        raise ValueError(f"backend must be 'fast' or 'reference', got {backend!r}")
    if status == TIME_UP:
        status = F_NO_APEX
    z1 = z_from_state(y) if status == APEX else None
    phases, durations = phases_from_events(events, t)
    traj = None
    if record_dt is not None and samples:
        ts = np.array([s[0] for s in samples])
        ys = np.array([s[1] for s in samples])
        traj = Trajectory(ts, ys[:, :4], ys[:, 4:], [s[2] for s in samples],
                          np.array([s[3] for s in samples]))
    return StrideResult(
        z0=z0, z1=z1, failure=failure_name(status), phases=phases, durations=durations,
        events=events, energy0=e0,
        energy1=total_energy(y, aux) if np.all(np.isfinite(y)) else math.nan,
        t_end=t, y_end=y, trajectory=traj,
    )  # fmt: skip
