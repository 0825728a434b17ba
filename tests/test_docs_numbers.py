"""Every number the docs quote of a measurement comes from the one JSON value it names.

A number in docs/**/*.md or README.md that quotes the results page (r50, Δr50, an interval, a
decision time, a speed ratio, a hold count, a torque) or another committed measurement (the
page's run time, a basin map's time, an env step's time) sits in a generated block: an inline
``<!-- n:KEY -->TEXT<!-- /n -->`` or a ``<!-- table:NAME -->`` (`agents.results.numbers`), a
``<!-- numbers:NAME -->`` sentence (`agents.results.prose`) or the README's headline table
(`agents.results.headline`). The blocks must be up to date, and a mutation of any of them (a
number changed by one in its last digit, or the block attributed to another controller) must
make the check fail. Outside the blocks, a sentence (or a clause between semicolons, or a
table under its caption) that quotes such a number must say that it is another measurement
(the validation seed, a quick budget, a history, a dated run, a script's own output);
otherwise it is an offender.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from agents.results.numbers import (
    INLINE,
    QUANTITIES,
    TABLE,
    Sources,
    parse_key,
    stale_blocks,
    table,
    update_text,
    value,
)
from agents.results.prose import BLOCK, doc_files, load_numbers
from agents.results.prose import update_text as update_sentences

ROOT = Path(__file__).resolve().parent.parent
HEADLINE_BLOCK = re.compile(r"<!-- headline:start -->.*?<!-- headline:end -->", re.S)
# a passage that says it is about another measurement than the committed page's
OTHER = re.compile(
    r"validation|seed\s+777|seeds?\s+20\d\d|seed\s+2024|quick\s+budget|budget\s+quick|"
    r"--budget\s+quick|--budget\s+test|test\s+budget|[Hh]istory|archived|[Tt]he\s+literal\s+reading|"
    r"\b20\d\d-\d\d-\d\d\b|hold_eval|control_table|control_effort|rescue_eval|validation_curve|"
    r"stride_validation|adaptive_hold|adaptive_tables|hold_vs_delta|run\.json|[Aa]blation|earlier\s+(?:version|measure)|own\s+benchmark|measured\s+with\s+margins\s+v2|older\s+page|not\s+shipped|tried",
)
NUM = r"[+−-]?\d+(?:\.\d+)?"
NOT_A_COUNT = r"(?!\s?(?:%|strides|directions|plants|seeds|robots|runs|windows))"
DETECTORS = {
    "r50": re.compile(
        rf"\b(?:Δ\s?)?r50\b(?:[^\d\n.;|]{{0,30}}?)(?<![\wσ])({NUM})(?![\d.]){NOT_A_COUNT}"
    ),
    "σ50": re.compile(rf"σ50\b(?:[^\d\n.;|]{{0,30}}?)(?<![\wσ])({NUM})(?![\d.]){NOT_A_COUNT}"),
    "paired difference": re.compile(r"\bpaired\b[^\d\n.;|]{0,25}?([+−-]\d+\.\d+)"),
    "interval": re.compile(rf"({NUM})°?\s*\[{NUM}°?,\s*{NUM}°?\]"),
    "decision time": re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?(?:ms|µs)\b"),
    "ratio": re.compile(r"(\d+(?:\.\d+)?)\s?×\s*faster"),
    "hold count": re.compile(r"\b(?:holds?|held)\b[^.;|]*?\b(\d+(?:-\d+)?\s?(?:/|of)\s?\d+)"),
    "torque": re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?N\s?·?\s?m\b(?!\s?/)"),
    "page time": re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?min\b"),
    "basin-map time": re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?s\b"),
}
# a table whose header gives the unit: every number of its cells is in that unit
TABLE_UNIT = {
    "decision time": re.compile(r"\[(?:ms|µs)\]"),
    "page time": re.compile(r"\[min\]"),
    "basin-map time": re.compile(r"\[s\]|grid time"),
    "torque": re.compile(r"\[N ?·? ?m\]"),
}
ANY_NUMBER = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)(?![\w.]|\s?[×%])")
# what a detector needs around it to be a quote of a measurement
CONTEXT = {
    "decision time": re.compile(r"decid|decision|median|p50|p99|percentile", re.I),
    "hold count": re.compile(r"plant", re.I),
    "torque": re.compile(r"\bheld\b|\bhold", re.I),
    "page time": re.compile(r"page|compare", re.I),
    "basin-map time": re.compile(r"basin.map|64 ?× ?64", re.I),
}
# numbers that are definitions, not measurements
NOT_MEASURED = {
    "decision time": {"390", "1", "10"},  # a stride's duration; the real-time threshold; dt
    "torque": {"80", "40"},  # the torque limits
}


def _blank_blocks(text: str) -> str:
    """The generated blocks and fenced code replaced by a placeholder (the blocks' numbers
    are checked apart; code is commands, not quotes)."""
    for pat in (INLINE, TABLE, BLOCK, HEADLINE_BLOCK, re.compile(r"```.*?```", re.S)):
        text = pat.sub(lambda m: "§" + "\n" * m.group(0).count("\n"), text)
    return text


def _cells(row: str) -> list[str]:
    return [c.strip() for c in re.split(r"(?<!\\)\|", row.strip().strip("|"))]


def _clauses(para: str) -> list[str]:
    """The sentences of a paragraph, and their clauses between semicolons outside
    parentheses (a parenthesis is one clause with the text around it)."""
    out, start, depth = [], 0, 0
    for i, ch in enumerate(para):
        depth += {"(": 1, ")": -1}.get(ch, 0)
        ends = ch == "." and (i + 1 == len(para) or para[i + 1].isspace())
        if (ends or (ch == ";" and depth <= 0)) and para[start : i + 1].strip():
            out.append(para[start : i + 1].strip())
            start, depth = i + 1, (0 if ends else depth)
    if para[start:].strip():
        out.append(para[start:].strip())
    return out


def _passages(text: str):
    """(line, passage, other, table, context) outside the generated blocks and fenced code:
    the sentences (and clauses between semicolons) of each paragraph, and each cell of a
    table as "row label, column header: cell", which takes the mark of another measurement of
    its caption (the paragraph before the table), its header or its row, and has its caption
    as context (what the numbers are: a page's time, a decision's)."""
    text = _blank_blocks(text)
    line = 1
    caption_other, caption = False, ""
    for para in re.split(r"(\n\s*\n)", text):
        if not para.strip():
            line += para.count("\n")
            continue
        if not para.replace("§", "").strip():  # a code block between a caption and its table
            line += para.count("\n")
            continue
        rows = para.splitlines()
        if rows[0].lstrip().startswith("|"):
            header = _cells(rows[0])
            other = caption_other or bool(OTHER.search(rows[0]))
            for i, row in enumerate(rows[2:], start=2):
                cells = _cells(row)
                row_other = other or bool(OTHER.search(row))
                for j, cell in enumerate(cells[1:], start=1):
                    head = header[j] if j < len(header) else ""
                    yield line + i, f"{cells[0]}, {head}: {cell}", row_other, True, caption
        else:
            caption_other, caption = bool(OTHER.search(para)), para
            for s in _clauses(para):
                at = line + para[: para.find(s)].count("\n")
                yield at, s, bool(OTHER.search(s)), False, ""
        line += para.count("\n")


def offenders(text: str, name: str = "doc") -> list[str]:
    """Numbers of measurements quoted outside a generated block, in a passage that does not
    say it is another measurement."""
    found = []
    for line, s, other, in_table, context in _passages(text):
        if other:
            continue
        bare = re.sub(r"`[^`\n]*`", "`…`", s)  # code spans are names and commands
        for kind, pat in DETECTORS.items():
            ctx = CONTEXT.get(kind)
            if ctx is not None and not (ctx.search(bare) or ctx.search(context)):
                continue
            nums = pat.findall(bare)
            if in_table and kind in TABLE_UNIT and TABLE_UNIT[kind].search(bare):
                nums += ANY_NUMBER.findall(bare.split(": ", 1)[-1])
            for num in dict.fromkeys(nums):
                if num.lstrip("+−-") in NOT_MEASURED.get(kind, ()):
                    continue
                found.append(f"{name}:{line}: {kind} {num}: {s.strip()[:120]!r}")
    return found


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.name)
def test_no_measured_number_outside_a_block(path):
    """A quoted measurement sits in a generated block, or its passage names what it is."""
    if path.name in ("MARGINS.md", "REPRODUCTION.md"):  # generated pages: their own source
        pytest.skip("a generated page")
    assert offenders(path.read_text(), path.name) == []


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.name)
def test_the_blocks_are_up_to_date(path):
    """Every inline block is its JSON value (the command that rewrites them is named)."""
    text = path.read_text()
    stale = stale_blocks(text, Sources())
    assert stale == [], f"{path.name}: run `python -m agents.results.prose`: {stale}"
    assert update_sentences(text, load_numbers(), str(path)) == text, (
        f"{path.name}: run `python -m agents.results.prose`"
    )


def _mutations(text: str):
    """Each number of a block's text changed by one in its last digit, one at a time."""
    for m in re.finditer(r"\d+(?:\.\d+)?", text):
        digits = m.group(0)
        last = int(digits[-1])
        new = digits[:-1] + str((last + 1) % 10 if last != 9 else 8)
        yield text[: m.start()] + new + text[m.end() :]


