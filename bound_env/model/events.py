"""Events of the hybrid system: guards, resets, status codes and stride flags.

This is the one place where touchdown, liftoff, apex and failure are decided (paper Sec.
III.B.2, III.D.1). The guards and resets are compiled functions shared by both integrator
back-ends, `bound_env.model.reference` (``scipy.integrate.solve_ivp``, DOP853, event functions) and
`bound_env.model.fast` (the whole loop compiled); the back-ends only integrate and locate the zero
crossings.

Guards (a transition fires when its guard crosses zero in its direction):

| guard | value | direction | active in |
| --- | --- | --- | --- |
| `TD_B`, `TD_F` | hip height − l_bar cos(gamma_td) (III.B.2, 1 and 3) | falling | leg flight |
| `LO_B`, `LO_F` | l − l_bar (III.B.2, 2 and 4) | rising | leg stance |
| `SHORT_B`, `SHORT_F` | l − min_leg_frac · l_bar (failure) | falling | leg stance |
| `GROUND_*` | height of the back hip, the spine joint, the front hip (failure) | falling | always |
| `BACKWARD` | xdot_g (failure) | falling | always |
| `APEX` | ydot_g (eq. 17) | falling | double flight, armed |

A leg whose hip is below its touchdown height when it lifts off (or at the start) stays in
flight until its hip has risen above that height and falls through it again: the toe cannot
be placed at gamma_td without reaching into the ground, so the leg keeps swinging.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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
    spine_joint,
    trig,
)
from .params import P_GB, P_GF, P_LB, P_LF, P_MINLEG

G_TD_B, G_TD_F, G_LO_B, G_LO_F, G_SHORT_B, G_SHORT_F = range(6)
G_GROUND_B, G_GROUND_J, G_GROUND_F, G_BACKWARD, G_APEX = range(6, 11)
N_GUARDS = 11
GUARD_DIRECTION = np.array([-1, -1, 1, 1, -1, -1, -1, -1, -1, -1, -1], dtype=np.int64)
GUARD_NAMES = (
    "touchdown_back",
    "touchdown_front",
    "liftoff_back",
    "liftoff_front",
    "short_back",
    "short_front",
    "ground_back_hip",
    "ground_spine_joint",
    "ground_front_hip",
    "backward",
    "apex",
)

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
(
    F_GROUND_B,
    F_GROUND_J,
    F_GROUND_F,
    F_BACKWARD,
    F_SHORT_B,
    F_SHORT_F,
    F_EXT_B,
    F_EXT_F,
    F_NO_APEX,
    F_NON_FINITE,
    F_INTEGRATION,
) = range(FAIL_FIRST, FAIL_FIRST + len(FAILURES))

# Flags carried along a stride: has each leg touched down since the start?
FL_TOUCHED_B, FL_TOUCHED_F, FL_STRICT = range(3)
N_FLAGS = 3

EVENT_COINCIDENCE = 1e-10  # guards within this of their zero at an event fire together [m, m/s]
PHASES = ("df", "bs", "fs", "ds")  # indexed by back_stance + 2 * front_stance


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
    touchdowns (which place the toe at x_hip + l_bar sin(gamma_td)), then the apex, which
    ends the stride and starts the next one (the touched-down flags are cleared).
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
        # the stride ends here and the next one starts: no leg has touched down in it yet
        flags[FL_TOUCHED_B] = False
        flags[FL_TOUCHED_F] = False
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


@dataclass
class Event:
    """A transition: time [s], guard name, phase after it."""

    t: float
    name: str
    phase: str
