"""The README's results table from the results page's numbers (``python -m agents.headline``).

``bound-env compare --docs docs`` writes ``docs/headline.json`` beside ``docs/MARGINS.md``
(`agents.compare.headline_numbers`) and puts its table (`agents.compare.headline_table`) first
on the page. This module puts the same table into README.md, between the markers
``<!-- headline:start -->`` and ``<!-- headline:end -->``, so that it is regenerated, never
edited by hand; ``--check`` only says whether the README is up to date (exit 1 if not).
tests/test_docs.py checks both tables against the JSON.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bound_env.cache import atomic_write
from bound_env.schema import check_keys, load_json_strict

from .compare import HEADLINE_FILE, ROOT, headline_table

START, END = "<!-- headline:start -->", "<!-- headline:end -->"
README = ROOT / "README.md"
HEADLINE_JSON = ROOT / "docs" / HEADLINE_FILE


# what each row of headline.json holds (`agents.compare.headline_numbers`): a measure is its
# value and 95 % interval (null where it could not be measured) and the interval's kind
_MEASURE = {"value": (float, None), "low": (float, None), "high": (float, None), "interval": str}
_ROW = {
    "role": str,
    "label": str,
    "what": str,
    "r50": _MEASURE,
    "mfpt_sigma_100_deg": _MEASURE,
}


def load_headline(path: Path = HEADLINE_JSON) -> dict:
    """docs/headline.json, checked: strict JSON (a NaN or Infinity is refused, so it never
    reaches the README), ``budget``, ``seed`` and ``rows``, and each row's keys and types
    (`_ROW`); a one-line ValueError naming the file and the key otherwise."""
    path = Path(path)
    head = load_json_strict(path, {"budget": str, "seed": int, "rows": list})
    for i, row in enumerate(head["rows"]):
        check_keys(row, _ROW, str(path), f"rows[{i}].")
    if not head["rows"]:
        raise ValueError(f"{path}: rows: empty (write it with bound-env compare --docs)")
    return head


def render_block(head: dict) -> str:
    """The README's block: the markers around the table and the line saying where it is from."""
    return (
        f"{START}\n{headline_table(head)}\n\n"
        f"The **{head['budget']}** budget on the test set (seed {head['seed']}); generated from "
        f"`docs/{HEADLINE_FILE}` by `python -m agents.headline`.\n{END}"
    )


def update_readme(text: str, head: dict) -> str:
    """``text`` with its headline block replaced (a ValueError if the markers are missing)."""
    i, j = text.find(START), text.find(END)
    if i < 0 or j < i:
        raise ValueError(f"README.md: no {START} ... {END} block")
    return text[:i] + render_block(head) + text[j + len(END) :]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.headline", description=__doc__)
    ap.add_argument("--json", default=str(HEADLINE_JSON), help="the page's headline.json")
    ap.add_argument("--readme", default=str(README), help="the README to update")
    ap.add_argument("--check", action="store_true", help="only check; exit 1 if out of date")
    args = ap.parse_args(argv)
    try:
        head = load_headline(Path(args.json))
        readme = Path(args.readme)
        old = readme.read_text()
        new = update_readme(old, head)
    except (OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.check:
        print("README.md headline up to date" if new == old else "README.md headline is stale")
        return 0 if new == old else 1
    if new != old:
        atomic_write(readme, new)
    print(f"wrote {readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