def _all_blocks():
    for path in doc_files():
        for m in INLINE.finditer(path.read_text()):
            yield path, m


def _valued_blocks(sources):
    """The inline blocks whose source has their value (before a regeneration, a block of a
    JSON file the committed page does not have yet is reported by the up-to-date test)."""
    for path, m in _all_blocks():
        try:
            value(m.group("key"), sources)
        except ValueError:
            continue
        yield path, m


def test_every_quoted_number_changed_in_its_last_digit_fails():
    sources, n = Sources(), 0
    for path, m in _valued_blocks(sources):
        key, text = m.group("key"), m.group("text")
        for mutated in _mutations(text):
            block = f"<!-- n:{key} -->{mutated}<!-- /n -->"
            assert stale_blocks(block, sources), f"{path.name}: {key}: {mutated!r} passes"
            n += 1
    # the tables (the model-error section, the presets): each number changed is stale
    for path in doc_files():
        for m in TABLE.finditer(path.read_text()):
            try:
                table(m.group("name"), sources)
            except ValueError:
                continue  # its source is not committed yet (the up-to-date test says so)
            for mutated in _mutations(m.group("text")):
                block = (
                    f"<!-- table:{m.group('name')} -->{mutated}<!-- /table:{m.group('name')} -->"
                )
                assert stale_blocks(block, sources), f"{path.name}: table {m.group('name')}"
                n += 1
    # the generated sentences: each number changed is a stale block too
    numbers = load_numbers()
    for path in doc_files():
        for m in BLOCK.finditer(path.read_text()):
            for mutated in _mutations(m.group(2)):
                block = f"<!-- numbers:{m.group(1)} -->{mutated}<!-- /numbers:{m.group(1)} -->"
                assert update_sentences(block, numbers) != block, f"{path.name}: {mutated!r}"
                n += 1
    assert n >= 50, n  # the docs quote the page


