"""Every number the docs quote of a measurement comes from the one JSON value it names.

A number in docs/**/*.md or README.md that quotes a measurement (r50, Δr50, an interval, a
time in any unit, a speed ratio, a hold count, a torque, basin_min, e_max, an angle where the
MFPT or the terrain's survival falls) sits in a generated block bound to its source: an inline
``<!-- n:KEY -->TEXT<!-- /n -->`` (a quantity of the page's JSON, or ``data(FILE,PATH)`` of a
named data file) or a ``<!-- table:NAME -->`` (`agents.results.numbers`), a
``<!-- numbers:NAME -->`` sentence (`agents.results.prose`) or the README's headline table
(`agents.results.headline`). The blocks must be up to date, a mutation of any of them (a number
changed by one in its last digit, or the block attributed to another controller) must make the
check fail, and a block in a sentence that names a controller must name that controller.

No word of a passage exempts it. A number that is not a measurement (a setting, a value of the
paper's tables, a seed, a definition) is recognised by a narrow rule only: it sits in a
``<!-- c:REASON -->TEXT<!-- /c -->`` marker (`CONSTANT`, REASON one of `REASONS`) or matches
one of `CONSTANTS`. Passages not bound yet are listed one by one in `UNBOUND`, which may only
shrink.
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
# an explicit mark of a number that is not a measurement, and why
CONSTANT = re.compile(r"<!-- c:(?P<why>[a-z-]+) -->(?P<text>.*?)<!-- /c -->", re.S)
REASONS = {
    "setting": "a parameter, option or threshold the code sets (a tolerance, a budget)",
    "paper": "a value of the paper's tables",
    "seed": "a seed, a version, a commit, a section or equation number",
    "definition": "a number fixed by a definition (a count by construction, a level)",
}
# constant-like patterns: numbers that are never measurements, wherever they appear
CONSTANTS = [
    (re.compile(r"(?<![\w.])(?:80|40)\s?N\s?·?\s?m\b"), "the torque limits (v1, v0)"),
    (re.compile(r"(?<![\w.])390\s?ms\b"), "a stride's duration, the real-time budget"),
    (re.compile(r"(?<![\w.])1\s?ms\b"), "the real-time threshold of a decision"),
    (re.compile(r"±\s?\d+(?:\.\d+)?\s?%"), "a model-error spec's size"),
    (re.compile(r"(?<![\w.])100\s+strides\b"), "the MFPT level, a hold's length"),
    (
        re.compile(
            r"\bdt`?\s*=?\s*(?:10\s?ms|0\.01\s?s)\b|\b10\s?ms(?=\)?\s+(?:control|grid))"
            r"|control interval \(10 ms\)"
        ),
        "the control interval dt of the step env",
    ),
]
NUM = r"[+−-]?\d+(?:\.\d+)?"
NOT_A_COUNT = r"(?!\s?(?:%|strides|directions|plants|seeds|robots|runs|windows))"
TIME_UNIT = r"(?:ms|µs|us|s|sec|secs|seconds?|milliseconds?|microseconds?|min|mins|minutes?|hours?)"
DETECTORS = {
    "r50": re.compile(
        rf"\b(?:Δ\s?)?r50\b(?:[^\d\n.;|]{{0,30}}?)(?<![\wσ])({NUM})(?!\.?\d){NOT_A_COUNT}"
    ),
    "σ50": re.compile(
        rf"σ(?:50|100)\b(?:[^\d\n.;|]{{0,30}}?)(?<![\wσ])({NUM})(?!\.?\d){NOT_A_COUNT}"
    ),
    "basin_min/e_max": re.compile(
        rf"\b(?:basin_min|basin min|e_max|e max)\b(?:[^\d\n.;|]{{0,30}}?)(?<![\w])({NUM})(?!\.?\d)"
    ),
    "paired difference": re.compile(r"\bpaired\b[^\d\n.;|]{0,25}?([+−-]\d+\.\d+)"),
    "interval": re.compile(rf"({NUM})°?\s*\[{NUM}°?,\s*{NUM}°?\]"),
    "time": re.compile(rf"(?<![\w.,-])(\d+(?:\.\d+)?(?:e[+-]?\d+)?)\s?{TIME_UNIT}(?![\w/])"),
    "ratio": re.compile(
        r"(?<![\w.×])(\d+(?:\.\d+)?)\s?(?:×|x|times)(?!\s?\d)"
        r"(?:\s*(?:faster|slower|more|less|fewer|larger|smaller|longer|shorter|as\b))?"
    ),
    "hold": re.compile(
        r"(?<![\w./-])(\d+\s?/\s?\d+)(?![\w./])"
        r"|\b(\d+\s+of\s+\d+)\b(?!\s?%|\.\d)"
        r"|\b(\d+)\s+of\s+(?:the\s+|its\s+|their\s+|\d+\s+)?(?:[^\s.;|]+\s+){0,3}?"
        r"(?:plants|robots)\b"
        r"|\b(?:holds?|held|keeps?|kept)\s+(\d+)\s+(?:[^\s.;|]+\s+){0,2}?(?:plants|robots)\b"
    ),
    "torque": re.compile(r"(?<![\w.])(\d+(?:\.\d+)?(?:e[+-]?\d+)?)\s?N\s?·?\s?m\b(?!\s?/)"),
    "angle": re.compile(r"(?<![\w.±])(\d+(?:\.\d+)?)\s?(?:°|deg\b)"),
}
# a table whose header gives the unit: every number of its cells is in that unit
TABLE_UNIT = {
    "time": re.compile(r"\[(?:ms|µs|s|min)\]|grid time"),
    "torque": re.compile(r"\[N ?·? ?m\]"),
    "hold": re.compile(r"held\b"),
}
ANY_NUMBER = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)(?![\w.]|\s?[×%])")
# what a detector needs around it to be a quote of a measurement (its unit is not enough)
CONTEXT = {
    "hold": re.compile(r"plant|robot|\bhold|\bheld|\bkeep|\bkept|\blos[et]", re.I),
    "angle": re.compile(r"MFPT|σ|sigma|terrain|slope|survival|falls", re.I),
}
# the controllers a sentence may name, bare (``mpc``, the LQR) or in a code span (`default`)
CONTROLLERS = (
    "passive", "lqr", "lqr-of", "lqr+of", "deadbeat", "mpc", "mpc+of", "mpc-adaptive",
    "mpc-adaptive-bounded", "mpc-privileged", "mpc-true-plant", "fine-tuned", "finetuned",
    "default", "default+of",
    "step-ppo", "ppo-v1", "learned", "adaptive", "adaptive-nohist", "adaptive-nominal",
    "cycle-teacher", "cycle-teacher-blind1", "cycle-teacher-blind2", "stride-residual",
    "warm-started", "distilled",
)  # fmt: skip
BARE = {"lqr", "mpc", "lqr-of", "mpc-adaptive", "mpc-adaptive-bounded", "mpc-privileged",
        "fine-tuned", "step-ppo", "ppo-v1", "lqr+of", "mpc+of", "default+of"}  # fmt: skip
_NAMES = "|".join(re.escape(c) for c in sorted(CONTROLLERS, key=len, reverse=True))
NAMED = re.compile(rf"(?<![\w+-])(`?)({_NAMES})(?![\w+-])(`?)", re.I)
ALIASES = {"finetuned": "fine-tuned", "lqr+of": "lqr-of"}


def _blank_blocks(text: str) -> str:
    """The generated blocks, the constant markers and fenced code replaced by a placeholder
    (the blocks' numbers are checked apart; code is commands, not quotes)."""
    for pat in (INLINE, TABLE, BLOCK, HEADLINE_BLOCK, CONSTANT, re.compile(r"```.*?```", re.S)):
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
    """(line, passage, table, context) outside the generated blocks and fenced code: the
    sentences (and clauses between semicolons) of each paragraph, and each cell of a table as
    "row label, column header: cell", with its caption (the paragraph before it) as context."""
    text = _blank_blocks(text)
    line, caption = 1, ""
    for para in re.split(r"(\n\s*\n)", text):
        if not para.strip() or not para.replace("§", "").strip():
            line += para.count("\n")
            continue
        rows = para.splitlines()
        if rows[0].lstrip().startswith("|"):
            header = _cells(rows[0])
            for i, row in enumerate(rows[2:], start=2):
                cells = _cells(row)
                for j, cell in enumerate(cells[1:], start=1):
                    head = header[j] if j < len(header) else ""
                    yield line + i, f"{cells[0]}, {head}: {cell}", True, caption
        else:
            caption = para
            for s in _clauses(para):
                at = line + para[: para.find(s)].count("\n")
                yield at, s, False, ""
        line += para.count("\n")


def _bare(s: str) -> str:
    """A passage with its code spans that hold a digit (commands, paths, settings) blanked,
    and its constants (`CONSTANTS`) removed."""
    s = re.sub(r"`[^`\n]*\d[^`\n]*`", "`…`", s)
    for pat, _why in CONSTANTS:
        s = pat.sub("…", s)
    return s


def offenders(text: str, name: str = "doc") -> list[str]:
    """Each number of a measurement outside a bound block: ``FILE:LINE: NUMBER: unbound
    (KIND): 'PASSAGE'``."""
    found = []
    for line, s, in_table, context in _passages(text):
        bare = _bare(s)
        for kind, pat in DETECTORS.items():
            ctx = CONTEXT.get(kind)
            if ctx is not None and not (ctx.search(bare) or ctx.search(context)):
                continue
            nums = [
                next(g for g in m if g) if isinstance(m, tuple) else m for m in pat.findall(bare)
            ]
            if in_table and kind in TABLE_UNIT and TABLE_UNIT[kind].search(bare.split(": ")[0]):
                nums += ANY_NUMBER.findall(bare.split(": ", 1)[-1])
            for num in dict.fromkeys(nums):
                found.append(f"{name}:{line}: {num}: unbound ({kind}): {s.strip()[:100]!r}")
    return found


def _named(text: str) -> list[tuple[int, str]]:
    """(position, controller) of each controller ``text`` names: in a code span, or bare when
    the name cannot be an English word (`BARE`)."""
    out = []
    for m in NAMED.finditer(text):
        name = m.group(2).lower()
        if (m.group(1) and m.group(3)) or name in BARE:
            out.append((m.start(), ALIASES.get(name, name)))
    return out


def key_controllers(key: str) -> set[str]:
    """The controllers a block's key names (its arguments; a data block's path; a Δr50 under
    model error's reference, the model-error section's)."""
    named = {ALIASES.get(n, n) for n in (m.group(2).lower() for m in NAMED.finditer(key))}
    if key.startswith("dr50mm("):
        named.add(Sources()._load("model_error").get("reference"))
    return named


def _around(text: str, at: int) -> tuple[str, str, bool]:
    """The text of the clause that holds the position ``at``, before it and after it, without
    the blocks' comments; in a table row, the row's label and the cell's column header."""
    line_start = text.rfind("\n", 0, at) + 1
    end = text.find("\n", at)
    line = text[line_start : end if end >= 0 else len(text)]
    if line.lstrip().startswith("|"):
        col = text[line_start:at].count("|") - 1
        start = text.rfind("\n\n", 0, line_start) + 2
        header = _cells(text[start : text.find("\n", start)])
        return _cells(line)[0], header[col] if 0 <= col < len(header) else "", True
    para_start = text.rfind("\n\n", 0, at) + 2
    head = BLOCK.sub(". ", text[para_start:at])  # a generated sentence ends a clause
    cut = max((m.end() for m in re.finditer(r"[.;](?=\s)|^\s*[-*] ", head, re.M)), default=0)
    end = text.find("\n\n", at)
    tail = INLINE.sub("", text[at : end if end >= 0 else len(text)], count=1)
    tail = re.split(r"[.;](?=\s)|<!-- n:", tail, maxsplit=1)[0]  # up to the next number
    strip = re.compile(r"<!--.*?-->", re.S)
    return strip.sub("", head[cut:]), strip.sub("", tail), False


# "2.6 s for `lqr`": the controller named right after the number, by a preposition
POSTFIX = re.compile(r"^\W{0,3}(?:[^\s`]+\s+){0,1}(?:for|of|by|with|from|on)\s+(?:the\s+)?$")


def sentence_controller(text: str, at: int) -> str | None:
    """The controller the sentence (or table row) of the position ``at`` quotes there: one
    named right after the number by a preposition, else the last one named before it in its
    clause, else the first one after it; in a table, the row label's first, else its
    header's."""
    before, after, in_table = _around(text, at)
    if in_table:
        named = _named(before) or _named(after)
        return named[0][1] if named else None
    post = _named(after)
    if post and POSTFIX.match(after[: post[0][0]]):
        return post[0][1]
    pre = _named(before)
    if pre:
        return pre[-1][1]
    return post[0][1] if post else None


def misattributed(text: str, name: str = "doc") -> list[str]:
    """Each block whose sentence names a controller its key does not: ``FILE:LINE: TEXT:
    wrong controller: KEY in a sentence about C``."""
    out = []
    for m in INLINE.finditer(text):
        q, args = parse_key(m.group("key"))
        if q != "data" and not args:
            continue  # the page's run, an env's step: no controller
        ctrl = sentence_controller(text, m.start())
        if ctrl is not None and ctrl not in key_controllers(m.group("key")):
            line = text.count("\n", 0, m.start()) + 1
            out.append(
                f"{name}:{line}: {m.group('text')}: wrong controller: {m.group('key')} in a "
                f"sentence about {ctrl}"
            )
    return out


def bad_constants(text: str, name: str = "doc") -> list[str]:
    """Each constant marker of an unknown reason, or without a number."""
    return [
        f"{name}:{text.count(chr(10), 0, m.start()) + 1}: c:{m.group('why')}: "
        + ("not a reason" if m.group("why") not in REASONS else "holds no number")
        for m in CONSTANT.finditer(text)
        if m.group("why") not in REASONS or not re.search(r"\d", m.group("text"))
    ]


UNBOUND = ROOT / "tests" / "data" / "unbound_numbers.txt"
# the passages not bound yet (`UNBOUND`, one a line): this number may only fall
MAX_UNBOUND = 0


def _checked_docs():
    """The docs the check reads: every page but the generated ones (their own source)."""
    return [p for p in doc_files() if p.name not in ("MARGINS.md", "REPRODUCTION.md")]


def _without_line(finding: str) -> str:
    return re.sub(r"^([^:]+):\d+: ", r"\1: ", finding)


def _unbound_allowed() -> list[str]:
    if not UNBOUND.is_file():
        return []
    return [x for x in UNBOUND.read_text().splitlines() if x.strip() and not x.startswith("#")]


def test_no_measured_number_outside_a_block():
    """Every number of a measurement in the docs sits in a block bound to its source, and each
    block names the controller of its sentence; nothing is exempt by its topic. The passages
    not bound yet are listed in `UNBOUND`, which may only shrink."""
    from collections import Counter

    found, wrong = [], []
    for path in _checked_docs():
        text, name = path.read_text(), str(path.relative_to(ROOT))
        found += offenders(text, name)
        wrong += misattributed(text, name) + bad_constants(text, name)
    assert wrong == [], "\n".join(wrong)
    allowed = Counter(_unbound_allowed())
    new = [f for f in found if (Counter({_without_line(f): 1}) - allowed)]
    have = Counter(_without_line(f) for f in found)
    extra = have - allowed
    assert not extra, (
        "numbers not bound to a source:\n"
        + "\n".join(f for f in found if _without_line(f) in extra)
        + f"\n({len(new)} of them new)"
    )
    gone = allowed - have
    assert not gone, f"bound now: remove from {UNBOUND.name}:\n" + "\n".join(gone)
    assert sum(allowed.values()) <= MAX_UNBOUND, f"{UNBOUND.name} grew: bind the numbers"


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
        "Basin maps (64×64): lqr 1.5 s, `mpc` 44.8 s.\n"
    )
    found = offenders(bad)
    kinds = {f.split("(")[1].split(")")[0] for f in found}
    assert len(found) == 11, found
    assert {"time", "ratio", "r50", "interval", "hold", "torque"} <= kinds, kinds
    good = (
        "`mpc` reaches r50 <!-- n:r50(mpc) -->0.289<!-- /n --> and decides in "
        "<!-- n:p50ms(mpc) -->7.28<!-- /n --> ms at the median.\n"
    )
    assert offenders(good) == []


