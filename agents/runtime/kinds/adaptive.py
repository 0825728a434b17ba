"""Kind "adaptive": a learned adaptive controller, a folder with ``adaptive.npz``.

Checked (fingerprint, arrays, gait) and loaded by `agents.runtime.adaptive_policy`.
"""

from __future__ import annotations

from .folder import PolicyFolder

NAME = "adaptive"
POLICY_FILE = "adaptive.npz"


RECOGNISED_BY = ("file", POLICY_FILE)  # a folder holding it


def load(folder: PolicyFolder, gait=None, force: bool = False):
    from ..adaptive_policy import load_adaptive_policy

    return load_adaptive_policy(folder.path, gait=gait, force=force)
