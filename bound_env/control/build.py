"""A controller designed from a plain spec (`design_controller`): LQR, deadbeat, damping or
MPC, linearized on the stride map of its gait. `bound_env.control.load_controller` reads the
name or file and dispatches; the privileged and adaptive MPCs build their base here, so no
module of the package imports the package itself."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .controllers import DampingFeedback, StrideFeedback
from .design import deadbeat_gain, linearize, lqr_gain, spectral_radius
from .offset_free import OffsetFree
from .spec import ControllerSpec, read_gain, weights


def design_controller(s: ControllerSpec, gait: str | None = None):
    """The controller of the checked spec ``s`` (its ``privileged`` and ``adaptive`` blocks
    are the caller's), designed for ``gait`` (default: the spec's); held offset-free where
    the spec says so."""
    from ..sim.stride_task import StrideTask

    if s.offset_free is not None:
        inner = design_controller(replace(s, offset_free=None), gait)
        return OffsetFree(inner, name=s.name, **s.offset_free)
    gait = str(gait) if gait is not None else s.gait
    if s.controller == "damping":
        return DampingFeedback(s.name, s.c, s.max_torque, s.dt, gait)
    task = StrideTask(gait=gait, basis=s.basis, K=s.K, max_torque=s.max_torque, rtol=1e-12)
    K = task.K
    lin = linearize(task.sim, task.z_ref, s.jacobian)
    A_n, B_n = lin.normalized(task.apex_scales)
    G = read_gain(s, K, s.basis, gait)
    design = {
        "A": lin.A.tolist(),
        "B": lin.B.tolist(),
        "jacobian": s.jacobian,
        "rho_open": spectral_radius(lin.A),
    }
    if G is None:
        if s.controller in ("lqr", "mpc"):
            Q, R = weights(s.path, "Q", s.Q, 6), weights(s.path, "R", s.R, K)
            G_n = lqr_gain(A_n, B_n, Q, R)
            design.update(Q=np.diag(Q).tolist(), R=np.diag(R).tolist())
        else:
            G_n = deadbeat_gain(A_n, B_n)
        G = G_n / task.apex_scales[None, :]  # u = -G_n S dz, S = diag(1/s)
        design["source"] = "designed"
    else:
        design["source"] = "gain"
    design["rho_closed"] = spectral_radius(lin.A - lin.B @ G)
    fb = StrideFeedback(
        name=s.name,
        kind="lqr" if s.controller == "mpc" else s.controller,
        gain=G,
        z_ref=task.z_ref,
        basis=task.basis,
        max_torque=s.max_torque,
        dt=s.dt,
        gait=gait,
        design=design,
    )
    if s.controller != "mpc":
        return fb
    from .mpc import MPCController

    x = dict(s.extra)
    return MPCController(name=s.name, lqr=fb, params=task.params, rtol=x.pop("plan_rtol"), **x)
