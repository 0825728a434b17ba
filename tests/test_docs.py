"""The documentation: the site builds strictly, every sub-command is on the command-line page,
and the README's and the results page's headline tables are the numbers of docs/headline.json
(which the page's full table shows too)."""

from __future__ import annotations

import html as html_text
import importlib.util
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents.results.compare import (
    HEADLINE,
    headline_numbers,
    headline_table,
    load_result,
    mfpt_sigma_100_interval,
)
from agents.results.headline import END, START, load_headline, main, render_block, update_readme
from bound_env.analysis.margins import column_styles
from bound_env.analysis.margins.stats import t_interval

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


@pytest.mark.slow  # 5-9 s on the shared 2-core machine
def test_mkdocs_build_strict(tmp_path):
    """`mkdocs build --strict`: a broken link, a page missing from the nav's files or a bad
    API reference fails, and so does a page whose HTML shows a table as raw text, an italic
    that ran away or a list run into a paragraph (`rendered_problems`). Skipped only where
    MkDocs is absent outside CI (CI=1 in .ci/run)."""
    if importlib.util.find_spec("mkdocs") is None:
        if os.environ.get("CI"):
            pytest.fail("mkdocs is not installed but CI is set: install the [docs] extra")
        pytest.skip("mkdocs not installed (the [docs] extra)")
    t0 = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=str(ROOT), NO_MKDOCS_2_WARNING="1")
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    pages = (
        "envs/passive-bound-v0",
        "envs/passive-bound-v1",
        "envs/passive-bound-literal-v1",
        "envs/passive-bound-stride-v1",
        "envs/passive-bound-rescue-v0",
        "envs/passive-bound-rescue-v1",
        "cli",
        "MARGINS",
    )
    for page in pages:
        assert (tmp_path / "site" / page / "index.html").is_file(), page
    html = (tmp_path / "site" / "envs" / "passive-bound-v0" / "index.html").read_text()
    assert "Version History" in html and "Observation Space" in html  # the class docstring
    html = (tmp_path / "site" / "envs" / "passive-bound-rescue-v0" / "index.html").read_text()
    assert "Version History" in html and "Starting State" in html and "TO FILL" not in html
    problems = rendered_problems(tmp_path / "site")
    assert not problems, "\n".join(problems[:20])
    print(f"mkdocs build: {time.perf_counter() - t0:.1f} s")


def _outside_code(html: str) -> str:
    return re.sub(r"<(pre|code|script|style)\b.*?</\1>", "", html, flags=re.S)


def _toc_entries(html: str) -> int:
    m = re.search(r'<nav class="md-nav md-nav--secondary"(.*?)</nav>', html, re.S)
    return len(re.findall(r'class="md-nav__link"', m.group(1))) if m else 0


def rendered_problems(site: Path) -> list[str]:
    """The known failure shapes of the built HTML, one line each: an italic run opened by the
    star of z* (``z<em>``, or a run closed by a literal star), a reStructuredText ``::`` at
    the end of a paragraph, a ``\\|`` (an escaped table pipe shown as typed, in text or
    code), a Markdown list run into its paragraph (a line starting with ``- `` inside a
    ``<p>``), and a long page (over 600 words) with fewer than 3 table-of-contents entries."""
    out = []
    for f in sorted(site.rglob("index.html")):
        if "search" in f.parts:
            continue
        page, html = str(f.parent.relative_to(site)), f.read_text()
        text = _outside_code(html)
        for m in re.finditer(r"(?<=[zZ])<em>|\*</em>", text):
            out.append(f"{page}: italics opened by z*: {text[max(0, m.start() - 50) : m.end()]!r}")
        for m in re.finditer(r"::\s*</p>", text):
            out.append(f"{page}: '::' leak: {text[max(0, m.start() - 60) : m.end()]!r}")
        body = re.search(r"<article.*?</article>", html, re.S)
        article = body.group(0) if body else html
        if "\\|" in re.sub(r"<script\b.*?</script>", "", article, flags=re.S):
            out.append(f"{page}: a \\| shows")
        for m in re.finditer(r"<p>((?:(?!</p>).)*?)</p>", text, re.S):
            if re.search(r"\n\s*(- |\d+\. )\S", m.group(1)):
                out.append(f"{page}: a list run into a paragraph: {m.group(1)[:80]!r}")
        words = len(re.sub(r"<[^>]+>", " ", article).split())
        if words > 600 and _toc_entries(html) < 3:
            out.append(f"{page}: {words} words but {_toc_entries(html)} contents entries")
        out += page_problems(html, page)
    return out


