"""What decided a column's numbers (`column_fingerprint`), recorded in its ``margins.json``,
and the check that a recorded fingerprint is still what the code and data are (`stale_parts`).

A results page is true of the code and data that made it. Each column's result records, under
``fingerprint`` (``version`` 2), its checked parts (`CHECKED`, each a sha256 of 16 hex digits):

- the margins cache key's parts (`keys.setup_key`, recorded whole as ``margins_key``):
  ``sources``, every bound_env source (`keys.source_hash`: each file's code without its
  docstrings, `code_closure.code_text`); ``margins_settings``, the margins' settings
  (`keys.SETTINGS`); ``budget``, the budget, the seed and its sample seeds; ``gait``, the gait
  file's contents;
- the controller's code closure (`code_closure`): ``code`` and ``constants``, the definitions
  its objects' classes reach through imports within the project (bound_env and its sibling
  packages), per object, imports kept, docstrings and comments left out; its roots are
  recorded (``roots``), so that the check needs no controller loaded;
- its data: ``config``, the controller's data (`controller_data`: gains, weights, search
  settings, model parameters, and those of the controllers it holds), reals rounded to `DIGITS`
  significant digits, so that the last bits of a gain designed on another machine do not
  count; ``files``, the sha256 of the files that define it (its spec, a policy's weights and
  settings), given by the caller that resolved its name.

Beside them, a record, not checked: ``controller`` (its own exact ``fingerprint()``),
``settings`` (its ``settings()``, readable), ``commit`` and ``dirty`` (a tracked ``.py`` file
differed from the commit). An edited docstring or comment changes no part; any code or
constant edit in bound_env changes ``sources``, and in the controller's closure ``code`` or
``constants``; an edit of a module (or a class) the controller does not reach changes neither
part of its closure. A fingerprint of the first format (no ``version``: ``config``,
``constants`` and ``code`` of the controller's own modules, imports stripped) reads as stale.
tests/test_page_fingerprints.py runs the check on every column of the committed page.
"""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path

import numpy as np

from .code_closure import ROOT, code_parts

VERSION = 2  # the fingerprint's format (the first had no version)
# the parts `stale_parts` compares, and what each is (the check's message names it)
PARTS = {
    "sources": "bound_env's code (the margins cache key's source hash)",
    "margins_settings": "the margins settings (keys.SETTINGS)",
    "budget": "the budget and seed",
    "gait": "the gait file",
    "code": "the controller's code closure",
    "constants": "the constants of the controller's code closure",
    "config": "the controller's data (gains, weights, settings)",
    "files": "the controller's files (spec, weights)",
}
CHECKED = tuple(PARTS)
PASSIVE = "passive"  # no controller: zero torque
DIGITS = 8  # significant digits of a real in `controller_data`
# attributes that are not the data a controller acts on: its record or state of use, its label
# (``name``: a policy folder's path is spelled per checkout; its weights are data), and what
# it derived by finite differences from the model (an LQR's ``design``, the offset-free
# estimator's interval ``model`` and its preconditioner ``P_d``): their last digits, amplified
# by the difference, differ between a cold and a warm compiler cache. The code and constants
# that derive them are hashed in ``code`` and ``constants``.
RUNTIME = frozenset(
    {"decision_seconds", "decision_kinds", "searches", "given_up", "state", "name"}
    | {"design", "model", "P_d"}
)


def _real(x: float) -> str:
    return f"{x:.{DIGITS}g}"


def _data(v, depth: int):
    """``v`` as text for `controller_data` (reals rounded), or None if it is no data."""
    if isinstance(v, (bool, int, str, type(None))):
        return repr(v)
    if isinstance(v, (float, np.floating)):
        return _real(float(v))
    if isinstance(v, np.integer):
        return repr(int(v))
    if isinstance(v, np.ndarray):
        if v.dtype.kind in "biu":
            return f"int{v.shape}:" + hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()
        if v.dtype.kind == "f":
            text = ",".join(_real(x) for x in v.ravel().tolist())
            return f"real{v.shape}:" + hashlib.sha256(text.encode()).hexdigest()
        return None
    if isinstance(v, (list, tuple)):
        items = [_data(x, depth) for x in v]
        return None if any(i is None for i in items) else "[" + ",".join(items) + "]"
    if isinstance(v, dict):
        items = [(str(k), _data(x, depth)) for k, x in v.items()]
        kept = sorted((k, x) for k, x in items if x is not None)
        return "{" + ",".join(f"{k}:{x}" for k, x in kept) + "}"
    is_record = hasattr(v, "__dataclass_fields__") or callable(getattr(v, "fingerprint", None))
    if depth > 0 and is_record and not isinstance(v, type):
        return type(v).__name__ + _fields(v, depth - 1)
    return None


def _fields(obj, depth: int) -> str:
    items = []
    for k, v in sorted(getattr(obj, "__dict__", {}).items()):
        if k.startswith("_") or k in RUNTIME:
            continue
        text = _data(v, depth)
        if text is not None:
            items.append(f"{k}={text}")
    return "(" + ",".join(items) + ")"


def controller_data(controller) -> str:
    """The controller's data as text: its public attributes that are numbers, strings, arrays,
    lists and dicts of them, records (dataclasses) and the controllers it holds, three levels
    deep, reals to `DIGITS` significant digits; not its record of use (`RUNTIME`)."""
    return type(controller).__name__ + _fields(controller, 3)


def _sha(obj) -> str:
    return hashlib.sha256(repr(obj).encode()).hexdigest()[:16]