def test_every_quoted_number_given_to_another_controller_fails():
    """A block moved to another column (or pair) whose value differs is stale."""
    sources, moved = Sources(), 0
    labels = set()
    for _path, m in _all_blocks():
        _q, args = parse_key(m.group("key"))
        if args:
            labels.add(args[0])
    for path, m in _valued_blocks(sources):
        q, args = parse_key(m.group("key"))
        if not args:
            continue
        for other in sorted(labels - {args[0]}):
            key = f"{q}({','.join([other, *args[1:]])})"
            try:
                theirs = value(key, sources)
            except ValueError:
                continue  # no such value for that column
            if theirs == m.group("text"):
                continue  # the same number: no wrong attribution to catch
            block = f"<!-- n:{key} -->{m.group('text')}<!-- /n -->"
            assert stale_blocks(block, sources), f"{path.name}: {key} passes"
            moved += 1
    assert moved >= 20, moved


def test_the_detector_finds_numbers_outside_blocks():
    """The sentences that contradicted the JSON before are caught, whatever their value."""
    bad = (
        "`mpc` decides in 0.114 ms at the median and 32.8 ms at the 99th percentile.\n\n"
        "The students decide in 21 µs per decision, 7× faster than `mpc`'s median.\n\n"
        "`mpc` reaches r50 0.294 on the test set.\n\n"
        "The best learned beats the LQR, +0.091 [0.075, 0.112].\n\n"
        "At ±5 % lqr holds 29/32 plants with 12 N·m on the held cycles.\n\n"
        "The whole results page takes 12.2 min from an empty cache.\n\n"
        "Basin maps (64×64): lqr 1.5 s, `mpc` 44.8 s.\n\n"
        "On validation, `mpc` decides in 0.114 ms at the median.\n"
    )
    found = offenders(bad)
    kinds = [f.split(": ")[1].split(" ")[0] for f in found]
    assert len(found) == 11, found  # the last paragraph is another measurement
    assert {"decision", "ratio", "r50", "interval", "hold", "torque", "page", "basin-map"} <= set(
        kinds
    ), kinds
    good = (
        "`mpc` reaches r50 <!-- n:r50(mpc) -->0.289<!-- /n --> and decides in "
        "<!-- n:p50ms(mpc) -->7.28<!-- /n --> ms at the median.\n"
    )
    assert offenders(good) == []