# every escape of the topic-word check (issue: "Sentences with made-up numbers pass"), and
# passages whose topic words exempted them before; each must be flagged
ESCAPES = [
    "`lqr` holds 20 of the plants at ±10 %.",
    "`mpc-adaptive` loses 6 of 32 at ±15 %.",
    "The adaptive MPC keeps 20/32 robots on their cycle.",
    "It holds 20 plants at ±15 %.",
    "A decision takes 1.6 milliseconds.",
    "The stride is 150 times faster than the oracle.",
    "The stride is 95× faster than the oracle.",
    "One stride is 83× the oracle's speed.",
    "The design reaches basin_min 0.200 and e_max 0.050.",
    "The page took 9.9 minutes.",
    "step-ppo's column took 816 s.",
    "The run took 2 hours.",
    "The fine-tuned policy's MFPT falls to 100 strides at 0.95°.",
    "On the validation seed `mpc` reaches r50 0.311.",
    "History: the first MPC decided in 3.1 ms at the median.",
    "We tried a longer horizon: r50 0.301.",
    "The literal reading's saddle has e_max 1.364.",
    "`scripts/hold_vs_delta.py` gives `mpc` 15/32 at ±10 % with 16.8 N·m.",
    "Measured on 2026-12-04: the page took 18.6 min.",
]