def git_commit(root: Path | None = None) -> tuple[str | None, bool | None]:
    """(commit, dirty) of the checkout that holds bound_env/ (dirty: a tracked ``.py`` file
    differs from the commit); (None, None) outside a git checkout or without git."""
    root = Path(root) if root is not None else ROOT
    if not (root / ".git").exists():
        return None, None
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        status = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "--", "*.py"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None, None
    return head or None, bool(status)


def margins_parts(gait="default", budget=None, seed=None, extra_sources=()) -> dict:
    """The parts of the margins cache key (`keys.setup_key`) that are not the controller's:
    ``sources``, ``margins_settings``, ``budget`` (None without a budget) and ``gait``."""
    from dataclasses import asdict

    from ....files.cache import settings_hash
    from ..budget import DEFAULT_SEED, as_budget, check_seed, sample_seeds
    from .keys import SETTINGS, gait_key, source_files, source_hash

    seed = DEFAULT_SEED if seed is None else check_seed(seed)
    run = None
    if budget is not None:
        run = {"budget": asdict(as_budget(budget)), "seed": seed, "samples": sample_seeds(seed)}
    return {
        "sources": source_hash(source_files(extra_sources)),
        "margins_settings": settings_hash(SETTINGS),
        "budget": None if run is None else settings_hash(run),
        "gait": gait_key(gait)["file_sha256"][:16],
    }


def _is_passive(controller) -> bool:
    return (
        controller is None
        or (isinstance(controller, str) and controller == PASSIVE)
        or getattr(controller, "fingerprint", None) is None
    )


def column_fingerprint(
    controller,
    commit: bool = True,
    gait="default",
    budget=None,
    seed=None,
    extra_sources=(),
    files: str | None = None,
) -> dict:
    """What decides ``controller``'s numbers (module docstring) on ``gait`` with ``budget``
    and ``seed`` (no budget: ``budget`` and ``margins_key`` are None); ``None`` or
    ``"passive"`` is the passive gait. ``files``: the sha256 of the controller's files, from
    the caller that resolved its name (None: not known). ``commit=False`` leaves the commit
    out (a comparison needs none)."""
    from .code_closure import object_roots

    fp: dict = {"version": VERSION}
    if _is_passive(controller):
        fp.update(controller=PASSIVE, settings=None, config=PASSIVE, **code_parts([]))
    else:
        settings = getattr(controller, "settings", None)
        settings = settings() if callable(settings) else None
        fp.update(
            controller=str(controller.fingerprint()),
            settings={str(k): _jsonable(v) for k, v in settings.items()} if settings else None,
            config=_sha(controller_data(controller)),
            **code_parts(object_roots(controller)),
        )
    fp["files"] = files
    fp.update(margins_parts(gait, budget, seed, extra_sources))
    fp["margins_key"] = None
    if budget is not None and not _is_passive(controller):
        from ..budget import DEFAULT_SEED, as_budget
        from .keys import setup_key

        seed = DEFAULT_SEED if seed is None else seed
        fp["margins_key"] = setup_key(controller, gait, as_budget(budget), seed, extra_sources)
    if commit:
        fp["commit"], fp["dirty"] = git_commit()
    return fp


def recorded_parts(
    recorded: dict,
    gait="default",
    budget=None,
    seed=None,
    extra_sources=(),
    files: str | None = None,
) -> dict:
    """The checked parts as they are now for a recorded fingerprint, without loading its
    controller: the margins parts, the closure of its recorded ``roots`` and ``files``
    (``config`` is None: only a loaded controller has it)."""
    roots = recorded.get("roots") if isinstance(recorded, dict) else None
    now = {"config": None, "files": files}
    now.update(margins_parts(gait, budget, seed, extra_sources))
    if isinstance(roots, list):
        now.update(code_parts(roots))
    return now


def _jsonable(v):
    if isinstance(v, (bool, int, float, str, type(None))):
        return v
    if isinstance(v, np.generic):
        return v.item()
    return repr(v)


def stale_parts(recorded: dict | None, now) -> list[str]:
    """The parts of `CHECKED` in which ``recorded`` (a column's ``fingerprint``) differs from
    ``now`` (a fingerprint as `column_fingerprint` or `recorded_parts` make it now, or a
    controller: its `column_fingerprint` without a budget); a part that ``now`` cannot know
    (None) is not compared. Every part when nothing was recorded."""
    if not isinstance(recorded, dict):
        return list(CHECKED)
    if not isinstance(now, dict):
        now = column_fingerprint(now, commit=False)
    return [k for k in CHECKED if now.get(k) is not None and recorded.get(k) != now[k]]


def differing(recorded, now: dict) -> list[str]:
    """The keys of ``now`` (a row's fingerprint: `run_fingerprint`) whose value ``recorded``
    does not have; every key when nothing was recorded."""
    if not isinstance(recorded, dict):
        return sorted(now)
    return sorted(k for k, v in now.items() if recorded.get(k) != v)


def run_fingerprint(
    controller, gait="default", files: str | None = None, roots=(), **inputs
) -> dict:
    """The fingerprint of one row of a resumable script (a hold count, a factor estimate):
    bound_env's ``sources``, the controller's closure (and that of ``roots``, ``module:Name``:
    code the script runs besides the controller) and data (``config``, ``files``), the
    ``gait`` file and the row's ``inputs`` (a spec's contents, the strides, the robots: one
    hash, ``inputs``). A resumed row is reused only under the same one (`differing`)."""
    from ....files.cache import settings_hash
    from .code_closure import object_roots

    fp = column_fingerprint(controller, commit=False, gait=gait, files=files)
    own = object_roots(controller) if not _is_passive(controller) else []
    fp.update(code_parts(set(own) | {str(r) for r in roots}))
    keep = ("version", "sources", "gait", "code", "constants", "roots", "config", "files")
    out = {k: fp[k] for k in keep}
    out["inputs"] = settings_hash(inputs)
    return out
