"""Confidence intervals used by the margins and the comparison table.

- `wilson_interval`: the 95 % Wilson score interval of a success rate k/n (Wilson 1927;
  Brown, Cai & DasGupta 2001 recommend it over the Wald interval for small n or rates near
  0 and 1);
- `t_interval`: mean and 95 % Student-t interval of a few values (the seeds of one
  controller): mean +- t_{0.975, n-1} s / sqrt(n);
- `bounded_t_interval`: the same for a quantity that cannot go below a bound (effort,
  sizes, times: >= 0): the Student-t interval when it respects the bound, else the t
  interval of log(x - bound) mapped back (a log-scale interval, never below the bound);
- `threshold_on_grid`: the largest grid value up to which a rate stays >= 0.5 (p50);
- `crossing_on_grid`: where a rate first falls below 0.5, interpolated linearly in log x
  between the two grid points around the crossing (r50, sigma50); applied to the rate's
  lower and upper interval bounds it gives the crossing's interval.
- `crossing_censored`: whether such a crossing lies outside the grid ("below" its first size,
  "above" its last: only a bound is known), and `x50_text`, which prints it so ("< 0.01",
  "> 0.4");
- `mfpt_estimate`: the mean first-passage time (in strides) of a constant per-stride
  failure hazard from censored runs, and its exact Poisson interval;
- `mfpt_crossing`: where an MFPT curve falls to a level (100 strides), log-log interpolated.

The paired comparisons of two columns (McNemar, bootstrap of Delta r50) are in
`bound_env.analysis.paired`.
"""

from __future__ import annotations

import math

