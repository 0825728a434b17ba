"""``bound-env compare``: its columns (``--entry``, ``--keep-defaults``) and ``--render-only``.

The page is rewritten from a fixture (tests/data/render_only: a test-budget ``margins.json``
of passive and of lqr, as `compute_margins` wrote them, and a ``paired.json`` with decision
times) and must equal, byte for byte, what the code before the split of agents/results/compare.py
made from the same files (``MARGINS.md``, ``headline.json`` and ``paired.expected.json`` beside
them; four later, deliberate changes of the page applied to ``MARGINS.md``: the
reproducibility paragraph quotes differences, not an older page's numbers, the full table
is split with the headline columns first, `agents.results.table_split`, a table inside
``<details markdown="1">`` so that it renders, and a provenance that names the test set, not
"this page", which a user's page of another budget is not). A malformed
``margins.json``, ``paired.json`` or ``headline.json`` is one line naming the file and the key,
exit 2, never a traceback.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from agents.results.compare import chosen_entries, default_entries, parse_entry

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data" / "render_only"


def _labels(entries):
    return [e[0] for e in entries]


def test_entry_drops_the_default_columns_but_passive():
    assert _labels(chosen_entries([parse_entry("lqr")])) == ["passive", "lqr"]
    # the default-gait passive given as an entry replaces the default passive column
    assert _labels(chosen_entries([parse_entry("mine=passive")])) == ["mine"]


def test_keep_defaults_keeps_every_default_column():
    defaults = _labels(default_entries())
    assert {"passive", "lqr", "mpc"} <= set(defaults)
    extra = ("extra=" + str(ROOT / "agents" / "policies" / "literal-cycle"), "lqr@literal-cycle")
    parsed = [parse_entry(t) for t in extra]
    got = _labels(chosen_entries(parsed, keep_defaults=True))
    assert got[: len(defaults)] == [d for d in defaults if d not in ("extra", "lqr literal-cycle")]
    assert got[-2:] == ["extra", "lqr literal-cycle"]
    # an entry named like a default column replaces it, it is not a second column
    again = _labels(chosen_entries([parse_entry("lqr")], keep_defaults=True))
    assert again.count("lqr") == 1 and again[-1] == "lqr" and len(again) == len(defaults)
    # no entries: the defaults, with or without the flag
    assert _labels(chosen_entries([], keep_defaults=True)) == defaults
    assert _labels(chosen_entries([])) == defaults


def test_keep_defaults_on_the_command_line(monkeypatch):
    import agents.results.compare as compare_mod
    from bound_env.commands.cli import main

    seen = {}

    def fake(entries, **kwargs):
        seen["entries"] = entries
        return Path(kwargs["docs"]) / "MARGINS.md"

    monkeypatch.setattr(compare_mod, "compare", fake)
    args = ["compare", "--entry", "lqr@literal-cycle", "--no-progress", "--out", "/tmp/x"]
    assert main([*args, "--keep-defaults"]) == 0
    assert _labels(seen["entries"]) == _labels(default_entries()) + ["lqr literal-cycle"]
    assert main(args) == 0
    assert _labels(seen["entries"]) == ["passive", "lqr literal-cycle"]


def _fixture(tmp_path):
    out, docs = tmp_path / "out", tmp_path / "docs"
    shutil.copytree(DATA / "out", out)
    docs.mkdir()
    shutil.copyfile(DATA / "paired.input.json", docs / "paired.json")
    return out, docs


def _render_here(out, docs, capsys):
    """``bound-env compare --render-only --entry lqr`` in this process (no interpreter start
    each)."""
    from types import SimpleNamespace

    from bound_env.commands.cli import main

    argv = ["compare", "--budget", "test", "--render-only", "--no-progress", "--entry", "lqr"]
    code = main([*argv, "--out", str(out), "--docs", str(docs)])
    cap = capsys.readouterr()
    return SimpleNamespace(returncode=code, stdout=cap.out, stderr=cap.err)


def test_render_only_reproduces_the_page_byte_for_byte(tmp_path, capsys):
    """The renderer split into agents/results/page.py & co. writes what the old compare.py wrote."""
    out, docs = _fixture(tmp_path)
    r = _render_here(out, docs, capsys)
    assert r.returncode == 0, r.stderr
    assert (docs / "MARGINS.md").read_bytes() == (DATA / "MARGINS.md").read_bytes()
    assert (docs / "headline.json").read_bytes() == (DATA / "headline.json").read_bytes()
    assert (docs / "paired.json").read_bytes() == (DATA / "paired.expected.json").read_bytes()


def test_a_users_columns_sit_in_the_headline_and_their_page_is_theirs(tmp_path, capsys):
    """``--entry mine=...``: a headline row of its own beside passive and lqr, and a page that
    says nothing about the project's own page (its measured reproducibility, the literal
    reading's columns, its basin maps); columns.json has every column, with its
    fingerprints (none in this fixture, made before them)."""
    from bound_env.commands.cli import main

    out, docs = _fixture(tmp_path)
    shutil.copytree(out / "lqr", out / "mine")
    argv = ["compare", "--budget", "test", "--render-only", "--no-progress", "--entry", "lqr"]
    argv += ["--entry", "mine=lqr", "--out", str(out), "--docs", str(docs)]
    assert main(argv) == 0, capsys.readouterr().err
    head = json.loads((docs / "headline.json").read_text())
    assert [r["label"] for r in head["rows"]] == ["passive", "lqr", "mine"]
    assert head["rows"][-1]["what"] == "your column: `lqr`"
    page = (docs / "MARGINS.md").read_text()
    table = page.split("## Headline", 1)[1].split("##", 1)[0]
    assert "| **mine** | your column: `lqr` |" in table
    for project in ("**Reproducibility.**", "The literal reading of Table II", "## Basin maps"):
        assert project not in page, project
    cols = json.loads((docs / "columns.json").read_text())
    assert [c["label"] for c in cols["columns"]] == ["passive", "lqr", "mine"]
    assert cols["run"] is None  # a rewrite of columns no recorded run computed
    # the project's own page (its default columns) keeps them: the byte-for-byte fixture
    assert "**Reproducibility.**" in (DATA / "MARGINS.md").read_text()


def _edit(path: Path, change):
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    "file, change, key",
    [
        (
            "out/lqr/margins.json",
            lambda d: d["basin"]["theta1"]["+"].pop("rel"),
            "basin.theta1.+.rel",
        ),
        ("out/lqr/margins.json", lambda d: d.update(settings=[1, 2]), "settings"),
        ("out/lqr/margins.json", lambda d: d["basin_curve"].update(sizes="x"), "sizes"),
        ("out/passive/margins.json", lambda d: d["push"].pop("xdot"), "push.xdot"),
        ("out/passive/margins.json", lambda d: d.update(mfpt=[{"sigma_deg": 1}]), "mfpt.0"),
        ("out/passive/margins.json", lambda d: d["terrain"]["survival"].pop(), "terrain"),
        (
            "docs/paired.json",
            lambda d: d["decision_times"]["controllers"].update(mpc={"p50": "fast"}),
            "decision_times.controllers.mpc.p50",
        ),
        ("docs/paired.json", lambda d: d.update(decision_times=[]), "decision_times"),
    ],
)
def test_render_only_names_the_file_and_key_of_a_malformed_input(
    tmp_path, capsys, file, change, key
):
    out, docs = _fixture(tmp_path)
    _edit(tmp_path / file, change)
    r = _render_here(out, docs, capsys)
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert Path(file).name in lines[0] and key in lines[0], lines[0]


@pytest.mark.parametrize("text", ["[", "[1, 2]", '"x"'])
def test_render_only_refuses_a_paired_json_that_is_not_an_object(tmp_path, capsys, text):
    out, docs = _fixture(tmp_path)
    (docs / "paired.json").write_text(text)
    r = _render_here(out, docs, capsys)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "paired.json" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize(
    "change, key",
    [
        (lambda d: d["rows"][0]["r50"].pop("value"), "rows[0].r50.value"),
        (lambda d: d["rows"][0].update(what=3), "rows[0].what"),
        (lambda d: d.pop("budget"), "budget"),
        (lambda d: d["rows"].append("x"), "rows[2]"),
    ],
)
def test_a_malformed_headline_json_is_one_line(tmp_path, capsys, change, key):
    from agents.results.headline import main

    bad = tmp_path / "headline.json"
    shutil.copyfile(DATA / "headline.json", bad)
    _edit(bad, change)
    readme = tmp_path / "README.md"
    readme.write_text("<!-- headline:start -->\n<!-- headline:end -->\n")
    assert main(["--json", str(bad), "--readme", str(readme), "--check"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "headline.json" in err[0] and key in err[0], err


@pytest.mark.slow  # about 40 renders of the page
def test_no_top_level_key_of_margins_json_can_crash_the_page(tmp_path):
    """Without any one of its top-level keys, a margins.json renders or is one ValueError
    naming the file: never a KeyError, TypeError or AttributeError."""
    from agents.results.compare import compare

    keys = list(json.loads((DATA / "out" / "lqr" / "margins.json").read_text()))
    for k, key in enumerate(keys):
        out, docs = _fixture(tmp_path / str(k))
        _edit(out / "lqr" / "margins.json", lambda d, key=key: d.pop(key))
        entries = [("passive", ["passive"], "default"), ("lqr", ["lqr"], "default")]
        try:
            compare(entries, budget="test", out=out, docs=docs, progress=False, render_only=True)
        except ValueError as e:
            assert "margins.json" in str(e) and "\n" not in str(e), (key, e)
