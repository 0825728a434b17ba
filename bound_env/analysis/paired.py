"""Paired comparisons of two closed loops measured on the same random samples.

`bound_env.analysis.margins` scores every controller on the same random directions (one
``--seed``), so a comparison of two columns is *paired*: direction d gives both an outcome
(returned: 1, not: 0) at each size r. The direction-sampling error then largely cancels in the
difference, and the tests below use it:

- `sign_test`: the exact two-sided sign test of paired differences (zeros, the concordant
  pairs, dropped): under "no difference" the number of positive differences among the
  discordant pairs is Binomial(n, 1/2) (`scipy.stats.binomtest`).
- `mcnemar_exact`: the exact McNemar test of two 0/1 outcome vectors, i.e. the sign test on
  the discordant pairs (b: the first returns and the second not; c: the reverse).
- `paired_curve`: per size r, both success rates, their difference and the sign test on the
  directions. A column with several seeds contributes, per direction, the mean of its seeds'
  outcomes (with one seed on each side this is exactly McNemar's test).
- `crossing`: where a success curve first falls below 1/2, interpolated linearly in log r
  (``r50``; vectorized, the same definition as
  `bound_env.analysis.margins.stats.crossing_on_grid`).
- `bootstrap_delta_x50`: the difference of the two columns' r50 (each the mean over its
  seeds of the per-seed r50) with a percentile bootstrap interval that resamples the
  directions (the same resample for both columns: paired) and, independently for each
  column, its seeds. An r50 outside the grid is only a bound (0 below the first size, the
  last size above it: `censored`), and so is a difference that involves one: the result
  says which column is censored and in what share of the replicates, and `delta_text`
  prints it as what it is.

Pure NumPy/SciPy, no simulator.
"""

from __future__ import annotations

import math

import numpy as np


def sign_test(diffs) -> dict:
    """Exact two-sided sign test of paired differences ``diffs`` (zeros dropped):
    {"n_pos", "n_neg", "p"}; p = 1 when no difference is non-zero."""
    from scipy.stats import binomtest

    d = np.asarray(diffs, dtype=float).ravel()
    n_pos, n_neg = int(np.sum(d > 0)), int(np.sum(d < 0))
    n = n_pos + n_neg
    p = 1.0 if n == 0 else float(binomtest(n_pos, n, 0.5).pvalue)
    return {"n_pos": n_pos, "n_neg": n_neg, "p": min(1.0, p)}


def mcnemar_exact(a, b) -> dict:
    """Exact McNemar test of paired 0/1 outcomes ``a`` and ``b`` (same samples, same order):
    {"b": a=1 & b=0 count, "c": a=0 & b=1 count, "delta": mean(a) - mean(b), "p"}."""
    a = np.asarray(a, dtype=float).ravel()
    b = np.asarray(b, dtype=float).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired outcomes need the same length, got {a.size} and {b.size}")
    if not (np.isin(a, (0.0, 1.0)).all() and np.isin(b, (0.0, 1.0)).all()):
        raise ValueError("McNemar's test takes 0/1 outcomes")
    s = sign_test(a - b)
    delta = float(a.mean() - b.mean()) if a.size else math.nan
    return {"b": s["n_pos"], "c": s["n_neg"], "delta": delta, "p": s["p"]}


