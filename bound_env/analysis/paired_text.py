"""The paired comparisons of `bound_env.analysis.paired` in words and as Markdown tables.

`paired_text` writes the results page's "Paired differences" section from the entries that
``agents.results.compare.paired_comparisons`` makes (one per column and reference: ``delta_r50``
with its bootstrap interval, the per-size curve with McNemar's p, ``stands_out``; or ``skipped``
with the reason), i.e. from ``docs/paired.json``'s ``pairs``. Text only, no numerics.
"""

from __future__ import annotations


def paired_text(pairs) -> str:
    """The paired comparisons in words and as a table (see `paired_comparisons`)."""
    if not pairs:
        return "(no lqr column to compare against)"
    words, rows, details = [], [], []
    for e in pairs:
        name = f"**{e['column']}** vs {e['reference']}"
        if "skipped" in e:
            words.append(f"- {name}: not compared ({e['skipped']}).")
            continue
        d = e["delta_r50"]
        around = ", ".join(f"{r:g}" for r in e["around_r50"])
        ci_zero = d["low"] <= 0 <= d["high"]
        small_p = [p for p in e["p_around_r50"] if p < e["alpha"]]
        if e["stands_out"]:
            verdict = (
                f"**stands out of the noise** ({'better' if d['delta'] > 0 else 'worse'}): "
                f"the interval of Δr50 excludes 0 and McNemar's p < {e['alpha']:g} at "
                f"r = {around}"
            )
        else:
            why = []
            if ci_zero:
                why.append("the interval of Δr50 contains 0")
            if not small_p:
                why.append(f"McNemar's p ≥ {e['alpha']:g} at r = {around}")
            elif not ci_zero:
                why.append("the per-size tests disagree in sign with Δr50")
            verdict = "within the noise (" + "; ".join(why) + ")"
        words.append(
            f"- {name}: Δr50 = {d['delta']:+.3g} [{d['low']:+.3g}, {d['high']:+.3g}]; {verdict}."
        )
        near = [c for c in e["curve"] if c["size"] in e["around_r50"]]
        rows.append(
            f"| {e['column']} | {e['reference']} | {d['delta']:+.3g} "
            f"[{d['low']:+.3g}, {d['high']:+.3g}] ({d['resampled']}) | "
            + "; ".join(
                f"r = {c['size']:g}: {c['delta']:+.3f} ({c['n_better']}/{c['n_worse']}, "
                f"p = {c['p']:.2g})"
                for c in near
            )
            + f" | {'**yes**' if e['stands_out'] else 'no'} |"
        )
        drows = [
            f"| {c['size']:g} | {c['success']:.3f} | {c['success_ref']:.3f} | "
            f"{c['delta']:+.3f} | {c['n_better']} | {c['n_worse']} | {c['p']:.2g} |"
            for c in e["curve"]
        ]
        details.append(
            f'<details markdown="1"><summary>per size: {e["column"]} vs {e["reference"]}'
            "</summary>\n\n"
            "| r | P(return) | P(return), reference | Δ | directions better | "
            "directions worse | McNemar p |\n| --- | --- | --- | --- | --- | --- | --- |\n"
            + "\n".join(drows)
            + "\n\n</details>"
        )
    table = "\n".join(
        [
            "| column | reference | Δr50 [95 % bootstrap] | around the reference's r50: Δ "
            "P(return) (directions better/worse, McNemar p) | stands out |",
            "| --- | --- | --- | --- | --- |",
            *rows,
        ]
    )
    return "\n".join(words) + "\n\n" + table + "\n\n" + "\n\n".join(details)
