"""The results page's model-error section (issue 49): `bound-env compare` measures its own
columns under pm10, pm15 and pm10+noise at the model-error budget ``page`` by default
(``--no-mismatch`` leaves it out, ``--mismatch`` keeps its old meaning), the section renders
them paired against lqr with mpc-privileged marked, and the headline gains "held at ±10 % /
±15 %" (agents/results/compare.py, page.py, page_inputs.py, headline.py)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from agents.results import compare as compare_mod
from agents.results.compare import (
    MODEL_ERROR_SPECS,
    model_error_budget,
    model_error_entries,
    run_model_error,
)
from agents.results.headline import add_held, headline_table, held_at, load_headline
from agents.results.margins import compute_margins
from agents.results.page import model_error_section
from agents.results.page_inputs import load_model_error
from bound_env.analysis.margins.model_error.mismatch_tasks import MISMATCH_BUDGETS
from bound_env.model.mismatch import parse_specs


def test_the_sections_columns_specs_and_budget():
    labels = [lab for lab, _ in model_error_entries()]
    assert labels[:5] == ["passive", "lqr", "mpc", "default", "mpc-adaptive"]
    assert labels[-1] == "mpc-privileged" and "adaptive" in labels  # shipped: s0
    assert MODEL_ERROR_SPECS == ("pm10", "pm15", "pm10+noise")
    page = MISMATCH_BUDGETS[model_error_budget("full")]
    assert page.name == "page" and page.plants == 32 and page.hold_strides == 100
    assert page.mfpt_sigmas == () and page.curve_sizes == (0.05, 0.1, 0.2, 0.3, 0.4)
    assert model_error_budget("test") == "test"


@pytest.fixture(scope="module")
def lqr_under_error(tmp_path_factory):
    """lqr's model-error measures alone (nominal=False) and with its margins, test budget."""
    tmp = tmp_path_factory.mktemp("me")
    specs = parse_specs("pm10,pm15")
    kw = dict(budget="test", mismatch=specs, mismatch_budget="test")
    alone = compute_margins("lqr", out=tmp / "alone", nominal=False, **kw)
    return tmp, specs, alone


def test_the_model_error_measures_alone_are_those_of_a_whole_run(lqr_under_error):
    """``nominal=False`` runs the cycle and the model-error tasks only, writes margins.json
    only, and its blocks are those of a run of every measure (same plants, same numbers)."""
    tmp, specs, alone = lqr_under_error
    assert alone["nominal"] is False and "basin_curve" not in alone
    assert alone["tasks"]["computed"] == 1 + 2 * (1 + 2 + 1)  # cycle; hold, 2 sizes, 1 MFPT
    assert sorted(p.name for p in (tmp / "alone").iterdir()) == ["cache.jsonl", "margins.json"]
    whole = compute_margins("lqr", budget="test", mismatch=specs, mismatch_budget="test")
    for name in ("pm10", "pm15"):
        a, b = dict(alone["mismatch"][name]), dict(whole["mismatch"][name])
        a.pop("decision_times"), b.pop("decision_times")  # wall times
        assert json.dumps(a) == json.dumps(b), name
    with pytest.raises(ValueError, match="--mismatch"):
        compute_margins("lqr", budget="test", nominal=False)
    with pytest.raises(ValueError, match="budgets"):
        compute_margins("lqr", budget="test", mismatch=specs, mismatch_budget="nope")


def _fake_section(tmp, lqr: dict, budget="test", seed=12345):
    """Every section column's margins.json, lqr's numbers under each label (mpc-privileged's
    blocks marked privileged)."""
    for label, _ in model_error_entries():
        r = json.loads(json.dumps(lqr))
        if label == "mpc-privileged":
            for b in r["mismatch"].values():
                b["privileged"] = True
        d = tmp / "model-error" / label
        d.mkdir(parents=True, exist_ok=True)
        r["budget"], r["seed"] = budget, seed
        (d / "margins.json").write_text(json.dumps(r))


def test_the_section_renders_from_its_columns(tmp_path, lqr_under_error):
    _, specs, alone = lqr_under_error
    _fake_section(tmp_path, alone)
    groups = run_model_error("test", tmp_path, 12345, render_only=True, specs=("pm10", "pm15"))
    assert [g["label"] for g in groups] == [lab for lab, _ in model_error_entries()]
    text = model_error_section(groups)
    assert text.startswith("\n## Model error\n") and "model-error budget `test`" in text
    assert "### pm10" in text and "### pm15" in text
    assert "mpc-privileged (**privileged**: reads the true plant)" in text
    held = held_at(groups)
    k = alone["mismatch"]["pm10"]["hold"]["k"]
    assert held["default"]["pm10"] == {"k": k, "n": 8}
    assert model_error_section([]) == ""


def test_render_only_names_the_file_of_a_missing_or_wrong_column(tmp_path, lqr_under_error):
    _, specs, alone = lqr_under_error
    path = tmp_path / "margins.json"
    with pytest.raises(ValueError, match="no model-error result"):
        load_model_error(path, "test", 12345, specs, "test")
    path.write_text(json.dumps({**alone, "budget": "test", "seed": 12345}))
    with pytest.raises(ValueError, match="not of the page budget"):
        load_model_error(path, "test", 12345, specs, "page")
    with pytest.raises(ValueError, match="'pm10\\+noise'"):
        load_model_error(path, "test", 12345, parse_specs("pm10+noise"), "test")
    with pytest.raises(ValueError, match="budget 'full'"):
        load_model_error(path, "full", 12345, specs, "test")
    assert load_model_error(path, "test", 12345, specs[:1], "test")["mismatch"].keys() == {"pm10"}