def test_a_block_of_an_unknown_quantity_or_column_is_one_line(tmp_path):
    import json

    assert parse_key("r50(mpc)") == ("r50", ["mpc"])
    for key in ("r51(mpc)", "r50(mpc,lqr)", "r50"):
        with pytest.raises(ValueError, match="n:"):
            parse_key(key)
    m = {"value": 0.25, "low": 0.2, "high": 0.3}
    (tmp_path / "headline.json").write_text(json.dumps({"rows": [{"label": "mpc", "r50": m}]}))
    (tmp_path / "columns.json").write_text(
        json.dumps({"columns": [{"label": "lqr", "r50": {**m, "value": 0.17}}]})
    )
    sources = Sources(tmp_path)
    assert value("r50ci(mpc)", sources) == "0.25 [0.2, 0.3]"
    assert value("r50(lqr)", sources) == "0.17"
    with pytest.raises(ValueError, match=r"columns.json: columns\[label='no-such'\]"):
        value("r50(no-such)", sources)
    with pytest.raises(ValueError, match=r"model_error.json: missing \(written by `bound-env"):
        value("hold(lqr,pm5)", sources)
    doc = "r50 <!-- n:r50(lqr) -->0.18<!-- /n --> and <!-- n:hold(lqr,pm5) -->1/2<!-- /n -->"
    errors: list = []
    assert update_text(doc, sources, "doc", errors).startswith("r50 <!-- n:r50(lqr) -->0.17<")
    assert len(errors) == 1 and "model_error.json" in errors[0]


def test_every_quantity_is_documented():
    for q, (nargs, what, fn) in QUANTITIES.items():
        assert what and callable(fn) and nargs in (0, 1, 2), q


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.name)
def test_no_line_starts_with_an_inline_block(path):
    """A line that starts with an HTML comment ends the paragraph or the list item before it
    in Markdown (the number then renders on its own); blocks sit inside their sentence."""
    for i, line in enumerate(path.read_text().splitlines(), start=1):
        assert not re.match(r"\s*<!-- (n:|numbers:)", line), f"{path.name}:{i}: {line[:60]}"
