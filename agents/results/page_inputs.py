"""What the results page reads back under ``compare --render-only``, checked before it is used.

``--render-only`` rewrites the page from files an earlier run left: each column's
``margins.json`` (`load_result`, with `check_margins_result`), each Model error section
column's (`load_model_error`) and the decision times of the old ``paired.json``
(`read_decision_times`); ``python -m agents.results.headline`` reads ``headline.json``
(`agents.results.headline.load_headline`, with `check_fields`). A file that lacks a key the page
uses, or holds it with the wrong type, is a ValueError of one line naming the file and the key
(e.g. ``out/margins/lqr/margins.json: basin.th1.+.rel: missing``), never a KeyError,
TypeError or AttributeError from deep inside the renderer.

A check is a list of (path, kind) pairs: a path is a tuple of keys (``"*"``: every value of a
mapping or item of a list), a kind one of `KINDS`; a kind ending in ``?`` may also be null or
absent, ``num|null`` must be there but may be null.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from bound_env.analysis.margins import DEFAULT_SEED, Z_LABELS
from bound_env.files.schema import check_keys, read_json


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_finite(v) -> bool:
    return _is_num(v) and math.isfinite(v)


KINDS = {
    "num": lambda v: _is_num(v),
    "finite": lambda v: _is_finite(v),  # a measure the page prints with its interval
    "num|null": lambda v: v is None or _is_num(v),
    "str|null": lambda v: v is None or isinstance(v, str),
    "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "str": lambda v: isinstance(v, str),
    "bool": lambda v: isinstance(v, bool),
    "map": lambda v: isinstance(v, dict),
    "list": lambda v: isinstance(v, list),
    "nums": lambda v: isinstance(v, list) and all(_is_num(x) or x is None for x in v),
    "pair": lambda v: (
        isinstance(v, list) and len(v) == 2 and all(_is_num(x) or x is None for x in v)
    ),
    "finite pair": lambda v: (
        isinstance(v, list) and len(v) == 2 and all(_is_finite(x) or x is None for x in v)
    ),
}
NAMES = {
    "num": "a number",
    "num|null": "a number or null",
    "str|null": "a string or null",
    "int": "an integer",
    "str": "a string",
    "bool": "true or false",
    "map": "a JSON object",
    "list": "a list",
    "nums": "a list of numbers",
    "pair": "a list of two numbers",
    "finite": "a finite number",
    "finite pair": "a list of two finite numbers (or nulls)",
}

_SIGNS = ("+", "-")
# What the page, its plots and its headline read of one column's margins.json
MARGINS_FIELDS = [
    (("policy",), "str"),
    (("basin_curve",), "map"),
    *[(("basin_curve", k), "nums") for k in ("sizes", "success", "ci_low", "ci_high")],
    # r50 is never NaN (`crossing_on_grid`): a NaN or inf one is a damaged file, not "—"
    (("basin_curve", "r50"), "finite?"),
    (("basin_curve", "r50_ci"), "finite pair?"),
    (("basin_curve", "directions"), "int"),
    (("basin_curve", "outcomes"), "list?"),
    (("settings",), "map"),
    *[(("settings", k), "num") for k in ("rtol", "return_tol", "basin_strides", "basin_iters")],
    (("settings", "push_samples"), "num"),
    (("settings", "ceiling"), "map?"),
    (("settings", "basin_cap"), "num?"),
    (("basin",), "map"),
    *[(("basin", c, s), "map") for c in Z_LABELS for s in _SIGNS],
    *[(("basin", c, s, "rel"), "num") for c in Z_LABELS for s in _SIGNS],
    *[(("basin", c, s, "beyond"), "map?") for c in Z_LABELS for s in _SIGNS],
    (("basin_ceiling",), "map"),
    (("basin_ceiling", "*"), "map"),
    *[(("basin_ceiling", c, s), "map?") for c in Z_LABELS for s in _SIGNS],
    *[(("basin_ceiling", c, s, "rel"), "num?") for c in Z_LABELS for s in _SIGNS],
    *[(("basin_ceiling", c, s, "beyond"), "map?") for c in Z_LABELS for s in _SIGNS],
    (("basin_min",), "num?"),
    (("basin_min_direction",), "str|null"),
    (("terrain",), "map"),
    *[(("terrain", k), "nums") for k in ("sigmas_deg", "survival", "ci_low", "ci_high")],
    (("terrain_sigma50_ci_deg",), "pair?"),
    (("push",), "map"),
    *[(("push", k), "map") for k in ("xdot", "th1dot")],
    *[(("push", k, f), "nums") for k in ("xdot", "th1dot") for f in ("sizes", "success")],
    (("mfpt",), "list?"),
    (("mfpt", "*"), "map"),
    (("mfpt", "*", "sigma_deg"), "num"),
    (("mfpt", "*", "mfpt"), "num?"),
    (("mfpt", "*", "lower_bound"), "bool"),
    (("mfpt", "*", "ci"), "pair"),
    (("mfpt_settings",), "map?"),
    (("mfpt_settings", "sigmas_deg"), "nums?"),
    (("mfpt_settings", "seeds"), "list?"),
    (("terrain", "seeds"), "list?"),
    (("slope_nominal_deg",), "num"),
    (("kc_nominal",), "num"),
    (("decision_shares",), "map?"),
    *[(("decision_shares", w), "map?") for w in ("curve", "terrain")],
    *[
        (("decision_shares", w, k), "num")
        for w in ("curve", "terrain")
        for k in ("gate", "lqr", "override", "n")
    ],
]
# Lists the plots draw against each other: the same length
SAME_LENGTH = [
    ("basin_curve", ("sizes", "success", "ci_low", "ci_high")),
    ("terrain", ("sigmas_deg", "survival", "ci_low", "ci_high")),
]
# The decision times of paired.json, as the page's last section reads them
TIMES_FIELDS = [
    (("decision_times", "states"), "int"),
    (("decision_times", "measured_on"), "str"),
    (("decision_times", "load_average_before"), "nums?"),
    (("decision_times", "controllers"), "map"),
    (("decision_times", "controllers", "*"), "map"),
    *[(("decision_times", "controllers", "*", k), "num") for k in ("p50", "p99", "mean", "max")],
]


def _found(value, keys):
    """(dotted path, value) for every match of ``keys`` in ``value`` (``*``: every item);
    a missing key yields (path, `_MISSING`)."""
    todo = [((), value)]
    for key in keys:
        nxt = []
        for path, v in todo:
            if key == "*":
                items = (
                    v.items()
                    if isinstance(v, dict)
                    else enumerate(v)
                    if isinstance(v, list)
                    else ()
                )
                nxt += [((*path, str(k)), x) for k, x in items]
            elif isinstance(v, dict):
                nxt.append(((*path, key), v.get(key, _MISSING)))
            else:  # its parent was checked (or is optional and absent)
                continue
        todo = nxt
    return [(".".join(p), v) for p, v in todo]


_MISSING = object()


def check_fields(data, fields, where) -> None:
    """ValueError ``where: key: what is wrong`` for the first field of ``fields`` that
    ``data`` lacks or holds with the wrong type (see the module's docstring)."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: not a JSON object (got {type(data).__name__})")
    for keys, kind in fields:
        optional = kind.endswith("?")
        check = KINDS[kind.rstrip("?")]
        for path, v in _found(data, keys):
            if v is None and kind.endswith("|null"):
                continue
            if v is _MISSING or v is None:
                if optional:
                    continue
                raise ValueError(f"{where}: {path}: " + ("missing" if v is _MISSING else "null"))
            if not check(v):
                raise ValueError(
                    f"{where}: {path}: must be {NAMES[kind.rstrip('?')]}, got {_show(v)}"
                )


def _show(v) -> str:
    text = json.dumps(v) if not isinstance(v, str) else repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def check_mismatch_blocks(r, where) -> None:
    """The model-error blocks of a margins result (``mismatch.SPEC``), as the page's tables
    read them: each a JSON object with ``spec.name`` and ``hold`` (``k`` of ``n`` plants held:
    integers, 0 <= k <= n, ``outcomes`` n of them); one line naming the key otherwise."""
    mm = r.get("mismatch")
    if mm is None:
        return
    if not isinstance(mm, dict):
        raise ValueError(f"{where}: mismatch: must be a JSON object, got {_show(mm)}")
    for name, b in mm.items():
        key = f"mismatch.{name}"
        check_fields(
            b,
            [(("spec",), "map"), (("spec", "name"), "str"), (("hold",), "map")],
            f"{where}: {key}",
        )
        h = b["hold"]
        check_fields(
            h, [(("k",), "int"), (("n",), "int"), (("outcomes",), "list?")], f"{where}: {key}.hold"
        )
        if not 0 <= h["k"] <= h["n"]:
            raise ValueError(f"{where}: {key}.hold: k {h['k']} of n {h['n']} plants (0 <= k <= n)")
        if "outcomes" in h and len(h["outcomes"]) != h["n"]:
            raise ValueError(
                f"{where}: {key}.hold.outcomes: {len(h['outcomes'])} outcomes for n {h['n']}"
            )


def check_margins_result(r, where) -> dict:
    """``r`` (one column's ``margins.json``) if it holds every key the page reads."""
    check_fields(r, MARGINS_FIELDS, where)
    check_mismatch_blocks(r, where)
    for parent, keys in SAME_LENGTH:
        lengths = {k: len(r[parent][k]) for k in keys}
        if len(set(lengths.values())) > 1:
            raise ValueError(
                f"{where}: {parent}: lists of different lengths "
                + ", ".join(f"{k} {n}" for k, n in lengths.items())
            )
    return r


def read_decision_times(path: Path):
    """The ``decision_times`` of an earlier ``paired.json`` (None if it has none), checked."""
    data = check_keys(read_json(path), {}, str(path))  # a JSON mapping, or one line naming it
    if data.get("decision_times") is None:
        return None
    check_fields(data, [(("decision_times",), "map"), *TIMES_FIELDS], path)
    return data["decision_times"]


def load_result(path: Path, budget: str, seed: int, mismatch=None) -> dict:
    """A column's ``margins.json`` as `compute_margins` wrote it, for ``render_only``: it must
    exist, be of ``budget`` and ``seed`` and hold every key the page reads
    (`agents.results.page_inputs.check_margins_result`), else a ValueError naming the file (and the
    key). ``mismatch`` (specs): the result must hold a model-error block of each, measured
    under that very spec, and keeps only those (the page's section is theirs); None keeps
    the blocks it holds."""
    path = Path(path)
    r = _read_result(path, "no margins.json to render (run compare without --render-only)")
    if not isinstance(r, dict) or "basin_curve" not in r:
        raise ValueError(f"{path}: not a margins result (no basin_curve)")
    if r.get("budget") != budget or r.get("seed", DEFAULT_SEED) != seed:
        raise ValueError(
            f"{path}: budget {r.get('budget')!r}, seed {r.get('seed')!r}; "
            f"the page asks for budget {budget!r}, seed {seed}"
        )
    r = check_margins_result(r, path)  # every key the page reads, or one line naming it
    if mismatch is not None:
        r["mismatch"] = _measured_blocks(r, path, mismatch)
    return r


def _read_result(path: Path, missing: str):
    """The JSON of the margins result ``path``; a ValueError naming it (``missing`` when there
    is no such file, else why it does not parse)."""
    if not path.is_file():
        raise ValueError(f"{path}: {missing}")
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a margins result ({e})") from None


def _measured_blocks(r: dict, path: Path, specs) -> dict:
    """{name: block} of ``r``'s model-error blocks of ``specs``, each measured under that
    spec (its ``spec`` entry); ValueError naming the file and the spec otherwise."""
    held = r.get("mismatch") if isinstance(r.get("mismatch"), dict) else {}
    out = {}
    for spec in specs:
        block = held.get(spec.name)
        if not isinstance(block, dict):
            have = ", ".join(sorted(held)) or "none"
            raise ValueError(
                f"{path}: no model-error block {spec.name!r} (it holds: {have}); run compare "
                f"--mismatch {spec.name} without --render-only first"
            )
        if block.get("spec") != spec.to_dict():
            raise ValueError(
                f"{path}: its model-error block {spec.name!r} was measured under another spec "
                f"({block.get('spec')}); run compare --mismatch without --render-only first"
            )
        out[spec.name] = block
    return out


def load_model_error(path: Path, budget: str, seed: int, specs, mb: str) -> dict:
    """A model-error column's ``margins.json`` for ``--render-only``: of ``budget`` and
    ``seed``, with a block of each spec measured under it on the model-error budget ``mb``;
    a one-line ValueError naming the file otherwise."""
    from dataclasses import asdict

    from bound_env.analysis.margins.model_error.mismatch_tasks import MISMATCH_BUDGETS

    again = "run compare without --render-only first (or give --no-mismatch)"
    r = _read_result(path, f"no model-error result to render; {again}")
    if not isinstance(r, dict) or r.get("budget") != budget or r.get("seed") != seed:
        raise ValueError(f"{path}: not of budget {budget!r} and seed {seed}; {again}")
    held = r.get("mismatch") if isinstance(r.get("mismatch"), dict) else {}
    want = json.loads(json.dumps(asdict(MISMATCH_BUDGETS[mb])))  # as the JSON holds it
    for spec in specs:
        b = held.get(spec.name)
        if not isinstance(b, dict) or b.get("spec") != spec.to_dict():
            raise ValueError(f"{path}: no model-error block {spec.name!r} of its spec; {again}")
        if b.get("budget") != want:
            raise ValueError(f"{path}: block {spec.name!r} is not of the {mb} budget; {again}")
    r["mismatch"] = {s.name: held[s.name] for s in specs}
    return r
