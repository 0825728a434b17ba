"""Field checkers for the files a user can hand us (policy folders, controller specs).

Each checker takes the value and ``where``, the file and the field it came from
(``"policies/x/config.json: expert.settings.safe"``), and returns the value in its checked
type, or raises a one-line ValueError that starts with ``where``. The schema of each kind of
file lives in one place and is written with these: controller specs in
`bound_env.control.spec`, the policy folders in `agents.common.schema`.

Strings are never read as numbers (``horizon: "12"`` is an error, not 12), booleans are never
read as integers, and numbers must be finite.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np

# control interval dt [s] a file may set: below MIN_DT a stride needs more than ~4000
# intervals (dt = 1e-7 ran until it was killed); above MAX_DT a stride holds fewer than 4
MIN_DT, MAX_DT = 1e-4, 0.1
MAX_JSON_BYTES = 10 * 2**20  # a policy's config.json is a few kB
MAX_JSON_DEPTH = 32  # nesting of a JSON file (the policies' files nest 4 deep)


def integer(value, where: str, lo: int | None = None, hi: int | None = None) -> int:
    """An integer (not a bool, a float or a string) in [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{where} must be an integer{_range(lo, hi)}, got {_show(value)}")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ValueError(f"{where} must be an integer{_range(lo, hi)}, got {v}")
    return v


def boolean(value, where: str, numpy: bool = True) -> bool:
    """True or false: a bool (or, with ``numpy``, NumPy's), never 0, 1 or a string."""
    if not isinstance(value, (bool, np.bool_) if numpy else bool):
        raise ValueError(f"{where} must be true or false, got {value!r}")
    return bool(value)


def limited(value, where: str, lo, hi, lo_open: bool = False, text: bool = True):
    """A setting within its limits ``(lo, hi)`` (a settings table's entry): true or false for
    ``(False, True)``; an `integer` in [lo, hi] for an integer ``lo``; else a finite `real` in
    [lo, hi] (``lo_open``: in (lo, hi]), where with ``text`` a string that spells a number is
    read as it (PyYAML reads ``1e-8``, without a dot, as a string)."""
    if isinstance(lo, bool):
        return boolean(value, where, numpy=False)
    if isinstance(lo, (int, np.integer)):
        return integer(value, where, lo, hi)
    if text and isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise ValueError(f"{where} must be a number, got {value!r}") from None
    return real(value, where, lo, hi, lo_open)


def real(
    value,
    where: str,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
) -> float:
    """A finite real number (an int or a float, not a bool or a string) in [lo, hi] (``lo_open``:
    in (lo, hi])."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{where} must be a number{_range(lo, hi, lo_open)}, got {_show(value)}")
    v = float(value)
    bad = not math.isfinite(v)
    bad = bad or (lo is not None and (v < lo or (lo_open and v == lo)))
    bad = bad or (hi is not None and v > hi)
    if bad:
        raise ValueError(f"{where} must be a finite number{_range(lo, hi, lo_open)}, got {v!r}")
    return v


def dt_value(value, where: str) -> float:
    """A control interval [s] in [MIN_DT, MAX_DT] (bounded work per stride)."""
    return real(value, where, MIN_DT, MAX_DT)


def text(value, where: str, choices=None) -> str:
    if not isinstance(value, str):
        raise ValueError(f"{where} must be a string, got {_show(value)}")
    if choices is not None and value not in choices:
        raise ValueError(f"{where} must be one of {', '.join(map(str, choices))}, got {value!r}")
    return value


def mapping(value, where: str, required=(), allowed=None) -> dict:
    """A dict with string keys holding every key of ``required`` (and, if ``allowed`` is given,
    no other)."""
    if not isinstance(value, dict):
        raise ValueError(f"{where} must be a mapping, got {_show(value)}")
    for key in required:
        if key not in value:
            raise ValueError(f"{where}: missing key {key!r}")
    if allowed is not None:
        for key in value:
            if key not in allowed:
                raise ValueError(f"{where}: unknown key {key!r} (allowed: {', '.join(allowed)})")
    return value


def settings_block(
    value, path, block: str, defaults: dict, check_one, aliases: dict | None = None
) -> dict | None:
    """A spec's settings block ``block``: ``true`` (the defaults), ``false`` (None) or a mapping
    of some of ``defaults``' keys, each value checked by ``check_one(key, value, where)``
    (``where`` = ``"{path}: {block}.{key}"``, with the key as the user spelled it), over the
    defaults. ``aliases`` maps another spelling to its key (both in one block are refused).
    A one-line ValueError names ``path``, the block and the key."""
    if value is True:
        return dict(defaults)
    if value is False:
        return None
    if not isinstance(value, dict):
        raise ValueError(
            f"{path}: {block} must be true or a mapping of {', '.join(defaults)}, got {value!r}"
        )
    aliases = aliases or {}
    out = dict(defaults)
    for key, v in value.items():
        real = aliases.get(key, key)
        if real not in defaults:
            allowed = ", ".join([*defaults, *(f"{a} (= {k})" for a, k in aliases.items())])
            raise ValueError(f"{path}: unknown key {key!r} in {block} (allowed: {allowed})")
        if real != key and real in value:
            raise ValueError(f"{path}: {block}.{key} and {block}.{real} are one setting; give one")
        out[real] = check_one(real, v, f"{path}: {block}.{key}")
    return out


def real_array(
    value,
    where: str,
    shape: tuple | None = None,
    ndim: int | None = None,
    max_size: int = 10**7,
    lo: float | None = None,
    hi: float | None = None,
) -> np.ndarray:
    """A float64 array of real, finite numbers (ints and floats; not complex, strings, objects
    or bools), of ``shape`` (None entries: any length) or ``ndim``, in [lo, hi]."""
    if isinstance(value, np.ndarray):
        raw = value
    else:
        try:
            raw = np.asarray(value)
        except (TypeError, ValueError):  # ragged nested lists
            raise ValueError(f"{where} must be an array of numbers, got {_show(value)}") from None
    if raw.dtype.kind not in "iuf":
        raise ValueError(f"{where} must hold real numbers, got dtype {raw.dtype}")
    if shape is not None:
        ok = raw.ndim == len(shape) and all(
            n is None or n == m for n, m in zip(shape, raw.shape, strict=True)
        )
        if not ok:
            want = "(" + ", ".join("n" if n is None else str(n) for n in shape) + ")"
            raise ValueError(f"{where} must have shape {want}, got {raw.shape}")
    elif ndim is not None and raw.ndim != ndim:
        raise ValueError(f"{where} must be {ndim}-D, got shape {raw.shape}")
    if raw.size > max_size or raw.size == 0:
        raise ValueError(f"{where} must hold 1 to {max_size} numbers, got {raw.size}")
    a = raw.astype(np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{where} must be finite (no NaN or inf)")
    if (lo is not None and a.min() < lo) or (hi is not None and a.max() > hi):
        got = f"[{float(a.min())!r}, {float(a.max())!r}]"
        raise ValueError(f"{where} must lie in [{lo}, {hi}], got {got}")
    return a


def yaml_load(text: str):
    """``yaml.safe_load`` of ``text``, except that a mapping with a key twice is refused
    (a ``yaml.YAMLError`` naming the key and its line, as a parse error is): PyYAML keeps the
    last one silently, so ``params: {m1: 0.1}`` then ``params: {m2: 0.2}`` would drop m1."""
    import yaml

    class _Unique(yaml.SafeLoader):
        pass

    def mapping(loader, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = loader.construct_object(key_node, deep=deep)
            try:
                twice = key in seen
                seen.add(key)
            except TypeError:  # an unhashable key: safe_load's own error follows
                continue
            if twice:
                raise yaml.constructor.ConstructorError(
                    None, None, f"found duplicate key {key!r}", key_node.start_mark
                )
        return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)

    _Unique.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    return yaml.load(text, Loader=_Unique)  # noqa: S506 - a SafeLoader subclass


def yaml_error(e) -> str:
    """One line for a ``yaml.YAMLError``: its problem and line (``duplicate key 'params' at
    line 2``)."""
    mark = getattr(e, "problem_mark", None)
    at = f" at line {mark.line + 1}" if mark is not None else ""
    problem = getattr(e, "problem", None) or type(e).__name__
    return f"{problem}{at}"


def read_yaml(path, what: str = "YAML file"):
    """A YAML file's value (`yaml_load`: no key twice); a one-line ValueError naming the file
    (``{what} {path}: ...``) for a missing file, a folder, a non-UTF-8 file or invalid YAML."""
    import yaml

    p = Path(path)
    try:
        if p.is_dir():
            raise ValueError(f"{what} {p} is a folder, not a file")
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"{what} {p} does not exist") from None
    except UnicodeDecodeError:
        raise ValueError(f"{what} {p}: not a text (UTF-8) file") from None
    except (OSError, ValueError) as e:  # a name the OS refuses (too long, a NUL byte) too
        if isinstance(e, ValueError) and str(e).startswith(what):
            raise
        why = getattr(e, "strerror", None) or type(e).__name__
        raise ValueError(f"{what} {p}: cannot read it ({why})") from None
    try:
        return yaml_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"{what} {p}: not valid YAML ({yaml_error(e)})") from None
    except RecursionError:
        raise ValueError(f"{what} {p}: nested too deeply") from None


def regular_file(path, what: str = "file") -> Path:
    """``path`` if it is a non-empty regular file; a folder, a missing or an empty file is an
    error naming it."""
    p = Path(path)
    if not p.exists():
        raise ValueError(f"{p}: missing ({what})")
    if not p.is_file():
        raise ValueError(f"{p}: not a file ({what})")
    if p.stat().st_size == 0:
        raise ValueError(f"{p}: empty file ({what})")
    return p


def read_json(
    path, max_bytes: int = MAX_JSON_BYTES, max_depth: int = MAX_JSON_DEPTH, strict: bool = False
):
    """A JSON file's value: a regular file of at most ``max_bytes``, nested at most
    ``max_depth`` deep; ValueError naming the file otherwise. ``strict``: strict JSON, so
    ``NaN``, ``Infinity`` and ``-Infinity`` (which Python's json writes by default) are
    refused too."""
    p = regular_file(path, "a JSON file")
    if p.stat().st_size > max_bytes:
        raise ValueError(f"{p}: larger than {max_bytes} bytes, not a policy's JSON file")

    try:
        data = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{p}: not a readable JSON file ({str(e).splitlines()[0]})") from None
    except RecursionError:
        raise ValueError(f"{p}: nested deeper than {max_depth} levels") from None
    if depth(data, max_depth + 1) > max_depth:
        raise ValueError(f"{p}: nested deeper than {max_depth} levels")
    if strict:
        bad = nonfinite_path(data)
        if bad is not None:
            raise ValueError(
                f"{p}: {bad[0]} is {bad[1]}, which is not strict JSON (a number went non-finite)"
            )
    return data


def nonfinite_path(value, path: str = ""):
    """(path, token) of the first NaN or infinite number in a JSON value (``rows[2].r50.value``,
    ``"NaN"``), or None."""
    stack = [(value, path)]
    while stack:
        v, at = stack.pop()
        if isinstance(v, float) and not math.isfinite(v):
            return at or ".", "NaN" if math.isnan(v) else ("Infinity" if v > 0 else "-Infinity")
        if isinstance(v, dict):
            stack.extend((x, f"{at}.{k}" if at else str(k)) for k, x in reversed(v.items()))
        elif isinstance(v, list):
            stack.extend((x, f"{at}[{i}]") for i, x in reversed(list(enumerate(v))))
    return None


def load_json_strict(path, required: dict | None = None, max_bytes: int = MAX_JSON_BYTES):
    """A strict JSON file (`read_json` with ``strict``: no NaN or Infinity) holding a mapping
    with every key of ``required``, checked by type: ``{key: type, a tuple of types, or a dict
    (a mapping checked the same way)}``; ``float`` accepts an int (not a bool) and must be
    finite, ``None`` in a tuple allows null. A one-line ValueError naming the file and the key
    (``rows``, ``r50.value``) otherwise. For example:

    ```python
    head = load_json_strict("docs/headline.json", {"budget": str, "seed": int, "rows": list})
    ```
    """
    data = read_json(path, max_bytes=max_bytes, strict=True)
    return check_keys(data, required or {}, str(path))


def check_keys(value, required: dict, where: str, prefix: str = "") -> dict:
    """``value`` if it is a mapping holding every key of ``required`` with the type given
    there (`load_json_strict`'s convention); ValueError ``"{where}: {key} ..."`` otherwise."""
    if not isinstance(value, dict):
        name = prefix[:-1] if prefix else "the file"
        raise ValueError(f"{where}: {name} must be a mapping, got {_show(value)}")
    for key, want in required.items():
        name = f"{prefix}{key}"
        if key not in value:
            raise ValueError(f"{where}: {name}: missing")
        v = value[key]
        if isinstance(want, dict):
            check_keys(v, want, where, f"{name}.")
            continue
        kinds = want if isinstance(want, tuple) else (want,)
        nullable = None in kinds
        if v is None and nullable:
            continue
        kinds = tuple(k for k in kinds if k is not None)
        if float in kinds and not isinstance(v, bool) and isinstance(v, (int, float)):
            real(v, f"{where}: {name}")  # finite
            continue
        if (isinstance(v, bool) and bool not in kinds) or not isinstance(v, kinds):
            names = " or ".join(k.__name__ for k in kinds) + (" or null" if nullable else "")
            raise ValueError(f"{where}: {name} must be {names}, got {_show(v)}")
    return value


def depth(value, limit: int) -> int:
    """The nesting depth of a JSON value (a scalar: 0), counted up to ``limit``."""
    best, stack = 0, [(value, 0)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, (dict, list)):
            if d + 1 > best:
                best = d + 1
                if best >= limit:
                    return best
            stack.extend((x, d + 1) for x in (v.values() if isinstance(v, dict) else v))
    return best


def read_npz(path, max_arrays: int = 256) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` file (no pickled objects); ValueError naming the file."""
    p = regular_file(path, "an .npz file")
    try:
        with np.load(p, allow_pickle=False) as d:
            if len(d.files) > max_arrays:
                raise ValueError(f"{p}: more than {max_arrays} arrays")
            return {k: d[k] for k in d.files}
    except (zipfile.BadZipFile, OSError, EOFError, KeyError) as e:
        raise ValueError(f"{p}: not a readable .npz file ({type(e).__name__})") from None
    except ValueError as e:
        if str(e).startswith(str(p)):
            raise
        raise ValueError(f"{p}: not a readable .npz file ({str(e).splitlines()[0]})") from None


def _range(lo, hi, lo_open: bool = False) -> str:
    if lo is None and hi is None:
        return ""
    if hi is None:
        return f" {'>' if lo_open else '>='} {lo:g}"
    if lo is None:
        return f" <= {hi:g}"
    return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}]"


def _show(value) -> str:
    s = repr(value)
    s = s if len(s) <= 60 else s[:57] + "..."
    return f"{s} ({type(value).__name__})"
