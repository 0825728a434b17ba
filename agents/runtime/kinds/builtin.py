"""Kind "builtin": a built-in controller's name (`CONTROLLERS`) or a classical spec ``.yaml``.

Recognised by the resolved path being a name (a str) or the given one ending in ``.yaml`` /
``.yml``; checked and built by `bound_env.control` (a spec) or the name's factory.
"""

from __future__ import annotations

from pathlib import Path

from .folder import CONTROLLERS, PolicyFolder, classical_controller

NAME = "builtin"


RECOGNISED_BY = ("name",)  # the resolved path is a name (or the spec file as given)


def load(folder: PolicyFolder, gait=None, force: bool = False):
    if Path(folder.path).suffix in (".yaml", ".yml"):  # a spec file
        return classical_controller(folder.path, gait)
    return CONTROLLERS[folder.path][0](gait=gait)
