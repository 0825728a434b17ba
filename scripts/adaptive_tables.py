"""Markdown tables of docs/adaptive-learned.md from the committed hold JSON.

    PYTHONPATH=. python scripts/adaptive_tables.py docs/data/adaptive_hold_test.json

Per spec: each column's held count with its Wilson 95 % interval, the median effort of the
held plants, and paired against a reference column on the same plants (McNemar's exact
test on the discordant plants: won / lost, two-sided p). Seeds of one recipe (``name/sK``)
are also pooled as their mean held count and the range over the seeds.
"""

from __future__ import annotations

import sys
from collections import defaultdict

from scipy.stats import binomtest


def wilson(k: int, n: int) -> tuple[float, float]:
    from bound_env.analysis.margins.stats import wilson_interval

    return tuple(wilson_interval(k, n))


def mcnemar(a, b) -> tuple[int, int, float]:
    won = sum(1 for x, y in zip(a, b, strict=True) if x and not y)
    lost = sum(1 for x, y in zip(a, b, strict=True) if y and not x)
    p = binomtest(won, won + lost, 0.5).pvalue if won + lost else 1.0
    return won, lost, p


def table(entries: list, spec: str, reference: str) -> str:
    rows = [e for e in entries if e["spec_name"] == spec]
    by = {e["policy"]: e for e in rows}
    ref = by.get(reference)
    lines = [
        f"| column | held / {rows[0]['n']} [95 %] | effort median [N m] | vs {reference} "
        "(won/lost, p) |",
        "| --- | --- | --- | --- |",
    ]
    for e in rows:
        lo, hi = wilson(e["held"], e["n"])
        name = e["policy"] + (" (privileged, stride map)" if e.get("privileged") else "")
        eff = f"{e['effort_median']:.3g}" if e.get("effort_median") is not None else "-"
        if ref is not None and e is not ref:
            w, ls, p = mcnemar(e["outcomes"], ref["outcomes"])
            pair = f"{w}/{ls}, p = {p:.2g}"
        else:
            pair = ""
        lines.append(f"| {name} | {e['held']} [{lo:.2f}, {hi:.2f}] | {eff} | {pair} |")
    return "\n".join(lines)


def pooled(entries: list, spec: str) -> str:
    groups = defaultdict(list)
    for e in entries:
        if e["spec_name"] == spec and "/s" in e["policy"]:
            groups[e["policy"].rsplit("/s", 1)[0]].append(e["held"])
    lines = ["| recipe | seeds | held (mean) | range |", "| --- | --- | --- | --- |"]
    for g, v in groups.items():
        lines.append(f"| {g} | {len(v)} | {sum(v) / len(v):.1f} | {min(v)}-{max(v)} |")
    return "\n".join(lines)


def paired_seeds(entries: list, spec: str, a: str, b: str) -> str:
    """``a/sK`` against ``b/sK`` seed by seed on the same plants."""
    by = {e["policy"]: e for e in entries if e["spec_name"] == spec}
    out = []
    for k in range(3):
        x, y = by.get(f"{a}/s{k}"), by.get(f"{b}/s{k}")
        if x and y:
            w, ls, p = mcnemar(x["outcomes"], y["outcomes"])
            out.append(f"s{k}: {x['held']} vs {y['held']} ({w}/{ls}, p = {p:.2g})")
    return "; ".join(out)


def parser():
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("json", help="the hold JSON of scripts/adaptive_hold.py")
    ap.add_argument(
        "--reference", default="lqr", help="the column paired against (default: %(default)s)"
    )
    return ap


def main(argv=None) -> int:
    from bound_env.files.schema import read_json

    args = parser().parse_args(argv)
    try:
        raw = read_json(args.json)
        data = raw.get("entries") if isinstance(raw, dict) else None
        if not isinstance(data, list) or not all(
            isinstance(e, dict) and {"spec_name", "policy", "held", "n"} <= set(e) for e in data
        ):
            raise ValueError(f"{args.json}: entries: not a list of adaptive_hold.py's entries")
        if args.reference not in {e["policy"] for e in data}:
            raise ValueError(f"--reference {args.reference}: no such column in {args.json}")
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for spec in dict.fromkeys(e["spec_name"] for e in data):
        print(f"### {spec}\n")
        print(table(data, spec, args.reference))
        print()
        print(pooled(data, spec))
        print()
        print(
            "adaptive vs adaptive-nohist:", paired_seeds(data, spec, "adaptive", "adaptive-nohist")
        )
        print(
            "adaptive vs adaptive-nominal:",
            paired_seeds(data, spec, "adaptive", "adaptive-nominal"),
        )
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
