"""The kinds that need no run wrapper, and `load_apex_controller`, which loads them.

Built-in names and specs, adaptive and choice students and stride policies (in that order):
a controller wrapper (`agents.runtime.residual.ResidualOver`) loads its base controller from
here without reaching the step kinds that import it by name (no import circle).
"""

from __future__ import annotations

from pathlib import Path

import agents.runtime.kinds.adaptive as adaptive
import agents.runtime.kinds.builtin as builtin
import agents.runtime.kinds.choice as choice
import agents.runtime.kinds.stride as stride

from .folder import PolicyFolder, read_folder

APEX_KINDS = (builtin, adaptive, choice, stride)


def kind_of(folder: PolicyFolder, kinds=APEX_KINDS, wrapped=None):
    """The first kind of ``kinds`` whose ``RECOGNISED_BY`` rule ``folder`` meets
    (`PolicyFolder.meets`), or None; ``wrapped(section)`` decides the rule ``("wrapper",)``."""
    return folder.kind_in(kinds, wrapped)


def load_apex_controller(path: str | Path, gait: str | Path | None = None, force: bool = False):
    """The controller of a name, a classical spec ``.yaml``, a choice policy or a stride-level
    PPO policy; None for a step-level PPO policy (`agents.runtime.policy.load_controller` loads
    those). FileNotFoundError for a name or path that is neither; the loaders' ValueErrors."""
    folder = path if isinstance(path, PolicyFolder) else read_folder(path)
    kind = folder.kind_in(APEX_KINDS)
    return None if kind is None else kind.load(folder, gait, force)
