"""The real-time yardstick (JSON ``decision_times``): the wall time of every apex decision a
controller makes during its own margins measures, and the page's table of them.

The closed loop (`closed_loop`) appends the time of every apex decision to
`closed_loop.DECISION_SECONDS`: a stride controller's plan of each stride (its own
``decision_seconds`` where it times itself, else the batch call's time shared equally by its
robots), a step-level controller's ``on_apex`` hook. `run_task` keeps each task's times as a
log-binned histogram (`histogram`: `BINS_PER_DECADE` bins per decade, so a task's entry stays
small however many strides it ran), and `summary` merges the tasks' histograms into p50, p99
and n. A quantile is the geometric centre of its bin: within 1.2 % of the exact value.
"""

from __future__ import annotations

import math

BINS_PER_DECADE = 100
T_FLOOR = 1e-7  # [s]: bin 0 starts here (shorter times fall in it)
REAL_TIME_S = 1e-3  # the yardstick: one decision within 1 ms (p99)


def histogram(seconds) -> dict[str, int]:
    """{bin: count} of decision times [s] (bin k: [T_FLOOR 10^(k/B), T_FLOOR 10^((k+1)/B)),
    B = `BINS_PER_DECADE`; keys are strings, as in JSON)."""
    out: dict[str, int] = {}
    for t in seconds:
        k = max(0, int(math.floor(BINS_PER_DECADE * math.log10(max(t, T_FLOOR) / T_FLOOR))))
        out[str(k)] = out.get(str(k), 0) + 1
    return out


def merge(hists) -> dict[int, int]:
    """The sum of histograms ({bin: count}, keys str or int)."""
    total: dict[int, int] = {}
    for h in hists:
        for k, c in (h or {}).items():
            total[int(k)] = total.get(int(k), 0) + int(c)
    return total


def quantile(hist: dict[int, int], q: float) -> float:
    """The q-quantile [s] of a merged histogram: the centre of the bin holding it."""
    n = sum(hist.values())
    rank = q * (n - 1)  # the same rank as numpy's linear quantile, to the bin
    seen = 0
    for k in sorted(hist):
        seen += hist[k]
        if seen > rank:
            return T_FLOOR * 10 ** ((k + 0.5) / BINS_PER_DECADE)
    return T_FLOOR * 10 ** ((max(hist) + 0.5) / BINS_PER_DECADE)


def summary(results) -> dict | None:
    """{p50, p99, n} [s] of the decisions of every task result's ``decision_hist`` (None: the
    controller made no apex decision, e.g. passive or a step policy without an apex hook)."""
    hist = merge(r.get("decision_hist") for r in results if isinstance(r, dict))
    n = sum(hist.values())
    if not n:
        return None
    return {
        "p50": quantile(hist, 0.5),
        "p99": quantile(hist, 0.99),
        "n": n,
        "measured_on": "every apex decision of the controller's own margins measures "
        f"(wall time; log bins, {BINS_PER_DECADE} per decade)",
    }


def real_time_table(columns: dict) -> str:
    """The page's table: each controller's decision p99 and p50 and the row "best controller
    within 1 ms per decision (p99)": of the columns whose p99 is at most `REAL_TIME_S`, the one
    with the highest r50 (``r50``, or the JSON's ``basin_curve.r50``; a column without one is
    never named best). ``columns``: {label: margins JSON or its ``decision_times``}; a column
    with ``fixed`` times (the dedicated pass on fixed states, CPU time: the page's
    ``paired.json``) is given by them, with a last cell ``fixed``, and then the count of its
    measures' decisions (``decision_times.n``); the table without any ``fixed`` is as before."""
    rows, best = [], None
    any_fixed = any(isinstance(d, dict) and d.get("fixed") for d in columns.values())
    for label, data in columns.items():
        t = data.get("decision_times", data) if isinstance(data, dict) else None
        fixed = data.get("fixed") if isinstance(data, dict) else None
        n = (t or {}).get("n", "")
        if fixed:
            t, where = fixed, "fixed"
        else:
            where = "its measures"
        if not t or "p99" not in t:
            rows.append(f"| {label} | no apex decisions | | |" + (" |" if any_fixed else ""))
            continue
        cells = (
            f"| {label} | {1e3 * t['p50']:.3g} | {1e3 * t['p99']:.3g} | {n if fixed else t['n']} |"
        )
        rows.append(cells + (f" {where} |" if any_fixed else ""))
        r50 = data.get("r50", (data.get("basin_curve") or {}).get("r50"))
        if t["p99"] <= REAL_TIME_S and r50 is not None and math.isfinite(r50):
            if best is None or r50 > best[1]:
                best = (label, r50, t["p99"])
    head = "| controller | decision p50 [ms] | decision p99 [ms] | decisions |"
    rule = "| --- | --- | --- | --- |"
    lines = [
        head + (" timed on |" if any_fixed else ""),
        rule + (" --- |" if any_fixed else ""),
        *rows,
        "",
    ]
    if best is None:
        lines.append(f"Best controller within {1e3 * REAL_TIME_S:g} ms per decision (p99): none.")
    else:
        lines.append(
            f"Best controller within {1e3 * REAL_TIME_S:g} ms per decision (p99): **{best[0]}** "
            f"(r50 {best[1]:.3f}, p99 {1e3 * best[2]:.3g} ms)."
        )
    return "\n".join(lines) + "\n"
