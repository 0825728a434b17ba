"""Numbers in prose come from JSON (issue 30).

Every decision time, r50 and decision-speed ratio quoted in docs/*.md and README.md equals a
value of the results page's JSON (``docs/headline.json``, ``docs/paired.json``, and the r50
row of ``docs/MARGINS.md``'s table, which `agents.results.compare` writes from the columns'
``margins.json``) to the digits it is printed with. The sentences that quote the page are
written from the JSON (``<!-- numbers:NAME -->`` blocks, `agents.results.prose`) and must be up to
date; a sentence (or a clause between semicolons) that quotes another measurement says so
(validation, a quick budget, the history of an archived policy) and is not checked against
the page.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from agents.results.prose import BLOCK, doc_files, load_numbers, main, update_text

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
# a passage about another measurement than the test-set page
OTHER = re.compile(
    r"validation|seed 777|quick budget|budget quick|--budget quick|History|archived|"
    r"[Tt]he literal reading|results page of \d{4}-\d\d-\d\d",  # a dated, older page
)
DECISION = re.compile(r"decid|decision|median|p50|p99|percentile", re.I)
TIME = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?(ms|µs)\b")
R50 = re.compile(r"\br50\s*(?:=|of|≈|is|at|:)?\s*([+−-]?\d+\.\d+)")
RATIO = re.compile(r"(\d+(?:\.\d+)?)\s?×\s*faster")
NOT_DECISIONS = {(390.0, "ms"), (1.0, "ms")}  # a stride's duration; the real-time threshold


def _tolerance(text: str) -> float:
    """Half a unit of the last printed digit (``130``: 5, ``2.55``: 0.005)."""
    if "." in text:
        return 0.5 * 10 ** -len(text.split(".")[1])
    zeros = len(text) - len(text.rstrip("0"))
    return 0.5 * 10**zeros


def _matches(text: str, values) -> bool:
    x = float(text.replace("−", "-"))
    tol = _tolerance(text.lstrip("+−-"))
    return any(abs(x - v) <= tol * (1 + 1e-9) for v in values)


def _page_values():
    head = json.loads((DOCS / "headline.json").read_text())
    paired = json.loads((DOCS / "paired.json").read_text())
    r50 = set()
    for row in head["rows"]:
        r50 |= {row["r50"][k] for k in ("value", "low", "high") if row["r50"][k] is not None}
    for e in paired["pairs"]:
        if "skipped" not in e:
            d = e["delta_r50"]
            r50 |= {v for k in ("delta", "low", "high") for v in (d[k], -d[k])}
    page = (DOCS / "MARGINS.md").read_text()
    row = next(line for line in page.splitlines() if line.startswith("| random-direction **r50**"))
    r50 |= {float(v) for v in re.findall(r"(?<![\w.])(\d+\.\d+)", row)}
    ctrls = paired["decision_times"]["controllers"]
    times = {"ms": set(), "µs": set()}
    for t in ctrls.values():
        for k in ("p50", "p99", "mean", "max"):
            times["ms"].add(1e3 * t[k])
            times["µs"].add(1e6 * t[k])
    ratios = {
        a[k] / b[k] for a in ctrls.values() for b in ctrls.values() for k in ("p50", "mean") if b[k]
    }
    return r50, times, ratios


def _passages(text: str):
    """Paragraphs (and table rows) outside the generated blocks, with their line numbers."""
    text = BLOCK.sub(lambda m: " " * len(m.group(0)), text)
    text = re.sub(r"<!-- headline:start -->.*?<!-- headline:end -->", "", text, flags=re.S)
    start = 0
    for para in re.split(r"\n\s*\n", text):
        rows = para.splitlines() if para.lstrip().startswith("|") else [para]
        for row in rows:
            yield text.count("\n", 0, text.find(row, start)) + 1, row
        start += len(para)


def _sentences(para: str):
    """Sentences and their clauses between semicolons."""
    return re.split(r"(?<=[.;])\s+", para)


def _offenders(path: Path):
    r50, times, ratios = _page_values()
    found = []
    for line, para in _passages(path.read_text()):
        for s in _sentences(para):
            if OTHER.search(s):  # a clause about another measurement
                continue
            if DECISION.search(s):
                for num, unit in TIME.findall(s):
                    if (float(num), unit) not in NOT_DECISIONS and not _matches(num, times[unit]):
                        found.append(f"{path.name}:{line}: {num} {unit} is no decision time")
                for num in RATIO.findall(s):
                    if not _matches(num, ratios):
                        found.append(f"{path.name}:{line}: {num}× is no ratio of decision times")
            for num in R50.findall(s):
                if not _matches(num, r50):
                    found.append(f"{path.name}:{line}: r50 {num} is not the page's")
    return found


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.name)
def test_no_decision_time_or_r50_differs_from_the_json(path):
    assert _offenders(path) == []


def test_the_generated_sentences_are_up_to_date(capsys):
    numbers = load_numbers()
    blocks = 0
    for f in doc_files():
        text = f.read_text()
        run = "python -m agents.results.prose"
        assert update_text(text, numbers, str(f)) == text, f"{f}: run {run}"
        blocks += len(BLOCK.findall(text))
    assert blocks >= 3
    assert main(["--check"]) == 0


def test_the_checker_finds_the_old_contradictions(tmp_path):
    """The sentences issue 30 found contradicting the JSON are flagged."""
    old = tmp_path / "old.md"
    old.write_text(
        "`mpc` decides in 0.114 ms at the median and 32.8 ms at the 99th percentile.\n\n"
        "The students decide in 21 µs per decision, 7× faster than `mpc`'s median.\n\n"
        "`mpc` reaches r50 0.294 on the test set.\n\n"
        "On validation, `mpc` decides in 0.114 ms at the median.\n"
    )
    found = _offenders(old)
    assert len(found) == 5, found  # the last paragraph is another measurement: not checked
    good = tmp_path / "good.md"
    good.write_text(
        "`mpc` decides in 7.28 ms at the median (p99 67.5 ms), the students in 27 µs; "
        "`mpc` reaches r50 0.289.\n"
    )
    assert _offenders(good) == []


def test_a_malformed_json_is_one_line(tmp_path, capsys, monkeypatch):
    import agents.results.prose as prose

    bad = tmp_path / "paired.json"
    bad.write_text(json.dumps({"pairs": [], "decision_times": {"controllers": {}}}))
    monkeypatch.setattr(prose, "PAIRED_JSON", bad)
    monkeypatch.setattr(
        prose,
        "load_numbers",
        lambda: prose.Numbers(prose.load_headline(), prose.read_json(bad), paired_path=bad),
    )
    assert main(["--check"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "paired.json" in err[0], err