@pytest.mark.parametrize("sentence", ESCAPES)
def test_every_escape_of_the_topic_check_is_flagged(sentence):
    found = offenders(sentence + "\n")
    assert found, sentence
    assert all("unbound (" in f for f in found)


def test_a_constant_is_recognised_only_by_its_marker_or_pattern():
    assert offenders("The spine torque is limited to 80 N·m at action 1.\n") == []
    assert offenders("The search stops after <!-- c:setting -->20<!-- /c --> s.\n") == []
    assert offenders("The search stops after 20 s.\n")  # the same number unmarked
    assert bad_constants("after <!-- c:because -->20<!-- /c --> s") != []
    assert bad_constants("after <!-- c:setting -->twenty<!-- /c --> s") != []


def test_a_block_must_name_the_controller_of_its_sentence():
    """A block in a sentence about another controller than its key's is flagged, in prose and
    in a table's row."""
    ok = "`lqr` holds <!-- n:hold(lqr,pm5) -->29/32<!-- /n --> plants.\n"
    assert misattributed(ok) == []
    bad = "`lqr` holds <!-- n:hold(mpc,pm5) -->28/32<!-- /n --> plants.\n"
    (msg,) = misattributed(bad, "docs/x.md")
    assert msg.startswith("docs/x.md:1: 28/32: wrong controller: hold(mpc,pm5)"), msg
    assert msg.endswith("in a sentence about lqr")
    post = "a map takes <!-- n:basinmap(lqr) -->3.4<!-- /n --> s for `mpc`.\n"
    assert misattributed(post) != []
    row = (
        "| plant | held |\n| --- | --- |\n| `lqr` | <!-- n:hold(default,pm5) -->28/32<!-- /n --> |"
    )
    assert misattributed(row) != []
    data = (
        "`lqr` holds <!-- n:data(data/hold_vs_delta.json,columns.mpc.rows[delta=0.1]) -->"
        "13/32<!-- /n --> plants.\n"
    )
    assert misattributed(data) != []
    assert misattributed(data.replace("`lqr`", "`mpc`")) == []