CODE = re.compile(r"<(pre|code)\b.*?</\1>", re.S)
TAG = re.compile(r"<[^>]+>")
EM = re.compile(r"<em>(.*?)</em>", re.S)
RAW_ROW = re.compile(r"^\s*\|[^|\n]+\|[^|\n]*\|", re.M)
RAW_BULLET = re.compile(r"^[ \t]*[*+] [A-Za-z`]", re.M)  # a * or + item run into a paragraph
RST_TABLE = re.compile(r"^\s*={3,}(?:[ \t]+={3,})+\s*$", re.M)  # reStructuredText's table rules
MAX_EM_WORDS = 12  # an emphasis longer than this is an underscore or star taken for one
# what an emphasis that ran away holds or touches: the star or underscore of a name or a
# formula (``a * b``, ``_F``), or a table's rule
RUNAWAY = re.compile(r"\s[*_]|[*_]\s|={3,}")


def page_problems(page: str, name: str = "page") -> list[str]:
    """Raw table rows (Markdown or reStructuredText) and runaway italics in one page's HTML
    (code left out)."""
    body = CODE.sub("§", page)  # code stands for a word: a formula around it is text
    text = html_text.unescape(TAG.sub("", re.sub(r"<(p|li|td|th|div|h\d|br)\b", "\n<\\1", body)))
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
        inner = html_text.unescape(TAG.sub(" ", m.group(1)))
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


def test_rendered_problems_finds_the_known_shapes(tmp_path):
    page = tmp_path / "p" / "index.html"
    page.parent.mkdir()
    page.write_text(
        "<article><p>x = (z - z<em>) / s, z</em> the cycle</p><p>a loop::</p>"
        "<p>text\n- item</p><code>NAME\\|PATH</code></article>"
    )
    kinds = [p.split(": ")[1] for p in rendered_problems(tmp_path)]
    assert any(k.startswith("italics") for k in kinds) and "'::' leak" in kinds
    assert "a \\| shows" in kinds and any(k.startswith("a list run") for k in kinds)
    page.write_text("<article><p>z* and <em>word</em> and <code>a::</code></p></article>")
    assert rendered_problems(tmp_path) == []


def budget_table() -> str:
    """The yardsticks page's table of budgets, from `BUDGETS` (what the code runs)."""
    from bound_env.analysis.margins import BUDGETS

    names = ("test", "quick", "standard", "full")
    b = {n: BUDGETS[n] for n in names}

    def seq(t):
        return f"{len(t)} ({min(t):g}-{max(t):g})"

    rows = [
        ("random directions (curve)", lambda x: str(x.curve_dirs)),
        ("curve sizes r", lambda x: seq(x.curve_sizes)),
        ("strides to return (basin, curve, push)", lambda x: str(x.basin_strides)),
        ("basin bisection steps", lambda x: str(x.basin_iters)),
        (
            "push kick sizes (ẋ, θ̇1) × samples",
            lambda x: f"{len(x.push_xdot)}, {len(x.push_th1dot)} × {x.push_samples}",
        ),
        ("window bisection steps × strides", lambda x: f"{x.window_iters} × {x.window_strides}"),
        (
            "ceiling: strides, steps, random profiles, optimizer iterations",
            lambda x: (
                f"{x.ceiling_strides}, {x.ceiling_iters}, {x.ceiling_random}, {x.ceiling_opt}"
            ),
        ),
        (
            "rough terrain: σ levels, runs × strides",
            lambda x: f"{len(x.terrain_sigmas)}, {x.terrain_runs} × {x.terrain_strides}",
        ),
        (
            "MFPT: σ levels, robots × horizon [strides]",
            lambda x: f"{len(x.mfpt_sigmas)}, {x.mfpt_robots} × {x.mfpt_strides}",
        ),
    ]
    lines = ["| setting | " + " | ".join(f"`{n}`" for n in names) + " |"]
    lines.append("| --- |" + " --- |" * len(names))
    lines += [f"| {label} | " + " | ".join(f(b[n]) for n in names) + " |" for label, f in rows]
    return "\n".join(lines)


