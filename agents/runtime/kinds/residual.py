"""Kind "residual": a step-level PPO policy whose actor acts through its run's controller
wrapper (`agents.runtime.residual.ResidualOver`: a residual over a base controller).

Recognised by a controller wrapper in the run config's ``env_wrapper``
(`agents.runtime.kinds.step.controller_wrapper`); checked and loaded as a step policy, the base
pinned by its fingerprint (`agents.common.policy_files.check_base_pin`).
"""

from __future__ import annotations

import agents.runtime.kinds.step as step

from .folder import PolicyFolder

NAME = "residual"


RECOGNISED_BY = ("wrapper",)  # a controller wrapper in its run config's env_wrapper


def wrapped(section: dict | None) -> bool:
    """Whether a run config's section names a controller wrapper
    (`agents.runtime.kinds.step.controller_wrapper`); a broken entry is left to kind "step",
    which raises it where it always has."""
    try:
        wrapper = step.controller_wrapper((section or {}).get("env_wrapper") or [])
    except Exception:  # noqa: BLE001
        return False
    return wrapper is not None


def load(folder: PolicyFolder, gait=None, force: bool = False, env_id: str | None = None):
    return step.load(folder, gait, force, env_id)
