"""What decided a column's numbers (`column_fingerprint`), recorded in its ``margins.json``.

A results page is true of the code that made it. Each column's result records, under
``fingerprint``:

- ``config``: a hash of the controller's data (`controller_data`: gains, weights, search
  settings, model parameters, and those of the controllers it holds), its reals rounded to
  `DIGITS` significant digits, so that the last bits of a gain designed on one machine (or
  with a cold compiler cache) do not count; ``settings``: its ``settings()`` where it has
  them (readable); ``controller``: its own ``fingerprint()`` (the margins' cache key, exact);
- ``constants``: a hash of the planning constants, the module-level UPPER_CASE values of every
  module that defines the controller's classes and those of the controllers it holds (an
  MPC's LQR, a wrapper's inner controller, a residual's base), read when the column is made;
- ``code``: a hash of those modules' code (their syntax tree without docstrings and imports,
  so an edited docstring or comment, or a module moved to another package, changes nothing);
- ``commit``: the checkout's git commit (``dirty``: a tracked ``.py`` file differed from it).

`stale_parts` compares a recorded fingerprint with a controller as it is now: the parts that
differ (``config``, ``constants``, ``code``; the exact ``controller`` and the commit are a
record, not a check).
tests/test_page_fingerprints.py runs it on every column of the committed page.
"""

from __future__ import annotations

import ast
import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np

CHECKED = ("config", "constants", "code")  # the parts `stale_parts` compares
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


def _held(controller, depth: int = 3) -> list:
    """The controller and every controller it holds (attributes with ``fingerprint()``)."""
    out, todo = [], [(controller, 0)]
    while todo:
        c, d = todo.pop(0)
        if any(c is o for o in out):
            continue
        out.append(c)
        if d < depth:
            for v in getattr(c, "__dict__", {}).values():
                if callable(getattr(v, "fingerprint", None)) and not isinstance(v, type):
                    todo.append((v, d + 1))
    return out


def controller_modules(controller) -> list:
    """The modules whose code decides ``controller``'s actions: those of its classes (and
    their bases') and of the controllers it holds, in a stable order."""
    names = []
    for c in _held(controller):
        for cls in type(c).__mro__:
            m = cls.__module__
            if m != "builtins" and m not in names and m in sys.modules:
                names.append(m)
    return [sys.modules[m] for m in sorted(names)]


def _constant(value):
    """A constant's value as hashable text, or None if it is no planning constant."""
    if isinstance(value, (bool, int, float, str, bytes, type(None))):
        return repr(value)
    if isinstance(value, np.ndarray) and value.dtype != object:
        return f"array{value.shape}{value.dtype}:" + hashlib.sha256(value.tobytes()).hexdigest()
    if isinstance(value, (tuple, list, frozenset)):
        items = [
            _constant(v)
            for v in (sorted(value, key=repr) if isinstance(value, frozenset) else value)
        ]
        return (
            None if any(i is None for i in items) else f"{type(value).__name__}({','.join(items)})"
        )
    if isinstance(value, dict):
        items = [(repr(k), _constant(v)) for k, v in value.items()]
        if any(v is None for _, v in items):
            return None
        return "dict(" + ",".join(f"{k}:{v}" for k, v in sorted(items)) + ")"
    return None


def planning_constants(controller) -> dict:
    """{module.NAME: value text} of the UPPER_CASE module constants of `controller_modules`."""
    out = {}
    for mod in controller_modules(controller):
        for name, value in sorted(vars(mod).items()):
            if name.isupper() and not name.startswith("_"):
                text = _constant(value)
                if text is not None:
                    out[f"{mod.__name__.rsplit('.', 1)[-1]}.{name}"] = text
    return out


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


def _code_tree(source: str) -> str:
    """The module's syntax tree without docstrings and imports, as text."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if not isinstance(body, list):
            continue
        body[:] = [
            n
            for n in body
            if not isinstance(n, (ast.Import, ast.ImportFrom))
            and not (
                isinstance(n, ast.Expr)
                and isinstance(getattr(n, "value", None), ast.Constant)
                and isinstance(n.value.value, str)
            )
        ] or [ast.Pass()]
    return ast.dump(tree, annotate_fields=False, include_attributes=False)


def code_hash(controller) -> str:
    """sha256 (16 hex digits) of the code of `controller_modules` (`_code_tree`)."""
    h = hashlib.sha256()
    for mod in controller_modules(controller):
        path = getattr(mod, "__file__", None)
        if not path or not Path(path).is_file():
            continue
        h.update(mod.__name__.rsplit(".", 1)[-1].encode() + b"\0")
        h.update(_code_tree(Path(path).read_text()).encode())
    return h.hexdigest()[:16]


def _sha(obj) -> str:
    return hashlib.sha256(repr(obj).encode()).hexdigest()[:16]


def git_commit(root: Path | None = None) -> tuple[str | None, bool | None]:
    """(commit, dirty) of the checkout that holds bound_env/ (dirty: a tracked ``.py`` file
    differs from the commit); (None, None) outside a git checkout or without git."""
    root = Path(root) if root is not None else Path(__file__).resolve().parents[3]
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


def column_fingerprint(controller, commit: bool = True) -> dict:
    """What decides ``controller``'s numbers (module docstring); ``None`` or ``"passive"``
    is the passive gait. ``commit=False`` leaves the commit out (a comparison needs none)."""
    if (
        controller is None
        or controller == PASSIVE
        or getattr(controller, "fingerprint", None) is None
    ):
        fp = {"controller": PASSIVE, "settings": None}
        fp.update(dict.fromkeys(CHECKED, PASSIVE))
    else:
        settings = getattr(controller, "settings", None)
        settings = settings() if callable(settings) else None
        fp = {
            "controller": str(controller.fingerprint()),
            "settings": {str(k): _jsonable(v) for k, v in settings.items()} if settings else None,
            "config": _sha(controller_data(controller)),
            "constants": _sha(sorted(planning_constants(controller).items())),
            "code": code_hash(controller),
        }
    if commit:
        fp["commit"], fp["dirty"] = git_commit()
    return fp


def _jsonable(v):
    if isinstance(v, (bool, int, float, str, type(None))):
        return v
    if isinstance(v, np.generic):
        return v.item()
    return repr(v)


def stale_parts(recorded: dict | None, controller) -> list[str]:
    """The parts of `CHECKED` in which ``recorded`` (a column's ``fingerprint``) differs from
    ``controller`` as it is now; every part when nothing was recorded."""
    if not isinstance(recorded, dict):
        return list(CHECKED)
    now = column_fingerprint(controller, commit=False)
    return [k for k in CHECKED if recorded.get(k) != now[k]]
