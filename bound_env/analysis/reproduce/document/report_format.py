"""Values as the text of REPRODUCTION.md prints them: numbers (a dash when missing), windows,
pairs, eigenvalues, z vectors (paper units), milliseconds. Shared by `report` and
`report_table`."""

from __future__ import annotations

import math

from ..figures import Z_FMT

REAL_TOL = 1e-9  # |Im| below this prints an eigenvalue as real


def num_text(v, fmt="{:.4g}"):
    """``v`` formatted, or a dash when it is missing or not finite."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return fmt.format(v)


def window_text(w, fmt="{:.3f}"):
    return "none" if not w else f"{fmt.format(w[0])}–{fmt.format(w[1])}"


def pair_text(p, fmt) -> str:
    return "–" if not p else f"{fmt.format(p[0])} / {fmt.format(p[1])}"


def eig_text(eigs, n=6):
    if not eigs:
        return "–"
    parts = []
    for re, im in eigs[:n]:
        parts.append(f"{re:.4f}" if abs(im) < REAL_TOL else f"{re:.4f}{im:+.4f}i")
    return ", ".join(parts)


def z_text(q):
    return "[" + ", ".join(Z_FMT[i].format(v) for i, v in enumerate(q["z"])) + "]"


def millis_text(x, fmt="{:.2f}"):
    """Seconds as milliseconds (None stays None)."""
    return num_text(x and x * 1e3, fmt)


def vec_text(v) -> str:
    if v is None:
        return "–"
    return "[" + ", ".join(f"{x:+.3g}" for x in v) + "]"