def test_yardsticks_page_states_the_budgets_the_code_runs():
    """Each yardstick once, with its parameters: the budget table is `BUDGETS`, and the page
    carries no change log (that is CHANGELOG.md)."""
    page = (DOCS / "yardsticks.md").read_text()
    assert budget_table() in page
    for history in ("Margins v2", "Margins v3", "before the change", "298ea85", "2000 strides"):
        assert history not in page, history
    assert "## [Unreleased]" in (ROOT / "CHANGELOG.md").read_text()


def test_no_issue_numbers_in_product_text():
    from bound_env.commands.cli import build_parser

    texts = {p.name: p.read_text() for p in [ROOT / "README.md", *DOCS.rglob("*.md")]}
    sub = build_parser()._subparsers._group_actions[0]
    texts.update({f"{k} --help": v.format_help() for k, v in sub.choices.items()})
    for name, text in texts.items():
        assert not re.search(r"\b[Ii]ssues? #?\d+", text), name


def _subcommands() -> set[str]:
    from bound_env.commands.cli import build_parser

    action = build_parser()._subparsers._group_actions[0]
    return set(action.choices)


def test_every_subcommand_is_on_the_cli_page():
    text = (DOCS / "cli.md").read_text()
    rows = set(re.findall(r"^\| `([a-z-]+)` \|", text, re.M))  # the sub-commands table
    examples = set(re.findall(r"^bound-env ([a-z-]+)", text, re.M))
    commands = _subcommands()
    assert len(commands) >= 14
    assert commands <= rows, f"not in docs/cli.md's table: {sorted(commands - rows)}"
    assert commands <= examples, f"no example in docs/cli.md: {sorted(commands - examples)}"


def test_every_registered_env_id_has_a_page():
    import gymnasium as gym

    import bound_env  # noqa: F401 - registers the ids

    ids = [i for i in gym.registry if i.startswith("PassiveBound")]
    assert "PassiveBound-v0" in ids and "PassiveBoundStride-v1" in ids
    nav = (ROOT / "mkdocs.yml").read_text()
    for env_id in ids:
        slug = re.sub(
            r"(?<!^)(?=[A-Z])", "-", env_id
        ).lower()  # PassiveBound-v0 -> passive-bound-v0
        page = DOCS / "envs" / f"{slug}.md"
        assert page.is_file() and env_id in page.read_text(), env_id
        assert f"envs/{slug}.md" in nav, env_id


# The pages that show a shipped policy in the plain Gymnasium loop (the same code on each)
PLAIN_LOOP_PAGES = (
    "README.md",
    "docs/getting-started.md",
    "docs/learned.md",
    "docs/envs/passive-bound-v1.md",
)


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, re.S | re.M)


def test_plain_loop_example_runs():
    """The README's (and the site's) plain-loop example, run as written: a shipped stride
    controller on `gym.make("PassiveBound-v1")` with `act(obs, info)` bounds a whole episode
    (it falls within a few strides when the apex states do not reach it)."""
    examples = {}
    for name in PLAIN_LOOP_PAGES:
        blocks = [b for b in _python_blocks((ROOT / name).read_text()) if "act(obs, info)" in b]
        assert blocks, f"{name}: no plain-loop example"
        for b in blocks:
            assert 'gym.make("PassiveBound-v1")' in b and "obs, info = env.reset(" in b, name
            examples.setdefault(b, name)
    assert len(examples) == 1, "the plain-loop examples differ between pages"
    scope: dict = {}
    exec(next(iter(examples)), scope)  # noqa: S102 - the docs' code
    info = scope["info"]
    assert scope["truncated"] and not scope["terminated"] and info["failure"] is None
    assert info["stride"] >= 70  # 3000 control intervals of ~39 ms strides: ~76 strides
    assert scope["env"].unwrapped.task.max_torque == 80.0  # the published task


