"""How the results page writes numbers and paths (`agents.results.page`, `agents.results.headline`).

The repository's root (`ROOT`), a path relative to it (`rel`), a number to a few significant
digits (`fmt`, `num3`), one measure of one result (`value`: NaN where the result lacks it)
and several seeds' values as mean [95 % Student-t interval] (`agg`).
"""

from __future__ import annotations

import math
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


def slug(text: str) -> str:
    """``text`` as a folder name: every character but letters, digits and ``-_.`` as ``_``."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)
