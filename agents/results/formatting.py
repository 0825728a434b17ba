"""How the results page writes numbers and paths (`agents.results.page`, `agents.results.headline`).

The repository's root (`ROOT`), a path relative to it (`rel`), a number to a few significant
digits (`fmt`, `num3`), one measure of one result (`value`: NaN where the result lacks it)
and several seeds' values as mean [95 % Student-t interval] (`agg`); a value written in
the form of a text that quotes it (`render_like`, for `agents.results.numbers`'s data blocks).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from bound_env.analysis.margins.stats import bounded_t_interval, t_interval

ROOT = Path(__file__).resolve().parents[2]


def fmt(v, digits=4) -> str:
    """``v`` to ``digits`` significant digits; — for None or NaN."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.{digits}g}"


def fmt_list(values) -> str:
    """Numbers as ``a, b, c`` (``?`` for none)."""
    return ", ".join(f"{v:g}" for v in values) if values else "?"


def num3(v) -> str:
    """``v`` to 3 significant digits; — for None or a non-finite float."""
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.3g}"


def value(fn, r):
    """``fn(r)`` as a float: NaN where the result ``r`` lacks it (or it is None)."""
    try:
        v = fn(r)
    except (KeyError, TypeError, IndexError):
        return math.nan
    return math.nan if v is None else float(v)


def agg(values, digits, lower: float | None = None) -> str:
    """One value as it is; several (seeds) as mean [95 % t interval]; a quantity that cannot go
    below ``lower`` (effort, a size, a ratio: 0) gets an interval that respects the bound
    (`bounded_t_interval`)."""
    vals = [v for v in values if not math.isnan(v)]
    if not vals:
        return "—"
    if len(values) == 1:
        return fmt(vals[0], digits)
    ti = t_interval(vals) if lower is None else bounded_t_interval(vals, lower)
    return f"{fmt(ti['mean'], digits)} [{fmt(ti['low'], digits)}, {fmt(ti['high'], digits)}]"


def command_text(cmd: str) -> str:
    """The command as a reader would type it (``bound-env ...``, not the venv's path)."""
    parts = cmd.split()
    if parts and parts[0].endswith("bound-env"):
        parts[0] = "bound-env"
    return " ".join(parts)


def rel(p: str) -> str:
    """``p`` relative to the repository's root, or as it is when outside it."""
    try:
        return str(Path(p).resolve().relative_to(ROOT))
    except ValueError:
        return p


DATA_UNITS = {"ms": 1e3, "us": 1e6, "min": 1 / 60, "pct": 100.0, "k": 1e-3}
NUMBER_TEXT = re.compile(r"^(?P<sign>[+−-]?)\d+(?:\.(?P<dec>\d+))?(?P<exp>e[+-]?\d+)?$")


def render_like(v, text: str, unit: str = "") -> str:
    """``v`` written in the form of ``text``: ``k/n`` for a count of held plants, else a number
    with as many decimals (and the sign, the exponent) as ``text`` shows."""
    if isinstance(v, dict):
        k = v.get("k", v.get("held"))
        if isinstance(k, int) and isinstance(v.get("n"), int):
            return f"{k}/{v['n']}"
        raise TypeError(f"an item, not a number or a count k/n ({sorted(v)[:6]})")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError(f"not a number: {v!r}")
    if unit:
        if unit not in DATA_UNITS:
            raise ValueError(f"unit {unit!r}: not one of {', '.join(DATA_UNITS)}")
        v = v * DATA_UNITS[unit]
    m = NUMBER_TEXT.match(text.strip())
    if not m:
        raise ValueError(f"the text {text!r} is not a number to compare with {v!r}")
    dec = len(m.group("dec") or "")
    out = f"{v:.{dec}e}" if m.group("exp") else f"{v:.{dec}f}"
    if m.group("exp"):  # 1.3e-11, as written (no zero-padded exponent)
        mant, exp = out.split("e")
        out = f"{mant}e{int(exp)}"
    if m.group("sign") == "+" and v >= 0:
        out = "+" + out
    return out.replace("-", "−") if "−" in text else out


PATH_PART = re.compile(r"\[(?P<sel>[^\]]*)\]|(?P<key>[^.\[\]]+)")


def matches(item, conditions: list[tuple[str, str]]) -> bool:
    """Whether the mapping ``item`` has each field of ``conditions`` at its value."""
    if not isinstance(item, dict):
        return False
    for field, want in conditions:
        have = item.get(field)
        if isinstance(have, (int, float)) and not isinstance(have, bool):
            try:
                if float(want) != float(have):
                    return False
            except ValueError:
                return False
        elif str(have) != want:
            return False
    return True


def data_lookup(data, path: str):
    """The item of ``data`` at ``path``; a KeyError naming the part that is not there."""
    pos, seen = 0, ""
    path = path.strip()
    while pos < len(path):
        if path[pos] == ".":
            pos += 1
            continue
        m = PATH_PART.match(path, pos)
        if not m:
            raise KeyError(f"{path}: cannot read at {path[pos:]!r}")
        pos, part = m.end(), m.group(0)
        seen += part if part.startswith("[") or not seen else "." + part
        if m.group("sel") is not None:
            conds = [c.split("=", 1) for c in m.group("sel").split(";")]
            if any(len(c) != 2 for c in conds) or not isinstance(data, list):
                raise KeyError(f"{seen}: a selector [field=value;...] of a list")
            found = [x for x in data if matches(x, [(f.strip(), v.strip()) for f, v in conds])]
            if len(found) != 1:
                raise KeyError(f"{seen}: {len(found)} items match, not one")
            data = found[0]
        elif isinstance(data, list) and part.isdigit() and int(part) < len(data):
            data = data[int(part)]
        elif isinstance(data, dict) and part in data:
            data = data[part]
        else:
            raise KeyError(f"{seen}: missing")
    return data


def slug(text: str) -> str:
    """``text`` as a folder name: every character but letters, digits and ``-_.`` as ``_``."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)
