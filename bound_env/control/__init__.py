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

from .build import design_controller
from .controllers import DampingFeedback, StrideFeedback, notify_apex
from .design import Linearization, deadbeat_gain, linearize, lqr_gain, spectral_radius
from .offset_free import SUFFIX as OF_SUFFIX
from .offset_free import OffsetFree, interval_model
from .plain import PlainPolicy
from .spec import CONTROLLERS_DIR, ControllerSpec, load_spec
from .spec import read_gain as read_gain  # the public spelling of before
from .spec import weights as weights

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
    return design_controller(s, gait)