def test_measured_once_entries_match_their_sources():
    """A one-off measurement of docs/data/measured_once.json that is a value of a committed
    file (a gait's e_max, its stride period) is that value; each entry says what and how."""
    import json

    import yaml

    entries = json.loads((ROOT / "docs/data/measured_once.json").read_text())["entries"]
    sourced = 0
    for name, e in entries.items():
        v = e.get("value")
        count = isinstance(v, dict) and set(v) == {"k", "n"}
        assert e.get("what") and e.get("how") and (count or isinstance(v, (int, float))), name
        src = e.get("source")
        if not src:
            continue
        d = yaml.safe_load((ROOT / src["file"]).read_text())
        for k in src["path"].split("."):
            d = d[int(k)] if isinstance(d, list) else d[k]
        want = float(sum(d)) if src.get("sum") else float(d)
        assert e["value"] == pytest.approx(want, rel=1e-12), f"{name}: {src}"
        sourced += 1
    assert sourced >= 3


def test_a_data_block_is_its_files_value_in_its_form(tmp_path):
    import json

    (tmp_path / "data").mkdir()
    rows = {"columns": {"mpc": {"rows": [{"delta": 0.05, "k": 28, "n": 32, "e": 11.90327}]}}}
    (tmp_path / "data" / "h.json").write_text(json.dumps(rows))
    (tmp_path / "r.jsonl").write_text('{"policy": "lqr", "t": 0.00123}\n{"policy": "mpc"}\n')
    s = Sources(tmp_path)
    path = "columns.mpc.rows[delta=0.05]"
    assert value(f"data(data/h.json,{path})", s, "1/2") == "28/32"
    assert value(f"data(data/h.json,{path}.e)", s, "12") == "12"
    assert value(f"data(data/h.json,{path}.e)", s, "11.9033") == "11.9033"
    assert value("data(r.jsonl,[policy=lqr].t,ms)", s, "1.2") == "1.2"
    assert value("data(r.jsonl,0.t,us)", s, "1230") == "1230"
    block = f"<!-- n:data(data/h.json,{path}.e) -->11.91<!-- /n -->"
    (msg,) = stale_blocks(block, s)
    assert "'11.91', its source says '11.90'" in msg
    for key, match in (
        ("data(data/h.json,columns.lqr)", r"docs/data/h.json: columns.lqr: missing"),
        ("data(r.jsonl,[policy=ppo].t)", r"0 items match"),
        ("data(data/x.json,a)", r"x.json: missing"),
        ("data(../secret.json,a)", r"data takes \(FILE,PATH"),
        ("data(data/h.json,columns)", r"an item, not a number"),
        ("data(r.jsonl,0.t,hours)", r"unit 'hours'"),
    ):
        with pytest.raises(ValueError, match=match):
            value(key, s, "1.0")
    with pytest.raises(ValueError, match=r"not a number to compare"):
        value(f"data(data/h.json,{path}.e)", s, "about 12")


