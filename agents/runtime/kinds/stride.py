"""Kind "stride": a stride-level PPO policy, whose run config names ``PassiveBoundStride-v*``.

Checked and loaded by `agents.runtime.stride_policy`.
"""

from __future__ import annotations

from bound_env import STRIDE_ENV_IDS

from .folder import PolicyFolder

NAME = "stride"


RECOGNISED_BY = ("env_id", STRIDE_ENV_IDS)  # the env id its run config names


def load(folder: PolicyFolder, gait=None, force: bool = False):
    from ..stride_policy import load_stride_policy

    return load_stride_policy(folder.path, gait=gait, force=force)
