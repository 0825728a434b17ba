"""Kind "choice": a distilled or fine-tuned student, a folder with ``choice.npz``.

Recognised by `agents.common.schema.policy_kind` (a folder holding a ``model.zip`` too is
refused as ambiguous); checked and loaded by `agents.runtime.choice_policy`.
"""

from __future__ import annotations

from .folder import PolicyFolder

NAME = "choice"


RECOGNISED_BY = ("files", "choice")  # agents.common.schema.policy_kind of the folder


def load(folder: PolicyFolder, gait=None, force: bool = False):
    from ..choice_policy import load_choice_policy

    return load_choice_policy(folder.path, gait=gait, force=force)
