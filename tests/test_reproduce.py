"""`bound-env reproduce` on the quick budget: the report, its rows, figures, CSVs, the cache,
and that the numbers in the report come from the solvers."""

import json
import re
import time

import numpy as np
import pytest
import yaml

from bound_env.analysis.fixed_point import find_fixed_point
from bound_env.analysis.reproduce import run, write_gait_files
from bound_env.commands.cli import main
from bound_env.model.params import load_gait, z_to_paper

pytestmark = pytest.mark.slow  # the quick reproduction run takes ~20 s (idle)

REQUIRED_ROWS = (
    "z*: y_g",
    "z*: θ1",
    "z*: θ2",
    "z*: ẋ_g",
    "z*: θ̇1",
    "z*: θ̇2",
    "e_max at the published gait",
    "strides to converge",
    "stable α window",
    "stable kc window",
    "bs→df and df→fs interval",
    "damping constant from ζ",
    "gait type at and beyond the windows",
    "spine bends per stride",
    "body vibration amplitude",
    "α = 1.93 (text) vs 1.9343",
    "the stiff-spine branch reaches the published gait",
    "e_max close to 1 at large kc",
)
FIGURES = (
    "fig3_fixed_points_vs_kc",
    "fig4_parameters_vs_kc",
    "fig5_periodic_solution",
    "fig6_convergence",
    "fig7_emax_vs_alpha",
    "fig8_emax_vs_kc",
    "figL_literal_kc_path",
)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    t0 = time.perf_counter()
    res = run(out, quick=True, progress=False)
    return out, res, time.perf_counter() - t0


def _table_rows(text):
    rows = {}
    for line in text.splitlines():
        m = re.match(r"\| (\d+) \| ([^|]+) \| ([^|]*) \| ([^|]*) \|", line)
        if m:
            rows[m.group(2).strip()] = (m.group(3).strip(), m.group(4).strip())
    return rows


def test_report_has_every_required_row_and_section(quick):
    out, res, _ = quick
    text = (out / "REPRODUCTION.md").read_text()
    rows = _table_rows(text)
    for name in REQUIRED_ROWS:
        assert any(r.startswith(name) for r in rows), f"missing row {name!r}"
    for heading in (
        "## Headline",
        "## Every published number",
        "## The two readings of Table II side by side",
        "## Closest α and kc",
        "## The paper's path",
        "## The literal reading in detail",
        "## Edge case: a hip below its touchdown height",
    ):
        assert heading in text
    assert "quick mode" in text  # a quick report says so
    for name in FIGURES:
        assert (out / "figures" / f"{name}.png").stat().st_size > 5000
        assert (out / "figures" / f"{name}.csv").stat().st_size > 100
        assert f"](figures/{name}.png)" in text
    for link in re.findall(r"\]\((figures/[^)]+)\)", text):  # relative links resolve
        assert (out / link).is_file(), link
    data = json.loads((out / "results.json").read_text())
    assert set(data["compute_seconds"]) == {"reproducing", "closest", "sweeps", "stiff", "literal"}


def test_z_star_in_the_table_comes_from_newton(quick):
    out, res, _ = quick
    g = load_gait("paper")
    fp = find_fixed_point(g.params, g.z_published, recover=False)
    assert fp.converged
    z = z_to_paper(fp.z)
    rows = _table_rows((out / "REPRODUCTION.md").read_text())
    names = [r for r in rows if r.startswith("z*:")]
    assert len(names) == 6
    for i, name in enumerate(names):
        paper, ours = rows[name]
        assert float(paper) == pytest.approx(z_to_paper(g.z_published)[i])
        assert float(ours) == pytest.approx(z[i], abs=1e-4 if i >= 4 else 1e-6)
    assert np.allclose(res["reproducing"]["fixed_point"]["z"], z, rtol=0, atol=1e-8)
    assert res["reproducing"]["fixed_point"]["residual"] <= 1e-10