def test_results_page_commands_name_the_full_budget():
    """`compare` defaults to the quick budget: every command shown that writes the results
    page (`compare ... --docs docs`) names `--budget full`."""
    pages = [ROOT / "README.md", *sorted(DOCS.glob("*.md")), *sorted(DOCS.glob("*/*.md"))]
    found = 0
    for page in pages:
        if page.name in ("MARGINS.md", "REPRODUCTION.md"):
            continue
        for line in page.read_text().splitlines():
            if re.search(r"bound-env compare\b.*--docs docs\b", line):
                found += 1
                assert "--budget full" in line, f"{page.name}: {line.strip()}"
    assert found >= 3


def test_no_unfinished_pages():
    for page in [ROOT / "README.md", *DOCS.rglob("*.md")]:
        assert "TO FILL" not in page.read_text(), page
    assert not (DOCS / "changes").exists()  # folded into the site


# ---------------------------------------------------------------- the headline and its JSON


def test_readme_and_page_headline_are_the_json():
    head = load_headline()
    assert head["budget"] == "full" and head["seed"] == 12345
    assert [r["role"] for r in head["rows"]] == [h[0] for h in HEADLINE]
    readme = (ROOT / "README.md").read_text()
    block = readme[readme.index(START) : readme.index(END) + len(END)]
    assert block == render_block(head)  # the README's table is the JSON, rendered
    page = (DOCS / "MARGINS.md").read_text()
    table = headline_table(head)
    assert table in page
    assert page.index(table) < page.index("## All columns")  # first, the full table after it
    assert len(readme.splitlines()) <= 250
    for line in ("bash scripts/demo.sh", "bash scripts/test.sh"):  # the quick start, first
        assert readme.index(line) < readme.index("## Results")


def _full_table_row(page: str, title_start: str) -> list[str]:
    head = next(ln for ln in page.splitlines() if ln.startswith("| measure | "))
    labels = [c.strip().split(" (")[0] for c in head.strip("|").split("|")][1:]
    row = next(ln for ln in page.splitlines() if ln.startswith(f"| {title_start}"))
    cells = [c.strip() for c in row.strip("|").split("|")][1:]
    return dict(zip(labels, cells, strict=True))


def test_headline_json_is_what_the_full_table_shows():
    """Each headline number is the page's full-table cell of its column (3 significant
    digits), and a seed column's interval is the t interval of its per-seed values."""
    head = load_headline()
    page = (DOCS / "MARGINS.md").read_text()
    r50 = _full_table_row(page, "random-direction **r50**")
    mfpt = _full_table_row(page, "rough terrain σ at which the **MFPT**")
    for row in head["rows"]:
        for key, cells in (("r50", r50), ("mfpt_sigma_100_deg", mfpt)):
            m, cell = row[key], cells[row["label"]]
            assert cell.startswith(f"{m['value']:.3g}"), (row["label"], key, cell)
            if "per_seed" in m:
                ti = t_interval(m["per_seed"])
                assert (ti["mean"], ti["low"], ti["high"]) == (m["value"], m["low"], m["high"])
                assert cell.startswith(f"{m['value']:.3g} [{m['low']:.3g}, {m['high']:.3g}]")
            elif key == "r50":
                assert f"Wilson-based [{m['low']:.3g}, {m['high']:.3g}]" in cell
            assert m["low"] <= m["value"] <= m["high"]


def test_headline_cli_check(tmp_path, capsys):
    readme = tmp_path / "README.md"
    readme.write_text((ROOT / "README.md").read_text())
    assert main(["--readme", str(readme), "--check"]) == 0
    text = readme.read_text()
    readme.write_text(text.replace("| **lqr** |", "| **lqr (edited)** |"))
    assert main(["--readme", str(readme), "--check"]) == 1
    assert main(["--readme", str(readme)]) == 0 and readme.read_text() == text
    readme.write_text("no markers\n")
    assert main(["--readme", str(readme)]) == 2
    assert "README.md: no <!-- headline:start -->" in capsys.readouterr().err
    with pytest.raises(ValueError, match="no <!-- headline:start -->"):
        update_readme("text", load_headline())
    bad = tmp_path / "h.json"
    bad.write_text("{}")
    with pytest.raises(ValueError, match="h.json: budget: missing"):
        load_headline(bad)


def _run(r50, ci, mfpt=None, label="x"):
    return {
        "label": label,
        "basin_curve": {"r50": r50, "r50_ci": ci},
        "mfpt_sigma_100_deg": mfpt,
        "mfpt": [],
    }


