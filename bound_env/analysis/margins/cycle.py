"""The closed-loop cycle: its fixed point z_cl (iteration, then Newton with central differences),
the multipliers there, and the effort and period of one stride on it (JSON ``emax``,
``eigenvalues``, ``fixed_point_shift``, ``effort``)."""

from __future__ import annotations

import numpy as np

from ...model.numerics import map_fixed_point, sorted_eigenvalues
from .closed_loop import Setup, loop_for

FD_REL = 1e-4  # central-difference step, relative to max(|z*_i|, FD_FLOOR_i)
FD_FLOOR = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1])  # SI floors of the FD step scale


def fd_steps(z_star) -> np.ndarray:
    return FD_REL * np.maximum(np.abs(np.asarray(z_star)), FD_FLOOR)


def task_cycle(setup: Setup) -> dict:
    """Closed-loop fixed point, multipliers, effort on the cycle."""
    loop = loop_for(setup)
    b = setup.budget
    z_cl, res, jac = map_fixed_point(
        loop.map,
        setup.z_star,
        fd_steps(setup.z_star),
        settle=b.settle_strides,
        newton_iters=b.newton_iters,
    )
    lam = sorted_eigenvalues(jac)
    out = loop.stride(z_cl)
    return {
        "z_cl": z_cl.tolist(),
        "residual": res,
        "jacobian": jac.tolist(),
        "eigenvalues": [[float(v.real), float(v.imag)] for v in lam],
        "emax": float(np.abs(lam[0])),
        "effort": out.effort,
        "period": out.period,
        "cycle_steps": out.steps,
        "max_torque": loop.max_torque,
    }