def test_hold_eval_counts_are_its_rows_held_plants(tmp_path):
    """`holdevalk`, `holdevalbest` and `holdevalbelow` count a row's (or the test seeds')
    held plants of docs/hold_eval.jsonl; a best that another row beats is an error naming it."""
    import json

    def row(policy, seed, held, effort):
        return {"policy": policy, "delta": 0.05, "seed": seed, "measure": "mm_hold", "set": "",
                "n": len(held), "held": held, "tail_effort": effort}  # fmt: skip

    rows = [row("lqr", 777, [True, False], [3.0, None])]
    for seed in (2026, 2027, 2028):
        rows.append(row("lqr", seed, [True, True, False], [0.05, 2.0, None]))
        rows.append(row("mpc", seed, [seed == 2027, False, False], [0.01, None, None]))
    rows.append({**rows[1], "set": "other", "held": [True] * 3})  # another set: not counted
    (tmp_path / "hold_eval.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    s = Sources(tmp_path)
    assert value("holdevalk(lqr,0.05,777)", s) == "1"
    assert value("holdevalk(lqr,0.05,test)", s) == "6"
    assert value("holdevalk(mpc,0.05,test)", s) == "1"
    assert value("holdevalbelow(lqr,0.05,0.1)", s) == "3"
    assert value("holdevalbelow(lqr,0.05,2.5)", s) == "6"
    assert value("holdevalbest(lqr,0.05,2027)", s) == "2/3"
    with pytest.raises(ValueError, match=r"not the best at 0.05: lqr on seed 2026 holds 2/3"):
        value("holdevalbest(mpc,0.05,2027)", s)
    for key in ("holdevalk(ppo,0.05,777)", "holdevalk(lqr,0.1,777)", "holdevalk(lqr,0.05,1)"):
        with pytest.raises(ValueError, match=r"hold_eval.jsonl: \[policy="):
            value(key, s)


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
        assert what and callable(fn) and nargs in (0, 1, 2, 3), q


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.name)
def test_no_line_starts_with_an_inline_block(path):
    """A line that starts with an HTML comment ends the paragraph or the list item before it
    in Markdown (the number then renders on its own); blocks sit inside their sentence."""
    for i, line in enumerate(path.read_text().splitlines(), start=1):
        assert not re.match(r"\s*<!-- (n:|numbers:)", line), f"{path.name}:{i}: {line[:60]}"