Z95 = 1.959963984540054  # standard normal 0.975 quantile


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of the success probability after k successes in n trials."""
    if n <= 0:
        return (0.0, 1.0)
    if not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    lo = 0.0 if k == 0 else max(0.0, centre - half)  # exact at the ends (no rounding)
    hi = 1.0 if k == n else min(1.0, centre + half)
    return (lo, hi)


def t_interval(values, level: float = 0.95) -> dict:
    """Mean and Student-t interval of ``values`` (NaN and None dropped): {"mean", "low",
    "high", "n", "method"}. With one value the interval is that value (n = 1, no spread)."""
    from scipy import stats

    xs = [float(v) for v in values if v is not None and not math.isnan(float(v))]
    n = len(xs)
    if n == 0:
        return {"mean": math.nan, "low": math.nan, "high": math.nan, "n": 0, "method": "t"}
    mean = sum(xs) / n
    if n == 1:
        return {"mean": mean, "low": mean, "high": mean, "n": 1, "method": "t"}
    sd = math.sqrt(sum((x - mean) ** 2 for x in xs) / (n - 1))
    half = float(stats.t.ppf(0.5 + level / 2, n - 1)) * sd / math.sqrt(n)
    return {"mean": mean, "low": mean - half, "high": mean + half, "n": n, "method": "t"}


def bounded_t_interval(values, lower: float = 0.0, level: float = 0.95) -> dict:
    """`t_interval` of a quantity that cannot go below ``lower`` (effort, a basin size, a
    time: 0): the same dict, the same ``mean`` (the arithmetic mean of the values). When the
    Student-t interval stays at or above ``lower`` it is returned as it is (``method`` "t").
    Otherwise the interval is computed on the log scale: the t interval of log(x - lower),
    mapped back (``method`` "t, log scale"), widened if needed to contain the mean (the
    geometric mean the log scale centres on lies below it); values at ``lower`` itself have
    no logarithm, and then the interval is [lower, the t interval's high] (``method``
    "t, cut at the bound")."""
    ti = t_interval(values, level)
    if ti["n"] < 2 or not ti["low"] < lower:
        return ti
    xs = [float(v) for v in values if v is not None and not math.isnan(float(v))]
    if any(x < lower for x in xs):
        raise ValueError(f"values below the bound {lower:g}: {min(xs):g}")
    if any(x == lower for x in xs):
        return {**ti, "low": float(lower), "method": "t, cut at the bound"}
    lg = t_interval([math.log(x - lower) for x in xs], level)
    low, high = lower + math.exp(lg["low"]), lower + math.exp(lg["high"])
    return {
        **ti,
        "low": min(low, ti["mean"]),
        "high": max(high, ti["mean"]),
        "method": "t, log scale",
    }


def threshold_on_grid(sizes, rates, level: float = 0.5) -> float:
    """Largest size up to which ``rates`` stay >= level (0 if the first is below)."""
    best = 0.0
    for s, p in zip(sizes, rates, strict=True):
        if p < level:
            break
        best = s
    return best


def crossing_on_grid(xs, rates, level: float = 0.5) -> float:
    """Where ``rates`` (against increasing positive ``xs``) first drop below ``level``:
    interpolated linearly in log x between the last point >= level and the first point
    below it; 0 if the first point is already below; the last x if none is."""
    prev = None
    for x, p in zip(xs, rates, strict=True):
        if p < level:
            if prev is None:
                return 0.0
            x0, p0 = prev
            t = (p0 - level) / (p0 - p)
            return math.exp(math.log(x0) + t * (math.log(x) - math.log(x0)))
        prev = (x, p)
    return float(xs[-1]) if len(xs) else 0.0


def crossing_censored(xs, rates, level: float = 0.5) -> str | None:
    """Is the crossing of `crossing_on_grid` censored? "below": the first size already fails
    (the crossing is somewhere below it; `crossing_on_grid` says 0), "above": no size fails
    (somewhere above the last; it says the last size), None: it lies within the grid."""
    rates = list(rates)
    if not rates:
        return None
    if rates[0] < level:
        return "below"
    if all(p >= level for p in rates):
        return "above"
    return None


def x50_text(value, censored: str | None, xs, fmt: str = ".3g") -> str:
    """A crossing as text, a censored one as the bound it is: "< xs[0]" or "> xs[-1]"."""
    if censored == "below":
        return f"< {format(float(xs[0]), 'g')}"
    if censored == "above":
        return f"> {format(float(xs[-1]), 'g')}"
    if value is None or not math.isfinite(float(value)):
        return "–"
    return format(float(value), fmt)


def mfpt_estimate(strides_total: int, failures: int, level: float = 0.95) -> dict:
    """Mean first-passage time [strides] of runs with a constant per-stride failure hazard
    (Byl & Tedrake 2009), from ``failures`` falls in ``strides_total`` strides attempted
    (completed strides plus the strides in which a robot fell; a run that reaches the horizon
    is censored there). The hazard's maximum-likelihood estimate is failures / strides_total,
    so MFPT = strides_total / failures. With no failure only a bound exists: ``mfpt`` is then
    strides_total (as if one failure were next), flagged ``lower_bound``. ``ci``: the exact
    (Garwood) Poisson interval of the failure count with the strides as exposure, inverted
    (the upper end is None, unbounded, with no failure)."""
    from scipy.stats import chi2

    if strides_total < 0 or failures < 0 or failures > strides_total:
        raise ValueError(f"need 0 <= failures <= strides_total, got {failures}, {strides_total}")
    t, k = float(strides_total), int(failures)
    if t == 0:
        return {"mfpt": math.nan, "lower_bound": True, "ci": [math.nan, None]}
    a = 1.0 - level
    lo = 2.0 * t / float(chi2.ppf(1 - a / 2, 2 * k + 2))
    hi = None if k == 0 else 2.0 * t / float(chi2.ppf(a / 2, 2 * k))
    return {"mfpt": t / max(k, 1), "lower_bound": k == 0, "ci": [lo, hi]}


def mfpt_crossing(sigmas, mfpts, lower_bounds, level: float = 100.0) -> float | None:
    """The sigma at which the MFPT first falls to ``level``: log MFPT interpolated linearly
    in log sigma between the last grid point known to be above ``level`` and the first
    estimate below it. A zero-failure point counts as above only if its lower bound is; one
    whose bound is below ``level`` leaves the crossing undetermined there. None if the curve
    does not bracket ``level`` (below at the first sigma, never below, or undetermined)."""
    prev = None
    for s, m, lb in zip(sigmas, mfpts, lower_bounds, strict=True):
        if m is None or not math.isfinite(m):
            prev = None
        elif m >= level:
            prev = (s, m)
        elif lb:
            prev = None  # "at least m", m < level: the crossing may be anywhere around here
        else:
            if prev is None:
                return None
            (s0, m0), (s1, m1) = prev, (s, m)
            t = (math.log(m0) - math.log(level)) / (math.log(m0) - math.log(m1))
            return math.exp(math.log(s0) + t * (math.log(s1) - math.log(s0)))
    return None
