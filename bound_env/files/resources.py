"""Where the package's data lives: gait files, controller specs, the PPO configs, the
compiled-code cache.

The repository keeps ``configs/`` at its top level, where users look for it. An installed wheel
carries the same folder as package data, ``bound_env/configs/`` (``pyproject.toml`` maps it with
setuptools' ``package-dir``), and it is read with `importlib.resources`. A source checkout (an
editable install, or ``PYTHONPATH`` pointing at the repository) has no ``bound_env/configs/``
and reads the repository's own ``configs/``, so editing a gait file there takes effect at once.

This module imports nothing heavy (no numba, no Gymnasium): `bound_env/__init__.py` uses it to
choose the Numba cache location before any compiled module is imported.
"""

from __future__ import annotations

import copy
import functools
import os
import sys
from importlib import resources
from pathlib import Path

# The repository root when the package runs from a source checkout.
_SOURCE_ROOT = Path(__file__).resolve().parents[2]


def _as_path(traversable) -> Path:
    """A resource folder as a real path (pip installs packages unzipped, so it always is one)."""
    if isinstance(traversable, Path):
        return traversable
    raise RuntimeError(f"bound_env must be installed unzipped to read {traversable}")


def installed_configs() -> Path | None:
    """``bound_env/configs/`` shipped in a wheel, or None in a source checkout."""
    p = _as_path(resources.files("bound_env")) / "configs"
    return p if p.is_dir() else None


def is_installed() -> bool:
    """True for a non-editable install (the wheel's package data is present)."""
    return installed_configs() is not None


def configs_dir() -> Path:
    """The ``configs/`` folder: the wheel's package data, else the repository's."""
    return installed_configs() or _SOURCE_ROOT / "configs"


def gaits_dir() -> Path:
    """The folder of the named gait files (``paper``, ``default``, ...)."""
    return configs_dir() / "gaits"


def controllers_dir() -> Path:
    """The folder of the named controller specs (``lqr``, ``deadbeat``, ``damping``, ...)."""
    return configs_dir() / "controllers"


def user_cache_dir() -> Path:
    """The per-user cache folder of this platform (``~/.cache/bound_env`` on Linux)."""
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local"
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "bound_env"


def configure_numba_cache() -> str | None:
    """Send an installed package's compiled-code cache to the user cache; returns the folder.

    Numba's default writes ``*.nbi``/``*.nbc`` files into ``__pycache__`` beside the sources. In
    ``site-packages`` those files are not in the wheel's RECORD, so ``pip uninstall`` leaves
    them behind, and the leftover ``bound_env/`` folder then shadows a later editable install as
    an empty namespace package. An installed package therefore caches under
    ``user_cache_dir()/numba`` (Numba mirrors each source file's full path below it, and checks
    the source file's time stamp, so a reinstall recompiles). A source checkout keeps the cache
    beside its sources (ignored by git). A ``NUMBA_CACHE_DIR`` set by the user always wins.
    """
    if os.environ.get("NUMBA_CACHE_DIR") or not is_installed():
        return None
    folder = str(user_cache_dir() / "numba")
    os.environ["NUMBA_CACHE_DIR"] = folder  # read when numba is imported (and by subprocesses)
    numba = sys.modules.get("numba")
    if numba is not None:  # imported already: its config was read from the old environment
        numba.config.CACHE_DIR = folder
    return folder


def parse_yaml(text: str):
    """``yaml.safe_load(text)`` refusing a key twice (`bound_env.files.schema.yaml_load`), parsed
    once per distinct text: each call gets its own copy.

    Every environment, task and controller reads its gait file or spec, and pure-Python YAML
    took a tenth of the test suite's time; a changed file is new text, so it is parsed anew.
    Raises what ``yaml.safe_load`` raises (a key twice: a ``yaml.YAMLError`` naming it).
    """
    return copy.deepcopy(_parsed_yaml(text))


@functools.lru_cache(maxsize=64)
def _parsed_yaml(text: str):
    from .schema import yaml_load

    return yaml_load(text)