def _head():
    m = {"value": 0.2, "low": 0.1, "high": 0.3, "interval": "Wilson-based"}
    rows = [
        {"role": r, "label": lab, "what": "w", "r50": m, "mfpt_sigma_100_deg": m}
        for r, lab in (("lqr", "lqr"), ("best learned", "fine-tuned"), ("x", "step-ppo"))
    ]
    return {"budget": "full", "seed": 12345, "rows": rows}


def test_the_headline_gains_held_at_10_and_15_percent(tmp_path):
    plain = headline_table(_head())
    assert "held at" not in plain  # a page without its section: the table as before
    held = {
        "lqr": {"pm10": {"k": 20, "n": 32}, "pm15": {"k": 9, "n": 32}},
        "default": {"pm10": {"k": 25, "n": 32}, "pm15": {"k": 14, "n": 32}},
    }
    head = add_held(_head(), held, "page")
    table = headline_table(head)
    assert "| held at ±10 % / ±15 % (model-error budget `page`) |" in table.splitlines()[0]
    lines = table.splitlines()
    assert lines[2].endswith("| 20/32 / 9/32 |")
    assert lines[3].endswith("| 25/32 / 14/32 (`default`) |")  # the best learned's s0
    assert lines[4].endswith("| not measured |")
    path = tmp_path / "headline.json"
    path.write_text(json.dumps(head))
    assert headline_table(load_headline(path)) == table
    head["rows"][0]["held"]["pm15"]["k"] = "9"
    path.write_text(json.dumps(head))
    with pytest.raises(ValueError, match=r"rows\[0\]\.held\.pm15\.k must be int"):
        load_headline(path)


@pytest.mark.parametrize(
    "argv, model_error, mismatch",
    [
        ([], True, None),
        (["--no-mismatch"], False, None),
        (["--entry", "lqr"], False, None),
        (["--entry", "lqr", "--keep-defaults"], True, None),
        (["--mismatch", "pm5"], True, ["pm5"]),  # compare measures every column instead
    ],
)
def test_the_section_is_on_by_default_for_the_pages_own_columns(
    monkeypatch, tmp_path, argv, model_error, mismatch
):
    from bound_env.commands.cli import main

    seen = {}

    def fake(entries, **kw):
        seen.update(kw)
        return tmp_path / "MARGINS.md"

    monkeypatch.setattr(compare_mod, "compare", fake)
    assert main(["compare", "--no-progress", "--out", str(tmp_path), *argv]) == 0
    assert seen["model_error"] is model_error
    assert [s.name for s in seen["mismatch"] or []] == (mismatch or [])


def test_the_page_gets_its_section_and_the_headline_its_held_column(tmp_path, lqr_under_error):
    """``compare(model_error=True)`` (rendered from the test fixture's passive and lqr
    columns and the section's columns): the page ends with its Model error section,
    headline.json's rows carry their hold, model_error.json names its budget and
    columns.json each section column's time; with ``mismatch`` the section is not run."""
    data = Path(__file__).resolve().parent / "data" / "render_only"
    out, docs = tmp_path / "out", tmp_path / "docs"
    shutil.copytree(data / "out", out)
    docs.mkdir()
    shutil.copyfile(data / "paired.input.json", docs / "paired.json")
    _fake_section(out, lqr_under_error[2])
    cols = [("passive", ["passive"], "default"), ("lqr", ["lqr"], "default")]
    kw = dict(budget="test", out=out, docs=docs, render_only=True, progress=False)
    with pytest.raises(ValueError, match="model-error block 'pm10\\+noise'"):
        compare_mod.compare(cols, model_error=True, **kw)  # the fixture has pm10 and pm15 only
    specs = ("pm10", "pm15")
    real = compare_mod.run_model_error
    compare_mod.run_model_error = lambda *a, **k: real(*a, **k, specs=specs)
    try:
        page = compare_mod.compare(cols, model_error=True, **kw).read_text()
    finally:
        compare_mod.run_model_error = real
    assert "\n## Model error\n" in page and "(**privileged**: reads the true plant)" in page
    head = json.loads((docs / "headline.json").read_text())
    lqr = next(r for r in head["rows"] if r["label"] == "lqr")
    assert lqr["held"]["pm10"]["n"] == 8 and lqr["held"]["budget"] == "test"
    assert "held at ±10 % / ±15 %" in page.split("## Headline", 1)[1].split("##", 1)[0]
    me = json.loads((docs / "model_error.json").read_text())
    assert me["mismatch_budget"] == "test" and [s["name"] for s in me["specs"]] == ["pm10", "pm15"]
    times = json.loads((docs / "columns.json").read_text())["model_error"]
    assert [c["label"] for c in times] == [lab for lab, _ in model_error_entries()]
    assert all("cpu_seconds" in c and "r50" not in c for c in times)
    page = compare_mod.compare(cols, model_error=False, **kw).read_text()
    assert "## Model error" not in page
