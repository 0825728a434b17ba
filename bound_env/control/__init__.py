"""Classical (model-based) spine controllers on the stride map: LQR, deadbeat, damping, MPC.

They live in `bound_env` rather than `agents` because they are part of the model's analysis:
they need the simulator and its linearization (NumPy, SciPy), never torch or
Stable-Baselines3, and `bound_env` must not import `agents`. The tools that take a controller
by name (``bound-env margins``, compare, rollout) find them through `load_controller`.

    from bound_env.control import load_controller
    ctrl = load_controller("lqr")            # configs/controllers/lqr.yaml, or a path
    u = ctrl.stride_action(z)                # PassiveBoundStride-v1 action at apex state z

In the step env (PassiveBound-v0, unwrapped observation) a loop calls
``notify_apex(ctrl, obs, info)`` after ``reset`` and after every ``step``, and ``ctrl(obs)``
for each action (`bound_env.control.controllers` describes the protocol), or wraps it in
`PlainPolicy` and calls ``act(obs, info)``, which does both (`bound_env.control.plain`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from .controllers import DampingFeedback, StrideFeedback, notify_apex
from .design import Linearization, deadbeat_gain, linearize, lqr_gain, spectral_radius
from .offset_free import SUFFIX as OF_SUFFIX
from .offset_free import OffsetFree, interval_model
from .plain import PlainPolicy
from .spec import CONTROLLERS_DIR, ControllerSpec, load_spec, read_gain, weights

__all__ = [
    "CONTROLLERS_DIR",
    "ControllerSpec",
    "DampingFeedback",
    "Linearization",
    "OffsetFree",
    "PlainPolicy",
    "StrideFeedback",
    "controller_names",
    "deadbeat_gain",
    "is_controller",
    "linearize",
    "load_controller",
    "load_spec",
    "interval_model",
    "lqr_gain",
    "notify_apex",
    "spectral_radius",
]


def controller_names() -> list[str]:
    """Names of the shipped specs (``configs/controllers/*.yaml``)."""
    return sorted(p.stem for p in CONTROLLERS_DIR.glob("*.yaml"))


def is_controller(policy) -> bool:
    """Whether ``policy`` (a string) names a controller spec: a shipped name or a .yaml
    (either with the suffix ``+of``: held offset-free)."""
    s = str(policy)
    if s.endswith(OF_SUFFIX):
        s = s[: -len(OF_SUFFIX)]
    return s in controller_names() or Path(s).suffix in (".yaml", ".yml")


def load_controller(spec, gait: str | None = None):
    """A controller from a spec (name or path, or a `ControllerSpec`), designed for ``gait``
    (default: the spec's). LQR and deadbeat linearize the stride map there (~0.1 s)."""
    from ..stride_task import StrideTask

    if isinstance(spec, (str, Path)) and str(spec).endswith(OF_SUFFIX) and str(spec) != OF_SUFFIX:
        return OffsetFree(load_controller(str(spec)[: -len(OF_SUFFIX)], gait), name=str(spec))
    s = spec if isinstance(spec, ControllerSpec) else load_spec(spec)
    if s.offset_free is not None:
        inner = load_controller(replace(s, offset_free=None), gait)
        return OffsetFree(inner, name=s.name, **s.offset_free)
    if s.privileged:
        from .privileged import PrivilegedMPC

        return PrivilegedMPC(gait, spec=s, name=s.name)
    if s.adaptive:
        from .adaptive import AdaptiveMPC

        return AdaptiveMPC(gait, spec=s, name=s.name, **s.adaptive)
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
