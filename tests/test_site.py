"""The built documentation site shows what its sources say.

``mkdocs build --strict`` (mkdocs.yml: the pages of docs/ and the API reference built from the
docstrings) into a temporary folder; in every page's HTML, outside code, no Markdown table row
is left as text (``| a | b |``: a table inside an HTML block without ``markdown="1"``, a
docstring's reStructuredText table) and no italic runs away (an ``_`` or ``*`` taken as the
start of an emphasis that swallows a paragraph).
"""

from __future__ import annotations

import html
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CODE = re.compile(r"<(pre|code)\b.*?</\1>", re.S)
TAG = re.compile(r"<[^>]+>")
EM = re.compile(r"<em>(.*?)</em>", re.S)
RAW_ROW = re.compile(r"^\s*\|[^|\n]+\|[^|\n]*\|", re.M)
RAW_BULLET = re.compile(r"^[ \t]*[*+-] [A-Za-z`]", re.M)  # a list item run into a paragraph
RST_TABLE = re.compile(r"^\s*={3,}(?:[ \t]+={3,})+\s*$", re.M)  # reStructuredText's table rules
MAX_EM_WORDS = 12  # an emphasis longer than this is an underscore or star taken for one
# what an emphasis that ran away holds or touches: the star or underscore of a name or a
# formula (``a * b``, ``_F``), or a table's rule
RUNAWAY = re.compile(r"\s[*_]|[*_]\s|={3,}")


def page_problems(page: str, name: str = "page") -> list[str]:
    """Raw table rows (Markdown or reStructuredText) and runaway italics in one page's HTML
    (code left out)."""
    body = CODE.sub("§", page)  # code stands for a word: a formula around it is text
    text = html.unescape(TAG.sub("", re.sub(r"<(p|li|td|th|div|h\d|br)\b", "\n<\\1", body)))
    found = [
        f"{name}: a raw table row: {m.group(0).strip()[:100]!r}" for m in RAW_ROW.finditer(text)
    ]
    found += [
        f"{name}: a reStructuredText table: {m.group(0).strip()[:60]!r}"
        for m in RST_TABLE.finditer(text)
    ]
    found += [
        f"{name}: a bullet in a paragraph: {m.group(0).strip()!r}…"
        for m in RAW_BULLET.finditer(text)
    ]
    for m in EM.finditer(body):
        inner = html.unescape(TAG.sub(" ", m.group(1)))
        words = inner.split()
        after = body[m.end() : m.end() + 1]
        if len(words) > MAX_EM_WORDS or RUNAWAY.search(inner) or after in ("*", "_"):
            found.append(f"{name}: a runaway italic: {' '.join(words[:10])}…")
    return found


def test_the_checker_finds_raw_rows_and_runaway_italics():
    bad = (
        "<p>| guard | value |\n| --- | --- |</p>"
        "<p>SHORT<em>B / _F l - min_leg_frac * l_bar (failure) falling leg stance GROUND "
        "height of back hip, spine joint, front hip</em></p>"
        "<p>=====  =====\nguard  value\nSHORT_B / <em>F   l - min_leg_frac * l_bar "
        "GROUND</em>*  height</p>"
        "<p>Liftoff: R = identity, a row of dR.\n* The stride ends on S_apex</p>"
    )
    assert len(page_problems(bad)) == 6  # 2 raw rows, an RST rule, 2 runaway italics, a bullet
    good = "<table><tr><td>a</td></tr></table><p><em>a word</em></p><pre>| a | b |</pre>"
    assert page_problems(good) == []


@pytest.mark.slow  # builds the whole site (the API reference imports every module): ~1 min
def test_the_built_site_renders_every_table_and_no_runaway_italic(tmp_path):
    if shutil.which("mkdocs") is None and not (Path(sys.executable).parent / "mkdocs").exists():
        pytest.skip("mkdocs is not installed (pip install -e '.[docs]')")
    site = tmp_path / "site"
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    problems = []
    pages = sorted(site.rglob("*.html"))
    assert len(pages) > 20
    for page in pages:
        if page.name == "404.html":
            continue
        problems += page_problems(page.read_text(), str(page.relative_to(site)))
    assert problems == [], "\n".join(problems)