def test_headline_numbers_from_groups():
    groups = [
        {"label": "passive", "gait": "default", "policies": ["passive"],
         "runs": [_run(0.05, [0.04, 0.06], 0.2)]},
        {"label": "passive", "gait": "literal-cycle", "policies": ["passive"],
         "runs": [_run(0.0, [0.0, 0.0])]},
        {"label": "fine-tuned", "gait": "default", "policies": ["a", "b", "c"],
         "runs": [_run(0.26, None, 0.7), _run(0.27, None, 0.8), _run(0.25, None, 0.75)]},
    ]  # fmt: skip
    head = headline_numbers(groups, "quick", 7)
    assert [r["label"] for r in head["rows"]] == ["passive", "fine-tuned"]  # order of HEADLINE
    p, f = head["rows"]
    assert (p["r50"]["value"], p["r50"]["low"], p["r50"]["high"]) == (0.05, 0.04, 0.06)
    assert p["mfpt_sigma_100_deg"]["low"] is None  # no MFPT curve: no interval
    ti = t_interval([0.26, 0.27, 0.25])
    assert f["r50"]["value"] == ti["mean"] and f["r50"]["high"] == ti["high"]
    assert f["r50"]["interval"] == "Student-t over 3 seeds"
    table = headline_table(head)
    assert table.count("\n") == 3 and "| **passive** |" in table and "[—, —]" in table


def test_mfpt_interval_brackets_the_estimate():
    from bound_env.analysis.margins.stats import mfpt_crossing, mfpt_estimate

    sig = [0.1, 0.2, 0.4, 0.8]
    m = []
    for s, k in zip(sig, (0, 3, 40, 200), strict=True):
        e = mfpt_estimate(4000, k)
        m.append({"sigma_deg": s, **e})
    r = {"mfpt": m}
    est = mfpt_crossing(sig, [e["mfpt"] for e in m], [e["lower_bound"] for e in m])
    lo, hi = mfpt_sigma_100_interval(r)
    assert lo < est < hi and 0.2 < lo and hi < 0.8
    assert mfpt_sigma_100_interval({"mfpt": []}) == [None, None]


def test_load_result_refuses(tmp_path):
    with pytest.raises(ValueError, match="margins.json: no margins.json"):
        load_result(tmp_path / "margins.json", "full", 12345)
    f = tmp_path / "margins.json"
    f.write_text(json.dumps({"budget": "quick", "seed": 12345, "basin_curve": {}}))
    with pytest.raises(ValueError, match="budget 'quick'"):
        load_result(f, "full", 12345)
    f.write_text("[")
    with pytest.raises(ValueError, match="not a margins result"):
        load_result(f, "full", 12345)


def test_column_styles_unique_and_fixed():
    from agents.results.compare import COLUMN_STYLES, default_entries

    labels = [e[0] for e in default_entries()] + ["extra one", "extra two"]
    st = column_styles(labels, COLUMN_STYLES)
    pairs = [(st[lab]["color"], st[lab]["ls"]) for lab in labels]
    assert len(set(pairs)) == len(labels)  # one colour and line style per column
    assert st["passive"] == COLUMN_STYLES["passive"]
    if "lqr literal" in st:
        assert st["lqr literal"]["color"] != st["passive"]["color"]
    many = column_styles([f"c{k}" for k in range(50)])
    assert len({(s["color"], s["ls"]) for s in many.values()}) == 50


def test_the_readme_table_says_which_budget_each_column_is():
    """The headline's caption names the nominal budget, and the model-error budget of the held
    column where the rows have one (with its plants and strides, from `MISMATCH_BUDGETS`)."""
    head = load_headline(DOCS / "headline.json")
    with_held = render_block(head)
    caption = with_held.splitlines()[-2]
    assert f"r50 and σ: the **{head['budget']}** budget" in caption
    held = [r["held"] for r in head["rows"] if r.get("held")]
    if held:
        assert f"the model-error budget `{held[0]['budget']}` (" in caption
    bare = {**head, "rows": [{k: v for k, v in r.items() if k != "held"} for r in head["rows"]]}
    assert "model-error budget" not in render_block(bare)