def test_findings_on_the_quick_budget(quick):
    _, res, _ = quick
    fp = res["reproducing"]["fixed_point"]
    assert fp["phases"] == ["df", "bs", "df", "fs", "df"] and 0.85 < fp["emax"] < 0.9
    assert res["reproducing"]["spine"]["count"] == 2
    paths = res["stiff"]["paths"]
    end = paths["speed"]["points"][-1]  # the speed-pinned path lands on z* at alpha = 1.9343
    assert end["kc"] == pytest.approx(295.0) and end["alpha_deg"] == pytest.approx(1.9343)
    assert np.max(np.abs(np.array(end["z"]) - np.array(fp["z"]))) < 1e-6
    assert (
        paths["energy_star"]["folds_kc"]
        and 315 < max(q["kc"] for q in paths["energy_star"]["points"]) < 330
    )  # the fold near kc = 322
    assert res["stiff"]["family_min_energy"]["energy"] > res["stiff"]["energy_star"]
    lit = res["literal"]["fixed_point"]
    assert lit is not None and lit["emax"] > 1.0 and lit["residual"] <= 1e-10
    assert res["literal"]["stride_from_published"]["failure"] == "leg_overcompressed_front"
    assert res["literal"]["kc_path"]["crossing"][0] > 900  # stable only for stiffer spines


def test_rerun_reads_the_cache(quick):
    out, res, first = quick
    files = sorted((out / "cache").glob("*.json"))
    assert len(files) == 5
    mtimes = [f.stat().st_mtime_ns for f in files]
    t0 = time.perf_counter()
    again = run(out, quick=True, progress=False)
    second = time.perf_counter() - t0
    assert again["cache"]["hits"] == ["reproducing", "closest", "sweeps", "stiff", "literal"]
    assert again["cache"]["misses"] == []
    assert [f.stat().st_mtime_ns for f in files] == mtimes
    assert again["reproducing"]["fixed_point"]["z"] == res["reproducing"]["fixed_point"]["z"]
    assert second < first


def test_cli_and_docs_copy(quick, tmp_path, capsys):
    out, _, _ = quick
    docs = tmp_path / "docs"
    assert main(["reproduce", "--out", str(out), "--quick", "--quiet", "--docs", str(docs)]) == 0
    assert "cached stages: reproducing, closest, sweeps, stiff, literal" in capsys.readouterr().out
    text = (docs / "REPRODUCTION.md").read_text()
    for link in re.findall(r"\]\((figures/[^)]+)\)", text):
        assert (docs / link).is_file(), link
    assert not list((docs / "figures").glob("*.csv"))


def test_gait_files(quick, tmp_path):
    _, res, _ = quick
    paths = write_gait_files(res, tmp_path)
    assert [p.name for p in paths] == ["default.yaml", "literal-cycle.yaml"]
    d = load_gait(tmp_path / "default.yaml")
    ref = load_gait("paper")
    assert d.params == ref.params
    np.testing.assert_allclose(d.z_published, ref.z_published)
    raw = yaml.safe_load((tmp_path / "default.yaml").read_text())
    for key in (
        "z_star",
        "eigenvalues",
        "emax",
        "phases",
        "durations",
        "found_by",
        "h_b_unused",
        "h_f_unused",
        "reading",
    ):
        assert key in raw, key
    assert all(len(e) == 2 for e in raw["eigenvalues"]) and raw["residual"] <= 1e-10
    fp = find_fixed_point(d.params, d.z_star, recover=False, analyse=False)
    assert fp.converged and fp.iterations == 0  # z_star is already a fixed point
    lit = load_gait(tmp_path / "literal-cycle.yaml")
    assert lit.params == load_gait("paper-literal").params
    lraw = yaml.safe_load((tmp_path / "literal-cycle.yaml").read_text())
    assert lraw["emax"] > 1.0 and lraw["residual"] <= 1e-10
