"""What a ``--policy`` name or path is: the names API, importable from here as before.

The names, their resolution and the folder reader live in `agents.runtime.kinds.folder`;
`load_apex_controller` (names, specs, choice, adaptive and stride policies) in
`agents.runtime.kinds.apex`. Names come first (`CONTROLLERS`), then the shipped policies
(`shipped_policies`), then paths.
"""

from __future__ import annotations

from .kinds.apex import load_apex_controller  # noqa: F401
from .kinds.folder import (  # noqa: F401
    ARCHIVE_DIR,
    CONTROLLERS,
    SHIPPED_DIR,
    PolicyFolder,
    archived_message,
    classical_controller,
    policy_names,
    read_folder,
    register_controller,
    resolve_policy,
    shipped_names,
    shipped_policies,
    unwrapped_name,
    wrapped_policy,
)
