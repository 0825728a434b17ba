"""Rough terrain: the slope angle changes at every apex (``slope_noise_deg``).

Real ground is not one plane. Following Erez & Smart's compass-gait walker on terrain whose
incline changes at every step, the slope becomes alpha_k = alpha + sigma xi_k at the k-th apex,
xi_k standard normal (drawn from the environment's RNG by the task layer).

The frame change
----------------
The model's state lives in the slope frame (eq. 2: x along the slope, downhill forward; y
normal to it). At an apex both legs are in flight, so a new slope is a new ground line under
a robot whose motion in the world does not change. The state is re-expressed in the frame of
the new ground line:

- the new ground line passes through the point of the old ground line straight below the
  centre of mass (the foot of the normal through it, x = x_g): the ground tilts about that
  point, so the height becomes y_g cos(d_alpha) (a second-order change) and x_g moves by
  -y_g sin(d_alpha) (x is an odometer; nothing depends on it);
- both pitch angles are measured from the ground line, so theta1 grows by d_alpha (a steeper
  slope tilts the ground nose-down under a body whose orientation in the world is unchanged);
  theta2 (relative) and the pitch rates do not change;
- the velocity of the centre of mass is the same vector, its components rotate:
  xdot' = xdot cos d - ydot sin d, ydot' = xdot sin d + ydot cos d, so a steeper slope gives
  ydot' > 0 after an apex: the robot is still rising in the new frame and passes a new apex
  a little later (it does not end a stride: both legs must touch down first);
- gravity along and normal to the ground becomes g sin(alpha'), g cos(alpha') (eq. 2).

Speeds, the kinetic energy and the centre of mass's height in the world are unchanged, so the
total energy is unchanged up to the offset of the potential's origin (none when x_g = 0).
"""

from __future__ import annotations

import math

from .dynamics import A_CB, A_CF, jit
from .params import P_ALPHA, P_G, P_GX, P_GY


@jit
def change_slope(y, aux, d_alpha):
    """Tilt the ground under a robot in flight by ``d_alpha`` [rad] (alpha' = alpha + d_alpha)
    and re-express y = [x_g, y_g, th1, th2, xdot_g, ydot_g, th1dot, th2dot] in its frame,
    in place (see the module docstring). Returns False (and changes nothing) if a leg is in
    stance: a toe on the ground fixes the old ground line."""
    if aux[A_CB] > 0.5 or aux[A_CF] > 0.5:
        return False
    c, s = math.cos(d_alpha), math.sin(d_alpha)
    x, h, xd, yd = y[0], y[1], y[4], y[5]
    y[0] = x - h * s  # centre of mass along the new ground line (pivot at x)
    y[1] = h * c  # its height above the new ground line
    y[2] = y[2] + d_alpha  # pitch from the new ground line
    y[4] = xd * c - yd * s  # the same velocity vector in the rotated basis
    y[5] = xd * s + yd * c
    alpha = aux[P_ALPHA] + d_alpha
    aux[P_ALPHA] = alpha
    aux[P_GX] = aux[P_G] * math.sin(alpha)  # eq. (2)
    aux[P_GY] = aux[P_G] * math.cos(alpha)
    return True


def set_slope(aux, alpha) -> None:
    """Put the slope alpha [rad] into a parameter vector (alpha and gravity, eq. 2)."""
    aux[P_ALPHA] = alpha
    aux[P_GX] = aux[P_G] * math.sin(alpha)
    aux[P_GY] = aux[P_G] * math.cos(alpha)
