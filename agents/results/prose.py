"""The docs' sentences whose numbers are the results page's (``python -m agents.results.prose``).

A sentence that quotes the page's r50s, paired differences or decision times is written from
``docs/headline.json`` and ``docs/paired.json`` (what ``bound-env compare --docs docs`` wrote),
never by hand: it sits between ``<!-- numbers:NAME -->`` and ``<!-- /numbers:NAME -->`` in a
page of ``docs/``, and `BLOCKS` [NAME] makes its text. ``python -m agents.results.prose`` rewrites
every block after a new page, with the inline numbers and the tables of
`agents.results.numbers` (``<!-- n:KEY -->``, ``<!-- table:NAME -->``: every number the docs
quote of a measurement); ``--check`` only says whether they are up to date (exit 1 if not).
tests/test_docs_numbers.py checks the blocks, and that no such number is quoted outside them.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from bound_env.files.cache import atomic_write
from bound_env.files.schema import check_keys, read_json

from .formatting import ROOT, num3
from .headline import HEADLINE_JSON, load_headline
from .numbers import NOT_FINITE

# every opening and closing comment of a block, as the block patterns above read them
MARKER = re.compile(
    r"<!-- (?:n:[^>]*?|(?:table|numbers):[a-z0-9-]+) -->"
    r"|<!-- /(?:n|table:[a-z0-9-]+|numbers:[a-z0-9-]+) -->"
)


def closer(opening: str) -> str:
    kind = opening[5:-4].split(":", 1)
    return "<!-- /n -->" if kind[0] == "n" else f"<!-- /{kind[0]}:{kind[1]} -->"


def check_markers(text: str, where: str = "") -> None:
    """A ValueError of one line naming the file and the line when the block comments of
    ``text`` are not pairs: a block opened and not closed before the next one (a lost
    closing comment, which would make a rewrite swallow the words up to the next block's
    end), a closing comment without its opening, a block inside another. Blocks do not
    nest."""
    opened = None  # (comment, line) of the block open at this point
    for m in MARKER.finditer(text):
        mark, line = m.group(0), text.count("\n", 0, m.start()) + 1
        if mark.startswith("<!-- /"):
            if opened is None or mark != closer(opened[0]):
                what = (
                    f"inside {opened[0]} of line {opened[1]}" if opened else "without its opening"
                )
                raise ValueError(f"{where}:{line}: {mark} {what} (a lost or extra comment)")
            opened = None
        elif opened is not None:
            raise ValueError(
                f"{where}:{opened[1]}: {opened[0]} is not closed by {closer(opened[0])} "
                f"before {mark} of line {line}"
            )
        else:
            opened = (mark, line)
    if opened is not None:
        raise ValueError(f"{where}:{opened[1]}: {opened[0]} is never closed ({closer(opened[0])})")


PAIRED_JSON = ROOT / "docs" / "paired.json"
BLOCK = re.compile(r"<!-- numbers:([a-z0-9-]+) -->(.*?)<!-- /numbers:\1 -->", re.S)
STRIDE_MS = 390  # a stride of the default gait lasts about 390 ms (the real-time budget)


class Numbers:
    """The page's numbers by name: r50 rows (`r50`), paired differences (`pair`) and decision
    times (`times`), each a ValueError naming the file and the key when missing."""

    def __init__(self, head: dict, paired: dict, head_path=HEADLINE_JSON, paired_path=PAIRED_JSON):
        self.head, self.paired = head, paired
        self.head_path, self.paired_path = head_path, paired_path

    def r50(self, label: str) -> dict:
        for row in self.head["rows"]:
            if row["label"] == label:
                return row["r50"]
        raise ValueError(f"{self.head_path}: rows: no row {label!r}")

    def pair(self, column: str, reference: str) -> dict:
        for e in self.paired.get("pairs") or []:
            if e.get("column") == column and e.get("reference") == reference and "skipped" not in e:
                return e
        raise ValueError(f"{self.paired_path}: pairs: no {column!r} against {reference!r}")

    def times(self, label: str) -> dict:
        ctrls = (self.paired.get("decision_times") or {}).get("controllers") or {}
        if label not in ctrls:
            raise ValueError(f"{self.paired_path}: decision_times.controllers.{label}: missing")
        return ctrls[label]


def _interval(m: dict) -> str:
    return f"{num3(m['value'])} [{num3(m['low'])}, {num3(m['high'])}]"


def _delta(d: dict, sign: str = "+") -> str:
    return f"{d['delta']:{sign}.2g} [{d['low']:{sign}.2g}, {d['high']:{sign}.2g}]"


def _ms(seconds: float) -> str:
    return f"{1e3 * seconds:.3g}"


def _us(seconds: float) -> str:
    return f"{1e6 * seconds:.2g}"


def _ratio(a: float, b: float) -> str:
    r = a / b
    return f"{r:.0f}" if r >= 10 else f"{r:.2g}"


def _near(e: dict) -> str:
    """Per direction at the sizes around the reference's r50: better/worse and McNemar's p."""
    near = [c for c in e["curve"] if c["size"] in e["around_r50"]]
    return "; ".join(
        f"r = {c['size']:.3g}: {c['n_better']} directions better, {c['n_worse']} worse, "
        f"McNemar p = {c['p']:.2g}"
        for c in near
    )


def test_set(n: Numbers) -> str:
    """docs/learned.md, "On the test set": mpc's and the fine-tuned students' r50 and times."""
    mpc, ft = n.times("mpc"), n.times("fine-tuned")
    return (
        f"`mpc` reaches r50 {_interval(n.r50('mpc'))} (the LQR {num3(n.r50('lqr')['value'])}) "
        f"and decides in {_ms(mpc['p50'])} ms at the median and {_ms(mpc['p99'])} ms at the "
        f"99th percentile (mean {_ms(mpc['mean'])} ms; a stride lasts {STRIDE_MS} ms, so it "
        "runs in real time on one core). The fine-tuned students (3 seeds, final models) reach "
        f"r50 {_interval(n.r50('fine-tuned'))}, "
        f"{_delta(n.pair('fine-tuned', 'lqr')['delta_r50'])} over the LQR on the same "
        f"directions, and decide in {_us(ft['p50'])} µs at the median. They do not beat their "
        f"teacher: {_delta(n.pair('fine-tuned', 'mpc')['delta_r50'])} in r50 against `mpc`."
    )


def learned_vs_classical(n: Numbers) -> str:
    """docs/learned.md, the headline in words: the fine-tuned students against lqr and mpc."""
    lqr, mpc = n.pair("fine-tuned", "lqr"), n.pair("fine-tuned", "mpc")
    d = mpc["delta_r50"]
    return (
        f"The fine-tuned students gain {lqr['delta_r50']['delta']:+.2g} in r50 over the LQR, "
        f"{'well out of' if lqr['stands_out'] else 'within'} the noise (per direction at "
        f"{_near(lqr)}). They stay {-d['delta']:.2g} [{-d['high']:.2g}, {-d['low']:.2g}] below "
        f"`mpc` in r50, a difference that "
        f"{'stands out' if mpc['stands_out'] else 'does not stand out'} of the noise too "
        f"({_near(mpc)})."
    )


def decision_speed(n: Numbers) -> str:
    """docs/learned.md, the headline in words: how fast the fine-tuned students decide."""
    mpc, ft = n.times("mpc"), n.times("fine-tuned")
    return (
        f"They decide in {_us(ft['p50'])} µs at the median, {_ratio(mpc['p50'], ft['p50'])}× "
        f"faster than `mpc`'s median and {_ratio(mpc['mean'], ft['mean'])}× faster on average "
        f"({_ms(mpc['mean'])} ms; `mpc`'s p99 is {_ms(mpc['p99'])} ms, well within a stride of "
        f"{STRIDE_MS} ms)."
    )


BLOCKS = {
    "test-set": test_set,
    "learned-vs-classical": learned_vs_classical,
    "decision-speed": decision_speed,
}


def load_numbers(head_path: Path = HEADLINE_JSON, paired_path: Path = PAIRED_JSON) -> Numbers:
    paired = check_keys(read_json(paired_path), {}, str(paired_path))  # a JSON mapping
    return Numbers(load_headline(head_path), paired, head_path, paired_path)


def update_text(text: str, numbers: Numbers, where: str = "") -> str:
    """``text`` with every ``numbers:NAME`` block rewritten (a ValueError for an unknown NAME)."""

    def fill(m: re.Match) -> str:
        name = m.group(1)
        if name not in BLOCKS:
            raise ValueError(
                f"{where}: <!-- numbers:{name} -->: no such block ({', '.join(BLOCKS)})"
            )
        sentence = BLOCKS[name](numbers)
        bad = NOT_FINITE.search(sentence)
        if bad:
            raise ValueError(f"{where}: <!-- numbers:{name} -->: not a finite number ({bad[0]!r})")
        return f"<!-- numbers:{name} -->{sentence}<!-- /numbers:{name} -->"

    check_markers(text, where)
    return BLOCK.sub(fill, text)


def doc_files(root: Path = ROOT) -> list[Path]:
    """The pages the blocks may sit in: docs/**/*.md and README.md."""
    return sorted((root / "docs").rglob("*.md")) + [root / "README.md"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.results.prose", description=__doc__)
    ap.add_argument("--check", action="store_true", help="only check; exit 1 if out of date")
    args = ap.parse_args(argv)
    from . import numbers as inline

    try:
        numbers = load_numbers()
        sources = inline.Sources()
        new_text, missing = {}, []
        for f in doc_files():  # every file made first: an error anywhere writes nothing
            old = f.read_text()
            new = inline.update_text(update_text(old, numbers, str(f)), sources, str(f), missing)
            if new != old:
                new_text[f] = new
    except (OSError, ValueError, KeyError, TypeError) as e:
        msg = str(e) if isinstance(e, (OSError, ValueError)) else f"a malformed key: {e!r}"
        print(f"error: {msg}", file=sys.stderr)
        return 2
    for e in dict.fromkeys(missing):  # a block its source has no value for: nothing written
        print(f"error: {e}", file=sys.stderr)
    if missing:
        return 2
    for f, new in new_text.items():
        if not args.check:
            atomic_write(f, new)
        print(f"{f}: {'stale' if args.check else 'rewritten'}")
    return 1 if new_text and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