def _as_seeds(x) -> np.ndarray:
    """Outcomes as (n_seeds, n_sizes, n_directions) floats."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 2:
        x = x[None]
    if x.ndim != 3:
        raise ValueError(
            f"outcomes must be (sizes, directions) or (seeds, sizes, directions), got {x.shape}"
        )
    return x


def crossing(xs, rates, level: float = 0.5) -> np.ndarray:
    """Where each curve ``rates[..., :]`` (against increasing positive ``xs``) first drops
    below ``level``: linear in log x between the last point >= level and the first below;
    0 if the first point is below, the last x if none is."""
    xs = np.asarray(xs, dtype=float)
    r = np.asarray(rates, dtype=float)
    below = r < level
    any_below = below.any(axis=-1)
    j = np.argmax(below, axis=-1)
    jm = np.maximum(j - 1, 0)
    p0 = np.take_along_axis(r, jm[..., None], axis=-1)[..., 0]
    p1 = np.take_along_axis(r, j[..., None], axis=-1)[..., 0]
    lx0, lx1 = np.log(xs[jm]), np.log(xs[j])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = (p0 - level) / (p0 - p1)  # not finite only where it is not used
        inner = np.exp(lx0 + t * (lx1 - lx0))
    out = np.where(j == 0, 0.0, inner)
    return np.where(any_below, out, xs[-1] if xs.size else 0.0)


def paired_curve(sizes, a, b) -> list[dict]:
    """Per size: {"size", "success", "success_ref", "delta", "n_better", "n_worse", "p"} of
    column ``a`` against reference ``b`` (outcomes (seeds, sizes, directions) or (sizes,
    directions), the same directions in the same order). n_better/n_worse: directions where
    a's mean outcome over its seeds is above/below b's; p: `sign_test` on them."""
    a, b = _as_seeds(a), _as_seeds(b)
    if a.shape[1:] != b.shape[1:] or a.shape[1] != len(sizes):
        raise ValueError(f"outcomes do not pair: {a.shape} against {b.shape}, {len(sizes)} sizes")
    ma, mb = a.mean(axis=0), b.mean(axis=0)  # (sizes, directions)
    rows = []
    for k, r in enumerate(sizes):
        s = sign_test(ma[k] - mb[k])
        rows.append(
            {
                "size": float(r),
                "success": float(ma[k].mean()),
                "success_ref": float(mb[k].mean()),
                "delta": float(ma[k].mean() - mb[k].mean()),
                "n_better": s["n_pos"],
                "n_worse": s["n_neg"],
                "p": s["p"],
            }
        )
    return rows


def bootstrap_delta_x50(
    sizes, a, b, n_boot: int = 2000, level: float = 0.95, seed: int = 0
) -> dict:
    """Difference of the r50 of column ``a`` and reference ``b`` (outcomes as in
    `paired_curve`; each column's r50 is the mean over its seeds of the per-seed crossing)
    with a percentile bootstrap interval: each replicate draws the directions with
    replacement (the same draw for both columns) and each column's seeds with replacement.
    Returns {"delta", "low", "high", "n_boot", "level", "resampled"}."""
    a, b = _as_seeds(a), _as_seeds(b)
    if a.shape[1:] != b.shape[1:] or a.shape[1] != len(sizes):
        raise ValueError(f"outcomes do not pair: {a.shape} against {b.shape}, {len(sizes)} sizes")
    xs = np.asarray(sizes, dtype=float)
    n_dirs = a.shape[2]
    delta = float(np.mean(crossing(xs, a.mean(axis=2))) - np.mean(crossing(xs, b.mean(axis=2))))
    rng = np.random.default_rng(seed)
    # a direction resample as multiplicities: success = outcomes @ counts / n_dirs
    counts = rng.multinomial(n_dirs, np.full(n_dirs, 1.0 / n_dirs), size=n_boot).T  # (D, B)

    def replicate_x50(x):
        succ = np.einsum("srd,db->sbr", x, counts) / n_dirs  # (seeds, B, sizes)
        per_seed = crossing(xs, succ)  # (seeds, B)
        n_seeds = x.shape[0]
        if n_seeds == 1:
            return per_seed[0]
        pick = rng.integers(0, n_seeds, size=(n_boot, n_seeds))
        return np.take_along_axis(per_seed.T, pick, axis=1).mean(axis=1)

    d = replicate_x50(a) - replicate_x50(b)
    lo, hi = np.quantile(d, [(1 - level) / 2, (1 + level) / 2])
    seeds = a.shape[0] > 1 or b.shape[0] > 1
    # censored crossings: of the observed curves (any seed), and of the replicates (either
    # column), where the difference is only a bound
    cens = [censored(xs, x.mean(axis=2)) for x in (a, b)]
    succ = [np.einsum("srd,db->sbr", x, counts) / n_dirs for x in (a, b)]
    edge = [(s[..., 0] < 0.5) | (s >= 0.5).all(axis=-1) for s in succ]  # (seeds, B)
    share = float(np.mean(edge[0].any(axis=0) | edge[1].any(axis=0)))
    return {
        "delta": delta,
        "low": float(lo),
        "high": float(hi),
        "n_boot": int(n_boot),
        "level": level,
        "resampled": "directions and seeds" if seeds else "directions",
        "censored": cens[0],
        "censored_ref": cens[1],
        "censored_share": share,
    }


def censored(xs, rates, level: float = 0.5) -> str | None:
    """Where the crossings of curves ``rates[..., :]`` (against ``xs``) are censored: "below"
    (some curve fails already at the first size: its crossing is only known to be below it),
    "above" (some curve never fails: above the last size), "below and above", or None."""
    r = np.atleast_2d(np.asarray(rates, dtype=float))
    if r.shape[-1] == 0:
        return None
    low = bool(np.any(r[..., 0] < level))
    high = bool(np.any((r >= level).all(axis=-1)))
    return {(True, False): "below", (False, True): "above", (True, True): "below and above"}.get(
        (low, high)
    )


def delta_text(d: dict, xs) -> str:
    """A `bootstrap_delta_x50` result as text: "+0.05 [+0.01, +0.09]" where both crossings lie
    within the grid; where one is censored the difference is a bound and says so (e.g.
    "both r50 < 0.01: no difference measured", "≥ +0.12 (ref r50 < 0.01)"), and an interval
    resting partly on censored replicates is marked with their share."""
    lo_x, hi_x = format(float(xs[0]), "g"), format(float(xs[-1]), "g")
    ca, cb = d.get("censored"), d.get("censored_ref")
    where = {"below": f"< {lo_x}", "above": f"> {hi_x}"}
    if ca is not None and ca == cb and ca in where:
        return f"both r50 {where[ca]}: no difference measured"
    if ca is not None or cb is not None:
        # a censored column's r50 is a bound: so is the difference
        bound = None
        if ca in ("above", None) and cb in ("below", None):
            bound = "≥"  # a's r50 could only be larger, the reference's only smaller
        elif ca in ("below", None) and cb in ("above", None):
            bound = "≤"
        notes = []
        if ca in where:
            notes.append(f"r50 {where[ca]}")
        if cb in where:
            notes.append(f"ref r50 {where[cb]}")
        if ca not in (None, *where) or cb not in (None, *where):
            notes.append("censored at both ends")
        text = f"{bound} {d['delta']:+.3g}" if bound else "not measured"
        return f"{text} ({', '.join(notes)})"
    text = f"{d['delta']:+.3g} [{d['low']:+.3g}, {d['high']:+.3g}]"
    share = d.get("censored_share", 0.0)
    if share and share > 0.0:
        text += f" ({100 * share:.0f} % of resamples censored)"
    return text


def radii_around(sizes, x: float) -> list[float]:
    """The grid sizes on either side of ``x`` (the last <= x and the first > x; one at a
    grid end)."""
    xs = [float(s) for s in sizes]
    below = [s for s in xs if s <= x]
    above = [s for s in xs if s > x]
    return ([below[-1]] if below else []) + ([above[0]] if above else [])


def compare_paired(
    sizes, a, b, alpha: float = 0.05, n_boot: int = 2000, level: float = 0.95, seed: int = 0
) -> dict:
    """Everything the comparison page says about column ``a`` against reference ``b``:
    {"curve": `paired_curve`, "delta_r50": `bootstrap_delta_x50`, "around_r50": the grid
    sizes around the reference's r50, "p_around_r50", "stands_out"}. ``stands_out``: the
    interval of Delta r50 excludes 0 *and* the sign test gives p < ``alpha`` at a size around
    the reference's r50, in the same direction."""
    curve = paired_curve(sizes, a, b)
    dr = bootstrap_delta_x50(sizes, a, b, n_boot=n_boot, level=level, seed=seed)
    r50_ref = float(np.mean(crossing(sizes, _as_seeds(b).mean(axis=2))))
    around = radii_around(sizes, r50_ref)
    rows = [c for c in curve if c["size"] in around]
    sign = 1 if dr["low"] > 0 else -1 if dr["high"] < 0 else 0
    agree = [c for c in rows if c["p"] < alpha and np.sign(c["delta"]) == sign]
    return {
        "curve": curve,
        "delta_r50": dr,
        "r50_ref": r50_ref,
        "around_r50": around,
        "p_around_r50": [c["p"] for c in rows],
        "stands_out": bool(sign != 0 and agree),
        "alpha": alpha,
    }
